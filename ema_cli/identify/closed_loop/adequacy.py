"""Whether a fitted model is adequate for a closed-loop log: the residual tests of output-error
identification (Ljung, System Identification, 2nd ed., §16.6), per channel.

- *fit %*: ``100 (1 - |y - y_model| / |y - mean y|)`` (the normalised RMS fit; 100 % is exact).
- *whiteness*: the residual's normalised autocorrelation ``rho(k)``, lags 1..M. For white
  residuals each ``rho(k)`` is about N(0, 1/N), so the 95 % bound of a single lag is
  ``1.96/sqrt(N)``, and the portmanteau ``Q = N sum_k rho(k)^2`` is chi-square with M
  degrees of freedom: the test fails when Q exceeds its (1 - :data:`P_LIMIT`) quantile.
- *independence of the input*: the normalised cross-correlation ``r_eu(k)`` of the residual
  with the input (the reference), lags 0..M (the input's past). When the residual is white
  each lag is N(0, 1/N) whatever the input's colour (Bartlett: the same bound), but the lags
  are correlated as the input is: the statistic is ``N r^T P^-1 r`` with ``P`` the input's
  autocorrelation matrix (Ljung eq. 16.63), chi-square with P's rank as degrees of freedom.
  A model that misses a term leaves residuals that follow the input.

Where a channel fails, the windows of the log (the fit's segments) with the largest residual
relative to the rest name the time ranges where the model does not fit. A model is *adequate*
when every judged channel passes both tests. The tests assume the measurement noise is white
(a logger's quantisation or a filtered channel is not): the verdict says which test failed, on
which channel, with the statistic and its limit, so a coloured sensor is seen as such.
"""

from __future__ import annotations

from typing import Any

import numpy as np

LAGS = 20
"""Lags of the whiteness and cross-correlation tests, M [samples]: at 1 kHz, 20 ms (the
closed loop's fastest dynamics; the contact's ring-down is shorter)."""
P_LIMIT = 1e-3
"""A test fails when its portmanteau statistic's chance under white residuals is below this
[-]: several channels and two tests are judged at once (8 tests on a 4-channel log: a right
model fails one by chance 0.8 % of the time)."""
WINDOW_RATIO = 1.5
"""A window is named where the model fails when its residual RMS is above this x the channel's
over the log [-]."""


def _acf(e: np.ndarray, lags: int) -> np.ndarray:
    """Normalised autocorrelation of ``e`` (mean removed), lags 1..``lags`` [-]."""
    e = e - e.mean()
    d = float(e @ e)
    n = e.shape[0]
    if d <= 0:
        return np.zeros(lags)
    return np.array([float(e[k:] @ e[:n - k]) / d for k in range(1, lags + 1)])


def _xcf(e: np.ndarray, u: np.ndarray, lags: int) -> np.ndarray:
    """Normalised cross-correlation of the residual ``e`` with the input's past ``u``,
    ``r(k) = sum_t e(t) u(t - k) / (|e| |u|)``, lags 0..``lags`` (means removed) [-]."""
    e = e - e.mean()
    u = u - u.mean()
    d = float(np.sqrt((e @ e) * (u @ u)))
    n = e.shape[0]
    if d <= 0:
        return np.zeros(lags + 1)
    return np.array([float(e[k:] @ u[:n - k]) / d for k in range(lags + 1)])


def fit_percent(y: np.ndarray, y_model: np.ndarray) -> float:
    """The normalised RMS fit ``100 (1 - |y - y_model| / |y - mean y|)`` [%]."""
    den = float(np.linalg.norm(y - y.mean()))
    return float(100.0 * (1.0 - np.linalg.norm(y - y_model) / den)) if den > 0 else float("nan")


def failing_windows(e: np.ndarray, t: np.ndarray, first: np.ndarray, k: int = 3
                    ) -> list[tuple[float, float, float]]:
    """The (at most ``k``) windows starting at samples ``first`` whose residual RMS exceeds
    :data:`WINDOW_RATIO` x the channel's over the log, worst first -> (t0 [s], t1 [s], ratio)."""
    n = e.shape[0]
    whole = float(np.sqrt(np.mean(e**2)))
    if whole <= 0:
        return []
    edges = [*np.asarray(first, dtype=int).tolist(), n]
    out = []
    for a, b in zip(edges[:-1], edges[1:], strict=True):
        if b > a:
            q = float(np.sqrt(np.mean(e[a:b] ** 2))) / whole
            if q > WINDOW_RATIO:
                out.append((float(t[a]), float(t[b - 1]), q))
    return sorted(out, key=lambda w: -w[2])[:k]


def channel_adequacy(e: np.ndarray, u: np.ndarray, y: np.ndarray, y_model: np.ndarray,
                     t: np.ndarray, first: np.ndarray, lags: int = LAGS) -> dict[str, Any]:
    """The tests of one channel: residual ``e`` (any unit), input ``u``, measured ``y`` and
    modelled ``y_model`` (same unit), times ``t`` [s], window starts ``first`` [samples]."""
    from scipy.stats import chi2

    n = e.shape[0]
    bound = 1.96 / np.sqrt(n)
    rho = _acf(e, lags)
    rxu = _xcf(e, u, lags)
    q_w = float(n * rho @ rho)
    # the lags of r_eu are correlated as the input is (Cov = rho_u(k - j)/N for white e): the
    # quadratic form in the inverse of the input's autocorrelation matrix (Ljung eq. 16.63),
    # chi-square with its rank as degrees of freedom (a smooth input's matrix is near-singular)
    from scipy.linalg import toeplitz

    P = toeplitz(np.r_[1.0, _acf(u, lags)])
    Pinv = np.linalg.pinv(P, rcond=1e-6, hermitian=True)
    dof_x = int(np.linalg.matrix_rank(P, tol=1e-6 * np.linalg.norm(P, 2), hermitian=True))
    q_x = float(n * rxu @ Pinv @ rxu)
    p_w = float(chi2.sf(q_w, lags))
    p_x = float(chi2.sf(q_x, dof_x))
    white, indep = p_w >= P_LIMIT, p_x >= P_LIMIT
    return {
        "fit_percent": fit_percent(y, y_model),
        "autocorrelation": {"lags": lags, "bound_95": float(bound),
                            "max_abs": float(np.max(np.abs(rho))),
                            "lags_outside_bound": int(np.sum(np.abs(rho) > bound)),
                            "q": q_w, "q_limit": float(chi2.isf(P_LIMIT, lags)),
                            "p_value": p_w, "passes": white},
        "cross_correlation_input": {"lags": lags + 1, "dof": dof_x, "bound_95": float(bound),
                                    "max_abs": float(np.max(np.abs(rxu))),
                                    "lags_outside_bound": int(np.sum(np.abs(rxu) > bound)),
                                    "q": q_x, "q_limit": float(chi2.isf(P_LIMIT, dof_x)),
                                    "p_value": p_x, "passes": indep},
        "passes": white and indep,
        "failing_windows_s": [] if white and indep else [
            [a, b, q] for a, b, q in failing_windows(e, t, first)],
    }


def adequacy(channels: tuple[str, ...], measured: np.ndarray, modelled: np.ndarray,
             u: np.ndarray, t: np.ndarray, first: np.ndarray,
             judged: tuple[str, ...] | None = None, lags: int = LAGS) -> dict[str, Any]:
    """The adequacy of a fit: per channel (rows of ``measured`` and ``modelled``, SI) the
    tests of :func:`channel_adequacy` against the input ``u`` (SI); ``judged`` the channels
    that count (default all) -> {"adequate", "channels", "failures" (one line each: the
    channel, the test, its statistic and limit, the time ranges)}."""
    judged = tuple(channels) if judged is None else judged
    per = {}
    failures = []
    for j, c in enumerate(channels):
        e = measured[j] - modelled[j]
        a = channel_adequacy(e, u, measured[j], modelled[j], t, first, lags)
        per[c] = a
        if c in judged and not a["passes"]:
            tests = [f"{name} Q = {a[key]['q']:.3g} > {a[key]['q_limit']:.3g} "
                     f"(max |r| {a[key]['max_abs']:.3g}, bound {a[key]['bound_95']:.2g})"
                     for key, name in (("autocorrelation", "residual autocorrelation"),
                                       ("cross_correlation_input",
                                        "cross-correlation with the input"))
                     if not a[key]["passes"]]
            where = ", ".join(f"t = {w[0]:.3g}-{w[1]:.3g} s ({w[2]:.2g} x)"
                              for w in a["failing_windows_s"])
            failures.append(f"{c}: " + "; ".join(tests)
                            + (f"; worst at {where}" if where else "")
                            + f"; fit {a['fit_percent']:.4g} %")
    return {"adequate": not failures, "channels": per, "failures": failures,
            "judged": list(judged), "p_limit": P_LIMIT,
            "method": f"residual whiteness and cross-correlation with the input (lags 0..{lags},"
                      f" portmanteau chi-square, p >= {P_LIMIT:g}), fit % per channel"}


__all__ = ["LAGS", "P_LIMIT", "adequacy", "channel_adequacy", "failing_windows", "fit_percent"]
