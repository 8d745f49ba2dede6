"""One vocabulary for the values that are not plain numbers, in every command, table and report.

A value is printed as a number with its unit (4 significant digits), or in the same words
wherever it appears (``margins``, ``acceptance``, ``yield.md``, ``design.md``, the API's tables):

- a value known only by a bound: ``> 109.4 dB``, ``<= 0.0001 s``, ``1..2 s`` (:func:`bound`);
- a margin whose loop never crosses: ``no phase crossover`` (gain margin), ``no gain crossover``
  (phase margin), followed by the bound a simulation measured when there is one:
  ``no phase crossover (> 109.4 dB)`` (:func:`quantity`);
- nothing known: ``not measured``; a step that never settles: ``not settled within 1 s``;
- a negative free play says what it means (:func:`free_play`).

Below the computing layers (imports only ``units``): ``cli/``, ``report/`` and ``api/`` use it.
"""

from __future__ import annotations

import math
from typing import Any

from ema_cli.units import fmt_num

NOT_MEASURED = "not measured"
NO_CROSSOVER = {"gain_margin": "no phase crossover", "phase_margin": "no gain crossover"}
"""What an infinite margin means (the metric names of the acceptance battery)."""
MARGIN_OF = {"gm_db": "gain_margin", "pm_deg": "phase_margin"}
"""The linear model's margin fields -> the acceptance metric they are."""


def number(value: float | None, unit: str = "", digits: int = 4) -> str:
    """A measured number with its unit (``12.3 dB``); NaN -> ``not measured``, an infinity
    -> ``∞`` / ``-∞`` (with the unit)."""
    if value is None:
        return NOT_MEASURED
    return fmt_num(value, unit, digits, nan=NOT_MEASURED, inf=None, neg_inf=None).replace(
        "inf", "∞")


def bound(lower: float, upper: float, unit: str = "", digits: int = 4) -> str:
    """A value known only to lie in ``[lower, upper]``: ``> lower`` (no upper end), ``<= upper``
    (no positive lower end), ``lower..upper``, or ``not measured`` when neither end says
    anything."""
    u = f" {unit}" if unit and unit != "-" else ""
    lo_ok = math.isfinite(lower) and lower > 0
    hi_ok = math.isfinite(upper)
    if lo_ok and not hi_ok:
        return f"> {lower:.{digits}g}{u}"
    if hi_ok and not lo_ok:
        return f"<= {upper:.{digits}g}{u}"
    if lo_ok and hi_ok:
        return f"{lower:.{digits}g}..{upper:.{digits}g}{u}"
    return NOT_MEASURED


def quantity(value: float, unit: str = "", *, metric: str = "", measured: bool = True,
             lower: float = math.nan, upper: float = math.nan, note: str | None = None,
             digits: int = 4) -> str:
    """One quantity as every command prints it: the number when ``measured``, else the bound
    it is known by; a margin (``metric`` gain_margin / phase_margin) that is infinite, or known
    only from below, leads with its words: ``no phase crossover`` /
    ``no phase crossover (> 109.4 dB)`` (``note``: when given, the bound leads with the words
    only if the note says them)."""
    word = NO_CROSSOVER.get(metric, "")
    if measured:
        if word and isinstance(value, float | int) and math.isinf(value) and value > 0:
            return word
        return number(value, unit, digits)
    text = bound(lower, upper, unit, digits)
    if (word and math.isfinite(lower) and not math.isfinite(upper)
            and (note is None or word in note)):
        return f"{word} ({text})"
    return text


def verdict_text(v: Any) -> str:
    """A verdict row's value (``acceptance.verdict.Verdict``: value, unit, metric, measured,
    lower, upper, note) in the words of :func:`quantity`."""
    return quantity(v.value, v.unit, metric=v.metric, measured=v.measured, lower=v.lower,
                    upper=v.upper, note=v.note)


def margin_text(value: float, metric: str) -> str:
    """A margin of the linear model (dB or deg; infinite or NaN where the loop never crosses)
    in the words :func:`quantity` uses: ``no phase crossover`` or ``12.3 dB``."""
    unit = "dB" if metric == "gain_margin" else "deg"
    v = math.inf if not math.isfinite(value) else value
    return quantity(v, unit, metric=metric)


def not_settled(within_s: float) -> str:
    """``not settled within 1 s``: a settling time the run never reached."""
    return f"not settled within {within_s:g} s"


def free_play(value: float, unit: str = "deg", digits: int = 4) -> str:
    """A fitted or measured free play; a negative one says what it means (the two sides
    overlap: a preload or an interference, no lost motion)."""
    text = number(value, unit, digits)
    if math.isfinite(value) and value < 0:
        return f"{text} (negative: the flanks overlap, a preload, no lost motion)"
    return text
