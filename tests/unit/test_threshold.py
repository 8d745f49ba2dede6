"""The threshold finder on analytic metrics with known answers, and on the simulator."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest

from ema_cli.analysis.threshold import (
    Criterion,
    expected_rounds,
    find_threshold,
    simulation_evaluator,
)
from ema_cli.errors import EmaError
from ema_cli.sim.signals import InputSignal
from ema_cli.units import DEG


def analytic(values: np.ndarray) -> pd.DataFrame:
    # metric = x^2: the largest x with x^2 <= 2 is sqrt(2)
    return pd.DataFrame({"iae_pos_deg_s": values**2, "overshoot_pct": 10.0 / values})


def test_max_direction_finds_sqrt2():
    r = find_threshold(analytic, [Criterion("iae_pos_deg_s", "<=", 2.0)], 0.01, 100.0,
                       rtol=1e-6)
    assert r.status == "found"
    assert r.threshold == pytest.approx(math.sqrt(2), rel=1e-6)
    assert r.threshold <= math.sqrt(2)  # conservative: the last passing value
    assert r.bracket[1] >= math.sqrt(2)
    assert r.rel_width <= 1e-6
    assert r.n_sims == len(r.history) and r.n_sims <= 12 * 12


@pytest.mark.parametrize("lo, hi, log, rtol, limit", [
    (0.01, 100.0, True, 1e-6, 2.0), (0.001, 0.1, True, 1e-3, 1e-3), (1.0, 1e4, True, 0.05, 50.0),
    (0.1, 10.0, False, 1e-3, 30.0), (0.5, 3.0, False, 1e-4, 3.0)])
def test_the_estimate_counts_the_rounds_the_search_runs(lo, hi, log, rtol, limit):
    """The time estimate's round count (ema threshold announces it) is the count the search
    uses when the threshold lies inside the range: at most one round off (the threshold's
    position decides whether the last grid interval is already narrow enough)."""
    r = find_threshold(analytic, [Criterion("iae_pos_deg_s", "<=", limit)], lo, hi, log=log,
                       rtol=rtol)
    assert r.status == "found"
    assert r.rounds <= expected_rounds(lo, hi, log, rtol) <= r.rounds + 1


def test_min_direction_finds_smallest_passing_value():
    # overshoot = 10/x <= 4  <=>  x >= 2.5: the smallest passing x is 2.5
    r = find_threshold(analytic, [Criterion("overshoot_pct", "<=", 4.0)], 0.1, 1000.0,
                       direction="min", rtol=1e-5, log=True)
    assert r.status == "found"
    assert r.threshold == pytest.approx(2.5, rel=1e-5) and r.threshold >= 2.5


def test_two_criteria_take_the_stricter():
    # x^2 <= 2 (x <= 1.414) and 10/x >= 8 (x <= 1.25): threshold 1.25, linear grid
    crit = [Criterion.parse("iae_pos_deg_s<=2"), Criterion.parse("overshoot_pct>=8")]
    r = find_threshold(analytic, crit, 0.5, 3.0, log=False, rtol=1e-6)
    assert r.threshold == pytest.approx(1.25, rel=1e-6)


def test_out_of_range_and_nan_handling():
    crit = [Criterion("iae_pos_deg_s", "<=", 1e6)]
    assert find_threshold(analytic, crit, 1, 10).status == "all-pass"
    crit = [Criterion("iae_pos_deg_s", "<=", 1e-9)]
    assert find_threshold(analytic, crit, 1, 10).status == "none-pass"
    nan_after_3 = lambda v: pd.DataFrame({"iae_pos_deg_s": np.where(v > 3, np.nan, 0.0)})  # noqa: E731
    r = find_threshold(nan_after_3, [Criterion("iae_pos_deg_s", "<=", 1)], 1, 10, rtol=1e-6)
    assert r.threshold == pytest.approx(3.0, rel=1e-6)


def test_bad_requirements_are_clear():
    with pytest.raises(EmaError, match="METRIC<=VALUE"):
        Criterion.parse("overshoot is small")
    with pytest.raises(EmaError, match="unknown metric 'nope'"):
        Criterion.parse("nope<=1")
    with pytest.raises(EmaError, match="LO > 0"):
        find_threshold(analytic, [Criterion("iae_pos_deg_s", "<=", 1)], 0.0, 1.0)


def test_dead_band_threshold_on_the_simulator_is_consistent():
    # Largest transmission dead band keeping the residual oscillation of a 0.1 deg step
    # below 2 % of the step; spot-check the answer by simulating both bracket ends.
    ev = simulation_evaluator("deadzone2", {}, {}, InputSignal("step", 0.1 * DEG), 0.5, 1e-5)
    crit = [Criterion("p2p_err_pos_deg", "<=", 0.002)]
    r = find_threshold(ev, crit, 1e-4, 0.1, rtol=0.02)
    assert r.status == "found"
    lo, hi = r.bracket
    check = ev(np.array([lo, hi]))
    assert check["p2p_err_pos_deg"][0] <= 0.002 < check["p2p_err_pos_deg"][1]
