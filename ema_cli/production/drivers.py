"""Why units fail: the tolerances ranked by their effect on each limit's margin.

For each limit, the standardised rank regression coefficients (SRRC) of the normalised margin
on the sampled values: ranks of the margin and of each tolerance, standardised, fitted by least
squares over the units with a margin. The SRRC of a tolerance is the change of the margin's
rank, in standard deviations, per standard deviation of the tolerance's rank, the others held:
its sign says which way the tolerance pushes the margin (negative: a larger value eats the
margin), its magnitude ranks the tolerances, and R^2 says how much of the margin's scatter the
ranked tolerances explain together (a low R^2: interactions or noise dominate, the ranking is
weak). Chosen over Sobol indices because it uses the yield's own units (no extra runs, no
special sampling design), captures any monotonic effect (a step, a saturation), and is the
standard screening measure of sampling-based reliability studies (Saltelli et al., "Global
Sensitivity Analysis: The Primer", 2008, §1.2.5; Helton & Davis 2003).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

MIN_UNITS = 10  # units with a margin needed to rank [-]


def srrc(X: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, float]:
    """Standardised rank regression coefficients of ``y`` [n] on the columns of ``X`` [n, d]
    and the R^2 of the rank regression -> (coefficients [d], R^2). Constant columns get 0."""
    from scipy.stats import rankdata

    R = np.column_stack([rankdata(X[:, j]) for j in range(X.shape[1])])
    ry = rankdata(y)
    sd = R.std(axis=0)
    ok = sd > 0
    beta = np.zeros(X.shape[1])
    if not ok.any() or ry.std() == 0:
        return beta, 0.0
    Z = (R[:, ok] - R[:, ok].mean(axis=0)) / sd[ok]
    zy = (ry - ry.mean()) / ry.std()
    coef, *_ = np.linalg.lstsq(Z, zy, rcond=None)
    beta[ok] = coef
    resid = zy - Z @ coef
    return beta, float(1.0 - np.mean(resid ** 2))


def rank_drivers(samples: Any, paths: Sequence[str], rows: Sequence[Any]) -> list[dict[str, Any]]:
    """Per limit row (``rows``: :class:`~ema_cli.production.run.Row`), the tolerances ranked
    by |SRRC| of its margin -> ``[{label, n_fail, n, r2, drivers: [(path, srrc), ...]}]``
    (limits with fewer than :data:`MIN_UNITS` margins, or that never vary, are left out)."""
    X_all = samples[list(paths)].to_numpy(dtype=float)
    out = []
    for r in rows:
        y = samples[f"{r.label} margin"].to_numpy(dtype=float)
        ok = np.isfinite(y)
        if ok.sum() < MIN_UNITS or np.ptp(y[ok]) == 0:
            continue
        beta, r2 = srrc(X_all[ok], y[ok])
        order = np.argsort(-np.abs(beta), kind="stable")
        out.append({"label": r.label, "test": r.test,
                    "n_fail": int((samples[f"{r.label} result"] == "FAIL").sum()),
                    "n": int(ok.sum()), "r2": r2,
                    "drivers": [(paths[j], float(beta[j])) for j in order]})
    return out
