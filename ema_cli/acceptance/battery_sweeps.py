"""The acceptance tests that sweep frequency, each batched over units: the frequency response
(a sinestream per amplitude) and the dynamic stiffness (a load-torque sinestream refined
around its minimum). Every unit and amplitude of one frequency runs in one kernel batch
(``analysis.freqresp``); a unit's result is bit for bit its result alone."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from ema_cli.acceptance.battery import PEAK_DC_DB, REFINE_POINTS, REFINE_ROUNDS, _bound, _m
from ema_cli.acceptance.measurement import Measurement, TestRun
from ema_cli.config.acceptance import DynamicStiffnessTest, FrequencyResponseTest
from ema_cli.units import DEG


def run_frequency_response(name: str, test: FrequencyResponseTest,
                           units: Sequence[Mapping[str, float]], dt: float) -> list[TestRun]:
    from ema_cli.analysis.freqresp import sinestream_units

    freqs = list(np.geomspace(test.f_min_hz, test.f_max_hz, test.n))
    if test.phase_at_hz is not None:
        freqs = sorted({*freqs, test.phase_at_hz})
    amps = list(test.amplitudes_deg)
    per_unit = sinestream_units(units, amps, freqs, dt=dt)
    return [_frequency_case(name, test, p, points, amps, len(freqs), dt)
            for p, points in zip(units, per_unit, strict=True)]


def _frequency_case(name: str, test: FrequencyResponseTest, params: Mapping[str, float],
                    points: list[Any], amps: list[float], nf: int, dt: float) -> TestRun:
    from ema_cli.analysis.freqresp import binding_limit, crossing, snap_frequency
    from ema_cli.analysis.linear import linear_model

    out: list[Measurement] = []
    notes = []
    f_at = snap_frequency(test.phase_at_hz, dt)[0] if test.phase_at_hz is not None else None
    for k, a in enumerate(amps):
        blk = points[k * nf:(k + 1) * nf]
        f = np.array([p.f_hz for p in blk])
        g = np.array([p.gain_db for p in blk])
        cond = f"{a:g} deg"
        bw = crossing(f, g, -3.0)
        lim = binding_limit(blk, bw if math.isfinite(bw) else math.nan)
        note = f"binding limit {lim}" if lim is not None else ""
        if math.isfinite(bw):
            out.append(_m("frequency_response", "bandwidth", cond, bw, note))
        elif np.all(g > -3.0):
            out.append(_bound("frequency_response", "bandwidth", cond, f[-1], math.inf,
                              f"bandwidth above the highest frequency measured, {f[-1]:.3g} "
                              "Hz: widen f_max_hz", note))
        else:
            out.append(_bound("frequency_response", "bandwidth", cond, 0.0, f[0],
                              f"bandwidth below the lowest frequency measured, {f[0]:.3g} Hz: "
                              "lower f_min_hz", note))
        if f_at is not None:
            j = int(np.argmin(np.abs(f - f_at)))
            out.append(_m("frequency_response", "phase_lag", f"{cond} at {f_at:.4g} Hz",
                          -blk[j].phase_deg * DEG))
        k = int(np.argmax(g))
        if k == len(g) - 1 and len(g) > 1:
            out.append(_bound("frequency_response", "peak_gain", cond, float(g[k]), math.inf,
                              f"the gain is highest at the highest frequency measured, "
                              f"{f[k]:.4g} Hz (it may rise further): widen f_max_hz"))
        elif k == 0 and g[0] > PEAK_DC_DB:
            out.append(_bound("frequency_response", "peak_gain", cond, float(g[k]), math.inf,
                              f"the gain is highest, {g[0]:.3g} dB, at the lowest frequency "
                              f"measured, {f[0]:.4g} Hz (it may rise below): lower f_min_hz"))
        else:
            out.append(_m("frequency_response", "peak_gain", cond, float(g[k]),
                          f"at {f[k]:.4g} Hz"))
        if any(p.diverged for p in blk):
            notes.append(f"{cond}: diverged at some frequency")
    fs = np.array([p.f_hz for p in points[:nf]])
    return TestRun(name, "frequency_response", out,
                   {"points": points, "amplitudes": amps, "f_hz": fs,
                    "linear": linear_model(params).response(fs)}, notes=notes)


def run_dynamic_stiffness(name: str, test: DynamicStiffnessTest,
                          units: Sequence[Mapping[str, float]], dt: float) -> list[TestRun]:
    """The grid, then :data:`REFINE_ROUNDS` rounds around each unit's minimum: every round
    one batch per frequency asked, over the units asking for it."""
    from ema_cli.analysis.freqresp import compliance_units

    freqs = np.geomspace(test.f_min_hz, test.f_max_hz, test.n)
    pts = compliance_units(units, test.amplitude_nm, [freqs] * len(units), dt)
    active = list(range(len(units)))
    for _ in range(REFINE_ROUNDS):
        asks = {}
        for u in active:
            pts[u].sort(key=lambda p: p.f_hz)
            k = int(np.argmin([p.stiffness for p in pts[u]]))
            lo = pts[u][max(k - 1, 0)].f_hz
            hi = pts[u][min(k + 1, len(pts[u]) - 1)].f_hz
            if hi > lo:
                asks[u] = np.geomspace(lo, hi, REFINE_POINTS + 2)[1:-1]
        active = list(asks)
        if not active:
            break
        more = compliance_units([units[u] for u in active], test.amplitude_nm,
                                [asks[u] for u in active], dt)
        for u, extra in zip(active, more, strict=True):
            pts[u] += extra
    return [_stiffness_case(name, test, p, q) for p, q in zip(units, pts, strict=True)]


def _stiffness_case(name: str, test: DynamicStiffnessTest, params: Mapping[str, float],
                    pts: list[Any]) -> TestRun:
    from ema_cli.analysis.linear import linear_model

    pts.sort(key=lambda p: p.f_hz)
    k = int(np.argmin([p.stiffness for p in pts]))
    f = np.array([p.f_hz for p in pts])
    cond = f"{test.amplitude_nm:g} N*m, {test.f_min_hz:g}-{test.f_max_hz:g} Hz"
    if k in (0, len(pts) - 1):
        edge, key = (("lowest", "lower f_min_hz") if k == 0 else ("highest", "widen f_max_hz"))
        out = [_bound("dynamic_stiffness", "dynamic_stiffness", cond, 0.0, pts[k].stiffness,
                      f"the minimum lies at the {edge} frequency measured, {pts[k].f_hz:.4g} Hz "
                      f"(it may fall beyond): {key}", f"at {pts[k].f_hz:.4g} Hz")]
    else:
        out = [_m("dynamic_stiffness", "dynamic_stiffness", cond, pts[k].stiffness,
                  f"at {pts[k].f_hz:.4g} Hz")]
    lin = linear_model(params).response(f, inp="torque_disturbance")
    reached = sorted({x for p in pts for x in p.limits})
    return TestRun(name, "dynamic_stiffness", out,
                   {"points": pts, "f_hz": f, "linear": lin, "k_min": k},
                   notes=[f"limits reached: {', '.join(reached)}"] if reached else [])
