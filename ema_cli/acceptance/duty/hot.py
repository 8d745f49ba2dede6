"""The hot actuator beside the cold one: the acceptance battery's frequency response
(bandwidth) and no-load rate with the winding resistance at the profile's peak winding
temperature, R(T_peak) = R0 (1 + alpha (T_peak - T_ref)), against R at the ambient.

The two actuators run in the same kernel batches (the battery's runners,
``acceptance.battery_sweeps.run_frequency_response`` and ``acceptance.battery.run_no_load_rate``),
every other parameter the same: what heating alone does to the servo's speed of response. An
actuator the battery cannot run (a translational axis reports in other units) is skipped with a
note.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

from ema_cli.acceptance.measurement import Measurement

AMPLITUDE_DEG = 1.0  # the frequency response's amplitude [deg]
F_RANGE_HZ = (0.5, 50.0)  # its range [Hz]
N_FREQ = 16  # its frequencies [-]
RATE_STEP_DEG = 40.0  # the no-load rate's step [deg]
RATE_S = 1.0  # its duration [s]


@dataclass
class HotCheck:
    """Cold and hot: the resistances [ohm] and temperatures [K], and for each the bandwidth
    and no-load rate measurements (SI; a bound when outside what the test measures)."""

    r_cold: float
    r_hot: float
    t_cold: float
    t_hot: float
    bandwidth: tuple[Measurement, Measurement]
    rate: tuple[Measurement, Measurement]


def hot_check(p: Mapping[str, float], ambient_k: float, peak_k: float, dt: float
              ) -> HotCheck:
    """The cold (``R(ambient_k)``) and hot (``R(peak_k)``) actuator's bandwidth at
    :data:`AMPLITUDE_DEG` and no-load rate on a :data:`RATE_STEP_DEG` step."""
    from ema_cli.acceptance.battery import run_no_load_rate
    from ema_cli.acceptance.battery_sweeps import run_frequency_response
    from ema_cli.config.acceptance import FrequencyResponseTest, NoLoadRateTest
    from ema_cli.model.params import resolve
    from ema_cli.model.thermal import resistance_nb

    rs = [resistance_nb.py_func(p["R"], p["alpha_cu"], t, p["T_ref"])
          for t in (ambient_k, peak_k)]
    units = []
    for r in rs:
        q = dict(p)
        q.update({"R": r, "thermal": 0.0})
        units.append(resolve(q))
    fr = FrequencyResponseTest.model_validate(
        {"test": "frequency_response", "amplitudes_deg": [AMPLITUDE_DEG],
         "f_min_hz": F_RANGE_HZ[0], "f_max_hz": F_RANGE_HZ[1], "n": N_FREQ,
         "limits": {"bandwidth": {"min": 0, "unit": "Hz"}}})
    nl = NoLoadRateTest.model_validate(
        {"test": "no_load_rate", "amplitude_deg": RATE_STEP_DEG, "duration_s": RATE_S,
         "limits": {"rate": {"min": 0, "unit": "deg/s"}}})
    bw = [r.values("bandwidth")[0] for r in run_frequency_response("hot-bandwidth", fr, units, dt)]
    rate = [r.values("rate")[0] for r in run_no_load_rate("hot-rate", nl, units, dt)]
    return HotCheck(rs[0], rs[1], ambient_k, peak_k, (bw[0], bw[1]), (rate[0], rate[1]))


def as_dict(h: HotCheck) -> dict[str, object]:
    """The check in edge units (degC, Hz, deg/s) for reports."""
    def val(m: Measurement, f: float) -> dict[str, object]:
        v = m.value * f if math.isfinite(m.value) else None
        return {"value": v, "measured": m.measured, "reason": m.reason}

    deg = 180.0 / math.pi
    return {"resistance_ohm": {"cold": h.r_cold, "hot": h.r_hot},
            "temperature_c": {"cold": h.t_cold - 273.15, "hot": h.t_hot - 273.15},
            "bandwidth_hz": {"cold": val(h.bandwidth[0], 1.0), "hot": val(h.bandwidth[1], 1.0),
                             "amplitude_deg": AMPLITUDE_DEG},
            "no_load_rate_deg_s": {"cold": val(h.rate[0], deg), "hot": val(h.rate[1], deg),
                                   "step_deg": RATE_STEP_DEG}}
