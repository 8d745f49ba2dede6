"""The exact Clopper-Pearson interval (``ema_cli.production.stats``) against closed forms,
against scipy's ``binomtest`` and by its exact coverage."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import stats

from ema_cli.errors import EmaError
from ema_cli.production.stats import clopper_pearson


def test_the_ends_have_closed_forms():
    # k = 0: the upper bound solves (1 - p)^n = a/2, p = 1 - (a/2)^(1/n); k = n mirrors it
    assert clopper_pearson(0, 10) == (0.0, pytest.approx(1 - 0.025 ** 0.1, rel=1e-12))
    assert clopper_pearson(0, 10)[1] == pytest.approx(0.3085, abs=5e-5)  # the tables' value
    assert clopper_pearson(10, 10) == (pytest.approx(0.025 ** 0.1, rel=1e-12), 1.0)
    assert clopper_pearson(0, 100, 0.9)[1] == pytest.approx(1 - 0.05 ** 0.01, rel=1e-12)
    assert clopper_pearson(0, 0) == (0.0, 1.0)
    assert clopper_pearson(0, 0, 0.5) == (0.0, 1.0)


def test_it_equals_scipys_exact_interval_on_a_grid():
    for n in (1, 2, 5, 10, 37, 100, 500, 1000):
        for k in sorted({0, 1, n // 3, n // 2, n - 1, n}):
            for level in (0.8, 0.95, 0.99):
                ci = stats.binomtest(k, n).proportion_ci(confidence_level=level,
                                                         method="exact")
                lo, hi = clopper_pearson(k, n, level)
                # binomtest finds the bounds by a root search (brentq, its own tolerance):
                # the two agree to ~1e-9 relative, 1e-7 leaves room
                assert lo == pytest.approx(ci.low, rel=1e-7, abs=1e-14), (k, n, level)
                assert hi == pytest.approx(ci.high, rel=1e-7, abs=1e-14), (k, n, level)
                # and each bound solves its defining equation: P(X >= k | lo) = a/2,
                # P(X <= k | hi) = a/2
                a = 1 - level
                if k > 0:
                    assert stats.binom.sf(k - 1, n, lo) == pytest.approx(a / 2, rel=1e-9)
                if k < n:
                    assert stats.binom.cdf(k, n, hi) == pytest.approx(a / 2, rel=1e-9)


@pytest.mark.parametrize("p", [0.05, 0.5, 0.9])
def test_the_exact_coverage_is_at_least_the_level(p):
    n = 100
    covered = 0.0
    for k in range(n + 1):
        lo, hi = clopper_pearson(k, n)
        if lo <= p <= hi:
            covered += stats.binom.pmf(k, n, p)
    assert covered >= 0.95, covered
    assert covered < 0.995  # conservative, not vacuous


def test_a_higher_level_gives_a_wider_interval_around_the_estimate():
    widths = []
    for level in (0.5, 0.9, 0.95, 0.999):
        lo, hi = clopper_pearson(30, 100, level)
        assert lo < 0.3 < hi
        widths.append(hi - lo)
    assert np.all(np.diff(widths) > 0)


@pytest.mark.parametrize("args, part", [
    ((0, 10, 1.0), "strictly between 0 and 1"), ((0, 10, 0.0), "strictly between 0 and 1"),
    ((0, 10, math.nan), "strictly between 0 and 1"), ((0, 10, True), "strictly between"),
    ((11, 10), "0 <= k <= n"), ((-1, 10), "0 <= k <= n"), ((0, -1), "0 <= k <= n"),
    ((1.5, 10), "whole number"), ((1, True), "whole number"),
])
def test_bad_arguments_are_one_line_errors(args, part):
    with pytest.raises(EmaError, match=part) as ei:
        clopper_pearson(*args)
    assert "\n" not in ei.value.message
