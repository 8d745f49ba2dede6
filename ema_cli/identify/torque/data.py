"""Identification data: synthetic (the full simulator, docs/model.md §8) or a user's CSV, validated.

Both give an :class:`IdentData` with the transmission deflection dth [rad], its rate dw [rad/s]
and the measured torque [N*m] (load side), sampled at times t [s].
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ema_cli.errors import EmaError
from ema_cli.files import read_csv

if TYPE_CHECKING:
    import pandas as pd

CSV_COLUMNS = ("t_s", "dtheta_rad", "domega_rad_s", "torque_nm")
"""Columns of an identification CSV: time [s], deflection [rad], its rate [rad/s], torque [N*m]."""
MIN_ROWS = 20  # fewest samples accepted from a data file [rows]
MIN_CONTACT_SAMPLES = 10  # fewest samples with |dth| beyond the smallest alpha searched [rows]
NOISE_TAG = 0x6E6F6973  # second entropy word of the noise stream: independent of the GA seeds


@dataclass(frozen=True)
class IdentData:
    """Samples for identification (1-D arrays of one length, SI) and where they came from.

    truth: the generating parameters {"kL", "alpha", "c"} for synthetic data, else None.
    """

    t: np.ndarray
    dth: np.ndarray
    dw: np.ndarray
    torque: np.ndarray
    source: str
    truth: dict[str, float] | None = None
    damping: str | None = None
    noise_pct: float = 0.0
    noise_std: float = 0.0
    tau: float | None = None  # the simulator's contact_tau (synthetic data) [s]

    @property
    def n_samples(self) -> int:
        """Number of samples."""
        return int(self.t.shape[0])

    def describe(self) -> dict[str, Any]:
        """A JSON-ready summary (ranges and counts, no arrays)."""
        return {
            "source": self.source,
            "n_samples": self.n_samples,
            "t_range_s": [float(self.t[0]), float(self.t[-1])],
            "max_abs_dtheta_rad": float(np.max(np.abs(self.dth))),
            "torque_rms_nm": float(np.sqrt(np.mean(self.torque**2))),
            "damping_form_of_data": self.damping,
            "contact_tau_of_data_s": self.tau,
            "noise_pct_of_torque_rms": self.noise_pct,
            "noise_std_nm": self.noise_std,
            "truth": self.truth,
        }

    def to_frame(self) -> pd.DataFrame:
        """The samples as a DataFrame with the canonical columns (:data:`CSV_COLUMNS`)."""
        import pandas as pd

        return pd.DataFrame(dict(zip(CSV_COLUMNS, (self.t, self.dth, self.dw, self.torque),
                                     strict=True)))

    def contact_fraction(self, alpha: float) -> float:
        """Fraction of samples with |dth| > alpha (outside the gap) [-]."""
        return float(np.mean(np.abs(self.dth) > alpha))


def add_noise(torque: np.ndarray, noise_pct: float, seed: int) -> tuple[np.ndarray, float]:
    """Add Gaussian noise of ``noise_pct`` % of the torque RMS -> (noisy torque, std [N*m]).

    The stream is ``SeedSequence([seed, NOISE_TAG])``: fixed by ``seed``, independent of the
    GA's ``SeedSequence(seed).spawn(n)`` children.
    """
    if noise_pct <= 0.0:
        return torque.copy(), 0.0
    std = noise_pct / 100.0 * float(np.sqrt(np.mean(torque**2)))
    rng = np.random.default_rng(np.random.SeedSequence([seed, NOISE_TAG]))
    return torque + std * rng.standard_normal(torque.shape[0]), std


def synthetic_data(
    plant: Mapping[str, Any],
    kL: float,
    alpha: float,
    damping: str,
    amplitude_rad: float,
    freq_hz: float,
    freq_end_hz: float,
    sweep_time_s: float,
    duration_s: float,
    dt_s: float,
    sample_interval_s: float,
    noise_pct: float,
    seed: int,
) -> IdentData:
    """Drive the full simulator with a chirp and record dth, dw and the shaft torque.

    ``plant``: SI overrides of the parameter table; ``kL`` [N*m/rad], ``alpha`` [rad] and
    ``damping`` ("contact" | "paper") are set on top. c is the simulator's (derived from
    zeta_t unless ``plant`` sets it). The chirp goes ``freq_hz -> freq_end_hz`` over
    ``sweep_time_s``; samples are taken every ``sample_interval_s``.
    """
    from ema_cli.config.loader import resolve_params
    from ema_cli.sim.runner import simulate
    from ema_cli.sim.signals import InputSignal

    params = resolve_params({**dict(plant), "kL": kL, "alpha": alpha, "damping": damping}, {})
    signal = InputSignal("chirp", amplitude=amplitude_rad, freq=freq_hz, freq_end=freq_end_hz,
                         sweep_time=sweep_time_s)
    res = simulate(params, signal, duration=duration_s, dt=dt_s,
                   output_interval=sample_interval_s)
    if bool(res.diverged[0]):
        raise EmaError("the simulation that generates the identification data diverged; "
                       "check the plant parameters and the time step", 1)
    df = res.signals_frame(0)
    torque = df["torque_shaft_nm"].to_numpy(np.float64)
    noisy, std = add_noise(torque, noise_pct, seed)
    truth = {"kL": params["kL"], "alpha": params["alpha"], "c": params["c"]}
    desc = (f"synthetic: {signal.describe()}, {sweep_time_s:g} s sweep, {duration_s:g} s, "
            f"{damping} damping, noise {noise_pct:g} % of torque RMS")
    return IdentData(df["t_s"].to_numpy(np.float64), df["dtheta_rad"].to_numpy(np.float64),
                     df["domega_rad_s"].to_numpy(np.float64), noisy, desc, truth, damping,
                     float(noise_pct), std, params["contact_tau"])


def load_csv(path: str | Path, columns: Mapping[str, str] | None = None) -> IdentData:
    """Read and validate an identification CSV.

    ``columns`` maps the canonical names (:data:`CSV_COLUMNS`) to the file's column names, e.g.
    ``{"torque_nm": "T_meas"}``. Every problem (missing file or columns, non-numeric, NaN or inf
    values, fewer than :data:`MIN_ROWS` rows, time not strictly increasing) is an EmaError that
    names the file.
    """
    import pandas as pd

    p = Path(path)
    mapping = {name: name for name in CSV_COLUMNS}
    for canon, col in (columns or {}).items():
        if canon not in mapping:
            raise EmaError(f"--columns: unknown column '{canon}'; the mappable names are "
                           f"{', '.join(CSV_COLUMNS)}")
        mapping[canon] = col
    df = read_csv(p)
    missing = [f"{col}" + (f" (for {canon})" if col != canon else "")
               for canon, col in mapping.items() if col not in df.columns]
    if missing:
        raise EmaError(
            f"data file '{p}' lacks column(s) {', '.join(missing)}; expected columns "
            f"{', '.join(mapping.values())} (map other names with --columns NAME=COLUMN); "
            f"found {', '.join(map(str, df.columns)) or 'none'}")
    arrays = {}
    for canon, col in mapping.items():
        values = pd.to_numeric(df[col], errors="coerce").to_numpy(np.float64)
        bad = ~np.isfinite(values)
        if bad.any():
            row = int(np.flatnonzero(bad)[0]) + 2  # +1 header, +1 one-based
            raise EmaError(f"data file '{p}': column '{col}' has {int(bad.sum())} empty, "
                           f"non-numeric, NaN or inf value(s) (first at line {row})")
        arrays[canon] = values
    n = arrays["t_s"].shape[0]
    if n < MIN_ROWS:
        raise EmaError(f"data file '{p}' has {n} data rows; at least {MIN_ROWS} are needed")
    steps = np.diff(arrays["t_s"])
    if np.any(steps <= 0):
        row = int(np.flatnonzero(steps <= 0)[0]) + 3
        raise EmaError(f"data file '{p}': column '{mapping['t_s']}' (time) must be strictly "
                       f"increasing; it is not at line {row}")
    return IdentData(arrays["t_s"], arrays["dtheta_rad"], arrays["domega_rad_s"],
                     arrays["torque_nm"], f"file: {p}")


def check_exercises_gap(data: IdentData, alpha_lo: float, source: str) -> None:
    """EmaError unless enough samples leave the gap for the smallest alpha searched [rad]."""
    n_out = int(np.count_nonzero(np.abs(data.dth) > alpha_lo))
    if n_out < MIN_CONTACT_SAMPLES:
        raise EmaError(
            f"{source}: only {n_out} sample(s) have |dtheta| above the smallest alpha searched "
            f"({alpha_lo:g} rad; max |dtheta| = {float(np.max(np.abs(data.dth))):.4g} rad), "
            f"at least {MIN_CONTACT_SAMPLES} are needed: the data do not reach gear contact, "
            f"so the dead band lies outside the alpha range or the excitation is too small")

