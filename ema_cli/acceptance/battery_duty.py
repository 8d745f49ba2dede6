"""The acceptance battery's ``duty`` test: a mission profile (``ema duty``) on every actuator of
``units``, the blocks' kernel batches shared, each unit's thermal history integrated on its own
(``duty.run``). The measurements are ``ema duty``'s; the winding temperature is a bound when it
lies within the multirate method's error of its limit or a segment's cycle was not steady
(``duty.summary``), and then decides only when the whole bound is on one side of the limit."""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

from ema_cli.acceptance.measurement import TestRun
from ema_cli.config.acceptance import DutyTest
from ema_cli.errors import EmaError


def insulation_k(word: str) -> float:
    """An insulation class (A E B F H N R) or a temperature ('150 degC') -> its limit [K]."""
    from ema_cli.model.thermal import INSULATION_CLASSES
    from ema_cli.units import ZERO_CELSIUS, parse_temperature

    if word.strip().upper() in INSULATION_CLASSES:
        return INSULATION_CLASSES[word.strip().upper()] + ZERO_CELSIUS
    try:
        return parse_temperature(word)
    except ValueError as exc:
        raise EmaError(f"insulation: expected a class ({' '.join(INSULATION_CLASSES)}) or a "
                       f"temperature such as '150 degC' ({exc})") from None


def run_duty(name: str, test: DutyTest, units: Sequence[Mapping[str, float]],
             dt: float) -> list[TestRun]:
    from ema_cli.acceptance.duty.run import Limits, run_units

    prof = test.load_profile()
    class_k = insulation_k(test.insulation)
    lim = test.limits.get("winding_temperature")
    winding_k = lim.si()[1] if lim is not None and lim.max is not None else class_k
    limits = Limits(winding_k, class_k, prof.life.insulation_life_h, test.insulation)
    _, runs = run_units(prof, units, prof.simulation.dt_s or dt, limits, "rotary", hot=False,
                        margin=False)
    out = []
    for r in runs:
        tr = r.thermal.trace
        out.append(TestRun(name, "duty", r.measurements,
                           {"t": np.asarray(tr.t), "t_w": np.asarray(tr.t_w),
                            "peak": np.asarray(tr.peak), "t_h": np.asarray(tr.t_h),
                            "ambient": np.asarray(tr.ambient), "profile": prof.name},
                           notes=list(r.notes)))
    return out
