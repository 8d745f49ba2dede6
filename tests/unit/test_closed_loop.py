"""Closed-loop output-error identification (identify.closed_loop, closed_loop_fit): log checks,
bounds, the record grid, the batched Jacobian, and fits of synthetic logs against the truth.

Budget: the fits here use 2 s logs (the chirp 0.5 -> 8 Hz over 2 s), bounds +-5 % around the
truth and a tiny GA at a coarse step (the polish at dt = 1e-5 s does the work); the 4 s,
default-budget, full-bounds, 10-seed runs are in ``experiments/bench_identify_logs.py``.
The data and the fits use the model's defaults: the `contact` damping form with its damping
ramp (``contact_tau`` = 1e-4 s, docs/model.md §2), as ``ema identify --make-data closed-loop``
and ``--closed-loop`` do without options.
"""

from __future__ import annotations

import numpy as np
import pytest

from ema_cli.errors import EmaError
from ema_cli.identify.closed_loop.ga_fit import (
    build_problem,
    fd_jacobian,
    horizons,
    run_closed_loop,
)
from ema_cli.identify.closed_loop.problem import (
    CHANNELS,
    ClosedLoopLog,
    check_free,
    load_log,
    make_grid,
)
from ema_cli.identify.log_settings import ClosedLoopSettings
from ema_cli.identify.make_data import closed_loop_log
from ema_cli.units import DEG

NAMES = ("kL", "alpha", "Fc", "sigma2")
PLANT: dict[str, float] = {}  # the model's defaults
DURATION_S = 2.0  # test logs [s] (the default is 4 s)


def as_log(syn) -> ClosedLoopLog:
    c = syn.columns
    return ClosedLoopLog(c["t_s"], c["theta_ref_deg"] * DEG,
                         {k: c[k] * CHANNELS[k][1] for k in CHANNELS}, "synthetic", 0.0,
                         syn.truth)


def narrow(truth: dict[str, float], rel: float = 0.05) -> dict[str, tuple[float, float]]:
    return {n: (truth[n] * (1 - rel), truth[n] * (1 + rel)) for n in NAMES}


def small_settings(truth: dict[str, float], **kw) -> ClosedLoopSettings:
    return ClosedLoopSettings(plant=PLANT, free=narrow(truth), search="ga",
                              ga={"pop": 16, "generations": 3},
                              ga_dt_s=1e-4, profile_points=5, **kw)


@pytest.fixture(scope="module")
def clean():
    return closed_loop_log(PLANT, 0.0, 0, duration_s=DURATION_S)


def test_the_simulator_at_the_truth_reproduces_the_log(clean):
    """The log was made following the chirp itself and keeps the command at its samples
    only: at the truth, the simulator fed the default cubic command table reproduces every
    channel within 2e-5 of its range (measured 1.1e-5), and 10x closer than fed straight
    lines between the samples (7.7e-4)."""
    worst = {}
    for mode in ("cubic", "linear"):
        problem, _ = build_problem(ClosedLoopSettings(plant=PLANT, free_contact=False,
                                                      command=mode), as_log(clean))
        x = np.array([clean.truth[n] for n in problem.names])
        Y = problem.predict(x[None])[0]
        worst[mode] = max(float(np.max(np.abs(Y[j] - problem.measured[j]))
                                / np.ptp(problem.measured[j]))
                          for j in range(len(problem.channels)))
    assert worst["cubic"] < 2e-5 and 10 * worst["cubic"] < worst["linear"], worst


def _fd_mismatch(problem, x, j, rel):
    """|forward difference (step rel*x_j) - batched central column| / |column|."""
    r0, J = fd_jacobian(problem, x)
    xp = x.copy()
    xp[j] += rel * x[j]
    rp = problem.weighted_residuals(xp[None])[0]
    return np.linalg.norm((rp - r0) / (rel * x[j]) - J[:, j]) / np.linalg.norm(J[:, j])


def test_batched_jacobian_matches_one_sided_differences(clean):
    problem, _ = build_problem(ClosedLoopSettings(plant=PLANT, free_contact=False), as_log(clean))
    x = np.array([clean.truth[n] for n in problem.names])
    j = problem.names.index("kL")
    # forward difference (step 3e-4 of kL) vs the central one (1e-4): measured 1.6 % of the
    # column (the paper form: 0.17 %); the contact's kinks (entry, the end of the damping ramp,
    # the no-pull clamp) leave ~1 % of non-smoothness at this scale, and no more
    assert _fd_mismatch(problem, x, j, 3e-4) < 0.03
    # the jump form (contact_tau = 0, the damping torque jumps at each impact) on the same log:
    # the simulator spreads the jump over the step centred on the touch (docs/model.md §2), so
    # it is as differentiable as the ramp: 1.3 % (measured; 48 % before that band, 87 % at
    # 1e-3, 240 % at 3e-5, where a contact moving across the step grid moved the output)
    jump, _ = build_problem(ClosedLoopSettings(plant={"contact_tau": 0.0}, free_contact=False),
                            as_log(clean))
    assert _fd_mismatch(jump, x, j, 3e-4) < 0.03


def test_noise_free_log_gives_the_truth(clean):
    fit = run_closed_loop(small_settings(clean.truth), as_log(clean))
    err = {n: fit.x[j] / clean.truth[n] - 1 for j, n in enumerate(fit.names)}
    assert max(abs(e) for e in err.values()) < 1e-4, err  # issue: 1e-4 relative
    assert fit.to_json()["not_determined"] == []


@pytest.mark.slow  # the slow tier: make test-all (CI runs it)
def test_default_fit_of_a_default_log_gives_the_truth():
    """The GA search (``search: ga``) on the issue's noise-free figure: a 4 s ``--make-data
    closed-loop`` log (contact form, backlash 3 mrad) fitted with the default free set, bounds
    and budget. The GA on the first second and the polish continued over 1, 2, 4 s land on the truth
    (measured 1e-12 relative, 24 s on 2 cores); the GA on the whole log instead ends in
    another valley (kL +11 %, alpha +8 %; experiments/bench_identify_logs.py)."""
    syn = closed_loop_log({}, 0.0, 0)
    fit = run_closed_loop(ClosedLoopSettings(search="ga"), as_log(syn))
    assert fit.horizons == [1.0, 2.0, 4.0]
    assert [s["horizon_s"] for s in fit.stages] == fit.horizons
    err = {n: fit.x[j] / syn.truth[n] - 1 for j, n in enumerate(fit.names)}
    assert max(abs(e) for e in err.values()) < 1e-4, err  # issue: 1e-4 relative


def test_continuation_horizons_and_prefix(clean):
    assert horizons(4.0, 1.0) == [1.0, 2.0, 4.0]
    assert horizons(4.5, 1.0) == [1.0, 2.0, 4.5]  # 4 s would be within 1.5x of the log
    assert horizons(2.0, 1.0) == [1.0, 2.0]
    assert horizons(1.2, 1.0) == [1.2]
    assert horizons(4.0, None) == [4.0]
    problem, _ = build_problem(ClosedLoopSettings(plant=PLANT, free_contact=False), as_log(clean))
    part = problem.prefix(0.5)
    assert part.log.n == 501 and part.log.t[-1] == 0.5
    assert np.array_equal(part.scales, problem.scales) and part.names == problem.names
    # the prefix's simulation is the whole log's, cut: same samples where both exist
    x = np.array([clean.truth[n] for n in problem.names])
    np.testing.assert_array_equal(part.predict(x[None])[0],
                                  problem.predict(x[None])[0][:, :501])
    assert problem.prefix(10.0).log.n == problem.log.n


@pytest.mark.slow  # the slow tier: make test-all (CI runs it)
def test_one_percent_noise_within_tolerance_and_covered():
    """Seeds 0..2 (the 10-seed run with the default budget is in the benchmark)."""
    covered = dict.fromkeys(NAMES, 0)
    for seed in range(3):
        syn = closed_loop_log(PLANT, 1.0, seed, duration_s=DURATION_S)
        fit = run_closed_loop(small_settings(syn.truth, seed=seed), as_log(syn))
        js = fit.to_json()
        e = js["error_pct_vs_truth"]
        assert abs(e["kL"]) < 0.5 and abs(e["alpha"]) < 0.5, e
        assert abs(e["Fc"]) < 2 and abs(e["sigma2"]) < 2, e
        assert js["not_determined"] == []
        for n in NAMES:
            covered[n] += js["truth_in_ci95"][n]
        q = js["quadratic_check"]
        assert all(0.5 < q[n] < 2 for n in NAMES), q  # a smooth cost: SEs are meaningful
        # the residuals are the noise: RMS ~ 1 noise estimate per channel (measured 0.91-1.03;
        # the current 0.69: its second differences carry the impacts' fast transients too, so
        # its noise estimate is high)
        assert js["fit_quality"]["reaches_noise_level"] is True, js["fit_quality"]
        assert all(0.5 < v < 1.3 for v in js["fit_quality"]["rms_over_scale"].values())
    assert all(v >= 2 for v in covered.values()), covered


def test_a_fit_that_misses_the_noise_level_says_so():
    """A model that cannot explain the log (the load inertia fixed 30 % high): the residuals
    stay far above the channels' noise estimates, and the tool warns instead of presenting the
    standard errors as the whole story. (The multiple-shooting search at a small budget: 2
    starts, 10 joint iterations, no lengthening, the contact law stated, no whole-log polish;
    the warning comes from the fit's own residuals, whatever the budget: the default budget
    took 37 s here for the same verdict, on a 2 s log.)"""
    syn = closed_loop_log(PLANT, 1.0, 0, duration_s=1.0)
    settings = ClosedLoopSettings(plant={**PLANT, "JL": 0.013}, free=narrow(syn.truth),
                                  free_contact=False, polish=False, profile_points=5,
                                  shooting={"starts": 2, "max_iter": 10, "lengthen_s": []})
    js = run_closed_loop(settings, as_log(syn)).to_json()
    assert js["fit_quality"]["reaches_noise_level"] is False
    assert max(js["fit_quality"]["rms_over_scale"].values()) > 2.0
    assert any("does not reach the noise level" in w for w in js["warnings"]), js["warnings"]


def _write(tmp_path, text: str):
    p = tmp_path / "log.csv"
    p.write_text(text)
    return p


def _rows(n: int, bad: dict[int, str] | None = None) -> str:
    lines = ["t_s,theta_ref_deg,theta_load_deg,current_a"]
    for i in range(n):
        lines.append(bad.get(i) if bad and i in bad else
                     f"{i * 1e-3},{np.sin(i / 10)},{np.sin(i / 10 - 0.1)},{np.cos(i / 7)}")
    return "\n".join(lines) + "\n"


@pytest.mark.parametrize("text, expect", [
    ("t_s,theta_ref_deg\n0,0\n", "lacks column(s) theta_load_deg"),
    (_rows(100, {40: "0.04,0.1,nan,1"}), "column 'theta_load_deg' has 1 empty, non-numeric, "
                                         "NaN or inf value(s) (first at line 42)"),
    (_rows(100, {40: "0.039,0.1,0.1,1"}), "column 't_s' must be strictly increasing; it is not "
                                          "at line 42"),
    (_rows(20), "has 20 data rows; a closed-loop log needs at least 50"),
    (_rows(100).replace(",1.0\n", ",x\n", 1), "column 'current_a' has 1 empty"),
])
def test_bad_logs_are_named(tmp_path, text, expect):
    with pytest.raises(EmaError) as exc:
        load_log(_write(tmp_path, text))
    assert expect in exc.value.message


def test_constant_channel_is_refused(tmp_path):
    text = _rows(100).splitlines()
    text = [text[0]] + [",".join(line.split(",")[:3] + ["2.0"]) for line in text[1:]]
    with pytest.raises(EmaError, match="column 'current_a' is constant"):
        load_log(_write(tmp_path, "\n".join(text) + "\n"))


@pytest.mark.parametrize("free, fixed, expect", [
    ({"kL": (900, 300)}, {}, "free.kL: needs LO < HI"),
    ({"kL": (-1, 300)}, {}, "free.kL: the lower bound must be >= 0"),
    ({"bogus": (0, 1)}, {}, "free.bogus: not a parameter a closed-loop fit can free"),
    ({"kL": (300, 900)}, {"kL": 500}, "free.kL: kL is also fixed by plant.kL"),
    ({"zeta_t": (0, 1), "c": (0, 2)}, {}, "free zeta_t or c, not both"),
    ({"kL": (300, float("inf"))}, {}, "bounds must be finite"),
    ({}, {}, "no free parameters"),
])
def test_bad_bounds_are_named(free, fixed, expect):
    with pytest.raises(EmaError) as exc:
        check_free(free, fixed)
    assert expect in exc.value.message


def test_record_grid_exact_or_interpolated():
    t = np.arange(401) * 1e-3
    g = make_grid(t, 1e-5, 8)
    assert g.n_steps == 40_000 and g.dec == 100 and np.array_equal(g.index, np.arange(401))
    t2 = np.sort(np.concatenate([t, [0.0105]]))  # an off-grid stamp: interpolate
    g2 = make_grid(t2 + 3e-7, 1e-5, 8)
    assert g2.index is None and g2.dec == 50  # twice as fine as the log's median step


def test_non_uniform_log_is_interpolated(clean):
    """Stamps off the integration grid and unevenly spaced: the record (twice as fine as the
    log) is interpolated; at the truth it matches the log to the interpolation error."""
    log = as_log(clean)
    rng = np.random.default_rng(0)
    keep = np.sort(rng.choice(np.arange(1, log.n - 1), size=log.n // 2, replace=False))
    t = np.concatenate([[0.0], log.t[keep] + 3.7e-6])  # from rest at 0, then off the grid
    ch = {c: np.interp(t, log.t, y) for c, y in log.channels.items()}
    uneven = ClosedLoopLog(t, np.interp(t, log.t, log.theta_ref), ch, "uneven", 0.0,
                           clean.truth)
    problem, _ = build_problem(ClosedLoopSettings(plant=PLANT, free_contact=False), uneven)
    x = np.array([clean.truth[n] for n in problem.names])
    Y = problem.predict(x[None])[0]
    for j, c in enumerate(problem.channels):
        # the two sides differ by the interpolation of a 1 ms log, ~(w*h)^2/8 of a 8 Hz wave,
        # more where the backlash impacts give the current fast transients: measured 0.69 %
        # (current; 0.40 % in the paper form), <= 0.17 % for the other channels
        rel = np.sqrt(np.mean((Y[j] - problem.measured[j]) ** 2)) / np.ptp(problem.measured[j])
        assert rel < 1e-2, (c, rel)


@pytest.mark.slow  # the slow tier: make test-all (CI runs it); about 45 s on 2 cores
def test_the_fit_estimate_counts_the_kernel_work_of_a_fit():
    """The estimate's cost model (``api.identify_logs.fit_estimate``: passes that do not depend
    on the starts plus passes per start) against the kernel's own lane-step tally of a
    multiple-shooting fit of the README's 4 s log (1 % noise) at 2 starts, where the earlier
    model (per start only) counted a third of the work: within 20 %."""
    from ema_cli.api import identify_logs as il
    from ema_cli.sim import runner

    syn = closed_loop_log({}, 1.0, 0)
    cfg = ClosedLoopSettings(shooting={"starts": 2})
    before = runner.TALLY["lane_steps"]
    run_closed_loop(cfg, as_log(syn))
    passes = (runner.TALLY["lane_steps"] - before) / (syn.columns["t_s"][-1] / cfg.dt_s)
    model = il.FIT_PASSES_FIXED + 2 * il.FIT_PASSES_PER_START
    assert 0.8 < passes / model < 1.2, (passes, model)
