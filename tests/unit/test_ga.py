"""GA engine and operators: bounds, coding, selection, determinism, budget, convergence."""

from __future__ import annotations

import numpy as np
import pytest

from ema_cli.optim import operators as ops
from ema_cli.optim.ga import GAOptions, preset, run_ga

LO = np.array([-2.0, 10.0])
HI = np.array([3.0, 20.0])


class Quadratic:
    """J(x) = (x - x*)^T A (x - x*), minimum 0 at x* (inside the bounds); counts evaluations."""

    def __init__(self, x_star, A=None, lower=LO, upper=HI):
        self.x_star = np.asarray(x_star, dtype=float)
        self.A = np.eye(self.x_star.size) if A is None else np.asarray(A, dtype=float)
        self.lower, self.upper = np.asarray(lower, float), np.asarray(upper, float)
        self.rows = 0
        self.calls = 0

    def evaluate(self, X):
        self.rows += X.shape[0]
        self.calls += 1
        d = (X - self.x_star) / (self.upper - self.lower)
        return np.einsum("pi,ij,pj->p", d, self.A, d)


def rotated_valley(condition: float = 1e4) -> np.ndarray:
    """A 2x2 SPD matrix with eigenvalues 1 and ``condition`` along the diagonals (a narrow
    valley oblique to the axes, like kL-alpha)."""
    R = np.array([[1.0, 1.0], [-1.0, 1.0]]) / np.sqrt(2.0)
    return R @ np.diag([1.0, condition]) @ R.T


# ------------------------------------------------------------------------------ operators
@pytest.mark.parametrize("eta", [0.0, 1.0, 15.0, 100.0])
def test_real_operators_keep_bounds(eta):
    rng = np.random.default_rng(1)
    X = ops.random_real(rng, 400, LO, HI)
    X[:50] = LO  # parents on the bounds are the hard case
    X[50:100] = HI
    for op in (ops.sbx, ops.line_sbx):
        Y = op(rng, X, LO, HI, 1.0, eta)
        assert np.all(Y >= LO) and np.all(Y <= HI)
    Y = ops.polynomial_mutation(rng, X, LO, HI, 1.0, eta)
    assert np.all(Y >= LO) and np.all(Y <= HI)


def test_line_sbx_children_lie_on_the_parents_line():
    rng = np.random.default_rng(2)
    lo, hi = np.full(3, -1e3), np.full(3, 1e3)  # wide bounds: no clipping
    X = rng.standard_normal((200, 3))
    Y = ops.line_sbx(rng, X, lo, hi, 1.0, 1.0)
    p1, p2, c1 = X[0::2], X[1::2], Y[0::2]
    # c1 - p1 is parallel to p2 - p1: the cross products vanish (to rounding)
    cross = np.cross(c1 - p1, p2 - p1)
    assert np.max(np.abs(cross)) < 1e-12 * np.max(np.abs(X)) ** 2 * 10
    # the pair's midpoint is preserved: (c1 + c2)/2 = (p1 + p2)/2
    np.testing.assert_allclose(Y[0::2] + Y[1::2], X[0::2] + X[1::2], atol=1e-12)


def test_crossover_probability_zero_is_identity():
    rng = np.random.default_rng(3)
    X = ops.random_real(rng, 10, LO, HI)
    B = ops.random_binary(rng, 10, 40)
    np.testing.assert_array_equal(ops.sbx(rng, X, LO, HI, 0.0, 15.0), X)
    np.testing.assert_array_equal(ops.line_sbx(rng, X, LO, HI, 0.0, 1.0), X)
    np.testing.assert_array_equal(ops.single_point_crossover(rng, B, 0.0), B)


def test_single_point_crossover_swaps_one_tail():
    rng = np.random.default_rng(4)
    B = ops.random_binary(rng, 200, 40)
    C = ops.single_point_crossover(rng, B, 1.0)
    a, b, ca = B[0::2], B[1::2], C[0::2]
    for i in range(a.shape[0]):
        from_b = np.flatnonzero(ca[i] != a[i])
        if from_b.size:  # everything after the first differing bit came from b
            cut = from_b[0]
            np.testing.assert_array_equal(ca[i, :cut], a[i, :cut])
            np.testing.assert_array_equal(ca[i, cut:], b[i, cut:])
    # bits are conserved per column within each pair
    np.testing.assert_array_equal(C[0::2] + C[1::2], B[0::2] + B[1::2])


def test_bit_flip_rates():
    rng = np.random.default_rng(5)
    B = np.zeros((2000, 40), dtype=np.uint8)
    per_bit = ops.bit_flip(rng, B, 0.05, "bit")
    # 80,000 Bernoulli(0.05) draws: sd of the mean = sqrt(.05*.95/80000) = 7.7e-4; 5 sd
    assert abs(per_bit.mean() - 0.05) < 5 * 7.7e-4
    per_chrom = ops.bit_flip(rng, B, 0.05, "chromosome")
    flips = per_chrom.sum(axis=1)
    assert flips.max() == 1
    # 2000 rows, p = 0.05: sd = sqrt(.05*.95/2000) = 4.9e-3; 5 sd
    assert abs(flips.mean() - 0.05) < 5 * 4.9e-3


def test_binary_decoding_resolution_and_round_trip():
    bits = 10
    lo, hi = np.array([500.0, 0.002]), np.array([700.0, 0.004])
    zeros = np.zeros((1, 2 * bits), dtype=np.uint8)
    ones = np.ones((1, 2 * bits), dtype=np.uint8)
    np.testing.assert_allclose(ops.decode(zeros, lo, hi, bits)[0], lo)
    np.testing.assert_allclose(ops.decode(ones, lo, hi, bits)[0], hi)
    res = ops.resolution(lo, hi, bits)
    np.testing.assert_allclose(res, (hi - lo) / 1023.0)
    # integer 1 in the last (least significant) bit of each parameter = one resolution step
    one = zeros.copy()
    one[0, bits - 1] = 1
    one[0, 2 * bits - 1] = 1
    np.testing.assert_allclose(ops.decode(one, lo, hi, bits)[0] - lo, res, rtol=1e-12)
    # the most significant bit is worth 512 steps
    msb = zeros.copy()
    msb[0, 0] = 1
    np.testing.assert_allclose(ops.decode(msb, lo, hi, bits)[0, 0] - lo[0], 512 * res[0])
    rng = np.random.default_rng(6)
    B = ops.random_binary(rng, 50, 2 * bits)
    np.testing.assert_array_equal(ops.encode(ops.decode(B, lo, hi, bits), lo, hi, bits), B)
    # the paper's 20 bits resolve kL to 1.9e-4 N*m/rad and alpha to 1.9e-9 rad
    np.testing.assert_allclose(ops.resolution(lo, hi, 20), [200 / (2**20 - 1), 0.002 / (2**20 - 1)])


def test_roulette_is_proportional_to_inverse_cost():
    rng = np.random.default_rng(7)
    cost = np.array([1.0, 2.0, 4.0, np.inf, np.nan])
    idx = ops.roulette(rng, cost, 200_000)
    p = np.array([1.0, 0.5, 0.25]) / 1.75
    freq = np.bincount(idx, minlength=5) / idx.size
    assert freq[3] == 0.0 and freq[4] == 0.0  # non-finite J: fitness 0
    # binomial sd <= sqrt(.25/200000) = 1.1e-3; 5 sd
    np.testing.assert_allclose(freq[:3], p, atol=5.6e-3)
    # J = 0 (a perfect fit) dominates rather than dividing by zero
    idx0 = ops.roulette(rng, np.array([0.0, 1.0, 1.0]), 1000)
    assert np.all(idx0 == 0)


def test_tournament_prefers_lower_cost():
    rng = np.random.default_rng(8)
    cost = np.arange(10.0)
    idx = ops.tournament(rng, cost, 100_000, size=2)
    # P(i wins a 2-tournament with replacement) = ((10-i)^2 - (9-i)^2)/100
    p = np.array([((10 - i) ** 2 - (9 - i) ** 2) / 100 for i in range(10)])
    np.testing.assert_allclose(np.bincount(idx, minlength=10) / idx.size, p, atol=0.008)


# ------------------------------------------------------------------------------ the GA loop
@pytest.mark.parametrize("mode", ["paper", "improved"])
def test_same_seed_same_result_bit_for_bit(mode):
    opts = preset(mode, pop=30, generations=40)
    a = run_ga(Quadratic([0.5, 12.0]), opts, np.random.default_rng(42))
    b = run_ga(Quadratic([0.5, 12.0]), opts, np.random.default_rng(42))
    np.testing.assert_array_equal(a.x, b.x)
    np.testing.assert_array_equal(a.history.best, b.history.best)
    np.testing.assert_array_equal(a.history.x_best, b.history.x_best)
    c = run_ga(Quadratic([0.5, 12.0]), opts, np.random.default_rng(43))
    assert not np.array_equal(a.history.x_best, c.history.x_best)


def test_evaluation_count_is_the_real_budget():
    prob = Quadratic([0.5, 12.0])
    paper = preset("paper")  # 100 x 200, the paper's budget
    res = run_ga(prob, paper, np.random.default_rng(0))
    assert res.evaluations == prob.rows == paper.budget == 20_000
    assert prob.calls == 200  # one batched call per generation
    assert res.history.evaluations[-1] == 20_000
    prob = Quadratic([0.5, 12.0])
    improved = preset("improved", pop=51, generations=30)  # odd pop: trimmed offspring
    res = run_ga(prob, improved, np.random.default_rng(0))
    assert res.evaluations == prob.rows == 51 + 29 * (51 - 2) == improved.budget


def test_early_stopping_stops_and_counts():
    prob = Quadratic([0.5, 12.0])
    # stop after 15 generations without a 1e-3 relative improvement of the best-ever J
    opts = preset("improved", pop=40, generations=500, patience=15, early_tol=1e-3)
    res = run_ga(prob, opts, np.random.default_rng(1))
    assert res.stopped_early and res.generations < 500
    assert res.evaluations == prob.rows == 40 + (res.generations - 1) * 38
    assert res.history.best.shape == (res.generations,)


@pytest.mark.parametrize("seed", range(5))
def test_improved_converges_on_a_rotated_valley(seed):
    # minimum at x* = (0.5, 12); a valley with condition number 1e4 oblique to the axes.
    # 100 x 200 evaluations reach J < 1e-12, i.e. |x - x*| < 1e-6 of the range width.
    x_star = np.array([0.5, 12.0])
    prob = Quadratic(x_star, rotated_valley(1e4))
    res = run_ga(prob, preset("improved"), np.random.default_rng(seed))
    assert res.cost < 1e-12
    assert np.all(np.abs(res.x - x_star) < 1e-6 * (HI - LO))
    # the history is monotone in best-ever (elitism keeps the best)
    assert np.all(np.diff(res.history.best_ever) <= 0)
    np.testing.assert_array_equal(res.history.best, res.history.best_ever)


def test_paper_mode_reports_the_final_generation_and_is_coarser():
    x_star = np.array([0.5, 12.0])
    A = rotated_valley(1e4)
    errs = {}
    for mode in ("paper", "improved"):
        worst = 0.0
        for seed in range(5):
            res = run_ga(Quadratic(x_star, A), preset(mode), np.random.default_rng(seed))
            worst = max(worst, float(np.max(np.abs(res.x - x_star) / (HI - LO))))
            if mode == "paper":  # no elitism: the result is the last generation's best
                np.testing.assert_array_equal(res.x, res.history.x_best[-1])
                assert res.cost >= res.cost_best_ever
        errs[mode] = worst
    # measured: paper ~1e-3 .. 1e-2 of the range, improved < 1e-6
    assert errs["improved"] < 1e-6 < errs["paper"]


def test_options_are_validated():
    with pytest.raises(ValueError, match="pc"):
        GAOptions(pc=1.5)
    with pytest.raises(ValueError, match="bits"):
        GAOptions(bits=60)
    with pytest.raises(ValueError, match="elitism"):
        GAOptions(pop=10, elitism=10)
    with pytest.raises(ValueError, match="mode"):
        preset("fancy")  # type: ignore[arg-type]
