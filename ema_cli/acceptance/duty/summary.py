"""A duty run's figures of merit from its blocks and its thermal history: RMS and peak current
and torque, the torque-speed envelope, the equivalent load and L10 life, the insulation's life,
the energy, the current margin, and the measurements the verdict judges.

Over one pass of the profile (duration ``T``), each block contributing its transient piece
once and its steady cycle ``n_rest`` times (``duty.mechanics``)::

    I_rms = sqrt(integral i^2 dt / T)            T_rms = sqrt(integral T_m^2 dt / T)
    P_eq  = (integral |F|^p |v| dt / integral |v| dt)^(1/p)     (mean load over the travel)
    L10   = (C / P_eq)^p * 1e6 revolutions        (ISO 281, ISO 3408-5: C is the load 90 % of
                                                   units carry for 1e6 revolutions)
    insulation: life used = integral 2^((T_w - T_class)/10 K) dt / L_ref   (the 10 K rule)
    energy    = integral (i^2 R(T_w) + T_m w_m) dt  (electrical, regeneration counted negative)

revolutions of the output (rotary) or of the screw (translational: travel / lead).
The RMS values, peaks and the load take the larger of a block's cold and hot simulations (the
current barely depends on R).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ema_cli.acceptance.duty.mechanics import PERIODIC_TOL, BlockRun
from ema_cli.acceptance.duty.profile import Expanded
from ema_cli.acceptance.duty.thermal import Network, Thermal, integrate
from ema_cli.acceptance.measurement import Measurement
from ema_cli.units import SI_UNIT

LIFE_REVS = 1e6  # revolutions a basic dynamic load rating is defined for (ISO 281) [-]
MARGIN_TOL_K = 0.01  # the current margin's search stops within this of the limit [K]
MARGIN_ITER = 40  # its iterations at most [-]


@dataclass
class Stats:
    """One pass of the profile on one actuator (SI): RMS and peak current [A] and motor torque
    [N*m], peak motor speed [rad/s], the envelope share used [-], the equivalent load [N*m |
    N] and L10 life [s] (inf: no travel or no rating), revolutions per pass, the electrical
    energy and its parts [J], the current margin [-]."""

    duration: float
    rms_current: float
    peak_current: float
    rms_torque: float
    peak_torque: float
    peak_speed: float
    envelope_use: float
    equivalent_load: float
    revolutions: float
    l10_revs: float
    l10_s: float
    energy: float
    copper_j: float
    housing_j: float
    mechanical_j: float
    margin: float
    per_block: list[dict[str, Any]] = field(default_factory=list)


def _both(run: BlockRun, n_rest: float, key: str, agg: str = "sum") -> float:
    """A block's ``sums`` (transient once + cycle n_rest times) or ``peaks``, the larger of
    its cold and hot simulations."""
    vals = []
    for j in (0, 1):
        if agg == "sum":
            v = run.transient[j].sums[key]
            if run.cycle is not None:
                v += n_rest * run.cycle[j].sums[key]
        else:
            v = run.transient[j].peaks[key]
            if run.cycle is not None:
                v = max(v, run.cycle[j].peaks[key])
        vals.append(v)
    return max(vals)


def stats(exp: Expanded, runs: Sequence[BlockRun], p: Mapping[str, float], th: Thermal,
          rating: float | None, life_exp: float, margin: float) -> Stats:
    """The figures of merit of one actuator (module docstring)."""
    total = exp.duration
    acc = {"i2": 0.0, "tm2": 0.0, "travel": 0.0, "fpv": 0.0, "p_em": 0.0}
    peaks = {"cur": 0.0, "t_m": 0.0, "w_m": 0.0, "env": 0.0}
    counts = np.bincount(exp.order, minlength=len(exp.blocks))
    per_block = []
    for bi, run in enumerate(runs):
        b = exp.blocks[bi]
        k = int(counts[bi])
        if k == 0:
            continue
        row = {"block": bi, "key": b.key, "label": b.label, "runs": k,
               "duration_s": b.duration, "method": th.methods.get(bi, "whole")}
        for key in acc:
            v = _both(run, run.n_rest, key) if key != "p_em" else 0.5 * sum(
                run.transient[j].sums["p_em"] + (run.n_rest * run.cycle[j].sums["p_em"]
                                                 if run.cycle is not None else 0.0)
                for j in (0, 1))
            acc[key] += k * v
            row[key] = v
        for key in peaks:
            v = _both(run, run.n_rest, key, "max")
            peaks[key] = max(peaks[key], v)
            row[f"peak_{key}"] = v
        row["rms_current"] = math.sqrt(row["i2"] / b.duration)
        row["change"] = run.cycle[0].change if run.cycle is not None else math.nan
        per_block.append(row)
    p_eq = (acc["fpv"] / acc["travel"]) ** (1.0 / life_exp) if acc["travel"] > 0 else 0.0
    per_rev = 2.0 * math.pi if exp.axis == "rotary" else 2.0 * math.pi / p["m"]
    revs = acc["travel"] / per_rev
    if rating is None or revs <= 0.0 or p_eq <= 0.0:
        l10, l10_s = math.inf, math.inf
    else:
        l10 = (rating / p_eq) ** life_exp * LIFE_REVS
        l10_s = l10 / revs * total
    return Stats(total, math.sqrt(acc["i2"] / total), peaks["cur"],
                 math.sqrt(acc["tm2"] / total), peaks["t_m"], peaks["w_m"], peaks["env"],
                 p_eq, revs, l10, l10_s, th.copper_j + acc["p_em"], th.copper_j, th.housing_j,
                 acc["p_em"], margin, per_block)


def current_margin(exp: Expanded, runs: Sequence[BlockRun], net: Network, limit_k: float,
                   class_k: float, base: Thermal) -> float:
    """The factor every current could be multiplied by (the motion unchanged) before the
    winding's peak reaches ``limit_k`` [-]: the root of ``peak(k) - limit`` by the secant on
    ``k^2`` from 0 and 1 (the peak rise is nearly linear in it: exactly so without R(T), where
    the second step lands on it), bisecting when a step leaves the bracket; 0 when the housing
    losses alone reach the limit."""
    def f(s: float) -> float:
        if s == 1.0:
            return base.peak_w - limit_k
        return integrate(exp, runs, net, limit_k, class_k, math.sqrt(max(s, 0.0))).peak_w \
            - limit_k

    lo, f_lo = 0.0, f(0.0)
    if f_lo >= 0.0:
        return 0.0
    hi = math.inf
    a, fa = lo, f_lo
    b, fb = 1.0, f(1.0)
    for _ in range(MARGIN_ITER):  # the secant on k^2, kept inside the bracket [lo, hi]
        if abs(fb) <= MARGIN_TOL_K:
            return math.sqrt(b)
        if fb < 0.0:
            lo, f_lo = b, fb
        else:
            hi = b
        s = b - fb * (b - a) / (fb - fa) if fb != fa else math.nan
        if not (lo < s < hi):  # outside the bracket: bisect it (or double it while open)
            s = 2.0 * lo if math.isinf(hi) else 0.5 * (lo + hi)
        if s > 1e8:
            return math.inf
        a, fa = b, fb
        b, fb = s, f(s)
    return math.sqrt(b)


CONDITIONS = {"winding_temperature": "peak", "housing_temperature": "peak",
              "time_above_limit": "winding", "peak_current": "peak", "rms_current": "RMS",
              "peak_torque": "motor, peak", "rms_torque": "motor, RMS",
              "envelope_use": "largest", "l10_life": "L10", "insulation_life_used": "per pass",
              "energy": "per pass"}
"""The condition each duty metric is shown with (``tvc: rms_current (RMS)``)."""


def _meas(metric: str, value: float, dim: str, note: str = "", bound: tuple | None = None,
          reason: str = "") -> Measurement:
    cond = CONDITIONS[metric]
    if bound is None:
        return Measurement(metric, cond, float(value), SI_UNIT[dim], note)
    return Measurement(metric, cond, float(value), SI_UNIT[dim], note, float(bound[0]),
                       float(bound[1]), reason)


def measurements(st: Stats, th: Thermal, runs: Sequence[BlockRun], exp: Expanded,
                 limit_k: float, insulation_life_h: float) -> list[Measurement]:
    """The duty metrics (``config.duty.METRICS``) in SI. The winding temperature is a bound
    ``peak +- error`` (the method's estimate, ``duty.thermal``) -- and its verdict then only
    decided when the whole interval is on one side of the limit -- when the peak lies within
    that error of ``limit_k``, when a block's cycle was not steady or when a run diverged."""
    err = th.error_k
    unsteady = [exp.blocks[r.block].key for r in runs
                if r.cycle is not None and r.cycle[0].change > PERIODIC_TOL]
    diverged = [exp.blocks[r.block].key for r in runs if r.diverged]
    reasons = []
    if diverged:
        reasons.append(f"the simulation of {', '.join(diverged)} diverged (lower "
                       "simulation.dt_s)")
    if unsteady:
        reasons.append(f"{', '.join(unsteady)} did not settle into a steady cycle (losses "
                       f"changed by more than {PERIODIC_TOL:.0%} between its last two periods: "
                       "raise simulation.settle_s)")
    note = f"multirate error estimate +-{err:.3g} K"
    if abs(th.peak_w - limit_k) <= err:
        reasons.append(f"within the multirate method's error (+-{err:.2g} K) of the limit: "
                       "check with the full-resolution reference (--full-resolution)")
    w_meas = _meas("winding_temperature", th.peak_w, "temperature", note)
    if reasons:
        w_meas = _meas("winding_temperature", th.peak_w - err, "temperature", note,
                       (th.peak_w - err, th.peak_w + err), "; ".join(reasons))
    life_used = 100.0 * th.life_h / insulation_life_h
    return [
        w_meas,
        _meas("housing_temperature", th.peak_h, "temperature"),
        _meas("time_above_limit", th.time_above, "time",
              f"above {limit_k - 273.15:g} degC"),
        _meas("peak_current", st.peak_current, "current"),
        _meas("rms_current", st.rms_current, "current"),
        _meas("peak_torque", st.peak_torque, "torque", "motor torque"),
        _meas("rms_torque", st.rms_torque, "torque", "motor torque"),
        _meas("envelope_use", 100.0 * st.envelope_use, "percent",
              "largest share of the drive's torque at the speed (cold and hot resistance)"),
        _meas("l10_life", st.l10_s, "time",
              "no travel or no dynamic_load_rating" if not math.isfinite(st.l10_s) else
              f"{st.l10_revs:.3g} revolutions"),
        _meas("insulation_life_used", life_used, "percent",
              f"{th.life_h:.3g} h at the class temperature per pass"),
        _meas("energy", st.energy, "energy", "electrical, per pass"),
    ]
