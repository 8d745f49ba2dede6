"""The EMPS benchmark's figures of merit: the four relative errors of a simulated response
against the measurement (``Simulation_EMPS.m``), the prediction error of an inverse model on a
record (``Script_IDIM_LS.m``, ``Script_IDIM_LS_CTV.m``), and the published values.

Relative error of a signal ``y`` against its simulation ``y_s``, both from the 0-based sample
49 (the scripts' ``n_border = 50``, 1-based) to the end::

    e = 100 * ||y - y_s|| / ||y||       [%]

where the measured position, velocity and acceleration are the filtered ones of the IDIM
pipeline (``plant.idim.filtered_kinematics``: Butterworth ``filtfilt``, ``diffcent`` twice)
and the simulated ones are taken as given; the force is ``gtau*vir`` measured against
``gtau*vir_s`` simulated. The benchmark calls a model good when all four are below 10 %.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ema_cli.errors import EmaError
from ema_cli.identify.plant.idim import (
    BENCHMARK,
    IdimEstimate,
    IdimSettings,
    build_regression,
    filtered_kinematics,
)
from ema_cli.identify.plant.records import PlantRecord

EMPS_IDIM_PUBLISHED: dict[str, tuple[float, float]] = {
    "M": (95.1089, 0.1085), "Fv": (203.5034, 1.1460), "Fc": (20.3935, 0.1012),
    "OF": (-3.1648, 0.0444)}
"""The benchmark's IDIM-LS estimate on DATA_EMPS.mat: name -> (value, standard deviation), SI
(kg, N*s/m, N, N); Janot, Gautier and Brunot, 2019 Workshop on Nonlinear System
Identification Benchmarks."""
EMPS_IDIM_RELATIVE_ERROR_PCT = 4.0834  # its relative error of the regression [%]
EMPS_SIMULATION_PUBLISHED_PCT = {"position": 0.013752, "velocity": 0.22911,
                                 "acceleration": 8.6036, "force": 5.848}
"""The benchmark's relative errors [%] of its closed-loop simulation with that estimate."""
GOOD_MODEL_PCT = 10.0  # the benchmark's criterion: every relative error below 10 % [%]


def relative_error_pct(y: np.ndarray, y_s: np.ndarray) -> float:
    """``100 ||y - y_s|| / ||y||`` [%]: the benchmark's relative error of ``y_s`` against
    ``y`` (same length; ``y`` not all zero)."""
    return float(100.0 * np.linalg.norm(y - y_s) / np.linalg.norm(y))


@dataclass(frozen=True)
class BenchmarkErrors:
    """The benchmark's four relative errors of a simulation [%]."""

    position_pct: float
    velocity_pct: float
    acceleration_pct: float
    force_pct: float

    def as_dict(self) -> dict[str, float]:
        """``{"position": ..., "velocity": ..., "acceleration": ..., "force": ...}`` [%]."""
        return {"position": self.position_pct, "velocity": self.velocity_pct,
                "acceleration": self.acceleration_pct, "force": self.force_pct}

    def good(self, limit_pct: float = GOOD_MODEL_PCT) -> bool:
        """The benchmark's verdict: every relative error below ``limit_pct`` [%]."""
        return all(v < limit_pct for v in self.as_dict().values())


def _simulated(record: PlantRecord, name: str, v: np.ndarray) -> np.ndarray:
    """A simulated signal checked against the record: a finite vector of its length."""
    a = np.asarray(v, dtype=np.float64)
    if a.ndim != 1 or a.shape[0] != record.n:
        raise EmaError(f"simulated {name} has shape {a.shape}; expected ({record.n},), the "
                       f"samples of {record.source}")
    bad = ~np.isfinite(a)
    if bad.any():
        raise EmaError(f"simulated {name} has {int(bad.sum())} NaN or inf value(s) (first at "
                       f"index {int(np.flatnonzero(bad)[0])}, 0-based)")
    return a


def benchmark_errors(record: PlantRecord, q_s: np.ndarray, dq_s: np.ndarray,
                     ddq_s: np.ndarray, force_s: np.ndarray,
                     settings: IdimSettings = BENCHMARK) -> BenchmarkErrors:
    """The four relative errors [%] of a simulation at the record's samples: position
    ``q_s`` [m], velocity ``dq_s`` [m/s], acceleration ``ddq_s`` [m/s^2] and force
    ``force_s`` [N], against the record's filtered motion and measured force, from
    ``settings.first_sample`` to the end (less ``settings.drop_end``), as
    ``Simulation_EMPS.m``."""
    sims = {"position q_s": q_s, "velocity dq_s": dq_s, "acceleration ddq_s": ddq_s,
            "force force_s": force_s}
    sim = {k.split()[0]: _simulated(record, k, v) for k, v in sims.items()}
    kin = filtered_kinematics(record.q_m, record.h_s, settings)
    meas = {"position": kin.q_m, "velocity": kin.dq_m_s, "acceleration": kin.ddq_m_s2,
            "force": record.force_n}
    start, stop = settings.first_sample, record.n - settings.drop_end
    if stop - start < 2:
        raise EmaError(f"{record.source}: {record.n} samples leave none to compare after "
                       f"dropping {settings.first_sample} at the start")
    out = {}
    for k, y in meas.items():
        ym = y[start:stop]
        if not np.any(ym):
            raise EmaError(f"{record.source}: the measured {k} is zero from "
                           f"{record.where(start)} on; a relative error needs a nonzero signal")
        out[k] = relative_error_pct(ym, sim[k][start:stop])
    return BenchmarkErrors(out["position"], out["velocity"], out["acceleration"], out["force"])


@dataclass(frozen=True)
class Prediction:
    """An inverse model's force prediction on a record's decimated regression: times ``t_s``
    [s], measured ``y_n`` and predicted ``y_hat_n`` force [N], ``relative_error_pct`` [%]."""

    t_s: np.ndarray
    y_n: np.ndarray
    y_hat_n: np.ndarray
    relative_error_pct: float


def prediction_error(record: PlantRecord, estimate: IdimEstimate,
                     settings: IdimSettings | None = None) -> Prediction:
    """The force an estimate predicts on a record (the same pipeline and law, the estimate's
    settings unless given) and its relative error ``100 ||y - W theta||/||y||`` [%]: on the
    estimation record, the regression's own error; on another, the benchmark's cross-test
    validation (``Script_IDIM_LS_CTV.m``)."""
    reg = build_regression(record, estimate.regression.terms,
                           estimate.regression.settings if settings is None else settings)
    y_hat = reg.W @ estimate.theta
    if not np.any(reg.y):
        raise EmaError(f"{record.source}: the force is zero on every row; expected a measured "
                       "actuation force [N]")
    return Prediction(reg.t_s, reg.y, y_hat, relative_error_pct(reg.y, y_hat))
