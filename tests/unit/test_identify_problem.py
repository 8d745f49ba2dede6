"""Eq. 8 problem and the least-squares certificate vs numpy, the simulator and brute force."""

from __future__ import annotations

import numpy as np
import pytest

from ema_cli.identify.torque.data import add_noise
from ema_cli.identify.torque.exact import solve_exact
from ema_cli.identify.torque.problem import TorqueProblem
from ema_cli.identify.torque.run import load_data
from ema_cli.identify.torque.settings import IdentifySettings
from ema_cli.model.transmission import shaft_torque

BOUNDS = (np.array([500.0, 0.002]), np.array([700.0, 0.004]))
BOUNDS_C = (np.array([500.0, 0.002, 0.0]), np.array([700.0, 0.004, 5.0]))


@pytest.fixture(scope="module")
def datasets():
    """Noise-free synthetic data (docs/model.md §8, 4,001 samples) in both damping forms."""
    return {form: load_data(IdentifySettings(synthetic={"damping": form}))
            for form in ("contact", "paper")}


def problem(data, form, fit_c=False, torque=None, step=1):
    lo, hi = BOUNDS_C if fit_c else BOUNDS
    tq = data.torque if torque is None else torque
    return TorqueProblem(data.dth[::step], data.dw[::step], tq[::step], form, lo, hi,
                         data.truth["c"], data.tau)


def test_data_exercise_the_gap(datasets):
    # the chirp drives |dth| well past alpha = 3 mrad: ~60 % of the samples are in contact
    for data in datasets.values():
        assert np.max(np.abs(data.dth)) > 2.0 * data.truth["alpha"]
        assert 0.4 < data.contact_fraction(data.truth["alpha"]) < 0.8


@pytest.mark.parametrize("form", ["contact", "paper"])
def test_model_torque_is_the_simulators_torque(datasets, form):
    # at the true parameters the model reproduces the kernel's _shaft_torque to rounding
    data = datasets[form]
    t = data.truth
    assert data.tau == 1e-4  # the simulator's default contact_tau [s]
    model = shaft_torque(data.dth, data.dw, t["kL"], t["alpha"], t["c"], form, data.tau)
    np.testing.assert_allclose(model, data.torque, rtol=0, atol=1e-12)
    prob = problem(data, form)
    assert prob.evaluate(np.array([[t["kL"], t["alpha"]]]))[0] < 1e-20
    # the ramp acts on contact-form data only: without it the torque differs just after
    # impacts (the jump form), with or without it the paper form is the same
    jump = shaft_torque(data.dth, data.dw, t["kL"], t["alpha"], t["c"], form, 0.0)
    differ = np.abs(jump - data.torque) > 1e-9
    assert differ.any() if form == "contact" else not differ.any()


def test_exact_jacobian_matches_finite_differences(datasets):
    # the analytic Jacobian of the contact form (the ramp's d/d alpha included) vs central
    # differences of the residuals, at a point off the optimum where samples are ramping
    from ema_cli.identify.torque.exact import _jacobian

    data = datasets["contact"]
    prob = problem(data, "contact", True)
    x = np.array([600.0, 0.00302, 0.7])
    A = _jacobian(prob, x)
    for j, h in enumerate((1e-3, 1e-10, 1e-6)):
        xp, xm = x.copy(), x.copy()
        xp[j] += h
        xm[j] -= h
        fd = (prob.residuals(xp) - prob.residuals(xm)) / (2 * h)
        # kinks (contact entry, the clamp, the ramp's end) make a few samples differ
        assert np.linalg.norm(fd - A[:, j]) < 1e-3 * np.linalg.norm(A[:, j]), j


@pytest.mark.parametrize("form", ["contact", "paper"])
@pytest.mark.parametrize("fit_c", [False, True])
def test_batched_cost_matches_numpy(datasets, form, fit_c):
    data = datasets["contact"]
    prob = problem(data, form, fit_c)
    rng = np.random.default_rng(0)
    X = prob.lower + rng.random((64, prob.lower.size)) * (prob.upper - prob.lower)
    ref = np.array([np.sum(prob.residuals(x) ** 2) for x in X])
    np.testing.assert_allclose(prob.evaluate(X), ref, rtol=1e-12)
    bad = X[:3].copy()
    bad[0, 0], bad[1, 1], bad[2, 1] = np.nan, np.inf, -1e-3
    assert np.all(np.isinf(prob.evaluate(bad)))


@pytest.mark.parametrize("fit_c", [False, True])
def test_exact_recovers_paper_form_data_exactly(datasets, fit_c):
    # Eq. 2 data fitted with Eq. 2: kL, c are a closed-form solve, so the optimum is the truth
    # to rounding (measured ~1e-14 relative)
    data = datasets["paper"]
    res = solve_exact(problem(data, "paper", fit_c))
    truth = np.array([data.truth[n] for n in res.names])
    np.testing.assert_allclose(res.x, truth, rtol=1e-9)
    assert res.cost < 1e-18


def test_exact_recovers_contact_form_data(datasets):
    data = datasets["contact"]
    res = solve_exact(problem(data, "contact", True))
    truth = np.array([data.truth[n] for n in res.names])
    np.testing.assert_allclose(res.x, truth, rtol=1e-9)


@pytest.mark.parametrize("form", ["contact", "paper"])
def test_exact_beats_a_brute_force_grid(datasets, form):
    # 1 % noise, every 8th sample (501): a 161 x 161 grid over the whole search box.
    # The certificate's J must not exceed the grid minimum, and it must sit within one grid
    # cell of the grid's argmin (the basin is unimodal at this resolution).
    data = datasets[form]
    noisy, _ = add_noise(data.torque, 1.0, seed=3)
    prob = problem(data, form, torque=noisy, step=8)
    ks = np.linspace(500.0, 700.0, 161)
    alphas = np.linspace(0.002, 0.004, 161)
    K, A = np.meshgrid(ks, alphas, indexing="ij")
    J = prob.evaluate(np.column_stack([K.ravel(), A.ravel()]))
    i = int(np.argmin(J))
    res = solve_exact(prob)
    assert res.cost <= J[i] * (1 + 1e-12)
    assert abs(res.x[0] - K.ravel()[i]) <= ks[1] - ks[0]
    assert abs(res.x[1] - A.ravel()[i]) <= alphas[1] - alphas[0]
    # and no grid point beats it anywhere (global, not only local)
    floor = res.cost * (1 - 1e-12)
    assert np.all(floor <= J)


def test_standard_errors_cover_the_truth(datasets):
    # with 1 % white noise the optimum's offset from the truth is a few standard errors at most
    data = datasets["contact"]
    noisy, _ = add_noise(data.torque, 1.0, seed=0)
    res = solve_exact(problem(data, "contact", torque=noisy))
    z = (res.x - [data.truth["kL"], data.truth["alpha"]]) / res.se
    assert np.all(np.abs(z) < 4.0)
    # kL and alpha trade off (a stiffer spring with a wider gap): positive correlation, 0.80
    # for the jump form (contact_tau = 0); the damping ramp (at most (c/tau)*pen, c/tau = 13 kL)
    # also tells alpha from the first samples of every impact: 0.53 at the default tau
    assert 0.4 < res.corr_k_alpha < 0.95


def test_the_fit_uses_the_datas_contact_tau(datasets):
    # synthetic data carry the simulator's contact_tau; a CSV does not (the model default);
    # the settings' contact_tau overrides either
    import dataclasses

    from ema_cli.identify.torque.run import build_problem
    from ema_cli.model.params import CONTACT_TAU

    data = datasets["contact"]
    assert build_problem(IdentifySettings(), data).tau == data.tau == 1e-4
    assert build_problem(IdentifySettings(contact_tau=0.0), data).tau == 0.0
    csv_like = dataclasses.replace(data, tau=None, truth=None)
    assert build_problem(IdentifySettings(c=0.8), csv_like).tau == CONTACT_TAU
