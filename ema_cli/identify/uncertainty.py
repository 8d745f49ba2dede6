"""Least-squares uncertainty: standard errors, 95 % intervals, correlations, determinability.

At a least-squares optimum ``x`` with residuals ``r[N]`` and Jacobian ``J[N, p] = dr/dx``, the
covariance of the estimate is ``s^2 (J^T J)^-1`` with ``s^2 = r.r/(N - p)`` (one noise level),
or, when the residuals come in groups with noise levels of their own (the channels of a
closed-loop log), the sandwich ``A^-1 B A^-1``, ``A = J^T J``, ``B = sum_g s_g^2 J_g^T J_g``
(``s_g^2`` the group's mean squared residual, corrected for the p fitted parameters), which
reduces to the first form for one group. Intervals use Student's t with ``N - p`` degrees of
freedom. Inverses go through the SVD of ``J`` with columns scaled to unit norm, so a
near-singular problem is detected (condition number) rather than inverted into noise.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

CONFIDENCE = 0.95  # level of the reported intervals [-]
MAX_REL_SE = 0.5  # a standard error above 50 % of |value| leaves the value undetermined [-]
MAX_CORR = 0.999  # |correlation| above this with a parameter whose SE is large: confounded [-]
CORR_REL_SE = 0.05  # ... where "large" means a relative SE above 5 % [-]
MAX_COND = 1e10  # condition number of the column-scaled J above which J^T J is near-singular
NULL_SHARE = 0.1  # a parameter takes part in a near-null direction with a component > 0.1 [-]


@dataclass
class Uncertainty:
    """Uncertainty of a least-squares estimate (SI, in the order of ``names``).

    se[p], cov[p, p], corr[p, p]     standard errors, covariance, correlation matrix
    ci_low[p], ci_high[p]            95 % intervals (Student's t, ``dof`` degrees of freedom)
    t_quantile                       the t quantile used
    cond                             condition number of the column-scaled Jacobian
    determined[p]                    False when the data cannot determine the parameter
    reasons[p]                       why not (empty when determined)
    """

    names: tuple[str, ...]
    x: np.ndarray
    se: np.ndarray
    cov: np.ndarray
    corr: np.ndarray
    ci_low: np.ndarray
    ci_high: np.ndarray
    dof: int
    t_quantile: float
    cond: float
    determined: np.ndarray
    reasons: list[list[str]]

    def to_json(self, units: dict[str, str]) -> dict[str, dict]:
        """Per parameter: value, unit, SE, interval, relative SE, determined flag, reasons."""
        out = {}
        for j, n in enumerate(self.names):
            v = float(self.x[j])
            out[n] = {
                "value": v, "unit": units.get(n, ""), "standard_error": float(self.se[j]),
                "relative_se": float(self.se[j] / abs(v)) if v != 0 else None,
                "ci95": [float(self.ci_low[j]), float(self.ci_high[j])],
                "determined": bool(self.determined[j]), "not_determined_because": self.reasons[j],
            }
        return out


def covariance(J: np.ndarray, r: np.ndarray,
               groups: Sequence[slice] | None = None) -> tuple[np.ndarray, float, int]:
    """The covariance of a least-squares estimate -> (cov[p, p], cond, dof).

    ``J[N, p]`` the Jacobian of the residuals ``r[N]`` at the optimum; ``groups`` slices of
    the residuals with a noise level each (None: one group). Directions of J with a singular
    value below ``1/MAX_COND`` of the largest (after scaling the columns to unit norm) get an
    infinite variance.
    """
    N, p = J.shape
    if groups is None:
        groups = [slice(0, N)]

    def meat(Js: np.ndarray) -> np.ndarray:
        B = np.zeros((p, p))
        for g in groups:
            Jg, rg = Js[g], r[g]
            n_g = Jg.shape[0]
            if n_g == 0:
                continue
            s2 = float(rg @ rg) / max(n_g - p * n_g / N, 1.0)
            B += s2 * (Jg.T @ Jg)
        return B

    cov, cond = _sandwich(J, meat)
    return cov, cond, max(N - p, 1)


def _sandwich(J: np.ndarray, meat: Callable[[np.ndarray], np.ndarray]
              ) -> tuple[np.ndarray, float]:
    """``A^-1 B A^-1`` with ``A = J^T J`` inverted through the SVD of J with columns scaled to
    unit norm and ``B = meat(J scaled)`` -> (cov[p, p], condition number). Directions with a
    singular value below ``1/MAX_COND`` of the largest are dropped from the inverse and the
    parameters taking part in them get an infinite variance."""
    norms = np.linalg.norm(J, axis=0)
    norms = np.where(norms > 0, norms, 1.0)
    Js = J / norms
    _, s, Vt = np.linalg.svd(Js, full_matrices=False)
    cond = float(s[0] / s[-1]) if s[-1] > 0 else np.inf
    keep = s > s[0] / MAX_COND
    inv_s = np.where(keep, 1.0 / np.where(keep, s, 1.0), 0.0)
    Ainv_s = (Vt.T * inv_s**2) @ Vt  # (Js^T Js)^-1 on the kept directions
    cov = (Ainv_s @ meat(Js) @ Ainv_s) / np.outer(norms, norms)
    # a direction dropped from the inverse is undetermined: infinite variance along it
    for k in np.flatnonzero(~keep):
        for j in np.flatnonzero(np.abs(Vt[k]) > NULL_SHARE):
            cov[j, j] = np.inf
    return cov, cond


def covariance_clustered(J: np.ndarray, r: np.ndarray, clusters: Sequence[np.ndarray],
                         recentre: bool = False) -> tuple[np.ndarray, float, int]:
    """The cluster-robust covariance of a least-squares estimate -> (cov[p, p], cond, dof).

    ``clusters`` are index arrays of the residuals (e.g. the samples of every channel in one
    time segment of a log): residuals may be correlated inside a cluster (model error,
    coloured noise), not across. The covariance is the delete-one-cluster jackknife's (CR3,
    MacKinnon and White 1985; Bell and McCaffrey 2002): with ``A = J^T J``, ``A_k`` and
    ``g_k = J_k^T r_k`` cluster k's share of A and its score, leaving cluster k out moves the
    (Gauss-Newton) estimate by ``d_k = (A - A_k)^-1 g_k`` (exactly, for a linear model), and
    ``cov = (G-1)/G sum_k d_k d_k^T``. The plain sandwich ``A^-1 (sum_k g_k g_k^T) A^-1``
    (CR1) understates the variance of a parameter that few clusters carry (a high-leverage
    cluster fits its own residuals); CR3 does not. ``dof = G - 1`` for Student's t (G
    clusters). Near-null directions of the column-scaled J get an infinite variance, as in
    :func:`covariance`.

    ``recentre``: the scores are taken at the optimum of the linearised problem (``r``
    projected off J's columns), for a point that is by construction not this problem's
    optimum: the covariance split evaluates shorter segments at the longer ones' estimate,
    and every cluster's score then shares the step back to the parts' optimum, which is no
    spread (measured: a 2 s-segment estimate 0.5 % from the 0.4 s parts' optimum in kL had
    its kL interval inflated 2.9x). Not at a fitted optimum: there what is left of a score's
    common part is the cost's roughness (a jump-law multisine log's contact timing) and the
    plain jackknife keeps it (measured: recentred there, one such log's kL interval shrank
    from +-0.24 to +-0.025 % and missed its truth).
    """
    G = len(clusters)

    def meat(Js: np.ndarray) -> np.ndarray:
        A = Js.T @ Js
        B = np.zeros_like(A)
        # recentre: the residuals at the optimum of the linearised problem
        r_opt = r - Js @ np.linalg.lstsq(Js, r, rcond=None)[0] if recentre else r
        for idx in clusters:
            Jk = Js[idx]
            d = np.linalg.lstsq(A - Jk.T @ Jk, Jk.T @ r_opt[idx], rcond=None)[0]
            g = A @ d  # A^-1 B A^-1 then sums d_k d_k^T
            B += np.outer(g, g)
        return B * ((G - 1) / max(G, 1))

    cov, cond = _sandwich(J, meat)
    return cov, cond, max(G - 1, 1)


def assess(names: Sequence[str], x: np.ndarray, cov: np.ndarray, dof: int, cond: float,
           lower: np.ndarray | None = None, upper: np.ndarray | None = None) -> Uncertainty:
    """Standard errors, intervals, correlations and the determined flags of an estimate.

    A parameter is *not determined* when its standard error is infinite (a near-null
    direction of J), above ``MAX_REL_SE`` of its value, its interval spans its whole search
    range [lower, upper], or it is correlated above ``MAX_CORR`` with another parameter while
    its relative SE exceeds ``CORR_REL_SE``.
    """
    from scipy.stats import t as student_t

    x = np.asarray(x, dtype=np.float64)
    var = np.diag(cov).copy()
    se = np.sqrt(np.where(var >= 0, var, np.nan))
    with np.errstate(invalid="ignore", divide="ignore"):
        d = np.where(np.isfinite(se) & (se > 0), se, np.nan)
        corr = cov / np.outer(d, d)
    np.fill_diagonal(corr, 1.0)
    tq = float(student_t.ppf(0.5 + CONFIDENCE / 2.0, dof))
    lo, hi = x - tq * se, x + tq * se
    p = x.shape[0]
    determined = np.ones(p, dtype=bool)
    reasons: list[list[str]] = [[] for _ in range(p)]
    for j, n in enumerate(names):
        rel = se[j] / abs(x[j]) if x[j] != 0 else np.inf
        if not np.isfinite(se[j]):
            reasons[j].append(f"J^T J is near-singular (condition {cond:.2g}) along {n}")
        elif rel > MAX_REL_SE:
            reasons[j].append(f"relative standard error {100 * rel:.3g} % > "
                              f"{100 * MAX_REL_SE:g} %")
        if lower is not None and upper is not None and np.isfinite(se[j]) \
                and lo[j] <= lower[j] and hi[j] >= upper[j]:
            reasons[j].append(f"the 95 % interval spans the whole search range "
                              f"[{lower[j]:g}, {upper[j]:g}]")
        for k, m in enumerate(names):
            if k != j and np.isfinite(corr[j, k]) and abs(corr[j, k]) > MAX_CORR \
                    and rel > CORR_REL_SE:
                reasons[j].append(f"correlation {corr[j, k]:+.4f} with {m}")
        determined[j] = not reasons[j]
    return Uncertainty(tuple(names), x, se, cov, corr, lo, hi, dof, tq, cond, determined,
                       reasons)
