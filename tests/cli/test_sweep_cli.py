"""`ema sweep`, `ema validate`, `ema show` through typer's CliRunner: outputs and bad input."""

from __future__ import annotations

import json
import shutil
import sqlite3
import sys
from pathlib import Path

import pandas as pd
import pytest
import yaml
from typer.testing import CliRunner

from ema_cli.cli.main import app
from ema_cli.sweep.cache import DB_NAME

runner = CliRunner()
CONFIGS = Path(__file__).resolve().parents[2] / "configs"
PNG_MAGIC = b"\x89PNG\r\n\x1a\n"
GOOD = {
    "name": "t",
    "input": {"kind": "step", "amplitude_deg": 0.1},
    "simulation": {"duration_s": 0.05, "dt_s": 1e-5, "output_interval_s": 1e-3},
    "sweep": {"axes": [{"nonlinearity": "deadzone2", "values": [0.01, 0.1]}]},
    "outputs": {"timeseries": False, "figures": []},
}


def invoke(*args: str | Path):
    return runner.invoke(app, [str(a) for a in args])


def flat(text: str) -> str:
    return " ".join(text.split())


def test_deadzone2_config_writes_every_output(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)  # default output root: ./results
    shutil.copy(CONFIGS / "deadzone2.yaml", tmp_path / "deadzone2.yaml")
    r = invoke("sweep", "deadzone2.yaml", "--set", "simulation.duration_s=0.1", "--n-jobs", "2",
               "--no-progress")
    assert r.exit_code == 0, r.output
    runs = tmp_path / "results" / "sweep" / "deadzone2"  # results/<command>/<config-name>/
    (run,) = (p for p in runs.iterdir() if p.name != "latest")
    assert (runs / "latest").is_symlink() and (runs / "latest").resolve() == run.resolve()
    assert "deadzone2: 4 jobs (4 ok, 0 diverged, 0 failed, 0 not run)" in flat(r.output)
    cfg = yaml.safe_load((run / "config.resolved.yaml").read_text())
    assert cfg["simulation"]["duration_s"] == 0.1 and cfg["parallel"]["backend"] == "auto"
    man = json.loads((run / "manifest.json").read_text())
    assert man["command"] == "sweep" and man["status"] == "complete" and man["seed"] == 0
    assert "ema_version" in man and "git_commit" in man and man["wall_time_s"] > 0
    assert man["job_counts"] == {"total": 4, "unique_runs": 4, "computed": 4, "cached": 0,
                                 "ok": 4, "diverged": 0, "failed": 0, "pending": 0}
    assert man["overrides"] == [["simulation.duration_s", "0.1"]]
    assert [j["status"] for j in man["jobs"]] == ["ok"] * 4
    met = pd.read_csv(run / "metrics.csv")
    assert list(met["deadzone2_deg"]) == [0.0, 0.001, 0.01, 0.1]
    assert list(met.columns[:4]) == ["job", "label", "status", "deadzone2_deg"]
    assert {"iae_pos_deg_s", "overshoot_pct", "peak_current_a", "key"} <= set(met.columns)
    # a 0.1 deg step: the largest position error is the step itself, at t = 0
    assert (met["max_abs_err_pos_deg"] >= 0.1 - 1e-12).all()
    signals = pd.read_parquet(run / "signals.parquet")
    assert list(signals["job"].unique()) == list(met["job"]) and not (run / "timeseries").exists()
    for _, ts in signals.groupby("job", observed=True):
        assert len(ts) == 1001 and ts["t_s"].iloc[-1] == pytest.approx(0.1)  # every 1e-4 s
    for fig in ("errors_deadzone2.png", "metrics_deadzone2.png"):
        assert (run / "figures" / fig).read_bytes()[:8] == PNG_MAGIC
    summary = (run / "summary.md").read_text()
    assert "| j0003 | deadzone2 = 0.1 deg | ok |" in summary
    assert "![errors_deadzone2](figures/errors_deadzone2.png)" in summary

    # signals every 10 steps: cheaper to recompute than to store twice, so only the metrics are
    # cached and the same sweep runs again; without time series every job comes from the cache
    assert man["signals_cache"]["cached"] is False and (tmp_path / "results" / ".cache").is_dir()
    r = invoke("sweep", "deadzone2.yaml", "--set", "simulation.duration_s=0.1", "--no-progress")
    assert r.exit_code == 0, r.output
    assert len([p for p in runs.iterdir() if p.name != "latest"]) == 2  # never overwritten
    assert "4 runs computed, 0 cached" in flat(r.output)
    r = invoke("sweep", "deadzone2.yaml", "--set", "simulation.duration_s=0.1", "--set",
               "outputs.timeseries=false", "--set", "outputs.figures=[metrics]", "--no-progress")
    assert r.exit_code == 0, r.output
    assert "0 runs computed, 4 cached" in flat(r.output)


def test_the_job_cache_goes_into_an_out_folder_outside_results(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    cfg = tmp_path / "c.yaml"
    cfg.write_text(yaml.safe_dump(GOOD))
    r = invoke("sweep", cfg, "--out", tmp_path / "run", "--no-progress")
    assert r.exit_code == 0, r.output
    assert (tmp_path / "run" / ".cache" / DB_NAME).is_file() and not (tmp_path / "results").exists()
    r = invoke("sweep", cfg, "--out", tmp_path / "run2", "--no-progress")
    assert r.exit_code == 0 and "3 runs computed, 0 cached" in flat(r.output)  # its own cache


def test_validate_counts_jobs_and_show_lists_them(tmp_path):
    cfg = tmp_path / "c.yaml"
    cfg.write_text(yaml.safe_dump(GOOD))
    r = invoke("validate", cfg)
    assert r.exit_code == 0 and "valid; grid over deadzone2 (2 values) -> 3 jobs" in flat(r.output)
    r = invoke("show", cfg, "--set", "sweep.axes.0.values=[0.02]")
    assert r.exit_code == 0, r.output
    text = flat(r.output)
    assert "deadzone2 = 0.02 deg" in text and "2 jobs (2 distinct runs)" in text
    assert "duration_s: 0.05" in r.output  # the resolved config, defaults filled in
    for config in sorted(CONFIGS.glob("*.yaml")):
        if config.name != "identify.yaml":
            assert invoke("validate", config).exit_code == 0, config


def bad(tmp_path: Path, data: dict | str, *extra: str):
    cfg = tmp_path / "bad.yaml"
    cfg.write_text(data if isinstance(data, str) else yaml.safe_dump(data))
    return invoke("sweep", cfg, "--out", tmp_path / "out", "--cache-dir", tmp_path / "cache",
                  "--no-progress", *extra)


def with_(path: str, value) -> dict:
    data = json.loads(json.dumps(GOOD))
    node = data
    keys = path.split(".")
    for k in keys[:-1]:
        node = node[int(k)] if isinstance(node, list) else node.setdefault(k, {})
    node[keys[-1]] = value
    return data


def axis(**kw) -> dict:
    return with_("sweep.axes", [kw])


@pytest.mark.parametrize(("data", "needles"), [
    ("name: t\nsweep: {axes: [\n", ["bad.yaml", "YAML syntax error at line"]),
    (with_("colour", "red"), ["bad.yaml", "colour: unknown key"]),
    (with_("sweep.axes.0.colour", "red"), ["sweep.axes.0.colour: unknown key"]),
    (with_("simulation.duration_s", "long"), ["simulation.duration_s", "valid number"]),
    (with_("simulation.dt_s", 0), ["simulation.dt_s", "greater than 0"]),
    (with_("simulation.duration_s", -1), ["simulation.duration_s", "greater than 0"]),
    (with_("simulation.dt_s", 0.1), ["simulation", "dt (0.1 s) must not exceed the duration"]),
    (with_("simulation.output_interval_s", 1.5e-5),
     ["simulation", "output interval (1.5e-05 s) must be a whole multiple of dt"]),
    (axis(nonlinearity="deadzone@gearbox", values=[1]),
     ["sweep.axes.0.nonlinearity", "unknown location 'gearbox'"]),
    (axis(nonlinearity="backlash@transmission", values=[1]),
     ["sweep.axes.0.nonlinearity", "unknown nonlinearity type 'backlash'"]),
    (axis(nonlinearity="saturation@amplifier", values=[1]),
     ["sweep.axes.0.nonlinearity", "a saturation cannot be placed at 'amplifier'"]),
    (axis(nonlinearity="gap1", values=["off"]),
     ["sweep.axes.0.values.0", "'gap1' cannot be 'off'"]),
    (axis(nonlinearity="deadzone2", values=[]), ["sweep.axes.0.values", "empty sweep"]),
    (with_("sweep.axes", []), ["bad.yaml: sweep.axes: empty sweep"]),
    (axis(parameter="Kpp", values=[-1]), ["sweep.axes.0.values.0", "must be >= 0"]),
    (with_("name", "../escape"), ["bad.yaml: name", "no path separators"]),
    (with_("name", "a/b"), ["bad.yaml: name", "no path separators"]),
    (with_("sweep.max_jobs", 2), ["bad.yaml: sweep: expands to 3 jobs, more than sweep.max_jobs"]),
    (with_("parallel.backend", "mpi"), ["parallel.backend", "'auto', 'loky', 'threads' or 'dask'"]),
])
def test_bad_config_is_one_clear_message(tmp_path, data, needles):
    r = bad(tmp_path, data)
    assert r.exit_code == 2, r.output
    text = flat(r.output)
    for needle in needles:
        assert needle in text, (needle, text)
    assert "Traceback" not in r.output
    assert not (tmp_path / "out").exists()  # refused before any folder is made


@pytest.mark.parametrize(("extra", "needle", "code"), [
    (["--set", "sweep.axes.3.values=[1]"], "--set sweep.axes.3.values: 'sweep.axes' is a list", 2),
    (["--set", "bogus=1"], "--set bogus: unknown key 'bogus'", 2),
    (["--backend", "mpi"], "--backend must be one of auto, loky, threads, dask", 2),
    (["--backend", "dask"], "the dask backend needs a scheduler address: --scheduler", 2),
    (["--n-jobs", "0"], "--n-jobs (-1: all cores) must be >= 1", 2),
])
def test_bad_options_are_one_clear_message(tmp_path, extra, needle, code):
    r = bad(tmp_path, GOOD, *extra)
    assert r.exit_code == code and needle in flat(r.output), r.output
    assert "Traceback" not in r.output


def test_missing_file_and_unwritable_output_folder(tmp_path):
    r = invoke("sweep", tmp_path / "nope.yaml")
    assert r.exit_code == 2 and f"config file '{tmp_path / 'nope.yaml'}' does not exist" in flat(
        r.output)
    cfg = tmp_path / "c.yaml"
    cfg.write_text(yaml.safe_dump(GOOD))
    blocker = tmp_path / "a-file"
    blocker.write_text("x")
    r = invoke("sweep", cfg, "--out", blocker / "run", "--cache-dir", tmp_path / "cache")
    assert r.exit_code == 2 and f"'{blocker}' is a file, not a folder" in flat(r.output), r.output
    r = invoke("sweep", cfg, "--out", blocker, "--cache-dir", tmp_path / "cache")
    assert r.exit_code == 2 and "is a file; expected a folder" in flat(r.output)
    assert "Traceback" not in r.output


def test_a_failed_invocation_loses_nothing_already_finished(tmp_path):
    cfg = tmp_path / "c.yaml"
    cfg.write_text(yaml.safe_dump(GOOD))
    cache = tmp_path / "cache"
    r = invoke("sweep", cfg, "--out", tmp_path / "first", "--cache-dir", cache, "--no-progress")
    assert r.exit_code == 0, r.output
    before = (tmp_path / "first" / "metrics.csv").read_bytes()
    r = invoke("sweep", cfg, "--out", tmp_path / "first" / "metrics.csv", "--cache-dir", cache)
    assert r.exit_code == 2
    with sqlite3.connect(cache / DB_NAME) as db:
        assert db.execute("SELECT COUNT(*) FROM jobs").fetchone()[0] == 3
    assert (tmp_path / "first" / "metrics.csv").read_bytes() == before


def test_dask_not_installed_says_how_to_install(tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "dask.distributed", None)  # import fails
    r = bad(tmp_path, GOOD, "--backend", "dask", "--scheduler", "tcp://127.0.0.1:8786")
    assert r.exit_code == 2 and "pip install 'ema-cli[dask]'" in r.output
    assert "Traceback" not in r.output


def test_a_damaged_cache_entry_is_recomputed_with_a_warning(tmp_path):
    cfg = tmp_path / "c.yaml"
    cfg.write_text(yaml.safe_dump(GOOD))
    cache = tmp_path / "cache"
    r = invoke("sweep", cfg, "--out", tmp_path / "a", "--cache-dir", cache, "--no-progress")
    assert r.exit_code == 0, r.output
    with sqlite3.connect(cache / DB_NAME) as db:  # one metrics row overwritten with zeros
        db.execute("UPDATE jobs SET metrics = zeroblob(length(metrics)) WHERE rowid = 2")
    r = invoke("sweep", cfg, "--out", tmp_path / "b", "--cache-dir", cache, "--no-progress")
    assert r.exit_code == 0, r.output
    text = flat(r.output)
    assert "warning: job cache" in text and "1 damaged entry not used and recomputed" in text
    assert "1 runs computed, 2 cached" in text
    man = json.loads((tmp_path / "b" / "manifest.json").read_text())
    assert man["cache_corrupt_entries"] == 1 and man["job_counts"]["computed"] == 1
    a, b = (pd.read_csv(tmp_path / d / "metrics.csv") for d in "ab")
    pd.testing.assert_frame_equal(a, b)
