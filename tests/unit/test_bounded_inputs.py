"""Issue 22, every input bounded before work starts: one estimate of a command's integration
steps against a documented cap (ema_cli/limits.py), refused with the option or key that reduces
it, through the API and the CLI; worker counts capped at the cores available, with a note."""

from __future__ import annotations

from pathlib import Path

import pytest
from typer.testing import CliRunner

from ema_cli.analysis.freqresp import sinestream_steps
from ema_cli.api import acceptance, freqresp, identify_closed_loop
from ema_cli.cli.main import app
from ema_cli.errors import EmaError
from ema_cli.limits import MAX_CASE_STEPS, cap_workers, check_steps, cores

ROOT = Path(__file__).resolve().parents[2]
LOG = str(ROOT / "experiments" / "logs" / "design_hc_1pct.csv")  # a 2 s closed-loop log
runner = CliRunner()


def test_the_sinestream_estimate_is_hand_arithmetic():
    # at most: 0.5 s of settling and one period, then (when the response still changes) a
    # run settling max(3 periods, 0.5 s) and measuring 4 periods. 1 Hz at dt 1e-3: 500 + 1000,
    # then max(3, ceil(0.5)) + 4 = 7 periods -> 7000 steps; 0.1 Hz: 500 + 10000, then 7
    # periods -> 70000; two amplitudes double it
    assert sinestream_steps([1.0, 0.1], 1e-3, 2) == pytest.approx(
        2 * (1500 + 7000 + 10500 + 70000))
    # 100 Hz: 500 + 10, then 0.5 s of settling is 50 periods: (50 + 4) x 10 steps
    assert sinestream_steps([100.0], 1e-3) == pytest.approx(510 + 540)


def test_check_steps_refuses_above_the_cap_naming_what_and_how():
    check_steps(MAX_CASE_STEPS, "x", "y")
    for bad in (MAX_CASE_STEPS * 1.01, float("inf"), float("nan")):
        with pytest.raises(EmaError, match=r"^thing: about .* more than the cap of 1e\+11; do y$"):
            check_steps(bad, "thing", "do y")


def test_a_frequency_response_down_to_a_microhertz_is_refused_before_it_runs():
    with pytest.raises(EmaError, match=r"frequency response from 1e-06 Hz .* about 5\.25e\+12 "
                                       r"integration steps.*raise f_min_hz"):
        freqresp(f_min_hz=1e-6)
    r = runner.invoke(app, ["freqresp", "--f-min", "1e-6", "--out", "/nonexistent/x"])
    assert r.exit_code == 2 and "raise --f-min" in " ".join(r.output.split()), r.output


def test_a_closed_loop_fit_at_a_nanosecond_step_is_refused_naming_the_log():
    with pytest.raises(EmaError, match=r"^dt_s: one pass over the 2 s log '.*design_hc_1pct"
                                       r"\.csv' at dt_s = 1e-09 s is 2e\+09 integration steps"):
        identify_closed_loop(data=LOG, dt_s=1e-9)
    r = runner.invoke(app, ["identify", "--closed-loop", "--data", LOG, "--set", "dt_s=1e-9"])
    assert r.exit_code == 2 and "raise dt_s" in r.output, r.output


def test_a_too_fine_actuator_step_names_the_acceptance_test():
    with pytest.raises(EmaError, match=r"^tests\.frequency-response \(frequency_response\): "
                                       r"about 1\.4e\+11 .*dt_s = 1e-08 s is too fine"):
        acceptance("configs/acceptance.yaml",
                   {"tests.frequency-response.set": {"simulation.dt_s": 1e-8}})


def test_workers_are_capped_at_the_cores_with_a_note(tmp_path):
    have = cores()
    assert cap_workers(None) == (None, "") and cap_workers(-1) == (-1, "")
    assert cap_workers(have) == (have, "")
    n, note = cap_workers(have + 8, "--n-jobs")
    assert n == have and f"--n-jobs {have + 8} is more than the {have} cores" in note
    assert cap_workers(10_000, cluster=True) == (10_000, "")
    out = tmp_path / "s"
    r = runner.invoke(app, ["sweep", "configs/deadzone2.yaml", "--n-jobs", str(have + 4),
                            "--set", "simulation.duration_s=0.01", "--no-figures",
                            "--no-progress", "--out", str(out)])
    assert r.exit_code == 0, r.output
    text = " ".join(r.output.split())
    assert f"note: --n-jobs {have + 4} is more than the {have} cores available" in text
    assert f"x{have};" in text or f"x{min(have, 4)}" in text or "serial" in text


def test_sweeps_sensitivity_and_tuning_are_bounded_too(tmp_path):
    from ema_cli.api import sensitivity, sweep, tune

    # 201 jobs (200 values and the baseline) x 1e9 steps = 2e11; 98,304 Sobol runs x 1e7
    # steps = 9.8e11; the tuning below: 999,990 evaluations x 2e6 steps (dt 1e-5)
    many = [0.001 * (k + 1) for k in range(200)]
    big = {"simulation.duration_s": 100, "simulation.dt_s": 1e-7, "sweep.axes.0.values": many}
    with pytest.raises(EmaError, match=r"20[01] jobs x 1e\+09 steps.*shrink sweep\.axes"):
        sweep("configs/deadzone2.yaml", big)
    with pytest.raises(EmaError, match=r"98,304 runs \(sobol, n = 4096\) x 1e\+07 steps"):
        sensitivity("configs/sensitivity.yaml", {"simulation.duration_s": 100})
    doc = {"name": "t", "scenarios": {"s": {"input": {"kind": "step", "amplitude_deg": 0.1}}},
           "variables": {"Kpp": {"bounds": [10, 100]}}, "simulation": {"duration_s": 20}}
    with pytest.raises(EmaError, match=r"^tune: .* evaluations x 1 scenarios x 2e\+06 steps"):
        tune(doc, budget=1_000_000)
    values = "[" + ", ".join(f"{v:g}" for v in many) + "]"
    r = runner.invoke(app, ["sweep", "configs/deadzone2.yaml", "--set",
                            "simulation.duration_s=100", "--set", "simulation.dt_s=1e-7",
                            "--set", f"sweep.axes.0.values={values}",
                            "--out", str(tmp_path / "s")])
    assert r.exit_code == 2 and "more than the cap of 1e+11" in " ".join(r.output.split())


def test_the_api_caps_workers_too():
    from ema_cli.api import sweep

    have = cores()
    with pytest.warns(UserWarning, match=f"n_jobs {have + 6} is more than the {have} cores"):
        res = sweep("configs/deadzone2.yaml", {"simulation.duration_s": 0.01},
                    n_jobs=have + 6)
    assert len(res.metrics) == 4  # 3 values and the baseline
