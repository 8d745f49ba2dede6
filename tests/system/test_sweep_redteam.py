"""Red-team findings on `ema sweep` / `ema reproduce` output folders and late checks: a finished
sweep is never rewritten (a resumed reproduction reuses its finished studies), `.cache` holding
user files is not empty, clashing column names and doubly set parameters are refused at plan
time, stale temporaries are removed on resume, bad --cache-dir / --scheduler / memory budgets
and bad study configs are refused before the output folder is created."""

from __future__ import annotations

import json
from pathlib import Path

import pandas as pd
import pytest
import yaml
from typer.testing import CliRunner

import ema_cli.api.study as api_study
from ema_cli.api.study import run_sweep
from ema_cli.cli.main import app
from ema_cli.config.loader import load_config
from ema_cli.config.study import StudyConfig
from ema_cli.errors import EmaError
from ema_cli.sweep.plan import plan_sweep

runner = CliRunner()


def study(tmp_path: Path, file: str = "study.yaml", **changes) -> Path:
    data = {
        "name": "rt",
        "input": {"kind": "step", "amplitude_deg": 0.1},
        "simulation": {"duration_s": 0.02, "dt_s": 1e-5, "output_interval_s": 1e-3},
        "sweep": {"axes": [{"nonlinearity": "deadzone2", "values": [0.001, 0.1]}]},
        "outputs": {"timeseries": True, "figures": []},
    }
    data.update(changes)
    path = tmp_path / file
    path.write_text(yaml.safe_dump(data))
    return path


def sweep_cli(cfg: Path, out: Path, *extra: str):
    return runner.invoke(app, ["sweep", str(cfg), "--out", str(out), "--n-jobs", "1",
                               "--no-progress", *extra])


def one_line(r, *needles: str) -> str:
    assert r.exit_code == 2, r.output
    text = " ".join(r.output.split())
    lines = [ln for ln in r.output.splitlines() if ln.strip()]
    assert lines and lines[0].startswith("error:"), r.output
    assert "Traceback" not in r.output
    for n in needles:
        assert n in text, r.output
    return text


def mtimes(folder: Path) -> dict[str, int]:
    return {str(p.relative_to(folder)): p.stat().st_mtime_ns
            for p in folder.rglob("*") if p.is_file()}


def outputs(folder: Path) -> dict[str, int]:
    """:func:`mtimes` of the outputs (the job cache in .cache aside: reading it may touch
    its journal)."""
    return {k: v for k, v in mtimes(folder).items() if not k.startswith(".cache")}


# ------------------------------------------------------------ 1, 2: finished runs are final


def test_sweep_twice_into_one_out_keeps_it_and_other_inputs_touch_nothing(tmp_path):
    cfg, out = study(tmp_path), tmp_path / "out"
    r = sweep_cli(cfg, out)
    assert r.exit_code == 0, r.output
    assert json.loads((out / ".ema-run.json").read_text())["finished"] is True
    before = outputs(out)
    r = sweep_cli(cfg, out)  # the same sweep: its finished folder is read, kept as it is
    assert r.exit_code == 0, r.output
    assert outputs(out) == before
    # another sweep: refused, naming what differs (not 'unfinished')
    other = study(tmp_path, "other.yaml", name="other")
    text = one_line(sweep_cli(other, out), "a finished `ema sweep` run of other inputs",
                    "name rt there, other here", "never overwritten")
    assert "unfinished" not in text
    assert outputs(out) == before


def test_api_save_twice_keeps_the_folder_and_another_sweep_is_refused(tmp_path):
    from ema_cli import api

    sw = api.sweep(study(tmp_path), n_jobs=1, progress=False)
    folder = sw.save(tmp_path / "saved")
    before = mtimes(folder)
    assert sw.save(folder) == folder
    other = api.sweep(study(tmp_path, "other.yaml", name="other"), n_jobs=1, progress=False)
    with pytest.raises(EmaError, match="finished `ema sweep` run of other inputs"):
        other.save(folder)
    assert mtimes(folder) == before


def test_unfinished_run_of_another_command_reads_right(tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    (out / ".ema-run.json").write_text(json.dumps(
        {"command": "simulate", "fingerprint": "x", "finished": False}))
    (out / "x.csv").write_text("1\n")
    text = one_line(sweep_cli(study(tmp_path), out), "an unfinished `ema simulate` run")
    assert "other inputs" not in text


EXPERIMENT = """name: rtbatch
studies:
  - id: figA
    config: a.yaml
    figure: figA.png
    caption: "Figure A"
  - id: figB
    config: b.yaml
    figure: figB.png
    caption: "Figure B"
claims:
  - id: osc
    paper: p
    statement: oscillation at 0.1 deg
    check: {kind: value, study: figA, where: {deadzone2_deg: 0.1}, metric: p2p_err_pos_deg,
            op: ">=", value: 0.0}
"""


def experiment(tmp_path: Path) -> Path:
    study(tmp_path, "a.yaml", name="a")
    study(tmp_path, "b.yaml", name="b",
          sweep={"axes": [{"nonlinearity": "deadzone2", "values": [0.01]}]})
    exp = tmp_path / "exp.yaml"
    exp.write_text(EXPERIMENT)
    return exp


def test_reproduce_resumed_after_the_first_study_keeps_it(tmp_path, monkeypatch):
    exp, out = experiment(tmp_path), tmp_path / "out"
    real = api_study.run_sweep
    calls = []

    def interrupted(cfg, folder, **kw):
        calls.append(folder)
        if len(calls) == 2:
            raise KeyboardInterrupt
        return real(cfg, folder, **kw)

    monkeypatch.setattr(api_study, "run_sweep", interrupted)
    r = runner.invoke(app, ["reproduce", str(exp), "--out", str(out), "--n-jobs", "1"])
    assert r.exit_code != 0
    first = out / "studies" / "figA"
    assert json.loads((first / ".ema-run.json").read_text())["finished"] is True
    before = mtimes(first)
    monkeypatch.setattr(api_study, "run_sweep", real)
    r = runner.invoke(app, ["reproduce", str(exp), "--out", str(out), "--n-jobs", "1"])
    assert r.exit_code == 0, r.output
    assert mtimes(first) == before  # reused, not rewritten
    assert pd.read_csv(out / "claims.csv")["result"].tolist() == ["PASS"]
    assert (out / "figA.png").is_file() and (out / "figB.png").is_file()
    assert len(pd.read_csv(out / "tables" / "figA_metrics.csv")) == 3
    # the finished reproduction is final: the same batch keeps it, another is refused
    before = outputs(out)
    r = runner.invoke(app, ["reproduce", str(exp), "--out", str(out), "--n-jobs", "1"])
    assert r.exit_code == 0, r.output
    assert outputs(out) == before
    r = runner.invoke(app, ["reproduce", str(exp), "--out", str(out), "--n-jobs", "1",
                            "--set", "name=other"])
    one_line(r, "finished `ema reproduce` run of other inputs", "--set name")


# ------------------------------------------------------------ 3: .cache with user files


def test_cache_folder_with_user_files_is_not_empty(tmp_path):
    out = tmp_path / "out"
    (out / ".cache").mkdir(parents=True)
    (out / ".cache" / "notes.txt").write_text("mine")
    one_line(sweep_cli(study(tmp_path), out), "--out", "other files")
    assert (out / ".cache" / "notes.txt").read_text() == "mine"


def test_cache_folder_with_only_a_job_cache_is_empty(tmp_path):
    cfg = study(tmp_path)
    out = tmp_path / "out"
    r = runner.invoke(app, ["sweep", str(cfg), "--out", str(tmp_path / "first"), "--n-jobs",
                            "1", "--no-progress", "--cache-dir", str(out / ".cache")])
    assert r.exit_code == 0, r.output
    assert (out / ".cache" / "jobs.sqlite").is_file()
    assert sweep_cli(cfg, out).exit_code == 0


# ------------------------------------------------------------ 4: clashing columns, parameters


@pytest.mark.parametrize(("axes", "needles"), [
    ([{"nonlinearity": "deadzone2", "name": "err_pos", "values": [0.01]}],
     ["sweep.axes.0", "'err_pos_deg'", "signal column"]),
    ([{"parameter": "m", "name": "status", "values": [1.0]}],
     ["sweep.axes.0", "'status'", "fixed column"]),
    ([{"parameter": "m", "name": "t_s", "values": [1.0]}], ["'t_s'"]),
    ([{"nonlinearity": "deadzone2", "name": "overshoot", "values": [0.01]},
      {"parameter": "m", "name": "overshoot_pct", "values": [1.0]}], ["'overshoot_pct'"]),
    ([{"nonlinearity": "deadzone2", "name": "a", "values": [0.01]},
      {"parameter": "m", "name": "a_deg", "values": [1.0]}],
     ["sweep.axes.1", "'a_deg'", "axis 0 ('a')"]),
])
def test_axis_column_clashes_are_refused_at_plan_time(tmp_path, axes, needles):
    cfg_path = study(tmp_path, sweep={"axes": axes})
    out = tmp_path / "out"
    text = one_line(sweep_cli(cfg_path, out), *needles)
    assert "\n" not in text and not out.exists()


def test_two_axes_setting_one_parameter_are_refused(tmp_path):
    cfg_path = study(tmp_path, sweep={"axes": [
        {"nonlinearity": "deadzone2", "values": [0.01]},
        {"parameter": "alpha", "values": [1e-4]}]})
    with pytest.raises(EmaError, match=r"sweep.axes.0 \('deadzone2'\) and sweep.axes.1 "
                                       r"\('alpha'\) both set the model parameter 'alpha'"):
        plan_sweep(load_config(cfg_path, (), StudyConfig))


# ------------------------------------------------------------ 5: stale temporaries


def test_resume_removes_stale_temporaries(tmp_path, monkeypatch):
    import ema_cli.sweep.run as sweep_run

    cfg = load_config(study(tmp_path), (), StudyConfig)
    out = tmp_path / "out"
    real = sweep_run.execute

    def stop(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(sweep_run, "execute", stop)
    with pytest.raises(KeyboardInterrupt):
        run_sweep(cfg, out, n_jobs=1, progress=False, cache_dir=tmp_path / "cache")
    monkeypatch.setattr(sweep_run, "execute", real)
    assert json.loads((out / ".ema-run.json").read_text())["finished"] is False
    stale = out / ".signals.parquet.0123456789ab.tmp"  # as a SIGKILL'd sweep leaves it
    stale.write_bytes(b"partial")
    mine = out / ".notes.tmp"  # not one of ours: kept
    mine.write_text("x")
    res = run_sweep(cfg, out, n_jobs=1, progress=False, cache_dir=tmp_path / "cache")
    assert res.counts()["ok"] == 3
    assert not stale.exists() and mine.exists()
    assert json.loads((out / ".ema-run.json").read_text())["finished"] is True


# ------------------------------------------------------------ 6: checks before any write


def test_cache_dir_that_is_a_file_is_refused_before_the_folder(tmp_path):
    f = tmp_path / "file"
    f.write_text("keep")
    out = tmp_path / "out"
    one_line(sweep_cli(study(tmp_path), out, "--cache-dir", str(f)), "--cache-dir", "a file")
    assert not out.exists()
    one_line(sweep_cli(study(tmp_path), out, "--cache-dir", str(f / "sub")), "--cache-dir",
             "cannot be created")
    assert not out.exists() and f.read_text() == "keep"


def test_bad_scheduler_address_is_refused_before_the_folder(tmp_path):
    out = tmp_path / "out"
    one_line(sweep_cli(study(tmp_path), out, "--backend", "dask", "--scheduler", "not an address"),
             "--scheduler", "tcp://HOST:PORT")
    assert not out.exists()


def test_scheduler_address_forms():
    from ema_cli.sweep.execute import SCHEDULER_ADDRESS

    for ok in ("tcp://127.0.0.1:8786", "localhost:8786", "tls://h.example.org:1", "[::1]:8786"):
        assert SCHEDULER_ADDRESS.fullmatch(ok), ok
    for bad in ("localhost", "tcp://", "http//x:1", "a b:1", "x:port"):
        assert not SCHEDULER_ADDRESS.fullmatch(bad), bad


def test_recording_past_the_memory_budget_is_refused_before_the_folder(tmp_path, monkeypatch):
    monkeypatch.setenv("EMA_MAX_RECORD_BYTES", "1000")
    out = tmp_path / "out"
    one_line(sweep_cli(study(tmp_path), out), "simulation.output_interval_s",
             "simulation.duration_s")
    assert not out.exists()


def test_reproduce_bad_study_config_is_refused_before_the_folder(tmp_path):
    exp = experiment(tmp_path)
    (tmp_path / "b.yaml").write_text("name: b\nsimulation: {duration_s: -1}\n")
    out = tmp_path / "out"
    one_line(runner.invoke(app, ["reproduce", str(exp), "--out", str(out)]), "figB", "b.yaml")
    assert not out.exists()
