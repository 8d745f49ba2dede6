"""The issue's accuracy claims on synthetic data (docs/model.md §8, 4,001 samples, paper budget).

Measured on this data (seed 0, SeedSequence(0).spawn(10)):
* noise-free, matched forms: the improved GA lands within ~1e-13 % of the truth in every seed;
  the paper-mode GA within ~6e-5 % (median) and ~0.002 % (worst).
* 1 % noise: the improved GA within ~1e-7 % of the least-squares optimum in every seed.
* contact data fitted with the paper form: the optimum is biased by ~ -0.66 % (kL), -0.47 %
  (alpha) (-0.99 %, -0.68 % with the jump form, contact_tau = 0).
"""

from __future__ import annotations

import numpy as np
import pytest

from ema_cli.api.reproduce import identification_summary
from ema_cli.identify.torque.run import load_data, run_identification
from ema_cli.identify.torque.settings import IdentifySettings

TARGET_PCT = 0.01  # the accuracy target for the improved GA [%]
SEEDS = 10


@pytest.fixture(scope="module")
def data():
    return {(form, noise): load_data(IdentifySettings(
        synthetic={"damping": form, "noise_pct": noise})) for form in ("contact", "paper")
        for noise in (0.0, 1.0)}


@pytest.mark.parametrize("form", ["contact", "paper"])
def test_improved_ga_hits_the_truth_on_matched_noise_free_data(data, form):
    s = IdentifySettings(method="ga", model=form, runs=SEEDS, synthetic={"damping": form})
    res = run_identification(s, data[(form, 0.0)])
    err = np.abs(res.errors_pct())
    assert err.shape == (SEEDS, 2)
    assert np.all(err < TARGET_PCT), err.max(axis=0)
    assert all(r.evaluations == s.ga.options("ga").budget == 19_602 for r in res.runs)


def test_paper_mode_ga_is_measured_not_assumed(data):
    s = IdentifySettings(method="ga-paper", runs=SEEDS)
    res = run_identification(s, data[("contact", 0.0)])
    err = np.abs(res.errors_pct())
    assert all(r.evaluations == 20_000 for r in res.runs)
    # measured: median ~6e-5 % / 3e-5 %, worst ~0.0017 % / 0.0003 % (kL / alpha): far from the
    # improved GA's 1e-13 %, yet far below the paper's 0.85 % / 3.7 % (with the jump contact,
    # contact_tau = 0: median ~2e-3 % / 7e-4 %, worst ~0.11 % / 0.05 %)
    worst = err.max(axis=0)
    assert np.all(worst > TARGET_PCT / 100)
    assert np.all(worst < [0.85, 3.7])


@pytest.mark.parametrize("form", ["contact", "paper"])
def test_improved_ga_reaches_the_optimum_with_noise(data, form):
    s = IdentifySettings(method="ga", model=form, runs=SEEDS,
                         synthetic={"damping": form, "noise_pct": 1.0})
    res = run_identification(s, data[(form, 1.0)])
    dist = np.abs(res.distance_to_optimum_pct())
    assert np.all(dist < TARGET_PCT), dist.max(axis=0)
    # with noise the optimum itself is off the truth (here by ~0.03 %), so the GA is judged
    # against the optimum, and no run may beat the certificate by more than rounding
    assert all(r.cost >= res.optimum.cost * (1 - 1e-9) for r in res.runs)


def test_improved_ga_fits_c_too(data):
    s = IdentifySettings(method="ga", runs=3, fit_c=True, synthetic={"noise_pct": 1.0})
    res = run_identification(s, data[("contact", 1.0)])
    assert res.names == ("kL", "alpha", "c")
    dist = np.abs(res.distance_to_optimum_pct())
    assert np.all(dist < TARGET_PCT), dist.max(axis=0)


def test_mismatch_bias_contact_data_paper_model(data):
    # the contact form's clamp and its zero torque in the gap are not in Eq. 2: fitting Eq. 2 to
    # contact data is biased. Measured on these data: kL -0.66 %, alpha -0.47 % (c fixed; with
    # the jump form, contact_tau = 0: -0.99 %, -0.68 %, the damping then jumps at each impact).
    res = run_identification(IdentifySettings(method="exact", model="paper"),
                             data[("contact", 0.0)])
    bias = res.optimum_errors_pct()
    np.testing.assert_allclose(bias, [-0.66, -0.47], atol=0.02)
    matched = run_identification(IdentifySettings(method="exact", model="contact"),
                                 data[("contact", 0.0)])
    assert np.all(np.abs(matched.optimum_errors_pct()) < 1e-9)


@pytest.mark.slow  # the slow tier: make test-all (CI runs it)
def test_summary_for_the_reproduction(tmp_path):
    flat = identification_summary({"runs": 2, "ga": {"generations": 60}}, tmp_path)
    for key in ("kL_error_pct_worst", "alpha_error_pct_worst", "kL_optimum", "corr_kL_alpha",
                "paper_mode_kL_error_pct_worst", "mismatch_kL_bias_pct"):
        assert np.isfinite(flat[key]), key
    assert flat["runs"] == 2 and flat["mismatch_model"] == "paper"
    assert (tmp_path / "convergence.png").is_file()
    assert (tmp_path / "ga-paper" / "fit.png").is_file()


def test_parallel_runs_equal_serial_runs(data):
    # each run draws only from its own SeedSequence child: processes change nothing
    base = {"runs": 3, "seed": 7, "ga": {"generations": 30}}
    serial = run_identification(IdentifySettings(**base), data[("contact", 1.0)])
    parallel = run_identification(IdentifySettings(**base, n_jobs=2), data[("contact", 1.0)])
    np.testing.assert_array_equal(serial.X, parallel.X)
    assert not np.array_equal(serial.X[0], serial.X[1])
