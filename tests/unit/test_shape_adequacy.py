"""The shape verdict's scatter estimates and tests (identify.shape_adequacy) against known
noise and the textbook lack-of-fit F-test."""

from __future__ import annotations

import numpy as np
from scipy.stats import f as f_dist

from ema_cli.identify.shape_adequacy import (
    assess_shape,
    pure_error,
    repeat_groups,
    second_difference_scatter,
)


def test_second_differences_recover_white_noise_on_a_smooth_signal():
    # 0.05 noise on a 1 Hz sine sampled at 1 kHz: the MAD estimate's relative SE is
    # ~1.1/sqrt(n) = 1.1 %, so 5 % is > 4 SE; the third differences agree: white
    t = np.linspace(0, 5, 5001)
    y = 10 * np.sin(2 * np.pi * t) + 0.05 * np.random.default_rng(0).standard_normal(t.size)
    s, dof, white = second_difference_scatter(y)
    assert abs(s / 0.05 - 1) < 0.05 and dof == t.size - 2 and white
    # sampled coarsely, the curvature dominates: the estimate is flagged an upper bound
    tc = np.linspace(0, 5, 60)
    s, _, white = second_difference_scatter(10 * np.sin(2 * np.pi * tc))
    assert not white


def test_lack_of_fit_p_is_the_textbook_f_test():
    # y = x^2 at 6 x's, 3 repeats each, fitted by a straight line: Draper & Smith §2.1
    rng = np.random.default_rng(1)
    x = np.repeat(np.arange(6.0), 3)
    y = x**2 + 0.3 * rng.standard_normal(x.size)
    A = np.column_stack([np.ones_like(x), x])
    coef, *_ = np.linalg.lstsq(A, y, rcond=None)
    r = y - A @ coef
    groups = repeat_groups(x)
    ss_pe, dof_pe = pure_error(y, groups)
    assert len(groups) == 6 and dof_pe == 12
    ss_lof = float(r @ r) - ss_pe
    ad = assess_shape(r, np.sqrt(ss_pe / dof_pe), dof_pe, "repeats", "-", [],
                      lof=(ss_lof, 6 - 2, ss_pe, dof_pe))
    F = (ss_lof / 4) / (ss_pe / 12)
    assert abs(ad.lack_of_fit_p - f_dist.sf(F, 4, 12)) < 1e-15
    assert ad.verdict == "does not fit" and ad.lack_of_fit_p < 1e-6
