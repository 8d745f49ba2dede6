"""The identification problem: the paper's Eq. 8 cost of a transmission-torque model, batched.

Model: the simulator's own shaft torque (``model.transmission.shaft_torque_nb``), load side::

    T_paper   = kL*DZ(dth, alpha) + c*dw                        (paper Eq. 2)
    T_contact = 0 inside the gap (|dth| <= alpha); in contact (penetration pen = |dth| - alpha)
                kL*DZ(dth, alpha) + c*clip(dw, -pen/tau, pen/tau), clamped so it pushes but
                never pulls: max(T, 0) if dth > alpha, min(T, 0) if dth < -alpha. tau [s] is
                the simulator's ``contact_tau`` (0: the Eq. 2 torque in contact).
                (alpha = 0 gives Eq. 2, as in the simulator.)

    J(kL, alpha[, c]) = sum_i (T_meas_i - T_model_i)^2          [N^2*m^2]   (paper Eq. 8)

kL [N*m/rad], alpha [rad] and c [N*m*s/rad] enter as the columns of ``X[n_pop, n_par]`` in the
order of :attr:`TorqueProblem.names`; c is either a column (fitted) or a fixed value.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ema_cli._numba import njit
from ema_cli.model.transmission import FORMS, inverse_tau, shaft_torque, shaft_torque_nb

PARAM_UNITS = {"kL": "N*m/rad", "alpha": "rad", "c": "N*m*s/rad"}


@njit(cache=True, error_model="numpy", entry=True)
def cost_batch_nb(X, dth, dw, tq, c_fixed, contact, inv_tau, out):
    """Eq. 8 for every row of ``X[n_pop, 2 or 3]`` (kL, alpha[, c]) into ``out[n_pop]``.

    A row with a non-finite parameter or a negative alpha gets ``inf``.
    """
    n_pop = X.shape[0]
    n = dth.shape[0]
    fit_c = X.shape[1] > 2
    for p in range(n_pop):
        k = X[p, 0]
        alpha = X[p, 1]
        c = X[p, 2] if fit_c else c_fixed
        if not (np.isfinite(k) and np.isfinite(alpha) and np.isfinite(c)) or alpha < 0.0:
            out[p] = np.inf
            continue
        s = 0.0
        for i in range(n):
            r = tq[i] - shaft_torque_nb(k, alpha, c, contact, inv_tau, 0.0, 0.0, dth[i], dw[i],
                                           0.0)
            s += r * r
        out[p] = s


@dataclass(frozen=True)
class TorqueProblem:
    """Eq. 8 over the data (dth [rad], dw [rad/s], torque [N*m]) with bounds on the parameters.

    ``names`` is ("kL", "alpha") with c fixed at ``c_fixed`` [N*m*s/rad], or ("kL", "alpha", "c")
    when c is fitted. ``lower``/``upper`` are the GA bounds in the same order. ``tau`` [s] is
    the contact form's damping ramp-in time (the simulator's ``contact_tau``; 0: none).
    """

    dth: np.ndarray
    dw: np.ndarray
    torque: np.ndarray
    form: str
    lower: np.ndarray
    upper: np.ndarray
    c_fixed: float = 0.0
    tau: float = 0.0

    def __post_init__(self) -> None:
        if self.form not in FORMS:
            raise ValueError(f"form must be one of {FORMS}, got {self.form!r}")
        for name in ("dth", "dw", "torque", "lower", "upper"):
            object.__setattr__(self, name,
                               np.ascontiguousarray(getattr(self, name), dtype=np.float64))
        if not self.tau >= 0.0:
            raise ValueError(f"tau must be >= 0, got {self.tau!r}")
        if not (self.dth.shape == self.dw.shape == self.torque.shape and self.dth.ndim == 1):
            raise ValueError("dth, dw and torque must be 1-D arrays of one length")
        if self.lower.shape not in ((2,), (3,)) or self.lower.shape != self.upper.shape:
            raise ValueError("bounds must have 2 (kL, alpha) or 3 (kL, alpha, c) entries")

    @property
    def fit_c(self) -> bool:
        """True when c is a free parameter (third column)."""
        return self.lower.shape[0] == 3

    @property
    def names(self) -> tuple[str, ...]:
        """Parameter names in column order."""
        return ("kL", "alpha", "c") if self.fit_c else ("kL", "alpha")

    @property
    def n_samples(self) -> int:
        """Number of data samples."""
        return int(self.dth.shape[0])

    def evaluate(self, X: np.ndarray) -> np.ndarray:
        """J[n_pop] for ``X[n_pop, n_par]`` in one compiled call (memory O(n_pop))."""
        X = np.ascontiguousarray(X, dtype=np.float64)
        if X.ndim != 2 or X.shape[1] != self.lower.shape[0]:
            raise ValueError(f"X must have shape (n_pop, {self.lower.shape[0]}), got {X.shape}")
        out = np.empty(X.shape[0])
        cost_batch_nb(X, self.dth, self.dw, self.torque, float(self.c_fixed),
                      self.form == "contact", inverse_tau(float(self.tau)), out)
        return out

    def full_params(self, x: np.ndarray) -> dict[str, float]:
        """One parameter vector -> {"kL", "alpha", "c"} (c fixed or fitted)."""
        x = np.asarray(x, dtype=np.float64)
        c = float(x[2]) if self.fit_c else float(self.c_fixed)
        return {"kL": float(x[0]), "alpha": float(x[1]), "c": c}

    def model_torque(self, x: np.ndarray) -> np.ndarray:
        """T_model [N*m] at the data for one parameter vector."""
        p = self.full_params(x)
        return shaft_torque(self.dth, self.dw, p["kL"], p["alpha"], p["c"], self.form,
                            self.tau)

    def residuals(self, x: np.ndarray) -> np.ndarray:
        """T_meas - T_model [N*m] for one parameter vector."""
        return self.torque - self.model_torque(x)
