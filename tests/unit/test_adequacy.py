"""The adequacy tests of a closed-loop fit (identify/closed_loop/adequacy.py): the statistics
against their distributions under white residuals, a model missing a term flagged with the
channel and the time range, the fit % against its closed form."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import chi2

from ema_cli.identify.closed_loop.adequacy import LAGS, P_LIMIT, adequacy, fit_percent

N = 4001
T = np.arange(N) * 1e-3
U = np.deg2rad(5.0) * np.sin(2 * np.pi * (0.5 * T + (8.0 - 0.5) / (2 * 4.0) * T**2))  # chirp
FIRST = np.arange(0, N, 400)


def test_white_residuals_pass_at_the_stated_rate():
    """Under white residuals Q is chi-square(M): its mean over seeds is M (within 3 standard
    errors of the mean, sqrt(2M/seeds)) and failures are as rare as P_LIMIT says."""
    qs, fails = [], 0
    seeds = 200
    for seed in range(seeds):
        rng = np.random.default_rng(seed)
        y_model = np.sin(T)
        y = y_model + 0.01 * rng.standard_normal(N)
        a = adequacy(("ch",), y[None], y_model[None], U, T, FIRST)
        qs.append(a["channels"]["ch"]["autocorrelation"]["q"])
        fails += not a["adequate"]
    assert abs(np.mean(qs) - LAGS) < 3 * np.sqrt(2 * LAGS / seeds)
    # two tests per run at P_LIMIT each: expected 0.4 failures in 200; 3 or more has a
    # chance below 1 % (binomial)
    assert fails <= 2
    assert chi2.isf(P_LIMIT, LAGS) == pytest.approx(
        adequacy(("ch",), np.zeros((1, N)) + 1, np.zeros((1, N)), U, T, FIRST)
        ["channels"]["ch"]["autocorrelation"]["q_limit"])


def _fit(columns: list[np.ndarray], y: np.ndarray) -> np.ndarray:
    A = np.column_stack(columns)
    return A @ np.linalg.lstsq(A, y, rcond=None)[0]


def test_a_model_missing_a_term_is_not_adequate_and_says_where():
    """Data with a cubic term of the input inside 2.0-2.8 s; a law without it is flagged on
    that channel and those times; the law with it passes."""
    rng = np.random.default_rng(7)
    gate = (T >= 2.0) & (T < 2.8)
    y = 3.0 * U + 40.0 * U**3 * gate + 0.002 * rng.standard_normal(N)
    wrong = _fit([U], y)
    right = _fit([U, U**3 * gate], y)
    other = np.cos(T) + 0.002 * rng.standard_normal(N)  # a second channel that fits
    a = adequacy(("current_a", "omega"), np.vstack([y, other]),
                 np.vstack([wrong, np.cos(T)]), U, T, FIRST)
    assert not a["adequate"]
    assert len(a["failures"]) == 1 and a["failures"][0].startswith("current_a:")
    windows = a["channels"]["current_a"]["failing_windows_s"]
    assert windows and all(w[0] >= 2.0 and w[1] <= 2.8 for w in windows)
    assert "t = 2" in a["failures"][0]
    assert a["channels"]["omega"]["passes"]
    b = adequacy(("current_a",), y[None], right[None], U, T, FIRST)
    assert b["adequate"], b["failures"]


def test_residuals_following_the_input_fail_the_cross_correlation():
    """White in themselves but a delayed copy of a white input: only the cross-correlation
    with the input (at lag 3) can see it."""
    rng = np.random.default_rng(3)
    u = rng.standard_normal(N)
    e = 0.2 * np.roll(u, 3) + rng.standard_normal(N)
    a = adequacy(("ch",), e[None], np.zeros((1, N)), u, T, FIRST)
    ch = a["channels"]["ch"]
    assert ch["autocorrelation"]["passes"] and not ch["cross_correlation_input"]["passes"]
    assert "cross-correlation with the input" in a["failures"][0]


def test_only_judged_channels_count():
    rng = np.random.default_rng(1)
    y = np.sin(T) + 0.1 * np.sin(40 * T) + 0.001 * rng.standard_normal(N)
    a = adequacy(("hand",), y[None], np.sin(T)[None], U, T, FIRST, judged=())
    assert a["adequate"] and not a["channels"]["hand"]["passes"]


def test_fit_percent_closed_form():
    y = np.sin(T)  # zero mean over whole periods? no: the mean is removed in the formula
    ym = y.mean()
    assert fit_percent(y, y) == 100.0
    model = ym + 0.9 * (y - ym)  # |y - model| = 0.1 |y - mean| -> 90 %
    assert fit_percent(y, model) == pytest.approx(90.0, abs=1e-9)
