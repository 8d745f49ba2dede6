"""The verdicts of the acceptance battery: each measurement against its limit, PASS, FAIL or
INCONCLUSIVE (a value known only as a bound that straddles the limit), and the battery's
overall verdict and exit code (docs/model.md §9).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from ema_cli.acceptance.battery import Measurement, TestRun

PASS, FAIL, INCONCLUSIVE = "PASS", "FAIL", "INCONCLUSIVE"
EXIT_CODES = {PASS: 0, FAIL: 1, INCONCLUSIVE: 3}
"""``ema acceptance``'s exit code per overall verdict (2 stays bad usage or input)."""


@dataclass(frozen=True)
class Verdict:
    """One row of the verdict table: a measurement against its limit, in the limit's unit.

    ``result`` is PASS or FAIL for a measured value; for a bound (``measured`` false, the
    value known only to lie in ``[lower, upper]``) PASS or FAIL only when the whole interval
    lies inside or outside the limit, else INCONCLUSIVE with ``reason`` naming the setting to
    change. A value that is not a number (a diverged run) is INCONCLUSIVE. ``lower`` and
    ``upper`` (in ``unit``) equal ``value`` for a measured value."""

    test: str
    kind: str
    metric: str
    condition: str
    value: float
    min: float | None
    max: float | None
    unit: str
    result: str
    measured: bool
    lower: float
    upper: float
    value_si: float
    si_unit: str
    note: str
    reason: str

    @property
    def passed(self) -> bool:
        return self.result == PASS


def judge(m: Measurement, lo: float, hi: float) -> tuple[str, str]:
    """(PASS | FAIL | INCONCLUSIVE, reason) of ``m`` against the SI bounds ``lo``..``hi``."""
    if m.measured:
        if math.isnan(m.value):
            return INCONCLUSIVE, "not measured (the simulation diverged: check the actuator " \
                                 "or reduce simulation.dt_s)"
        return (PASS if lo <= m.value <= hi else FAIL), ""
    if lo <= m.lower and m.upper <= hi:
        return PASS, ""
    if m.upper < lo or m.lower > hi:
        return FAIL, ""
    return INCONCLUSIVE, m.reason


def overall(results: list[str]) -> str:
    """FAIL if any row fails, else INCONCLUSIVE if any is inconclusive, else PASS."""
    if FAIL in results:
        return FAIL
    return INCONCLUSIVE if INCONCLUSIVE in results else PASS


def verdicts(run: TestRun, limits: Mapping[str, Any]) -> list[Verdict]:
    """Each measurement of ``run`` with a limit, compared in SI (:func:`judge`)."""
    from ema_cli.units import from_si

    out = []
    for m in run.measurements:
        lim = limits.get(m.metric)
        if lim is None:
            continue
        lo, hi = lim.si()
        result, reason = judge(m, lo, hi)
        note = m.note
        if not m.measured and result != INCONCLUSIVE:  # the bound, without the advice
            bound = m.reason.rsplit(": ", 1)[0]
            note = "; ".join(x for x in (note, f"decided on a bound: {bound}")
                             if x and x not in bound)
        lower, upper = (m.value, m.value) if m.measured else (m.lower, m.upper)
        out.append(Verdict(run.name, run.kind, m.metric, m.condition,
                           from_si(m.value, lim.unit), lim.min, lim.max, lim.unit, result,
                           m.measured, from_si(lower, lim.unit), from_si(upper, lim.unit),
                           m.value, m.si_unit, note, reason))
    return out
