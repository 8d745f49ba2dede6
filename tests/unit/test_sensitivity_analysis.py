"""The analysis layer of `ema sensitivity` (sensitivity/sampling.py, sensitivity/analyze.py) on
functions with known indices, through the same ``sample`` -> values -> ``indices`` path the
command takes for its metrics.

References: the Ishigami function's Sobol indices in closed form (Saltelli et al., Global
Sensitivity Analysis: The Primer, 2008, §4.4; a = 7, b = 0.1), and its Morris elementary
effects by brute force over the Morris grid.
"""

from __future__ import annotations

import itertools
import math

import numpy as np
import pandas as pd
import pytest

from ema_cli.errors import EmaError
from ema_cli.sensitivity import analyze
from ema_cli.sensitivity.analyze import (
    analysis_seed,
    convergence,
    indices,
    prefix_sizes,
    ranking,
    resample_counts,
    sobol_blocks,
    sobol_conf_asymptotic,
    sobol_estimates,
    sobol_indices,
    spearman,
)
from ema_cli.sensitivity.sampling import FactorRange, sample

A, B = 7.0, 0.1
PI = math.pi
ISHIGAMI = [FactorRange(f"x{i}", -PI, PI) for i in (1, 2, 3)]


def ishigami(x: np.ndarray) -> np.ndarray:
    """f = sin x1 + a sin^2 x2 + b x3^4 sin x1."""
    return np.sin(x[:, 0]) + A * np.sin(x[:, 1]) ** 2 + B * x[:, 2] ** 4 * np.sin(x[:, 0])


def ishigami_indices() -> tuple[np.ndarray, np.ndarray]:
    """Analytic (S1, ST): V1 = (1 + b pi^4/5)^2/2, V2 = a^2/8, V3 = 0,
    V13 = b^2 pi^8 (1/18 - 1/50), V = V1 + V2 + V13."""
    v1 = 0.5 * (1 + B * PI**4 / 5) ** 2
    v2 = A**2 / 8
    v13 = B**2 * PI**8 * (1 / 18 - 1 / 50)
    v = v1 + v2 + v13
    return np.array([v1, v2, 0.0]) / v, np.array([v1 + v13, v2, v13]) / v


def test_analytic_values_are_the_published_ones():
    s1, st = ishigami_indices()
    np.testing.assert_allclose(s1, [0.3139, 0.4424, 0.0], atol=5e-5)
    np.testing.assert_allclose(st, [0.5576, 0.4424, 0.2437], atol=5e-5)


@pytest.mark.parametrize("n", [1024, 4096])
def test_sobol_on_ishigami_within_the_confidence_intervals(n):
    design = sample(ISHIGAMI, "sobol", n, seed=1)
    assert design.n_rows == n * (3 + 2)
    table = indices(design, ishigami(design.values), seed=0)
    s1, st = ishigami_indices()
    assert list(table["factor"]) == ["x1", "x2", "x3"]
    # every estimate inside its own reported (95 %) interval around the analytic value
    assert np.all(np.abs(table["S1"] - s1) <= table["S1_conf"])
    assert np.all(np.abs(table["ST"] - st) <= table["ST_conf"])
    # and the intervals shrink like 1/sqrt(n): at n = 4096 every half-width is below 0.05
    if n == 4096:
        assert table["ST_conf"].max() < 0.05
    assert table[["mu_star", "sigma"]].isna().all().all()
    assert list(ranking(table, "sobol")["factor"]) == ["x1", "x2", "x3"]


def morris_brute_force(levels: int = 4) -> np.ndarray:
    """E|EE_i| over the Morris grid: factor i steps between levels l and l + p/2 (delta =
    p/(2(p-1)) of the range), the others uniform over the p levels."""
    grid = np.linspace(-PI, PI, levels)
    half = levels // 2
    delta = levels / (2 * (levels - 1))
    out = np.zeros(3)
    for i in range(3):
        effects = []
        others = [k for k in range(3) if k != i]
        for lo in range(half):
            for a, b in itertools.product(grid, grid):
                x_lo = np.zeros((1, 3))
                x_lo[0, others] = (a, b)
                x_hi = x_lo.copy()
                x_lo[0, i], x_hi[0, i] = grid[lo], grid[lo + half]
                effects.append(abs(ishigami(x_hi)[0] - ishigami(x_lo)[0]) / delta)
        out[i] = np.mean(effects)
    return out


def test_morris_on_ishigami_against_brute_force():
    design = sample(ISHIGAMI, "morris", 512, seed=3, num_levels=4)
    assert design.n_rows == 512 * (3 + 1)
    table = indices(design, ishigami(design.values), seed=0)
    exact = morris_brute_force()  # [7.70, 7.875, 6.25]: x2 > x1 > x3
    assert np.all(np.abs(table["mu_star"] - exact) <= table["mu_star_conf"] + 1e-9)
    assert list(ranking(table, "morris")["factor"]) == ["x2", "x1", "x3"]
    assert table[["S1", "ST"]].isna().all().all()


@pytest.mark.parametrize(("method", "big", "small"), [("sobol", 512, 64), ("morris", 40, 5)])
def test_designs_are_nested(method, big, small):
    """The first k*(D+2) (Sobol) or k*(D+1) (Morris) rows of an n-design are the k-design of
    the same seed: the convergence figure needs no new runs."""
    a = sample(ISHIGAMI, method, big, seed=7)
    b = sample(ISHIGAMI, method, small, seed=7)
    np.testing.assert_array_equal(a.prefix(small).unit, b.unit)
    np.testing.assert_array_equal(a.unit[:b.n_rows], b.unit)


def test_convergence_ends_at_the_full_design():
    design = sample(ISHIGAMI, "sobol", 256, seed=1)
    y = ishigami(design.values)
    conv = convergence(design, y, seed=0)
    assert sorted(set(conv["n"])) == [8, 16, 32, 64, 128, 256] == prefix_sizes(256)
    last = conv[conv["n"] == 256].reset_index(drop=True)
    full = indices(design, y, seed=0)
    np.testing.assert_allclose(last[["S1", "ST", "ST_conf"]], full[["S1", "ST", "ST_conf"]])
    reused = convergence(design, y, seed=0, full=full)  # the full design's table reused
    pd.testing.assert_frame_equal(reused, conv)


def test_factor_ranges_map_the_unit_interval():
    lin = FactorRange("a", 2.0, 6.0)
    log = FactorRange("b", 1e-3, 1e-1, log=True)
    u = np.array([0.0, 0.5, 1.0])
    np.testing.assert_allclose(lin.values(u), [2.0, 4.0, 6.0])
    np.testing.assert_allclose(log.values(u), [1e-3, 1e-2, 1e-1], rtol=1e-12)
    assert log.values(np.array([1.0]))[0] == 0.1  # the end points exactly
    with pytest.raises(EmaError, match="low < high"):
        FactorRange("c", 1.0, 1.0)
    with pytest.raises(EmaError, match="log range needs low > 0"):
        FactorRange("d", 0.0, 1.0, log=True)


def test_outputs_that_cannot_or_need_not_be_analysed():
    design = sample(ISHIGAMI, "sobol", 16, seed=0)
    zero = indices(design, np.full(design.n_rows, 3.0))
    assert (zero[["S1", "ST", "S1_conf", "ST_conf"]] == 0.0).all().all()
    y = ishigami(design.values)
    y[5] = np.nan
    with pytest.raises(ValueError, match="1 of 80 runs gave a non-finite value"):
        indices(design, y)
    with pytest.raises(ValueError, match="expected 80 values"):
        indices(design, y[:10])
    with pytest.raises(EmaError, match="power of two"):
        sample(ISHIGAMI, "sobol", 100, seed=0)


def test_same_seed_same_indices():
    d1, d2 = (sample(ISHIGAMI, "sobol", 64, seed=5) for _ in range(2))
    t1, t2 = (indices(d, ishigami(d.values), seed=9) for d in (d1, d2))
    np.testing.assert_array_equal(t1[["S1", "S1_conf", "ST", "ST_conf"]],
                                  t2[["S1", "S1_conf", "ST", "ST_conf"]])
    assert spearman(np.array([3.0, 1, 2]), np.array([30.0, 5, 20])) == pytest.approx(1.0)


def test_sobol_estimates_and_bootstrap_are_salibs():
    """The indices are SALib's (sobol.analyze); the bootstrap, given SALib's resamples (its
    index matrix r[n, num_resamples] of the same seed) as draw counts, gives SALib's
    half-widths."""
    from SALib.analyze import sobol

    from ema_cli.sensitivity.sampling import problem

    design = sample(ISHIGAMI, "sobol", 256, seed=2)
    y = ishigami(design.values)
    seed, nr, n = analysis_seed(4), 300, 256
    ref = sobol.analyze(problem(ISHIGAMI), y, calc_second_order=False, num_resamples=nr,
                        seed=seed)
    table = indices(design, y, num_resamples=nr, seed=4)
    np.testing.assert_allclose(table["S1"], ref["S1"], rtol=0, atol=1e-12)
    np.testing.assert_allclose(table["ST"], ref["ST"], rtol=0, atol=1e-12)
    r = np.random.default_rng(seed).integers(n, size=(n, nr))  # SALib's draws
    counts = np.stack([np.bincount(r[:, k], minlength=n) for k in range(nr)]).astype(float)
    s1, st = sobol_estimates(*sobol_blocks(y, 3), counts)
    z = 1.959963984540054
    np.testing.assert_allclose(z * s1.std(axis=0, ddof=1), ref["S1_conf"], rtol=1e-10)
    np.testing.assert_allclose(z * st.std(axis=0, ddof=1), ref["ST_conf"], rtol=1e-10)
    # our own draws are other resamples of the same bootstrap: the same half-widths up to the
    # bootstrap's scatter (about 1/sqrt(2*300) = 4 % each)
    np.testing.assert_allclose(table["ST_conf"], ref["ST_conf"], rtol=0.2)


def test_resample_counts_draw_n_of_n_in_blocks(monkeypatch):
    monkeypatch.setattr(analyze, "BOOTSTRAP_BLOCK", 64 * 10)  # 10 resamples of 64 per block
    blocks = list(resample_counts(64, 25, seed=3))
    assert [b.shape for b in blocks] == [(10, 64), (10, 64), (5, 64)]
    counts = np.concatenate(blocks)
    assert np.all(counts.sum(axis=1) == 64) and counts.min() >= 0
    np.testing.assert_array_equal(counts, np.concatenate(list(resample_counts(64, 25, seed=3))))
    # each base sample is drawn once per resample on average
    assert abs(counts.mean() - 1.0) < 1e-12 and 0.8 < counts.var() < 1.2


def test_bootstrap_half_widths_approach_the_asymptotic_ones():
    """With many resamples the bootstrap half-widths are the delta-method ones (the limit
    they approach) within their own scatter (about 1/sqrt(2*4000) = 1.1 %, 5 % allowed);
    at 200 resamples they scatter by several per cent between seeds."""
    design = sample(ISHIGAMI, "sobol", 2048, seed=1)
    y = ishigami(design.values)
    s1, s1_conf, st, st_conf = sobol_indices(y, 3, 0.95, 4000, seed=7)
    a_s1, a_st = sobol_conf_asymptotic(y, 3, 0.95)
    np.testing.assert_allclose(s1_conf, a_s1, rtol=0.05)
    np.testing.assert_allclose(st_conf, a_st, rtol=0.05)
    few = np.array([sobol_indices(y, 3, 0.95, 200, seed=k)[3] for k in range(8)])
    spread = few.std(axis=0, ddof=1) / few.mean(axis=0)
    assert np.all((spread > 0.01) & (spread < 0.15))
    # half-widths scale with the z of the confidence level
    _, a90 = sobol_conf_asymptotic(y, 3, 0.90)
    np.testing.assert_allclose(a90 / a_st, 1.6448536269514722 / 1.959963984540054)


def test_the_console_flags_indices_too_imprecise_to_rank():
    # issue 39: the console prints the ± next to each index and names the indices whose
    # half-width is over a fifth of the value, or whose ST lies outside [0, 1] (hand table)
    import pandas as pd

    from ema_cli.sensitivity.analyze import imprecise, index_text, ranking

    t = pd.DataFrame({"factor": ["a", "b", "c", "d"], "S1": [0.5, 0.2, 0.1, 0.0],
                      "S1_conf": [0.01] * 4, "ST": [0.6, 1.15, 0.3, 0.01],
                      "ST_conf": [0.05, 0.1, 0.2, 0.001]})
    # b: outside [0, 1]; c: 0.2 > 0.3 / 5; a: 0.05 <= 0.12; d: 0.001 <= 0.002
    assert imprecise(t, "sobol") == ["b ST = 1.15 (outside [0, 1])", "c ST = 0.3 ± 0.2"]
    assert imprecise(ranking(t, "sobol"), "sobol") == imprecise(t, "sobol")  # ranked or not
    assert index_text(t.iloc[0], "sobol") == "a 0.6 ± 0.05"
    m = pd.DataFrame({"factor": ["a"], "mu_star": [2.0], "mu_star_conf": [0.5]})
    assert imprecise(m, "morris") == ["a mu_star = 2 ± 0.5"]
