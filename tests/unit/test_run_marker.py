"""The run folder's marker (`.ema-run.json`, report/run_inputs.py and report/rundir.py): the
inputs' fingerprint is a pure function of the inputs; an unfinished folder of the same inputs
is completed, a finished one kept, one of other inputs refused naming what differs; Ctrl-C and
SIGTERM exit 130 and 143. (Every command interrupted at many instants, as a process: the slow
tier's tests/system/test_interrupted_runs.py.)"""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from typer.testing import CliRunner

from ema_cli.config.loader import load_config
from ema_cli.config.study import StudyConfig
from ema_cli.errors import EmaError, Terminated
from ema_cli.report import rundir
from ema_cli.report.run_inputs import differences, run_inputs

CONFIG = """# a study
name: m
plant: {kL: 600}
simulation: {duration_s: 0.05}
"""


def inputs(path: Path, sets=(), **kw):
    return run_inputs(load_config(path, sets, StudyConfig), sets=sets, **kw)


def test_the_fingerprint_depends_on_the_inputs_only(tmp_path):
    a = tmp_path / "a.yaml"
    a.write_text(CONFIG)
    first = inputs(a)
    assert inputs(a).fingerprint == first.fingerprint  # loaded again: identical
    b = tmp_path / "sub" / "b.yaml"  # another path, a comment more: the same inputs
    b.parent.mkdir()
    b.write_text("# edited\n" + CONFIG)
    assert inputs(b).fingerprint == first.fingerprint
    assert inputs(a, [("plant.kL", "600")]).fingerprint == first.fingerprint  # the same value
    changed = inputs(a, [("plant.kL", "700")])
    assert changed.fingerprint != first.fingerprint
    assert differences(first.components, changed) == "--set plant.kL 600 there, 700 here"
    c = tmp_path / "c.yaml"
    c.write_text(CONFIG.replace("0.05", "0.06"))
    text = differences(first.components, inputs(c))
    assert text == "simulation.duration_s 0.05 there, 0.06 here"  # the config file's change
    opt = inputs(a, options={"budget": 96})
    assert differences(first.components, opt) == "--budget not set there, 96 here"


def test_a_data_file_is_named_by_its_hash(tmp_path):
    cfg = tmp_path / "a.yaml"
    cfg.write_text(CONFIG)
    data = tmp_path / "log.csv"
    data.write_text("t_s,x\n0,1\n")
    one = inputs(cfg, files={"data": data})
    assert one.fingerprint == inputs(cfg, files={"data": data}).fingerprint
    data.write_text("t_s,x\n0,2\n")
    other = inputs(cfg, files={"data": data})
    assert other.fingerprint != one.fingerprint
    assert differences(one.components, other).startswith("data (sha256) sha256:")


def test_an_unfinished_folder_is_completed_a_finished_one_kept(tmp_path):
    cfg = tmp_path / "a.yaml"
    cfg.write_text(CONFIG)
    out = tmp_path / "run"
    calls = []

    def interrupted(folder: Path) -> None:
        rundir.write_text(folder / "one.csv", "1\n")
        raise KeyboardInterrupt  # Ctrl-C between two files

    def write(folder: Path) -> None:
        calls.append(folder)
        rundir.write_text(folder / "one.csv", "1\n")
        rundir.write_text(folder / "two.csv", "2\n")

    with pytest.raises(KeyboardInterrupt):
        rundir.write_run("simulate", "m", inputs(cfg), out, interrupted)
    mark = json.loads((out / rundir.MARKER).read_text())
    assert mark["finished"] is False and mark["fingerprint"] == inputs(cfg).fingerprint
    assert mark["inputs"]["plant.kL"] == 600  # what it knows: the inputs, named
    (out / ".two.csv.0123456789ab.tmp").write_text("partial")  # as a SIGKILL leaves it
    assert rundir.write_run("simulate", "m", inputs(cfg), out, write) == out
    assert sorted(p.name for p in out.iterdir()) == [rundir.MARKER, "one.csv", "two.csv"]
    mark = json.loads((out / rundir.MARKER).read_text())
    assert mark["finished"] is True and mark["outputs"] == {"one.csv": 2, "two.csv": 2}
    assert rundir.write_run("simulate", "m", inputs(cfg), out, write) == out
    assert calls == [out]  # finished: kept as it is, nothing written
    with pytest.raises(EmaError, match=r"^--out '.*run' already holds a finished `ema "
                                       r"simulate` run of other inputs \(--set plant.kL 600 "
                                       r"there, 700 here\); results are never overwritten"):
        rundir.write_run("simulate", "m", inputs(cfg, [("plant.kL", 700)]), out, write)


def test_a_folder_holding_only_temporaries_is_empty(tmp_path):
    out = tmp_path / "run"
    out.mkdir()
    (out / ".metrics.csv.0123456789ab.tmp").write_text("partial")
    folder, state = rundir.prepare_output("margins", "m", "f" * 16, out)
    assert state == rundir.NEW and [p.name for p in folder.iterdir()] == [rundir.MARKER]


def test_ctrl_c_exits_130_and_sigterm_143(monkeypatch, tmp_path):
    import importlib

    from ema_cli.cli.main import app

    api_margins = importlib.import_module("ema_cli.api.margins")

    for exc, code, word in ((KeyboardInterrupt, 130, "interrupted"),
                            (Terminated, 143, "terminated")):
        def stop(*args, _exc=exc, **kwargs):
            raise _exc

        monkeypatch.setattr(api_margins, "margins", stop)
        r = CliRunner().invoke(app, ["margins", "--out", str(tmp_path / "m")])
        assert r.exit_code == code, r.output
        assert f"{word}: finished work was kept" in r.output


def test_simulate_interrupted_while_writing_completes_on_the_same_command(tmp_path,
                                                                          monkeypatch):
    """The issue's case on `ema simulate`: Ctrl-C while its files are written leaves an
    unfinished folder; the same command completes it (exit 0), then keeps it."""
    import ema_cli.report.simulate_report as sim_report
    from ema_cli.cli.main import app

    out = tmp_path / "run"
    args = ["simulate", "--duration", "0.01", "--set", "plant.kL=600", "--out", str(out)]
    real = sim_report.write_simulation

    def interrupted(folder, *a, **kw):
        (folder / "timeseries.csv").write_text("partial? never: atomic\n")
        raise KeyboardInterrupt

    monkeypatch.setattr(sim_report, "write_simulation", interrupted)
    assert CliRunner().invoke(app, args).exit_code == 130
    assert json.loads((out / rundir.MARKER).read_text())["finished"] is False
    monkeypatch.setattr(sim_report, "write_simulation", real)
    r = CliRunner().invoke(app, args)
    assert r.exit_code == 0, r.output
    mark = json.loads((out / rundir.MARKER).read_text())
    assert mark["finished"] is True
    assert {"timeseries.csv", "metrics.csv", "manifest.json"} <= set(mark["outputs"])
    assert (out / "timeseries.csv").read_text().startswith("t_s")
    r = CliRunner().invoke(app, args)
    assert r.exit_code == 0, r.output


def test_tune_checks_its_own_interrupted_folder_as_the_same_inputs(tmp_path):
    """Issue 42's root cause: `ema tune` checked --out before tuning with no inputs, so the
    folder its own save() had left unfinished read as 'of other inputs'. The check and the
    save now record the same inputs, from the same function."""
    import yaml

    from ema_cli.api.tune import tune_inputs

    cfg = tmp_path / "tune.yaml"
    cfg.write_text(yaml.safe_dump({
        "name": "tiny", "simulation": {"duration_s": 0.3, "dt_s": 5.0e-5},
        "scenarios": {"a": {"input": {"kind": "step", "amplitude_deg": 1.0}}},
        "variables": {"Kpp": {"bounds": [20.0, 100.0], "scale": "log"}},
        "optimiser": {"budget": 240, "pop": 12}}))
    out = tmp_path / "run"
    rundir.prepare_output("tune", "tiny", tune_inputs(cfg, [("optimiser.seed", "0")]), out)
    rundir.write_text(out / "tuned.yaml", "x: 1\n")  # interrupted while writing
    again = tune_inputs(cfg, [("optimiser.seed", "0")], budget=240)  # the config's budget
    assert rundir.check_output(out, "tune", again) == rundir.RESUMED
    with pytest.raises(EmaError, match=r"unfinished `ema tune` run of other inputs \(--set "
                                       r"optimiser.seed 0 there, 3 here; --budget 240 there, "
                                       r"96 here\)"):
        rundir.check_output(out, "tune", tune_inputs(cfg, [("optimiser.seed", "3")], budget=96))
