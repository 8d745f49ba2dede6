"""Candidate friction laws of a constant-speed sweep, symmetric or per direction, and the
rule that chooses among them (BIC), with intervals for every parameter.

With ``u = |w|`` [rad/s or m/s] and ``y = sign(w)*T`` (the friction's magnitude as the sweep
measures it; a symmetric law gives the same ``y(u)`` in both directions), every law is::

    y = Fc + (Fs - Fc)*exp(-(u/vs)^delta) + sigma2*u        (Stribeck; Coulomb: Fs = Fc)

with one parameter set (``symmetric``) or one per direction (``per-direction``: the names of
the - direction end in ``_neg``, as ``ema params`` calls them: Fc_neg, Fs_neg, sigma2_neg;
vs_neg and delta_neg have no simulator parameter yet: the simulator shares vs and delta).
Candidates: coulomb, coulomb-dir (4 parameters), stribeck, stribeck-dir (8), each Stribeck
one with ``delta`` fitted too when asked (+1 / +2).

Rule: the candidate with the lowest BIC = n*ln(RSS/n) + k*ln(n) wins (Schwarz 1978: the
large-sample posterior choice, which penalises each parameter by ln n, so a term must cut
the residual by more than noise does by chance; P(a per-direction law wins on symmetric
data) is P(chi2_4 > 4 ln n) = 0.5 % at n = 40). Beside it the nested F-tests
(symmetric -> per direction, Coulomb -> Stribeck) are printed as support; the Stribeck
one is approximate (vs is not defined under the null).

Fits: variable projection (the linear Fc, Fs, sigma2 by least squares on a log-spaced vs grid
and, when delta is fitted, a delta grid), then a Levenberg-Marquardt polish of all parameters
jointly; covariance s^2 (J^T J)^-1 (``identify.uncertainty``), 95 % Student intervals.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from ema_cli.identify.uncertainty import Uncertainty, assess, covariance

LAWS = ("coulomb", "coulomb-dir", "stribeck", "stribeck-dir")
"""The candidate laws, simplest first."""
DELTA_GRID = (0.5, 0.75, 1.0, 1.5, 2.0, 3.0)  # delta values scanned when delta is fitted [-]
VS_GRID_POINTS = 121  # log-spaced vs values scanned per side [points]
VS_SPAN = 10.0  # vs from min u / VS_SPAN to max u * VS_SPAN [-]
FD_REL = 1e-6  # relative step of the central-difference Jacobian [-]
RSS_FLOOR_REL = 1e-12  # RSS below (this * max|T|)^2 * n is rounding: BIC floors it there [-]
LSQ_TOL = 1e-14  # xtol/ftol/gtol of the joint polish [-]
DELTA_BOUNDS = (0.1, 10.0)  # delta kept in this range by the polish [-]


@dataclass
class LawFit:
    """One candidate law fitted (SI): parameter names and values, RSS, BIC and intervals."""

    law: str
    names: tuple[str, ...]
    x: np.ndarray
    rss: float
    n: int
    bic: float
    uncertainty: Uncertainty
    delta: float | None  # the fixed delta (None when fitted or a Coulomb law)

    @property
    def per_direction(self) -> bool:
        return self.law.endswith("-dir")

    @property
    def params(self) -> dict[str, float]:
        return {n: float(v) for n, v in zip(self.names, self.x, strict=True)}

    def curve(self, w: np.ndarray) -> np.ndarray:
        """The law's friction T(w) [N*m or N] at speeds ``w`` [rad/s or m/s]."""
        return law_curve(self.law, self.params, w, self.delta)

    def differences(self) -> dict[str, dict[str, Any]]:
        """Per-direction laws: (- direction) - (+ direction) of every parameter with its 95 %
        interval (covariance of the joint fit) and whether 0 is inside."""
        if not self.per_direction:
            return {}
        u = self.uncertainty
        out = {}
        for j, n in enumerate(self.names):
            m = f"{n}_neg"
            if m not in self.names:
                continue
            k = self.names.index(m)
            d = float(self.x[k] - self.x[j])
            var = u.cov[k, k] + u.cov[j, j] - 2.0 * u.cov[j, k]
            se = math.sqrt(var) if var >= 0 and math.isfinite(var) else math.inf
            lo, hi = d - u.t_quantile * se, d + u.t_quantile * se
            out[f"{m} - {n}"] = {"value": d, "standard_error": se, "ci95": [lo, hi],
                                 "zero_inside": bool(lo <= 0.0 <= hi)}
        return out

    def to_json(self, units: dict[str, str]) -> dict[str, Any]:
        return {"law": self.law, "parameters": self.uncertainty.to_json(units),
                "rss": self.rss, "n": self.n, "k": len(self.names), "bic": self.bic,
                "delta_fixed": self.delta, "differences_neg_minus_pos": self.differences()}


def _side(params: dict[str, float], suffix: str, delta: float | None) -> tuple[float, ...]:
    fc = params["Fc" + suffix]
    fs = params.get("Fs" + suffix, fc)
    vs = params.get("vs" + suffix, 1.0)
    dl = params.get("delta" + suffix, params.get("delta", delta if delta is not None else 1.0))
    return fc, fs, vs, dl, params["sigma2" + suffix]


def _level(u: np.ndarray, fc: float, fs: float, vs: float, dl: float, s2: float) -> np.ndarray:
    with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
        E = np.exp(-np.power(u / vs, dl)) if fs != fc else 0.0
    return fc + (fs - fc) * E + s2 * u


def law_curve(law: str, params: dict[str, float], w: np.ndarray,
              delta: float | None = None) -> np.ndarray:
    """T(w) of a candidate law (module docstring) at speeds ``w``; ``delta`` the fixed
    exponent when the law does not carry one."""
    w = np.asarray(w, dtype=np.float64)
    u, s = np.abs(w), np.sign(w)
    pos = _level(u, *_side(params, "", delta))
    if law.endswith("-dir"):
        neg = _level(u, *_side(params, "_neg", delta))
        y = np.where(w >= 0, pos, neg)
    else:
        y = pos
    return s * y


def law_names(law: str, fit_delta: bool) -> tuple[str, ...]:
    """The parameter names of a candidate law, in fit order."""
    if law.startswith("coulomb"):
        base = ["Fc", "sigma2"]
    else:
        base = ["Fc", "Fs", "vs", "sigma2"] + (["delta"] if fit_delta else [])
    if law.endswith("-dir"):
        return (*base, *[f"{n}_neg" for n in base])
    return tuple(base)


def _project_side(u: np.ndarray, y: np.ndarray, stribeck: bool,
                  fit_delta: bool, delta: float) -> list[float]:
    """Starting values on one set of points by variable projection -> the side's params."""
    if not stribeck:
        A = np.column_stack([np.ones_like(u), u])
        c, *_ = np.linalg.lstsq(A, y, rcond=None)
        return [float(c[0]), float(c[1])]
    lo, hi = max(float(u.min()), 1e-12) / VS_SPAN, float(u.max()) * VS_SPAN
    best = (math.inf, [0.0, 0.0, 1.0, 0.0], delta)
    for dl in (DELTA_GRID if fit_delta else (delta,)):
        for vs in np.geomspace(lo, hi, VS_GRID_POINTS):
            E = np.exp(-np.power(u / vs, dl))
            A = np.column_stack([1.0 - E, E, u])
            c, *_ = np.linalg.lstsq(A, y, rcond=None)
            r = y - A @ c
            rss = float(r @ r)
            if rss < best[0]:
                best = (rss, [float(c[0]), float(c[1]), float(vs), float(c[2])], dl)
    x = best[1]
    return [*x, best[2]] if fit_delta else x


def _fd_jacobian(f: Any, x: np.ndarray) -> np.ndarray:
    """Central-difference Jacobian of ``f`` at ``x`` (step FD_REL * max(|x_j|, 1e-12))."""
    cols = []
    for j in range(x.shape[0]):
        h = FD_REL * max(abs(float(x[j])), 1e-12)
        xp, xm = x.copy(), x.copy()
        xp[j] += h
        xm[j] -= h
        cols.append((f(xp) - f(xm)) / (2.0 * h))
    return np.column_stack(cols)


def fit_law(law: str, w: np.ndarray, T: np.ndarray, delta: float = 1.0,
            fit_delta: bool = False) -> LawFit:
    """Fit one candidate law to the sweep (speeds ``w``, friction ``T``), see the module
    docstring; ``delta`` the fixed Stribeck exponent unless ``fit_delta``."""
    from scipy.optimize import least_squares

    names = law_names(law, fit_delta)
    stribeck = law.startswith("stribeck")
    u, y = np.abs(w), np.sign(w) * T
    if law.endswith("-dir"):
        x0 = (_project_side(u[w > 0], y[w > 0], stribeck, fit_delta, delta)
              + _project_side(u[w < 0], y[w < 0], stribeck, fit_delta, delta))
    else:
        x0 = _project_side(u, y, stribeck, fit_delta, delta)
    x0 = np.array(x0, dtype=np.float64)
    fixed = None if (fit_delta or not stribeck) else delta

    def resid(x: np.ndarray) -> np.ndarray:
        return law_curve(law, dict(zip(names, x, strict=True)), w, fixed) - T

    lower = np.full(x0.shape, -np.inf)
    upper = np.full(x0.shape, np.inf)
    for j, n in enumerate(names):
        if n.startswith("vs"):
            lower[j] = 1e-12
        if n.startswith("delta"):
            lower[j], upper[j] = DELTA_BOUNDS
    x = x0
    if stribeck:
        try:
            pol = least_squares(resid, np.clip(x0, lower, upper), bounds=(lower, upper),
                                method="trf", x_scale="jac", xtol=LSQ_TOL, ftol=LSQ_TOL,
                                gtol=LSQ_TOL, max_nfev=2000)
            r0 = resid(x0)
            if 2.0 * pol.cost <= float(r0 @ r0):
                x = pol.x
        except ValueError:
            pass
    r = resid(x)
    J = _fd_jacobian(resid, x) if stribeck else _linear_jacobian(law, w)
    cov, cond, dof = covariance(J, r)
    unc = assess(names, x, cov, dof, cond)
    n = int(w.shape[0])
    rss = float(r @ r)
    floor = n * (RSS_FLOOR_REL * float(np.max(np.abs(T)))) ** 2
    bic = n * math.log(max(rss, floor, 1e-300) / n) + len(names) * math.log(n)
    return LawFit(law, names, x, rss, n, bic, unc, fixed)


def _linear_jacobian(law: str, w: np.ndarray) -> np.ndarray:
    """d T / d (Fc, sigma2[, Fc_neg, sigma2_neg]) of the Coulomb laws (exact: linear)."""
    s = np.sign(w)
    if law == "coulomb":
        return np.column_stack([s, w])
    pos, neg = (w >= 0).astype(float), (w < 0).astype(float)
    return np.column_stack([s * pos, w * pos, s * neg, w * neg])


def f_test(small: LawFit, big: LawFit) -> dict[str, Any]:
    """The nested F-test of ``small`` inside ``big`` -> {F, dof, p}."""
    from scipy.stats import f as f_dist

    k0, k1, n = len(small.names), len(big.names), big.n
    if k1 <= k0 or n <= k1 or big.rss <= 0:
        return {"F": None, "dof": [k1 - k0, n - k1], "p": None}
    F = max((small.rss - big.rss) / (k1 - k0), 0.0) / (big.rss / (n - k1))
    return {"F": float(F), "dof": [k1 - k0, n - k1], "p": float(f_dist.sf(F, k1 - k0, n - k1))}


def min_points(law: str, fit_delta: bool) -> int:
    """Fewest distinct speeds per side (per-direction laws) or in all a law needs."""
    k = len(law_names(law.removesuffix("-dir"), fit_delta))
    return k + 1


def select_law(laws: dict[str, LawFit]) -> tuple[str, dict[str, Any]]:
    """The lowest-BIC law and why -> (law, selection JSON)."""
    order = sorted(laws, key=lambda k: laws[k].bic)
    best = order[0]
    tests = {}
    for small, big, what in (("coulomb", "coulomb-dir", "symmetric -> per direction (Coulomb)"),
                             ("stribeck", "stribeck-dir",
                              "symmetric -> per direction (Stribeck)"),
                             ("coulomb", "stribeck", "Coulomb -> Stribeck (symmetric)"),
                             ("coulomb-dir", "stribeck-dir",
                              "Coulomb -> Stribeck (per direction)")):
        if small in laws and big in laws:
            tests[what] = f_test(laws[small], laws[big])
    why = f"lowest BIC ({laws[best].bic:.2f}) of {len(laws)} candidate laws"
    if len(order) > 1:
        nxt = order[1]
        why += f"; next {nxt} (BIC {laws[nxt].bic:.2f}, +{laws[nxt].bic - laws[best].bic:.2f})"
    return best, {"rule": "lowest BIC = n ln(RSS/n) + k ln(n) (Schwarz); nested F-tests as "
                          "support (the Coulomb -> Stribeck one approximate)",
                  "chosen": best, "why": why,
                  "bic": {k: laws[k].bic for k in order}, "f_tests": tests}
