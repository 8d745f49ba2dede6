"""The local polish after the global optimiser (optim.polish, optim.cmaes) on functions with a
known minimum: a narrow rotated valley, a minimum on the bounds, the budget and determinism."""

from __future__ import annotations

import numpy as np
import pytest

from ema_cli.optim.cmaes import cma_search
from ema_cli.optim.ga import preset, run_ga
from ema_cli.optim.polish import compass_search, polished


class Quadratic:
    """f(x) = (x - c)' H (x - c) on [lo, hi]^n, counting the evaluations."""

    def __init__(self, c, H, lo=0.0, hi=1.0):
        self.c, self.H = np.asarray(c, float), np.asarray(H, float)
        n = self.c.size
        self.lower, self.upper = np.full(n, lo), np.full(n, hi)
        self.calls = 0

    def evaluate(self, X):
        self.calls += X.shape[0]
        d = X - self.c
        return np.einsum("ij,jk,ik->i", d, self.H, d)


def rotated_valley(n=4, cond=1e4, seed=3):
    """A valley 100 times narrower than long, not aligned with any variable."""
    q, _ = np.linalg.qr(np.random.default_rng(seed).standard_normal((n, n)))
    return q @ np.diag(np.geomspace(1.0, cond, n)) @ q.T


C_IN = np.array([0.3, 0.6, 0.45, 0.7])
X0 = np.array([0.8, 0.2, 0.1, 0.4])


def test_cma_follows_a_narrow_rotated_valley_to_its_minimum():
    p = Quadratic(C_IN, rotated_valley())
    f0 = float(Quadratic(C_IN, rotated_valley()).evaluate(X0[None])[0])
    x, f, h = cma_search(p, X0, f0, 1600, np.random.default_rng(1))
    assert f < 1e-10
    assert np.abs(x - C_IN).max() < 1e-4
    assert p.calls == int(h.evaluations[-1]) <= 1600
    assert np.all(np.diff(h.best_ever) <= 0.0)  # best so far never gets worse
    # the compass search on the same budget stays far above (it zig-zags along the valley)
    q = Quadratic(C_IN, rotated_valley())
    _, fc, _ = compass_search(q, X0, float(q.evaluate(X0[None])[0]), 1600)
    assert fc > 100 * f


def test_both_reach_a_minimum_on_the_bounds_exactly():
    c = np.array([0.2, 1.3, 0.5, -0.4])  # outside the box in two variables
    want = np.clip(c, 0.0, 1.0)
    for search in ("cma", "compass"):
        p = Quadratic(c, np.eye(4))
        if search == "cma":
            x, f, _ = cma_search(p, X0, float(p.evaluate(X0[None])[0]), 1600,
                                 np.random.default_rng(0))
        else:
            x, f, _ = compass_search(p, X0, float(p.evaluate(X0[None])[0]), 1600)
        assert x[1] == 1.0 and x[3] == 0.0, search
        assert np.abs(x - want).max() < 1e-4, search
        assert f == pytest.approx(0.3 ** 2 + 0.4 ** 2, abs=1e-7), search


def test_cma_is_deterministic_for_a_seed_and_respects_its_budget():
    runs = []
    for _ in range(2):
        p = Quadratic(C_IN, rotated_valley())
        runs.append(cma_search(p, X0, 1e9, 100, np.random.default_rng(5), lam=12))
        assert p.calls == 96  # whole iterations of 12 only
    assert np.array_equal(runs[0][0], runs[1][0]) and runs[0][1] == runs[1][1]


def test_polished_ga_result_improves_and_counts_every_evaluation():
    out = {}
    for method in ("cma", "compass"):
        p = Quadratic(C_IN, rotated_valley(cond=1e2))
        ga = run_ga(p, preset("improved", pop=16, generations=5, elitism=2),
                    np.random.default_rng(0))
        res = polished(p, ga, 800, method, np.random.default_rng(0))
        assert res.cost_best_ever < ga.cost_best_ever
        assert res.evaluations == p.calls <= ga.evaluations + 800
        assert res.history.evaluations[-1] == p.calls
        out[method] = res.cost_best_ever
    assert out["cma"] < 1e-6  # measured 2.8e-8 (compass: 7.1e-6)
    assert out["cma"] < 0.1 * out["compass"]


def test_polished_refuses_an_unknown_method():
    p = Quadratic(C_IN, np.eye(4))
    ga = run_ga(p, preset("improved", pop=8, generations=2, elitism=2), np.random.default_rng(0))
    with pytest.raises(ValueError, match="compass"):
        polished(p, ga, 100, "nelder-mead")
