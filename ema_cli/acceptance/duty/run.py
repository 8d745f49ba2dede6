"""A duty run: the profile's blocks simulated (``duty.mechanics``), the thermal network
integrated over the profile (``duty.thermal``), the figures of merit and the measurements
(``duty.summary``), the hot actuator (``duty.hot``), for one actuator or a batch of them
(``ema yield``: the blocks' kernel batches shared). Compute only: nothing is written.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

from ema_cli.acceptance.duty.hot import HotCheck
from ema_cli.acceptance.duty.mechanics import BlockRun, simulate_blocks
from ema_cli.acceptance.duty.profile import Expanded, expand
from ema_cli.acceptance.duty.summary import Stats, current_margin, measurements, stats
from ema_cli.acceptance.duty.thermal import Network, Thermal, integrate
from ema_cli.acceptance.measurement import Measurement
from ema_cli.config.duty import DutyProfile
from ema_cli.errors import EmaError
from ema_cli.model.thermal import continuous_current


@dataclass
class Limits:
    """The winding's temperature limit [K] (the verdict's, or the insulation's), the
    insulation class temperature the 10 K rule counts from [K] and its reference life [h]."""

    winding_k: float
    class_k: float
    insulation_life_h: float
    class_name: str = ""


@dataclass
class DutyRun:
    """One actuator through the profile: its blocks, thermal history, figures of merit,
    measurements (SI), the continuous current at the profile's ambient and the limit [A], the
    hot check (None when skipped), notes and the time each stage took [s]."""

    params: dict[str, float]
    runs: list[BlockRun]
    thermal: Thermal
    stats: Stats
    measurements: list[Measurement]
    continuous_current: float
    hot: HotCheck | None = None
    notes: list[str] = field(default_factory=list)
    timings: dict[str, float] = field(default_factory=dict)


def winding_limit(prof: DutyProfile, class_k: float) -> float:
    """The winding limit the verdict uses: the profile's winding_temperature max, else the
    insulation class's [K]."""
    lim = prof.limits.get("winding_temperature")
    if lim is not None and lim.max is not None:
        return lim.si()[1]
    return class_k


def run_units(prof: DutyProfile, units: Sequence[Mapping[str, float]], dt: float,
              limits: Limits, axis: str = "rotary", *, hot: bool = False,
              margin: bool = True,
              progress: Callable[[str, int, int], None] | None = None
              ) -> tuple[Expanded, list[DutyRun]]:
    """Run the profile on every actuator of ``units`` (SI parameters, step ``dt`` [s]) ->
    (the expanded profile, one :class:`DutyRun` per unit). ``hot``: the hot check (one more
    pair of acceptance tests per unit); ``margin``: the current margin (a few more thermal
    integrations)."""
    if not units:
        raise EmaError("duty: no actuator to run")
    for p in units:
        if not p["Kt"] > 0:
            raise EmaError("duty: the actuator's drive gives no current (an amplifier without "
                           "drive.torque_constant): copper losses need it")
    t0 = time.perf_counter()
    exps = [expand(prof, axis, p["T_amb"], dt) for p in units]
    exp = exps[0]
    notes = []
    if prof.ambient is not None and len({p["T_amb"] for p in units}) > 1:
        notes.append("the profile's ambient holds for every unit: their T_amb (a tolerance?) "
                     "is not used; leave ambient out of the profile to use it")
    runs_by_unit = simulate_blocks(exps, units, dt, prof.simulation.settle_s, limits.winding_k,
                                   prof.life.exponent, progress)
    t_mech = time.perf_counter() - t0
    rating = None
    if prof.life.dynamic_load_rating is not None:
        from ema_cli.units import parse_quantity

        try:
            rating = parse_quantity(prof.life.dynamic_load_rating, "force", axis)
        except ValueError as exc:
            raise EmaError(f"life.dynamic_load_rating: {exc}") from None
    out = []
    for e, p, runs in zip(exps, units, runs_by_unit, strict=True):
        t1 = time.perf_counter()
        net = Network.of(p)
        th = integrate(e, runs, net, limits.winding_k, limits.class_k)
        k = current_margin(e, runs, net, limits.winding_k, limits.class_k, th) if margin \
            else math.nan
        st = stats(e, runs, p, th, rating, prof.life.exponent, k)
        meas = measurements(st, th, runs, e, limits.winding_k, limits.insulation_life_h)
        amb = e.blocks[e.order[0]].ambient_k
        run = DutyRun(dict(p), runs, th, st, meas, continuous_current(p, limits.winding_k, amb))
        run.notes = notes + [n for r in runs for n in r.notes]
        run.timings = {"mechanics_s": t_mech / len(units),
                       "thermal_s": time.perf_counter() - t1}
        if hot:
            t2 = time.perf_counter()
            if axis != "rotary":
                run.notes.append("hot check skipped: the acceptance battery's frequency "
                                 "response reports a rotary axis")
            else:
                from ema_cli.acceptance.duty.hot import hot_check

                run.hot = hot_check(p, min(b.ambient_k for b in e.blocks), th.peak_w, dt)
            run.timings["hot_s"] = time.perf_counter() - t2
        out.append(run)
    return exp, out


def profile_seconds(prof: DutyProfile, dt: float) -> float:
    """The simulated seconds of the profile's block windows for one actuator at two
    resistances (what the acceptance battery's step estimate needs) [s]."""
    from ema_cli.acceptance.duty.mechanics import window

    try:
        exp = expand(prof, "rotary", 313.15, dt)
    except EmaError:
        return 0.0
    return 2.0 * sum(window(b, prof.simulation.settle_s).length for b in exp.blocks)


def describe(exp: Expanded) -> list[dict[str, Any]]:
    """The distinct blocks for reports (SI)."""
    return [{"key": b.key, "label": b.label, "kind": b.kind, "period_s": b.period,
             "count": b.count, "duration_s": b.duration, "ambient_k": b.ambient_k,
             "start": b.start, "end": b.end, "spring": b.spring} for b in exp.blocks]
