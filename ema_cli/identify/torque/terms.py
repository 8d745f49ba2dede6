"""Switchable terms of the torque-twist fit (paper Eq. 8 and more): a twist offset, friction in
the transmission (Coulomb-like or the Dahl path) and an anti-backlash preload.

The model fitted, load side, with ``d = dth - dth0`` the twist corrected by the offset::

    T = T_shaft(d, dw; kL, alpha, c)                       (the chosen form, model.transmission)
        + preload * clip(d/alpha, -1, 1)                   (preload: preload_torque_nb)
        + Ft * sign(dw)                                    (friction: a level +-Ft by the sign
                                                             of the twist rate)
      or + Fc_t * h(d; lam_t)                              (dahl: the Dahl path, dahl_path, of
                                                             twist scale lam_t = Fc_t/sigma_t)

``h`` is the unit Dahl path (Fc_t = 1) along the sampled twist, so the term is linear in
Fc_t for a fixed twist scale; ``sigma_t = Fc_t/lam_t`` [N*m/rad] is reported with its
interval by the delta method. Every term is a parameter with its sign free, so a term the
data do not need comes out at zero within its interval.

Fit: a grid over the nonlinear parameters (alpha, dth0, lam_t) with the linear ones (kL, c,
preload, Ft or Fc_t) by least squares on the Eq. 2 (paper) torque, then a trust-region polish
of all of them on the true residuals of the chosen form. Covariance: the delete-one-block
jackknife over BLOCKS contiguous time blocks (``identify.uncertainty.covariance_clustered``),
which stays honest when the residuals are coloured in time (a model error, filtered noise);
Student intervals with BLOCKS - 1 degrees of freedom.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ema_cli.errors import EmaError
from ema_cli.identify.shape_adequacy import (
    Adequacy,
    assess_shape,
    quantile_bins,
    second_difference_scatter,
)
from ema_cli.identify.uncertainty import Uncertainty, assess, covariance_clustered
from ema_cli.model.transmission import dahl_path, shaft_torque

TERMS = ("offset", "friction", "dahl", "preload")
"""The switchable terms (``--terms``, settings key ``terms``)."""
TERM_PARAMS = {"offset": ("dth0",), "friction": ("Ft",), "dahl": ("Fc_t", "sigma_t"),
               "preload": ("preload",)}
"""The parameters each term adds (names of ``ema params`` where the simulator has them)."""
TERM_UNITS = {"kL": "N*m/rad", "alpha": "rad", "c": "N*m*s/rad", "dth0": "rad", "Ft": "N*m",
              "Fc_t": "N*m", "sigma_t": "N*m/rad", "lam_t": "rad", "preload": "N*m"}
BLOCKS = 20  # contiguous time blocks of the jackknife covariance [blocks]
ALPHA_GRID = 21  # alpha values of the start grid [points]
OFFSET_GRID = 11  # dth0 values of the start grid [points]
LAM_GRID = 9  # Dahl twist scales of the start grid, log-spaced [points]
LAM_SPAN = (1e-3, 0.5)  # Dahl twist scale grid as fractions of the twist's range [-]
OFFSET_SPAN = 0.05  # default dth0 range: +-(this x the twist's range, at least alpha_hi) [-]
LSQ_TOL = 1e-12  # xtol/ftol/gtol of the polish [-]
FD_REL = 1e-7  # relative step of the central-difference Jacobian [-]
SHAPE_BINS = 5  # twist ranges per direction of the twist rate in the shape verdict [bins]


def check_terms(terms: list[str] | tuple[str, ...]) -> tuple[str, ...]:
    """Validate a list of terms -> a tuple in TERMS order; EmaError naming what is wrong."""
    bad = [t for t in terms if t not in TERMS]
    if bad:
        raise EmaError(f"unknown term(s) {', '.join(bad)}; expected any of {', '.join(TERMS)}")
    if "friction" in terms and "dahl" in terms:
        raise EmaError("terms friction and dahl are two laws of one friction: choose one")
    return tuple(t for t in TERMS if t in terms)


def unit_dahl(d: np.ndarray, lam: float) -> np.ndarray:
    """The Dahl path of unit level (Fc_t = 1) and twist scale ``lam`` [rad] along ``d``."""
    return dahl_path(d, 1.0, 1.0 / lam)


@dataclass
class TermsModel:
    """The torque-twist model with terms (module docstring) over one data set."""

    dth: np.ndarray
    dw: np.ndarray
    torque: np.ndarray
    form: str
    tau: float
    fit_c: bool
    c_fixed: float
    terms: tuple[str, ...]

    @property
    def names(self) -> tuple[str, ...]:
        """Fitted parameters in vector order (the Dahl term as Fc_t, lam_t)."""
        out = ["kL", "alpha"] + (["c"] if self.fit_c else [])
        for t in self.terms:
            out += ["Fc_t", "lam_t"] if t == "dahl" else list(TERM_PARAMS[t])
        return tuple(out)

    def split(self, x: np.ndarray) -> dict[str, float]:
        p = dict(zip(self.names, map(float, x), strict=True))
        p.setdefault("c", self.c_fixed)
        return p

    def torque_model(self, x: np.ndarray) -> np.ndarray:
        """T_model [N*m] at the data for the parameter vector ``x``."""
        p = self.split(x)
        d = self.dth - p.get("dth0", 0.0)
        alpha = max(p["alpha"], 0.0)
        T = shaft_torque(d, self.dw, p["kL"], alpha, p["c"], self.form, self.tau)
        if "preload" in p:
            T = T + p["preload"] * (np.clip(d / alpha, -1.0, 1.0) if alpha > 0 else np.sign(d))
        if "Ft" in p:
            T = T + p["Ft"] * np.sign(self.dw)
        if "Fc_t" in p:
            T = T + p["Fc_t"] * unit_dahl(d, max(p["lam_t"], 1e-300))
        return T

    def residuals(self, x: np.ndarray) -> np.ndarray:
        return self.torque - self.torque_model(x)


@dataclass
class TermsFit:
    """The torque-twist fit with terms: estimate, intervals (sigma_t by the delta method),
    residuals' shape verdict, and the grid start."""

    model: TermsModel
    x: np.ndarray
    cost: float
    uncertainty: Uncertainty
    adequacy: Adequacy
    base_adequacy: Adequacy | None
    wall_time_s: float
    warnings: list[str] = field(default_factory=list)

    @property
    def params(self) -> dict[str, float]:
        p = self.model.split(self.x)
        if "lam_t" in p:
            p["sigma_t"] = p["Fc_t"] / p["lam_t"] if p["lam_t"] > 0 else math.inf
        return p

    def intervals(self) -> dict[str, dict[str, Any]]:
        """Per reported parameter: value, unit, SE, 95 % interval, zero inside (terms)."""
        u = self.uncertainty
        out: dict[str, dict[str, Any]] = {}
        names = list(u.names)
        for j, n in enumerate(names):
            if n == "lam_t":
                continue
            lo, hi = float(u.ci_low[j]), float(u.ci_high[j])
            out[n] = {"value": float(u.x[j]), "unit": TERM_UNITS[n],
                      "standard_error": float(u.se[j]), "ci95": [lo, hi],
                      "zero_inside": bool(lo <= 0.0 <= hi),
                      "determined": bool(u.determined[j]),
                      "not_determined_because": u.reasons[j]}
        if "lam_t" in names:  # sigma_t = Fc_t/lam_t, delta method
            jf, jl = names.index("Fc_t"), names.index("lam_t")
            fc, lam = float(u.x[jf]), float(u.x[jl])
            g = np.zeros(len(names))
            g[jf], g[jl] = 1.0 / lam, -fc / lam**2
            var = float(g @ u.cov @ g) if np.all(np.isfinite(u.cov[np.ix_([jf, jl],
                                                                           [jf, jl])])) \
                else math.inf
            se = math.sqrt(var) if var >= 0 else math.inf
            s = fc / lam
            out["sigma_t"] = {"value": s, "unit": TERM_UNITS["sigma_t"], "standard_error": se,
                              "ci95": [s - u.t_quantile * se, s + u.t_quantile * se],
                              "zero_inside": bool(abs(s) <= u.t_quantile * se),
                              "determined": bool(np.isfinite(se) and se < 0.5 * abs(s)),
                              "not_determined_because": [] if np.isfinite(se) and
                              se < 0.5 * abs(s) else ["the Dahl level Fc_t is not resolved "
                                                      "from zero, or its twist scale is not"]}
            out["lam_t"] = {"value": lam, "unit": "rad", "standard_error": float(u.se[jl]),
                            "ci95": [float(u.ci_low[jl]), float(u.ci_high[jl])],
                            "zero_inside": False, "determined": bool(u.determined[jl]),
                            "not_determined_because": u.reasons[jl]}
        return out

    def to_json(self) -> dict[str, Any]:
        m = self.model
        return {
            "terms": list(m.terms),
            "form": m.form,
            "model": "T = T_shaft(dth - dth0, dw; kL, alpha, c) + preload*clip((dth - dth0)/"
                     "alpha, -1, 1) + Ft*sign(dw) | Fc_t*DahlPath(dth - dth0; Fc_t/sigma_t) "
                     "(identify.torque.terms)",
            "parameters": self.intervals(),
            "J": self.cost,
            "covariance": f"delete-one-block jackknife over {BLOCKS} contiguous time blocks "
                          f"(Student t, {self.uncertainty.dof} dof)",
            "adequacy": self.adequacy.to_json(),
            "adequacy_without_terms": (None if self.base_adequacy is None
                                       else self.base_adequacy.to_json()),
            "warnings": self.warnings,
            "wall_time_s": self.wall_time_s,
        }


def _linear_columns(m: TermsModel, alpha: float, off: float, lam: float | None
                    ) -> tuple[np.ndarray, list[str]]:
    """The paper-form columns of the linear parameters at fixed (alpha, dth0, lam_t)."""
    d = m.dth - off
    dz = np.sign(d) * np.maximum(np.abs(d) - alpha, 0.0)
    cols, names = [dz], ["kL"]
    if m.fit_c:
        cols.append(m.dw)
        names.append("c")
    if "preload" in m.terms:
        cols.append(np.clip(d / alpha, -1.0, 1.0) if alpha > 0 else np.sign(d))
        names.append("preload")
    if "friction" in m.terms:
        cols.append(np.sign(m.dw))
        names.append("Ft")
    if "dahl" in m.terms and lam is not None:
        cols.append(unit_dahl(d, lam))
        names.append("Fc_t")
    return np.column_stack(cols), names


def _start(m: TermsModel, alpha_range: tuple[float, float],
           offset_range: tuple[float, float]) -> np.ndarray:
    """The best grid point (alpha, dth0, lam_t) with the linear parameters by least squares."""
    span = float(np.ptp(m.dth)) or 1.0
    alphas = np.linspace(alpha_range[0], alpha_range[1], ALPHA_GRID)
    offs = (np.linspace(offset_range[0], offset_range[1], OFFSET_GRID)
            if "offset" in m.terms else np.zeros(1))
    lams = (np.geomspace(LAM_SPAN[0] * span, LAM_SPAN[1] * span, LAM_GRID)
            if "dahl" in m.terms else [None])
    y = m.torque - (0.0 if m.fit_c else m.c_fixed * m.dw)
    best, best_x = math.inf, None
    for a in alphas:
        for o in offs:
            for lam in lams:
                A, names = _linear_columns(m, float(a), float(o), lam)
                coef, *_ = np.linalg.lstsq(A, y, rcond=None)
                r = y - A @ coef
                rss = float(r @ r)
                if rss < best:
                    lin = dict(zip(names, coef, strict=True))
                    p = {"kL": lin["kL"], "alpha": float(a), "c": lin.get("c", m.c_fixed),
                         "dth0": float(o), "Ft": lin.get("Ft", 0.0),
                         "Fc_t": lin.get("Fc_t", 0.0), "lam_t": lam or 1.0,
                         "preload": lin.get("preload", 0.0)}
                    best, best_x = rss, np.array([p[n] for n in m.names])
    assert best_x is not None
    return best_x


def _fd_jacobian(m: TermsModel, x: np.ndarray) -> np.ndarray:
    """Central-difference Jacobian of the residuals (step FD_REL * max(|x_j|, scale_j))."""
    cols = []
    span = float(np.ptp(m.dth)) or 1.0
    for j, n in enumerate(m.names):
        scale = {"alpha": span, "dth0": span, "lam_t": span}.get(n, 1.0)
        h = FD_REL * max(abs(float(x[j])), 1e-3 * scale)
        xp, xm = x.copy(), x.copy()
        xp[j] += h
        xm[j] -= h
        cols.append((m.residuals(xp) - m.residuals(xm)) / (2.0 * h))
    return np.column_stack(cols)


def torque_adequacy(t: np.ndarray, dth: np.ndarray, dw: np.ndarray, torque: np.ndarray,
                    resid: np.ndarray) -> Adequacy:
    """Residuals of a torque-twist fit against the torque's own scatter (second differences
    of the time series); regions: SHAPE_BINS twist ranges x the sign of the twist rate
    (loading, unloading)."""
    scatter, dof, white = second_difference_scatter(torque)
    regions = []
    for sign, name in ((1.0, "twist rate > 0"), (-1.0, "twist rate < 0")):
        idx = np.flatnonzero(np.sign(dw) == sign)
        for b in quantile_bins(dth[idx], SHAPE_BINS):
            sel = idx[b]
            regions.append((f"{name}, twist {float(dth[sel].min()):.4g} .. "
                            f"{float(dth[sel].max()):.4g} rad", sel))
    method = ("second differences of the torque" if white else "second differences of the "
              "torque, an upper bound: the third differences disagree (coarse sampling)")
    return assess_shape(resid, scatter, dof, method, "N*m", regions, unbiased=white)


def fit_terms(t: np.ndarray, dth: np.ndarray, dw: np.ndarray, torque: np.ndarray,
              form: str, tau: float, fit_c: bool, c_fixed: float, terms: tuple[str, ...],
              alpha_range: tuple[float, float],
              offset_range: tuple[float, float] | None = None,
              base_resid: np.ndarray | None = None) -> TermsFit:
    """Fit the torque-twist model with ``terms`` (module docstring) to samples at times ``t``
    [s]: twist ``dth`` [rad], its rate ``dw`` [rad/s], torque [N*m]. ``alpha_range`` [rad]
    bounds alpha, ``offset_range`` [rad] the start grid of dth0 (default +-max(alpha_hi,
    OFFSET_SPAN x the twist's range)); ``base_resid`` the Eq. 8 fit's residuals, judged too."""
    from scipy.optimize import least_squares

    t0 = time.perf_counter()
    terms = check_terms(terms)
    m = TermsModel(np.ascontiguousarray(dth, dtype=np.float64),
                   np.ascontiguousarray(dw, dtype=np.float64),
                   np.ascontiguousarray(torque, dtype=np.float64), form, float(tau), fit_c,
                   float(c_fixed), terms)
    span = float(np.ptp(m.dth))
    if offset_range is None:
        w = max(alpha_range[1], OFFSET_SPAN * span)
        offset_range = (-w, w)
    x0 = _start(m, alpha_range, offset_range)
    lower = np.full(x0.shape, -np.inf)
    upper = np.full(x0.shape, np.inf)
    names = m.names
    ja = names.index("alpha")
    lower[ja], upper[ja] = alpha_range
    if "lam_t" in names:
        lower[names.index("lam_t")] = 1e-6 * (span or 1.0)
    warnings: list[str] = []
    x = x0
    try:
        pol = least_squares(m.residuals, np.clip(x0, lower, upper), bounds=(lower, upper),
                            method="trf", x_scale="jac", xtol=LSQ_TOL, ftol=LSQ_TOL,
                            gtol=LSQ_TOL, max_nfev=400)
        r0 = m.residuals(x0)
        if 2.0 * pol.cost <= float(r0 @ r0):
            x = pol.x
    except ValueError as exc:
        warnings.append(f"the polish failed ({exc}); the grid start stands")
    r = m.residuals(x)
    J = _fd_jacobian(m, x)
    blocks = [b for b in np.array_split(np.arange(r.shape[0]), BLOCKS) if b.size]
    cov, cond, dof = covariance_clustered(J, r, blocks)
    unc = assess(names, x, cov, dof, cond)
    if x[ja] <= alpha_range[0] + 1e-9 * (alpha_range[1] - alpha_range[0]) and alpha_range[0] > 0 \
            or x[ja] >= alpha_range[1] - 1e-9 * (alpha_range[1] - alpha_range[0]):
        warnings.append(f"alpha = {x[ja]:.4g} rad sits on a bound of its range "
                        f"[{alpha_range[0]:g}, {alpha_range[1]:g}]: widen --alpha-range")
    if "dth0" in names:
        v = x[names.index("dth0")]
        if not offset_range[0] <= v <= offset_range[1]:
            warnings.append(f"the offset dth0 = {v:.4g} rad left its start range "
                            f"[{offset_range[0]:.4g}, {offset_range[1]:.4g}] rad")
    adequacy = torque_adequacy(t, m.dth, m.dw, m.torque, r)
    base = None if base_resid is None else torque_adequacy(t, m.dth, m.dw, m.torque,
                                                           base_resid)
    return TermsFit(m, x, float(r @ r), unc, adequacy, base, time.perf_counter() - t0,
                    warnings)
