"""The kernel's vectorisable elementary functions (model.vmath) against numpy, in ulps.

They replace libm inside the SIMD lane loop (the compiled kernel cannot call libm there without
losing vectorisation), so every LuGre step depends on them: exp and expm1 (bristle decay,
Stribeck curve), log and pow (a Stribeck exponent other than 1).
"""

from __future__ import annotations

import numpy as np
import pytest

from ema_cli._numba import njit
from ema_cli.model.vmath import exp_nb, expm1_nb, log_nb, pow_nb


@njit(cache=False)
def _apply(name, x, a):
    out = np.empty_like(x)
    for j in range(x.size):
        if name == 0:
            out[j] = exp_nb(x[j])
        elif name == 1:
            out[j] = expm1_nb(x[j])
        elif name == 2:
            out[j] = log_nb(x[j])
        else:
            out[j] = pow_nb(x[j], a)
    return out


def ulps(got: np.ndarray, want: np.ndarray) -> np.ndarray:
    """|got - want| in units of the last place of ``want`` (both finite)."""
    return np.abs(got - want) / np.spacing(np.abs(want))


RNG = np.random.default_rng(7)


def test_exp_within_two_ulps_over_its_range():
    x = np.concatenate([RNG.uniform(-700, 700, 20000), RNG.uniform(-1, 1, 20000),
                        np.linspace(-0.36, 0.36, 2001)])
    assert ulps(_apply(0, x, 0.0), np.exp(x)).max() <= 2.0


def test_expm1_keeps_relative_accuracy_near_zero_and_far_from_it():
    x = np.concatenate([RNG.uniform(-60, 700, 20000), RNG.uniform(-2, 2, 20000),
                        np.geomspace(1e-300, 1e-2, 2000), -np.geomspace(1e-300, 1e-2, 2000),
                        np.linspace(-0.4, 0.4, 4001)])
    got, want = _apply(1, x, 0.0), np.expm1(x)
    assert ulps(got, want).max() <= 4.0  # measured: 4, just above |x| = 0.35 (exp(x) - 1)
    # tiny arguments: e**x - 1 = x to the last bit (a plain exp(x) - 1 would give 0)
    tiny = np.array([1e-300, -1e-300, 1e-20, -3e-17])
    assert np.array_equal(_apply(1, tiny, 0.0), tiny)


def test_expm1_and_exp_limits():
    x = np.array([-1e6, -61.0, -800.0, 710.0, np.inf, -np.inf, np.nan, 0.0])
    e1 = _apply(1, x, 0.0)
    assert e1[:3].tolist() == [-1.0, -1.0, -1.0]
    assert e1[3] == np.inf and e1[4] == np.inf and e1[5] == -1.0
    assert np.isnan(e1[6]) and e1[7] == 0.0
    e = _apply(0, x, 0.0)
    assert e[0] == 0.0 and e[2] == 0.0 and e[3] == np.inf and np.isnan(e[6]) and e[7] == 1.0


def test_log_within_four_ulps_over_positive_normals():
    x = np.concatenate([np.geomspace(1e-300, 1e300, 20000), RNG.uniform(0.5, 2.0, 20000)])
    x = x[np.abs(x - 1.0) > 1e-3]  # near 1 log's relative error is measured below in absolute
    assert ulps(_apply(2, x, 0.0), np.log(x)).max() <= 4.0  # measured: 3
    near = np.linspace(0.999, 1.001, 2001)
    assert np.abs(_apply(2, near, 0.0) - np.log(near)).max() <= 2.3e-16


@pytest.mark.parametrize("a", [1.0, 2.0, 0.5, 1.7])
def test_pow_matches_numpy(a):
    x = np.concatenate([np.geomspace(1e-8, 1e4, 5000), [0.0]])
    got, want = _apply(3, x, a), x ** a
    assert got[-1] == 0.0
    # exp(a*log x): the error grows with |a*log x| (here up to ~34) by about that many ulps
    assert np.allclose(got[:-1], want[:-1], rtol=1e-14, atol=0.0)
    if a == 1.0:
        assert np.array_equal(got, x)
