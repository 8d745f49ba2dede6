"""IDIM-LS: the inverse dynamic model of a rigid axis identified by least squares, as the EMPS
benchmark's ``Script_IDIM_LS.m`` does it (Janot, Gautier and Brunot, 2019).

The model is linear in its parameters (``plant.terms``)::

    F = W(q, q', q'') theta,   e.g.  F = M q'' + Fv q' + Fc sign(q') + OF      [N]

with ``F`` the measured actuation force (EMPS: ``gtau*vir``). The pipeline, step by step as the
script runs it (``plant.matlab`` emulates the MATLAB functions to the sample):

1. ``q`` filtered by a Butterworth low-pass (order 4, 100 Hz) forward and backward
   (MATLAB ``filtfilt``);
2. velocity and acceleration by central differences of the filtered position, twice
   (``diffcent``; one-sided differences at the two ends, as the script's);
3. the first samples dropped: the script keeps ``n_border:N_pts`` with ``n_border = 50``
   (1-based), i.e. from the 0-based index 49 (:attr:`IdimSettings.first_sample`); the end is
   kept (the record ends at rest);
4. every regressor column and the force decimated by 10 (MATLAB ``decimate``: Chebyshev I of
   order 8, 0.05 dB, cutoff 0.8/10 of Nyquist, ``filtfilt``, every 10th sample ending at the
   last);
5. ordinary least squares; the covariance ``sigma^2 (W^T W)^-1`` with
   ``sigma^2 = ||y - W theta||^2/(n - p)`` (``sigma_rule="unbiased"``) or the script's
   ``std(y - W theta)^2`` (mean removed, ``n - 1``; ``sigma_rule="benchmark"``), and the
   relative error of the regression ``100 ||y - W theta||/||y||`` [%].

What the MATLAB details are worth on DATA_EMPS.mat (relative change of M, Fv, Fc, OF and the
relative error; ``python -m experiments.emps_idim`` measures them): scipy's default
``filtfilt`` padding instead of MATLAB's moves them by up to 0.5 % (OF) and 1.4 % (relative
error); keeping the first sample of each 10 (scipy's decimate) instead of ending on the last,
up to 0.03 % and 0.15 %; starting at 0-based 48 or 50 instead of 49, up to 0.002 %, enough
to change the fourth published decimal of M and Fv. With all of them as the script has them,
every published value (four decimals) is reproduced to its last digit (the standard deviations
with ``sigma_rule="benchmark"``; the unbiased rule moves them by -0.002 to +0.09 %).

An instrumental-variable refinement fits the same :class:`Regression` with instruments built by
:func:`regression_from_kinematics` from a simulated motion; :func:`least_squares` is the first
estimator over that object.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy import signal

from ema_cli.errors import EmaError
from ema_cli.identify.plant import matlab
from ema_cli.identify.plant.records import PlantRecord
from ema_cli.identify.plant.terms import (
    RIGID,
    Kinematics,
    Term,
    regressors,
    resolve_law,
)
from ema_cli.identify.uncertainty import MAX_COND, Uncertainty, assess, covariance

SIGMA_RULES = ("unbiased", "benchmark")
"""How the noise level is estimated from the residual e: ``||e||^2/(n-p)`` or MATLAB's
``std(e)^2`` (the script's; mean removed, ``n-1``)."""
NULL_SHOWN = 1e-3  # a term takes part in a dependence when its coefficient exceeds this [-]


@dataclass(frozen=True)
class IdimSettings:
    """The pipeline's settings; the defaults are the benchmark script's (:data:`BENCHMARK`).

    cutoff_hz       Butterworth cutoff of the position filter [Hz]
    butter_order    its order [-]
    first_sample    0-based index of the first sample kept (the script's n_border = 50, 1-based)
    drop_end        samples dropped at the end [-] (the script: 0; a record that ends in motion
                    needs ~first_sample, the one-sided differences there being wrong)
    decimation      decimation factor of the columns and the force [-] (1: none)
    """

    cutoff_hz: float = 100.0
    butter_order: int = 4
    first_sample: int = 49
    drop_end: int = 0
    decimation: int = 10

    def __post_init__(self) -> None:
        if not (np.isfinite(self.cutoff_hz) and self.cutoff_hz > 0):
            raise EmaError(f"IDIM settings: cutoff_hz = {self.cutoff_hz!r}; expected a "
                           "positive frequency [Hz]")
        for name, lo in (("butter_order", 1), ("first_sample", 0), ("drop_end", 0),
                         ("decimation", 1)):
            v = getattr(self, name)
            if not isinstance(v, int | np.integer) or v < lo:
                raise EmaError(f"IDIM settings: {name} = {v!r}; expected an integer >= {lo}")

    def butterworth(self, h_s: float) -> tuple[np.ndarray, np.ndarray]:
        """The position filter's (b, a) for the sample interval ``h_s`` [s] (MATLAB
        ``butter(order, cutoff/(fs/2))``)."""
        wn = self.cutoff_hz / (0.5 / h_s)
        if wn >= 1.0:
            raise EmaError(f"IDIM settings: cutoff_hz = {self.cutoff_hz:g} Hz is not below the "
                           f"Nyquist frequency {0.5 / h_s:g} Hz of the record")
        return signal.butter(self.butter_order, wn)

    def min_samples(self, n_params: int) -> int:
        """The fewest samples the pipeline accepts for ``n_params`` parameters: more than the
        Butterworth filtfilt's padding, and after the dropped samples more than the decimation
        filter's padding and enough for ``n_params + 1`` decimated rows."""
        r = self.decimation
        dec = 0 if r == 1 else matlab.edge_length(*matlab.decimation_filter(r)) + 1
        kept = max(dec, r * n_params + 1, 3)
        butter = 3 * self.butter_order + 1
        return max(butter, self.first_sample + self.drop_end + kept)


BENCHMARK = IdimSettings()
"""The EMPS benchmark script's settings."""


def filtered_kinematics(q_m: np.ndarray, h_s: float,
                        settings: IdimSettings = BENCHMARK) -> Kinematics:
    """Steps 1-2: the position ``q_m`` [m] sampled every ``h_s`` [s] filtered (MATLAB
    ``filtfilt`` of the Butterworth), its velocity [m/s] and acceleration [m/s^2] by ``diffcent``
    twice; full length (nothing dropped)."""
    b, a = settings.butterworth(h_s)
    q_f = matlab.filtfilt(b, a, q_m)
    dq_f = matlab.diffcent(q_f, h_s)
    return Kinematics(q_f, dq_f, matlab.diffcent(dq_f, h_s))


@dataclass(frozen=True)
class Regression:
    """The decimated regression ``y ~ W theta``: ``W[n_rows, p]`` (column j in N per unit of
    parameter j), ``y[n_rows]`` the force [N], ``t_s[n_rows]`` the times of the kept samples
    [s], the law's ``terms``, the settings that built it and its ``source`` (for messages);
    ``W_raw[n_kept, p]`` the columns before decimation (the script's X_0)."""

    W: np.ndarray
    y: np.ndarray
    t_s: np.ndarray
    terms: tuple[Term, ...]
    settings: IdimSettings
    source: str
    W_raw: np.ndarray

    @property
    def names(self) -> tuple[str, ...]:
        """The parameters' names."""
        return tuple(t.name for t in self.terms)

    @property
    def units(self) -> dict[str, str]:
        """Name -> SI unit of every parameter."""
        return {t.name: t.unit for t in self.terms}


def regression_from_kinematics(kin: Kinematics, force_n: np.ndarray, t_s: np.ndarray,
                               law: Sequence[str | Term] = RIGID,
                               settings: IdimSettings = BENCHMARK,
                               source: str = "arrays") -> Regression:
    """Steps 3-4 on a full-length motion ``kin`` and force ``force_n`` [N] at times ``t_s`` [s]:
    drop the settings' first (and last) samples, build the law's columns, decimate every
    column and the force with MATLAB's ``decimate``."""
    terms = resolve_law(law)
    n = kin.q_m.shape[0]
    start, stop = settings.first_sample, n - settings.drop_end
    W0 = regressors(terms, kin.slice(start, stop))
    y0 = np.asarray(force_n, dtype=np.float64)[start:stop]
    r = settings.decimation
    W = np.column_stack([matlab.decimate(W0[:, j], r) for j in range(W0.shape[1])])
    t = np.asarray(t_s, dtype=np.float64)[start:stop]
    return Regression(W, matlab.decimate(y0, r), t[matlab.decimation_indices(t.size, r)],
                      terms, settings, source, W0)


def build_regression(record: PlantRecord, law: Sequence[str | Term] = RIGID,
                     settings: IdimSettings = BENCHMARK) -> Regression:
    """Steps 1-4 on a checked record; a record shorter than the pipeline needs
    (:meth:`IdimSettings.min_samples`) is an EmaError naming the source and the variable."""
    terms = resolve_law(law)
    need = settings.min_samples(len(terms))
    if record.n < need:
        r = settings.decimation
        raise EmaError(
            f"{record.source}: {record.label('position')} has {record.n} samples (last at "
            f"{record.where(record.n - 1)}); the IDIM pipeline needs at least {need}: "
            f"{settings.first_sample} dropped at the start, {settings.drop_end} at the end, "
            f"then enough for the filters and {len(terms) + 1} rows after decimation by {r}")
    kin = filtered_kinematics(record.q_m, record.h_s, settings)
    return regression_from_kinematics(kin, record.force_n, record.t_s, terms, settings,
                                      record.source)


def _check_rank(reg: Regression) -> None:
    """An EmaError for a zero column or columns that are linearly dependent on this record
    (condition number of the column-scaled columns above MAX_COND), naming the terms.

    Checked before decimation: MATLAB's decimation filter in transfer-function form (order 8,
    cutoff 0.08) loses about 8 digits (measured against its second-order-section form: 1e-8
    of the signal's peak), so exactly dependent columns come out of it with a condition
    number near 1e9, not 1e16."""
    norms = np.linalg.norm(reg.W_raw, axis=0)
    for j in np.flatnonzero(norms == 0):
        t = reg.terms[j]
        raise EmaError(f"{reg.source}: the column of term '{t.name}' ({t.meaning}) is zero on "
                       "every row; the record does not excite it: drop it from the law")
    _, s, Vt = np.linalg.svd(reg.W_raw / norms, full_matrices=False)
    if s[-1] > s[0] / MAX_COND:
        return
    c = Vt[-1] / norms
    c = c / c[np.argmax(np.abs(c))]
    combo = " ".join(f"{c[j]:+.3g}*{reg.names[j]}" for j in np.flatnonzero(np.abs(c) > NULL_SHOWN))
    hint = ""
    if {"Fc+", "Fc-", "OF"} <= set(reg.names):
        hint = (" (per-direction Coulomb terms and an offset: Fc+ - Fc- = OF whenever the "
                "velocity is never zero; drop OF, the estimates are then Fc+ + OF and Fc- - OF)")
    raise EmaError(f"{reg.source}: the law's columns are linearly dependent on this record: "
                   f"{combo} = 0 on every row; drop one of these terms{hint}")


@dataclass(frozen=True)
class IdimEstimate:
    """An IDIM-LS estimate, SI, in the order of ``names``: ``theta[p]``, standard deviations
    ``std[p]``, covariance ``cov[p, p]``; ``sigma_n`` the residual's standard deviation [N]
    (``sigma_rule``), ``relative_error_pct`` = 100 ||y - W theta||/||y|| [%], ``residual_n``
    [n_rows] [N]; ``uncertainty`` the house's intervals and determinability
    (``identify.uncertainty``); ``regression`` what was fitted."""

    regression: Regression
    theta: np.ndarray
    std: np.ndarray
    cov: np.ndarray
    sigma_n: float
    sigma_rule: str
    relative_error_pct: float
    residual_n: np.ndarray
    uncertainty: Uncertainty

    @property
    def names(self) -> tuple[str, ...]:
        """The parameters' names."""
        return self.regression.names

    @property
    def units(self) -> dict[str, str]:
        """Name -> SI unit."""
        return self.regression.units

    def _index(self, name: str) -> int:
        if name not in self.names:
            raise EmaError(f"no parameter '{name}' in this estimate; it has "
                           f"{', '.join(self.names)}")
        return self.names.index(name)

    def value(self, name: str) -> float:
        """The estimate of parameter ``name`` (SI)."""
        return float(self.theta[self._index(name)])

    def std_of(self, name: str) -> float:
        """The standard deviation of parameter ``name`` (SI)."""
        return float(self.std[self._index(name)])

    def contrast(self, weights: Mapping[str, float]) -> tuple[float, float]:
        """A linear combination ``sum w_j theta_j`` and its standard deviation from the
        covariance, e.g. ``{"Fc+": 1, "Fc-": -1}`` for the Coulomb asymmetry [N]."""
        w = np.zeros(len(self.names))
        for name, wj in weights.items():
            w[self._index(name)] = wj
        return float(w @ self.theta), float(np.sqrt(w @ self.cov @ w))

    def as_dict(self) -> dict[str, Any]:
        """A JSON-ready summary: per parameter value, unit and std; the regression's figures."""
        return {
            "parameters": {n: {"value": float(v), "unit": self.units[n], "std": float(s)}
                           for n, v, s in zip(self.names, self.theta, self.std, strict=True)},
            "relative_error_pct": self.relative_error_pct, "sigma_n": self.sigma_n,
            "sigma_rule": self.sigma_rule, "rows": int(self.regression.y.size),
            "condition_number_scaled_columns": self.uncertainty.cond,
        }


def least_squares(reg: Regression, sigma_rule: str = "unbiased") -> IdimEstimate:
    """Ordinary least squares on a regression -> :class:`IdimEstimate`; ``sigma_rule`` one of
    :data:`SIGMA_RULES`. Dependent columns are an EmaError naming the terms."""
    if sigma_rule not in SIGMA_RULES:
        raise EmaError(f"sigma_rule '{sigma_rule}'; expected one of {', '.join(SIGMA_RULES)}")
    _check_rank(reg)
    W, y = reg.W, reg.y
    if not np.any(y):
        raise EmaError(f"{reg.source}: the force is zero on every row; expected a measured "
                       "actuation force [N]")
    theta = np.linalg.lstsq(W, y, rcond=None)[0]
    e = y - W @ theta
    n, p = W.shape
    cov, cond, dof = covariance(W, e)  # sigma^2 (W^T W)^-1, sigma^2 = ||e||^2/(n - p)
    sigma = float(np.sqrt(e @ e / (n - p)))
    if sigma_rule == "benchmark":
        s = float(np.std(e, ddof=1))
        cov = cov * (s / sigma) ** 2 if sigma > 0 else cov
        sigma = s
    unc = assess(reg.names, theta, cov, dof, cond)
    return IdimEstimate(reg, theta, np.sqrt(np.diag(cov)), cov, sigma, sigma_rule,
                        float(100.0 * np.linalg.norm(e) / np.linalg.norm(y)), e, unc)


def idim_ls(record: PlantRecord, law: Sequence[str | Term] = RIGID,
            settings: IdimSettings = BENCHMARK, sigma_rule: str = "unbiased") -> IdimEstimate:
    """IDIM-LS of ``law`` on a record: :func:`build_regression` then :func:`least_squares`.
    With the defaults on DATA_EMPS.mat: the benchmark's published estimate."""
    return least_squares(build_regression(record, law, settings), sigma_rule)
