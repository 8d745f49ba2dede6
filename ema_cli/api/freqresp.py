"""``api.freqresp``: the sinestream frequency response at several amplitudes, with bandwidths."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ema_cli.api._inputs import ConfigSource, Overrides, base_dir, folder_arg, override_pairs
from ema_cli.config.support import check_command, checked
from ema_cli.errors import EmaError

if TYPE_CHECKING:
    import numpy as np
    import pandas as pd
    from matplotlib.figure import Figure

    from ema_cli.analysis.freqresp import FreqPoint
    from ema_cli.config.study import StudyConfig

DEFAULT_AMPLITUDES_DEG = (0.1, 1.0, 5.0)
DEFAULT_F_MIN_HZ, DEFAULT_F_MAX_HZ, DEFAULT_N = 0.5, 50.0, 30
MAX_POINTS = 2000  # amplitudes x frequencies at most [-]
BANDWIDTH_DROP = 0.10  # a bandwidth this much below the small-signal one is reported [-]


@dataclass
class FrequencyResponse:
    """A sinestream: ``points`` (amplitude-major), the linear model's response at the same
    frequencies (``linear``), and per-amplitude summaries (``summary``)."""

    config: StudyConfig
    params: dict[str, float]
    points: list[FreqPoint]
    linear: np.ndarray
    wall_time_s: float
    overrides: list[tuple[str, Any]] = field(default_factory=list)
    inputs: Any = None
    """What the folder's marker records (``report.run_inputs.RunInputs``)."""

    @property
    def amplitudes(self) -> list[float]:
        return sorted({p.amplitude_deg for p in self.points})

    def block(self, amplitude_deg: float) -> list[FreqPoint]:
        return [p for p in self.points if p.amplitude_deg == amplitude_deg]

    @property
    def f_hz(self) -> np.ndarray:
        import numpy as np

        return np.array([p.f_hz for p in self.block(self.amplitudes[0])])

    @property
    def summary(self) -> dict[str, Any]:
        """freqresp.json: per amplitude the -3 dB bandwidth, the -90 deg frequency, the
        resonance peak and the limits reached; the amplitude where the bandwidth first drops
        more than 10 % below the smallest amplitude's, with the limit responsible
        (``binding_limit``: the limit reached at the lowest frequency up to the bandwidth);
        the linear model's bandwidth and its estimate of the amplitude at which each limit is
        reached there."""
        import numpy as np

        from ema_cli.analysis.freqresp import (
            LIMITS,
            binding_limit,
            crossing,
            limit_amplitudes,
            limit_onsets,
        )

        rows = []
        for a in self.amplitudes:
            blk = self.block(a)
            f = np.array([p.f_hz for p in blk])
            g = np.array([p.gain_db for p in blk])
            ph = np.array([p.phase_deg for p in blk])
            k = int(np.argmax(g))
            onsets = limit_onsets(blk)
            f3 = crossing(f, g, -3.0)
            rows.append({"amplitude_deg": a, "f_3db_hz": f3,
                         "f_minus90_hz": crossing(f, ph, -90.0), "peak_db": float(g[k]),
                         "f_peak_hz": float(f[k]), "max_thd_pct": float(max(p.thd_pct
                                                                             for p in blk)),
                         "limits": list(onsets), "limit_onset_hz": onsets,
                         "binding_limit": binding_limit(blk, f3),
                         "diverged": any(p.diverged for p in blk)})
        small = rows[0]["f_3db_hz"]
        drop = None
        for r in rows[1:]:
            bw = r["f_3db_hz"]
            if math.isfinite(small) and (not math.isfinite(bw) or bw < (1 - BANDWIDTH_DROP)
                                         * small):
                drop = {"amplitude_deg": r["amplitude_deg"], "f_3db_hz": bw,
                        "small_signal_f_3db_hz": small,
                        "drop_pct": (100.0 * (1.0 - bw / small) if math.isfinite(bw)
                                     else math.nan),
                        "binding_limit": r["binding_limit"], "limits": r["limits"]}
                break
        f = self.f_hz
        gl = 20 * np.log10(np.abs(self.linear))
        f_lin = crossing(f, gl, -3.0)
        estimate = None
        if math.isfinite(f_lin):
            amp = {k: float(v[0]) for k, v in limit_amplitudes(self.params, [f_lin]).items()}
            first = min(LIMITS, key=lambda k: amp[k])
            estimate = {"f_hz": f_lin, "amplitude_deg": amp, "first_limit": first}
        return {"amplitudes": rows, "bandwidth_drop": drop,
                "linear": {"f_3db_hz": f_lin, "limit_at_bandwidth": estimate}}

    @property
    def metrics(self) -> pd.DataFrame:
        """One row per amplitude (the summary's ``amplitudes``)."""
        import pandas as pd

        return pd.DataFrame(self.summary["amplitudes"])

    def to_pandas(self, form: str = "wide") -> pd.DataFrame:
        """freqresp.csv: one row per (amplitude, frequency) with gain_db, phase_deg, thd_pct,
        the linear model's gain and phase and the limits reached (``wide``), or ``long``
        (amplitude_deg, f_hz, quantity, value)."""
        import numpy as np
        import pandas as pd

        lin_g = np.tile(20 * np.log10(np.abs(self.linear)), len(self.amplitudes))
        lin_p = np.tile(np.degrees(np.unwrap(np.angle(self.linear))), len(self.amplitudes))
        df = pd.DataFrame({
            "amplitude_deg": [p.amplitude_deg for p in self.points],
            "f_hz": [p.f_hz for p in self.points],
            "gain_db": [p.gain_db for p in self.points],
            "phase_deg": [p.phase_deg for p in self.points],
            "thd_pct": [p.thd_pct for p in self.points],
            "linear_gain_db": lin_g, "linear_phase_deg": lin_p,
            "limits": ["+".join(p.limits) for p in self.points],
            "diverged": [p.diverged for p in self.points]})
        if form == "wide":
            return df
        if form != "long":
            raise EmaError(f"form must be 'wide' or 'long', got {form!r}")
        return df.melt(id_vars=["amplitude_deg", "f_hz"], var_name="quantity",
                       value_name="value")

    @property
    def title(self) -> str:
        return (f"{self.config.name} ({self.config.actuator_label()}): frequency "
                "response of the load angle (sinestream)")

    def plot(self) -> Figure:
        """Bode plot: one curve per amplitude, the linear model dashed."""
        from ema_cli.report.freqresp_report import bode_figure

        return bode_figure(self, self.title)

    def save(self, folder: str | Path | None = None) -> Path:
        """Write freqresp.csv, freqresp.json, bode.png, summary.md, the resolved config and a
        manifest."""
        import yaml

        from ema_cli.report.freqresp_report import write_freqresp
        from ema_cli.report.run_inputs import run_inputs
        from ema_cli.report.rundir import write_run

        cfg_json = self.config.model_dump(mode="json")
        inputs = self.inputs or run_inputs(self.config, sets=self.overrides, options={
            "amplitudes": self.amplitudes, "frequencies": [p.f_hz for p in self.points]})
        return write_run("freqresp", self.config.name, inputs, folder_arg(folder),
                         lambda out: write_freqresp(
                             out, yaml.safe_dump(cfg_json, sort_keys=False), self,
                             {"seed": self.config.seed, "wall_time_s": self.wall_time_s,
                              "parameters_si": self.params,
                              "overrides": [[k, v] for k, v in self.overrides]}))


def amplitude_list(values: Any, name: str = "amplitudes_deg") -> list[float]:
    """``values`` as a list of finite amplitudes > 0 [deg] (EmaError naming ``name``)."""
    from collections.abc import Sequence as Seq

    if isinstance(values, str | bytes) or not isinstance(values, Seq) or not values:
        raise EmaError(f"{name} must be a non-empty list of amplitudes > 0 [deg], got "
                       f"{values!r}")
    out = []
    for v in values:
        if isinstance(v, bool) or not isinstance(v, int | float) or not (math.isfinite(v)
                                                                        and v > 0):
            raise EmaError(f"{name} must hold finite amplitudes > 0 [deg], got {v!r}")
        out.append(float(v))
    return out


def freqresp(config: ConfigSource = None, overrides: Overrides = None, *,
             amplitudes_deg: Sequence[float] = DEFAULT_AMPLITUDES_DEG,
             f_min_hz: float = DEFAULT_F_MIN_HZ, f_max_hz: float = DEFAULT_F_MAX_HZ,
             n: int = DEFAULT_N, nl: Mapping[str, Any] | None = None) -> FrequencyResponse:
    """The sinestream frequency response of the configured actuator (its nonlinearities on)
    at each amplitude [deg], ``n`` log-spaced frequencies from ``f_min_hz`` to ``f_max_hz``."""
    import time

    import numpy as np

    from ema_cli.analysis.freqresp import SETTLE_S, sinestream, sinestream_steps
    from ema_cli.analysis.linear import linear_model
    from ema_cli.config.loader import load_config, resolve_run
    from ema_cli.config.study import StudyConfig
    from ema_cli.limits import check_steps

    for v, name in ((f_min_hz, "f_min_hz"), (f_max_hz, "f_max_hz")):
        if isinstance(v, bool) or not (isinstance(v, int | float) and math.isfinite(v)
                                       and v > 0):
            raise EmaError(f"{name} must be a finite frequency > 0 [Hz], got {v!r}")
    if not f_min_hz < f_max_hz:
        raise EmaError(f"f_min_hz ({f_min_hz:g} Hz) must be below f_max_hz ({f_max_hz:g} Hz)")
    if isinstance(n, bool) or not isinstance(n, int) or n < 2:
        raise EmaError(f"n must be an integer >= 2, got {n!r}")
    amps = amplitude_list(amplitudes_deg)
    if len(amps) * n > MAX_POINTS:
        raise EmaError(f"{len(amps)} amplitudes x {n} frequencies is more than {MAX_POINTS} "
                       "points")
    pairs = override_pairs(overrides, nl)
    cfg = load_config(config, pairs, StudyConfig)
    check_command(cfg, "freqresp")
    params = resolve_run(cfg, base_dir(config)).params
    f = np.geomspace(f_min_hz, f_max_hz, n)
    dt = cfg.simulation.dt_s
    steps = sinestream_steps(f, dt, len(amps))
    check_steps(steps,
                f"frequency response from {f_min_hz:g} Hz at dt_s = {dt:g} s ({len(amps)} "
                f"amplitudes x {n} frequencies)",
                f"raise f_min_hz (a frequency measures a whole period after {SETTLE_S:g} s, "
                "and settles 3 periods and measures 4 when its response is still changing), "
                "or use "
                "fewer frequencies or amplitudes, or a larger simulation.dt_s")
    from ema_cli.limits import estimate

    estimate(steps, f"{len(amps)} amplitude(s) x {n} frequencies, {steps:,.0f} integration "
             "steps (a lower --f-min costs most)")
    t0 = time.perf_counter()
    points = sinestream(params, amps, f, dt=cfg.simulation.dt_s)
    wall = time.perf_counter() - t0
    fs = np.array([p.f_hz for p in points[:n]])
    return FrequencyResponse(cfg, params, points, linear_model(params).response(fs), wall, pairs,
                             _inputs(cfg, pairs, amps, f_min_hz, f_max_hz, n))


def _inputs(cfg: StudyConfig, pairs: list[tuple[str, Any]], amplitudes: Sequence[float],
            f_min_hz: float, f_max_hz: float, n: int) -> Any:
    from ema_cli.report.run_inputs import run_inputs

    return run_inputs(cfg, sets=pairs, options={
        "amplitudes": [float(a) for a in amplitudes], "f_min": float(f_min_hz),
        "f_max": float(f_max_hz), "n": int(n)})


def freqresp_inputs(config: ConfigSource = None, overrides: Overrides = None, *,
                    amplitudes_deg: Sequence[float] = DEFAULT_AMPLITUDES_DEG,
                    f_min_hz: float = DEFAULT_F_MIN_HZ, f_max_hz: float = DEFAULT_F_MAX_HZ,
                    n: int = DEFAULT_N, nl: Mapping[str, Any] | None = None) -> Any:
    """The inputs (``report.run_inputs.RunInputs``) a :func:`freqresp` with these arguments
    records in its folder's marker: what ``ema freqresp`` checks ``--out`` against first."""
    from ema_cli.config.loader import load_config
    from ema_cli.config.study import StudyConfig

    pairs = override_pairs(overrides, nl)
    return _inputs(checked(load_config(config, pairs, StudyConfig), "freqresp"), pairs,
                   amplitude_list(amplitudes_deg), f_min_hz, f_max_hz, n)
