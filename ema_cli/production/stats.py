"""Exact (Clopper-Pearson) confidence intervals on a yield: k passing units out of n."""

from __future__ import annotations

import math
import numbers

from scipy import stats

from ema_cli.errors import EmaError


def _count(name: str, value: object) -> int:
    if isinstance(value, bool) or not isinstance(value, numbers.Integral):
        raise EmaError(f"{name} must be a whole number of units, got {value!r}")
    return int(value)


def clopper_pearson(k: int, n: int, level: float = 0.95) -> tuple[float, float]:
    """The exact two-sided interval (lower, upper) on a proportion from ``k`` successes in
    ``n`` trials at confidence ``level`` in (0, 1).

    lower = B^-1(a/2; k, n-k+1), upper = B^-1(1-a/2; k+1, n-k) with a = 1 - level and B^-1
    the beta quantile; k = 0 gives lower 0, k = n gives upper 1, n = 0 gives (0, 1). Its
    coverage is at least ``level`` for every true proportion (conservative).
    """
    k, n = _count("k (units passing)", k), _count("n (units)", n)
    if n < 0 or not 0 <= k <= n:
        raise EmaError(f"expected 0 <= k <= n units, got k = {k}, n = {n}")
    if isinstance(level, bool) or not isinstance(level, numbers.Real) \
            or not (math.isfinite(level) and 0.0 < level < 1.0):
        raise EmaError(f"confidence level must lie strictly between 0 and 1 (e.g. 0.95), got "
                       f"{level!r}")
    if n == 0:
        return 0.0, 1.0
    a = 1.0 - float(level)
    lower = 0.0 if k == 0 else float(stats.beta.ppf(a / 2, k, n - k + 1))
    upper = 1.0 if k == n else float(stats.beta.ppf(1 - a / 2, k + 1, n - k))
    return lower, upper
