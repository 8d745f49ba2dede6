"""Bad input on the command line, class by class, for every command: one line naming the option,
a non-zero exit, no traceback, nothing written outside the output folder, nothing overwritten.

(Config-file classes — YAML bombs, names in paths, numeric settings, --nl conflicts — are in
tests/unit/test_bad_config.py.)
"""

from __future__ import annotations

from pathlib import Path

import pytest
from typer.testing import CliRunner

from ema_cli.cli.main import COMMANDS, app

ROOT = Path(__file__).resolve().parents[2]
CONFIG = str(ROOT / "configs" / "deadzone2.yaml")
runner = CliRunner()

# the quickest form of each command that writes a folder
WRITERS = {
    "simulate": ["simulate", "--duration", "0.01"],
    "sweep": ["sweep", CONFIG, "--set", "simulation.duration_s=0.01", "--no-progress", "-j", "1"],
    "threshold": ["threshold", CONFIG, "--vary", "deadzone2", "--range", "0.001", "0.1",
                  "--metric", "ss_err_pos_deg", "--limit", "0.5",
                  "--set", "simulation.duration_s=0.01"],
    "identify": ["identify", "--method", "exact"],
    "margins": ["margins"],
    "freqresp": ["freqresp", "--amplitudes", "1", "--f-min", "5", "--f-max", "10", "--n", "2"],
    "reproduce": ["reproduce", str(ROOT / "experiments" / "paper2020.yaml")],
    "acceptance": ["acceptance", str(ROOT / "configs" / "acceptance.yaml"), "--only", "margins"],
    "yield": ["yield", str(ROOT / "configs" / "acceptance.yaml"), "--tolerances",
              str(ROOT / "configs" / "tolerances.yaml"), "--n", "1", "--no-worst"],
    "tune": ["tune", str(ROOT / "configs" / "tune.yaml"), "--budget", "128"],
    "design": ["design", str(ROOT / "experiments" / "logs" / "design_hc_1pct.csv")],
    "duty": ["duty", str(ROOT / "configs" / "duty" / "hold_and_move.yaml"), "--no-hot",
             "--set", "segments.0.repeat.count=2", "--set", "segments.1.sine.cycles=4",
             "--set", "segments.0.repeat.segments.1.dwell.duration_s=0.1",
             "--set", "segments.0.repeat.segments.3.dwell.duration_s=0.1"],
    "sensitivity": ["sensitivity", str(ROOT / "configs" / "sensitivity.yaml"), "--n", "1",
                    "--set", "simulation.duration_s=0.01", "--no-progress", "-j", "1"],
}


def invoke(*args: str):
    return runner.invoke(app, list(args), catch_exceptions=False)


def one_clear_line(r, *needles: str) -> None:
    """Exit code 2 (bad input), one line starting with 'error:', naming every needle."""
    assert r.exit_code == 2, r.output
    lines = [ln for ln in r.output.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("error:"), r.output
    assert "Traceback" not in r.output
    for n in needles:
        assert n in lines[0], r.output


def test_every_writer_is_covered():
    # compile writes only numba's cache (under EMA_CACHE_DIR), no results folder
    assert set(WRITERS) == {n for n, _ in COMMANDS} - {"validate", "show", "locations",
                                                       "params", "compile"}


@pytest.mark.parametrize("cmd", sorted(WRITERS))
def test_out_is_a_file(tmp_path, cmd):
    f = tmp_path / "a_file"
    f.write_text("keep")
    one_clear_line(invoke(*WRITERS[cmd], "--out", str(f)), "--out", "is a file")
    assert f.read_text() == "keep"


@pytest.mark.parametrize("cmd", sorted(WRITERS))
def test_out_below_a_file(tmp_path, cmd):
    f = tmp_path / "a_file"
    f.write_text("keep")
    one_clear_line(invoke(*WRITERS[cmd], "--out", str(f / "sub")), "--out", "not a folder")


@pytest.mark.parametrize("cmd", sorted(WRITERS))
def test_out_holding_other_files_is_never_overwritten(tmp_path, cmd):
    (tmp_path / "mine.csv").write_text("precious")
    one_clear_line(invoke(*WRITERS[cmd], "--out", str(tmp_path)), "--out", "never overwritten")
    assert [p.name for p in tmp_path.iterdir()] == ["mine.csv"]
    assert (tmp_path / "mine.csv").read_text() == "precious"


OTHER_INPUT = {  # one input changed, and how the refusal names it
    "simulate": (["--set", "plant.kL=600"], "--set plant.kL"),
    "threshold": (["--set", "plant.kL=600"], "--set plant.kL"),
    "identify": (["--seed", "3"], "seed 0 there, 3 here"),
    "margins": (["--set", "plant.kL=600"], "--set plant.kL"),
    "freqresp": (["--set", "plant.kL=600"], "--set plant.kL"),
    "acceptance": (["--set", "actuator.plant.kL=600"], "--set actuator.plant.kL"),
    "sensitivity": (["--set", "seed=5"], "--set seed"),
    "duty": (["--set", "ambient=45"], "--set ambient"),
}


def _files(folder: Path) -> dict[str, int]:
    return {str(p.relative_to(folder)): p.stat().st_mtime_ns for p in folder.rglob("*")}


@pytest.mark.parametrize("cmd", sorted(OTHER_INPUT))
def test_a_finished_run_is_kept_and_one_of_other_inputs_refused(tmp_path, cmd):
    """The same command again: exit 0, the finished folder kept as it is (nothing rewritten);
    other inputs: refused in one line naming what differs, nothing touched."""
    import json

    out = tmp_path / "run"
    r = invoke(*WRITERS[cmd], "--out", str(out))
    assert r.exit_code == 0, r.output
    before = _files(out)
    r = invoke(*WRITERS[cmd], "--out", str(out))
    assert r.exit_code == 0, r.output
    assert _files(out) == before
    assert json.loads((out / ".ema-run.json").read_text())["finished"] is True
    extra, needle = OTHER_INPUT[cmd]
    one_clear_line(invoke(*WRITERS[cmd], *extra, "--out", str(out)), "--out", "finished",
                   "of other inputs", needle, "never overwritten")
    assert _files(out) == before


def test_nothing_is_written_outside_the_output_folder(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    out = tmp_path / "out"
    r = invoke(*WRITERS["sweep"], "--out", str(out))
    assert r.exit_code == 0, r.output
    assert [p.name for p in tmp_path.iterdir()] == ["out"]
    r = invoke(*WRITERS["simulate"], "--out", str(tmp_path / "out2"))
    assert r.exit_code == 0, r.output
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out", "out2"]


@pytest.mark.parametrize(("args", "needles"), [
    (["simulate", "--dt", "nan"], ["--dt", "finite"]),
    (["simulate", "--dt", "-1e-5"], ["--dt", "> 0"]),
    (["simulate", "--duration", "inf"], ["--duration", "finite"]),
    (["simulate", "--duration", "0"], ["--duration", "> 0"]),
    (["simulate", "--step", "nan"], ["--step", "finite"]),
    (["simulate", "--step", "-inf"], ["--step", "finite"]),
    (["sweep", CONFIG, "-j", "0"], ["--n-jobs", ">= 1"]),
    (["sweep", CONFIG, "-j", "100000"], ["--n-jobs", "<= 4096"]),
    (["sweep", CONFIG, "--backend", "gpu"], ["--backend", "gpu"]),
    (["reproduce", str(ROOT / "experiments" / "paper2020.yaml"), "--n-jobs", "-5"],
     ["--n-jobs", ">= 1"]),
    (["threshold", CONFIG, "--vary", "deadzone2", "--range", "nan", "1", "--metric",
      "ss_err_pos_deg", "--limit", "0.1"], ["--range", "finite"]),
    (["threshold", CONFIG, "--vary", "deadzone2", "--range", "1", "0.1", "--metric",
      "ss_err_pos_deg", "--limit", "0.1"], ["--range", "LO < HI"]),
    (["threshold", CONFIG, "--vary", "deadzone2", "--range", "0", "1", "--metric",
      "ss_err_pos_deg", "--limit", "0.1"], ["--range", "> 0"]),
    (["threshold", CONFIG, "--vary", "deadzone2", "--range", "0.01", "1", "--metric",
      "ss_err_pos_deg", "--limit", "inf"], ["limit", "finite"]),
    (["threshold", CONFIG, "--vary", "deadzone2", "--range", "0.01", "1", "--metric",
      "ss_err_pos_deg", "--limit", "0.1", "--rtol", "0"], ["--rtol"]),
    (["threshold", CONFIG, "--vary", "deadzone2", "--range", "0.01", "1", "--metric",
      "ss_err_pos_deg", "--limit", "0.1", "--rtol", "nan"], ["--rtol"]),
    (["threshold", CONFIG, "--vary", "deadzone2", "--range", "0.01", "1"], ["requirement"]),
    (["identify", "--pc", "1.5"], ["--pc", "<= 1"]),
    (["identify", "--pm", "nan"], ["--pm", "finite"]),
    (["identify", "--noise", "-1"], ["--noise", ">= 0"]),
    (["identify", "--k-range", "inf", "700"], ["--k-range", "finite"]),
    (["identify", "--c", "-2"], ["--c", ">= 0"]),
])
def test_numeric_options_are_checked_and_named(tmp_path, args, needles):
    one_clear_line(invoke(*args, "--out", str(tmp_path / "x")), *needles)
    assert not (tmp_path / "x").exists()


@pytest.mark.parametrize("cmd", ["simulate", "sweep", "threshold", "identify", "reproduce",
                                 "validate", "show", "margins", "freqresp"])
def test_every_command_takes_set(cmd):
    r = invoke(cmd, "--help")
    assert r.exit_code == 0 and "--set" in r.output


def test_help_keeps_units_literal():
    r = invoke("simulate", "--help")
    assert "[deg]" in r.output and "[s]" in r.output


def test_set_is_the_same_mechanism_everywhere(tmp_path):
    # a list item by index works on simulate as on sweep (the same override code)
    r = invoke("simulate", CONFIG, "--duration", "0.01", "--set", "sweep.axes.0.values=[1]",
               "--out", str(tmp_path / "a"))
    assert r.exit_code == 0, r.output
    one_clear_line(invoke("simulate", CONFIG, "--set", "sweep.axes.5.values=[1]"), "--set",
                   "sweep.axes", "index")
    one_clear_line(invoke("identify", "--set", "ga.pop=-3"), "ga.pop")
    one_clear_line(invoke("identify", "--set", "nope=1"), "--set nope", "unknown key")


def test_an_unexpected_error_is_one_line_not_a_traceback(monkeypatch, tmp_path):
    import ema_cli.api.simulation as sim_api

    def boom(*a, **k):
        raise RuntimeError("kaboom\nsecond line")

    monkeypatch.setattr(sim_api, "simulate", boom)
    r = invoke("simulate", "--out", str(tmp_path / "x"))
    assert r.exit_code == 1
    lines = [ln for ln in r.output.splitlines() if ln.strip()]
    assert len(lines) == 1 and "unexpected RuntimeError: kaboom second line" in lines[0]
    assert "Traceback" not in r.output


@pytest.mark.parametrize("args", [
    ["simulate", "--nl", "deadzone2=0.01", "--nl", "deadzone2=0.02"],
    ["simulate", "--set", "plant.kL=500", "--set", "plant.kL=600"],
    ["identify", "--columns", "torque_nm=a", "--columns", "torque_nm=b"],
])
def test_an_option_given_twice_is_refused(args):
    one_clear_line(invoke(*args), "given twice")


def test_a_fixed_setting_and_an_axis_on_one_placement():
    # the sweep axis replaces the study's fixed setting of the same placement, whatever its
    # name; the baseline removes it
    from ema_cli.config.loader import load_config
    from ema_cli.config.study import StudyConfig
    from ema_cli.sweep.plan import plan_sweep
    from ema_cli.units import DEG

    cfg = load_config(CONFIG, [("nonlinearities", {"deadzone@transmission": 0.5}),
                               ("sweep.axes.0.values", [0.01])], StudyConfig)
    plan = plan_sweep(cfg)
    alphas = sorted(j.params["alpha"] / DEG for j in plan.jobs)
    assert alphas == pytest.approx([0.0, 0.01], rel=1e-12)


@pytest.mark.parametrize(("path", "says"), [
    (ROOT / "experiments" / "paper2020.yaml", "valid experiment"),
    (ROOT / "configs" / "identify.yaml", "valid identification settings"),
    (ROOT / "configs" / "deadzone2.yaml", "valid; grid over deadzone2"),
])
def test_validate_knows_every_kind_of_file(path, says):
    r = invoke("validate", str(path))
    assert r.exit_code == 0 and says in " ".join(r.output.split()), r.output


def test_validate_names_the_key_of_an_experiment(tmp_path):
    p = tmp_path / "e.yaml"
    p.write_text("name: e\nstudies: []\nclaims: []\n")
    r = invoke("validate", str(p))
    assert r.exit_code == 2 and "e.yaml" in r.output and "Traceback" not in r.output


@pytest.mark.parametrize(("args", "needles"), [
    (["simulate", "--duration", "1e308"], ["too many"]),
    (["simulate", "--dt", "1e-320", "--duration", "0.01"], ["too many"]),
    (["simulate", "--duration", "0.01", "--set", "simulation.output_interval_s=1e308"],
     ["output interval", "must not exceed"]),
    (["simulate", "--duration", "0.01", "--set", "plant.m=1e308"], ["out of range"]),
    (["simulate", "--set", "plant.kL=" + "9" * 5000], ["plant.kL"]),
    (["simulate", "--nl", "deadzone2=0.01", "--set", "plant.alpha=0.001"],
     ["nonlinearities.deadzone2", "plant.alpha", "give one"]),
    (["simulate", "--set", "plant.locked=1", "--set", "motor.locked=false"],
     ["motor.locked", "plant.locked"]),
    (["simulate", "--set", "sweep.axes.5.values=[1]"], ["sweep.axes", "not in the config"]),
    (["identify", "--method", "exact", "--set", "synthetic.duration_s=1e308"],
     ["synthetic", "steps"]),
    (["identify", "--method", "exact", "--set", "synthetic.sample_interval_s=1.5e-5"],
     ["sample_interval_s", "whole multiple"]),
    (["threshold", CONFIG, "--vary", "deadzone2", "--range", "0.001", "0.1", "--metric",
      "ss_err_pos_deg", "--limit", "0.1", "--set", "plant.alpha=0.001"],
     ["--vary deadzone2", "plant.alpha"]),
])
def test_values_out_of_range_or_given_twice(tmp_path, args, needles):
    one_clear_line(invoke(*args, "--out", str(tmp_path / "x")), *needles)


def test_a_diverged_simulation_exits_1_with_its_outputs(tmp_path):
    out = tmp_path / "run"
    r = invoke("simulate", "--duration", "0.01", "--set", "plant.Kt=1e308", "--out", str(out))
    assert r.exit_code == 1 and "diverged" in r.output and "Traceback" not in r.output
    assert (out / "metrics.csv").is_file() and (out / "manifest.json").is_file()


def test_recording_can_be_turned_off(tmp_path):
    out = tmp_path / "run"
    r = invoke("simulate", "--duration", "0.05", "--set", "simulation.output_interval_s=null",
               "--out", str(out))
    assert r.exit_code == 0, r.output
    names = {p.name for p in out.iterdir()}
    assert "metrics.csv" in names and "timeseries.csv" not in names
    assert "tracking.png" not in names


@pytest.mark.parametrize(("call", "needle"), [
    (lambda api: api.simulate(42), "expected a YAML file path"),
    (lambda api: api.simulate(None, nl=[("deadzone2", 0.1)]), "nl: expected a mapping"),
    (lambda api: api.simulate(None, "plant.kL=5"), "overrides: expected a dict"),
    (lambda api: api.threshold(None, "deadzone2", (0.001, 0.01, 0.1), metric="ss_err_pos_deg",
                               limit=0.1), "^range must be two numbers"),
    (lambda api: api.threshold(None, "deadzone2", 0.1, metric="ss_err_pos_deg", limit=0.1),
     "^range"),
    (lambda api: api.threshold(None, "deadzone2", (0.001, 0.1), metric="ss_err_pos_deg",
                               limit="abc"), "^limit must be a finite number"),
])
def test_the_api_answers_bad_input_with_ema_errors(call, needle):
    from ema_cli import api
    from ema_cli.errors import EmaError

    with pytest.raises(EmaError, match=needle):
        call(api)


def test_the_api_refuses_a_self_referencing_config():
    from ema_cli import api
    from ema_cli.errors import EmaError

    d: dict = {"simulation": {"duration_s": 0.01}}
    d["plant"] = d
    with pytest.raises(EmaError):
        api.simulate(d)


def test_validate_accepts_a_run_config(tmp_path):
    p = tmp_path / "run.yaml"
    p.write_text("input:\n  kind: step\n  amplitude_deg: 1\n")
    r = invoke("validate", str(p))
    assert r.exit_code == 0 and "valid run config" in " ".join(r.output.split())


@pytest.mark.parametrize(("args", "needles"), [
    (["--budget", "0"], ["--budget", "[1, 1000000]"]),
    (["--runs", "0"], ["--runs", "[1, 100]"]),
    (["--method", "pso"], ["--method", "ga or de"]),
    (["--set", "variables.Kpp.bounds=[5,1]"], ["variables.Kpp", "above the upper bound"]),
    (["--set", "variables.kL.bounds=[300,900]"], ["variables.kL", "unknown variable"]),
    (["--set", "constraints.overshoot.max=-1"], ["constraints.overshoot.max", "infeasible"]),
])
def test_bad_tune_options(tmp_path, args, needles):
    one_clear_line(invoke("tune", str(ROOT / "configs" / "tune.yaml"), *args,
                          "--out", str(tmp_path / "o")), *needles)
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("key", ["input", "load"])
def test_a_profile_that_starts_after_the_end_is_refused(tmp_path, key):
    # issue 39: a profile whose first row is at or after the end of the run is never applied:
    # the run is refused in one line naming the key (exit 2), nothing is simulated
    prof = tmp_path / "late.csv"
    col = "theta_ref_deg" if key == "input" else "torque_nm"
    prof.write_text(f"t_s,{col}\n2.0,0.0\n3.0,1.0\n")
    sets = (["--set", "input.kind=csv", "--set", f"input.path={prof}"] if key == "input"
            else ["--set", f"load.profile={prof}"])
    r = runner.invoke(app, ["simulate", *sets, "--set", "simulation.duration_s=1",
                            "--out", str(tmp_path / "o")])
    assert r.exit_code == 2, r.output
    err = [ln for ln in r.output.splitlines() if ln.startswith("error:")]
    assert len(err) == 1 and "starts at 2 s" in err[0]
    assert ("input.path" if key == "input" else "load.profile") in err[0]
    assert not (tmp_path / "o" / "signals.csv").exists()


def test_a_closed_loop_log_shorter_than_its_slowest_time_constant_is_refused(tmp_path):
    """A log, or a --window, shorter than the closed loop's slowest time constant at the start
    of the fit (the middle of the free bounds) is refused in one line naming the file, the
    span and the time constant; the time constant is checked against the poles of the loop
    written out by hand (tests/helpers/linear.py, python-control); a window just longer than
    it passes the check."""
    import control
    import numpy as np
    import pandas as pd

    from ema_cli.api.identify_logs import check_log_span
    from ema_cli.identify.closed_loop.problem import DEFAULT_FREE, NUISANCE, load_log
    from ema_cli.identify.log_settings import ClosedLoopSettings
    from ema_cli.identify.make_data import closed_loop_log
    from ema_cli.model.params import resolve
    from tests.helpers.linear import linear_ss

    syn = closed_loop_log({}, 0.0, 0, duration_s=0.3)
    path = tmp_path / "short.csv"
    pd.DataFrame(syn.columns).to_csv(path, index=False)
    mid = {n: 0.5 * (lo + hi) for n, (lo, hi) in {**DEFAULT_FREE, **NUISANCE}.items()}
    p = resolve({**mid, "friction": 1.0})
    # the hand-written loop has no friction term: its viscous part joins the motor's damping
    poles = control.poles(linear_ss({**p, "bm": p["bm"] + p["sigma2"]}))
    tau = 1.0 / float(np.min(-poles.real))
    assert 0.1 < tau < 0.15  # the default loop's slow mode (the speed PI's), ~0.12 s
    r = invoke("identify", "closed-loop", "--data", str(path), "--window", "0,0.1",
               "--out", str(tmp_path / "o"))
    one_clear_line(r, "--window 0,0.1", "short.csv", "keeps 0.1 s", f"{tau:.4g} s")
    assert not (tmp_path / "o").exists()
    r = invoke("identify", "closed-loop", "--data", str(path), "--window", "0.2,0.3",
               "--out", str(tmp_path / "o"))
    one_clear_line(r, "0.2,0.3", "keeps 0.1 s", f"{tau:.4g} s")
    cut = tmp_path / "cut.csv"
    pd.DataFrame(syn.columns).iloc[:101].to_csv(cut, index=False)
    r = invoke("identify", "closed-loop", "--data", str(cut), "--out", str(tmp_path / "o"))
    one_clear_line(r, "cut.csv", "spans 0.1 s", f"{tau:.4g} s")
    # just longer than the time constant: no refusal
    cfg = ClosedLoopSettings(data=str(path), window=(0.0, 0.13))
    check_log_span(cfg, load_log(path, window=cfg.window), str(path))
