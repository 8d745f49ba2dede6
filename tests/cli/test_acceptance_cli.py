"""`ema acceptance`: files, PASS/FAIL exit codes, the table against the CSV, bad specs."""

from __future__ import annotations

import json

import pandas as pd
import pytest
from typer.testing import CliRunner

from ema_cli.cli.main import app

runner = CliRunner()
SPEC = "configs/acceptance.yaml"
QUICK = ["--only", "step-small", "--only", "margins", "--only", "load-deflection",
         "--only", "free-play"]


def test_a_passing_battery_writes_everything(tmp_path):
    out = tmp_path / "acc"
    r = runner.invoke(app, ["acceptance", SPEC, *QUICK, "--out", str(out)])
    assert r.exit_code == 0, r.output
    assert "PASS: every limit met (4 tests" in r.output
    names = ["acceptance.md", "acceptance.csv", "spec.resolved.yaml", "manifest.json",
             "step-small.png", "margins.png", "load-deflection.png", "free-play.png"]
    for name in names:
        assert (out / name).is_file(), name
    table = pd.read_csv(out / "acceptance.csv")
    assert set(table.test) == {"step-small", "margins", "load-deflection", "free-play"}
    assert table.passed.all()
    assert {"test", "metric", "condition", "value", "min", "max", "unit", "result", "passed",
            "measured", "lower", "upper", "value_si", "si_unit", "reason"} <= set(table.columns)
    assert set(table.result) == {"PASS"}
    md = (out / "acceptance.md").read_text()
    assert "**PASS**" in md and md.count("| PASS |") == len(table)
    man = json.loads((out / "manifest.json").read_text())
    assert man["passed"] is True and set(man["test_wall_s"]) == set(table.test)
    # a finished run is never overwritten: the same inputs keep it, others are refused
    before = {p: p.stat().st_mtime_ns for p in out.rglob("*")}
    r2 = runner.invoke(app, ["acceptance", SPEC, *QUICK, "--out", str(out)])
    assert r2.exit_code == 0, r2.output
    assert {p: p.stat().st_mtime_ns for p in out.rglob("*")} == before
    r2 = runner.invoke(app, ["acceptance", SPEC, *QUICK, "--set", "actuator.plant.kL=600",
                             "--out", str(out)])
    assert r2.exit_code == 2 and "never overwritten" in r2.output


def test_a_failing_limit_exits_1_and_says_which(tmp_path):
    out = tmp_path / "acc"
    r = runner.invoke(app, ["acceptance", SPEC, "--only", "load-deflection", "--set",
                            "actuator.plant.alpha=0.003", "--out", str(out)])
    assert r.exit_code == 1, r.output
    assert "FAIL: 1 of 2 limits not met" in r.output
    table = pd.read_csv(out / "acceptance.csv")
    row = table[table.metric == "free_play"].iloc[0]
    assert not row.passed and row.value == pytest.approx(0.3438, rel=0.01)
    assert "**FAIL**" in (out / "acceptance.md").read_text()


def test_an_inconclusive_battery_exits_3_with_its_own_row_style(tmp_path):
    # issue 22: margins searched up to 1 Hz hold no crossover: INCONCLUSIVE, never PASS/FAIL
    out = tmp_path / "acc"
    r = runner.invoke(app, ["acceptance", SPEC, "--only", "margins", "--only", "step-small",
                            "--set", "tests.margins.f_max_hz=1", "--out", str(out)])
    assert r.exit_code == 3, r.output
    text = " ".join(r.output.split())
    assert "INCONCLUSIVE: 4 of 8 limits not measured inside the test's range" in text
    assert text.count("INCONCLUSIVE ") == 4  # one mark per row; the verdict line has a colon
    assert "-> no gain crossover up to f_max_hz = 1 Hz" in text
    table = pd.read_csv(out / "acceptance.csv")
    assert (table.result == "INCONCLUSIVE").sum() == 4
    assert not table.loc[table.result == "INCONCLUSIVE", "measured"].any()
    assert table.loc[table.result == "INCONCLUSIVE", "reason"].str.endswith(
        "widen f_max_hz").all()
    md = (out / "acceptance.md").read_text()
    assert "**INCONCLUSIVE**: 4 of 8" in md and md.count("| _INCONCLUSIVE_ |") == 4
    rows = [ln for ln in md.splitlines() if ln.startswith("| margins |")]
    # |L| in a reason is escaped: every row keeps its 8 cells
    assert len(rows) == 4 and all(ln.replace("\\|", "").count("|") == 9 for ln in rows)
    man = json.loads((out / "manifest.json").read_text())
    assert man["verdict"] == "INCONCLUSIVE" and man["exit_code"] == 3
    # a FAIL outranks an INCONCLUSIVE: exit 1
    r = runner.invoke(app, ["acceptance", SPEC, "--only", "margins", "--only", "step-small",
                            "--set", "tests.margins.f_max_hz=1", "--set",
                            "tests.step-small.limits.rise_time.max=1", "--out",
                            str(tmp_path / "b")])
    assert r.exit_code == 1, r.output
    assert "FAIL: 1 of 8 limits not met, 4 inconclusive" in " ".join(r.output.split())


@pytest.mark.parametrize(("text", "message"), [
    ("name: x\ntests:\n  a: {test: nope, limits: {}}\n", "tests.a.test: unknown test 'nope'"),
    ("name: x\ntests:\n  a: {test: step, amplitude_deg: 1}\n", "tests.a.limits"),
    ("name: x\ntests:\n  a: {test: no_load_rate, limits: {rate: {min: 700, unit: Hz}}}\n",
     "tests.a.limits.rate.unit: 'Hz' is a unit of frequency, rate is a rate"),
    ("name: x\nactuator: {config: missing.yaml}\ntests:\n  a: {test: margins, limits: "
     "{gain_margin: {min: 6, unit: dB}}}\n", "actuator.config: 'missing.yaml' is not a file"),
    ("name: x\nactuator: {plant: {kL: -3}}\ntests:\n  a: {test: margins, limits: "
     "{gain_margin: {min: 6, unit: dB}}}\n", "kL"),
])
def test_bad_specs_exit_2_with_one_line(tmp_path, text, message):
    spec = tmp_path / "spec.yaml"
    spec.write_text(text)
    out = tmp_path / "out"
    r = runner.invoke(app, ["acceptance", str(spec), "--out", str(out)])
    assert r.exit_code == 2, r.output
    assert message in " ".join(r.output.split()), r.output
    assert r.output.strip().count("\n") == 0
    assert not out.exists()


def test_missing_spec_file(tmp_path):
    r = runner.invoke(app, ["acceptance", str(tmp_path / "none.yaml")])
    assert r.exit_code == 2 and "is not a file" in r.output


def test_validate_recognises_a_spec():
    r = runner.invoke(app, ["validate", SPEC])
    assert r.exit_code == 0, r.output
    assert "valid acceptance spec; 10 tests, 21 limits" in " ".join(r.output.split())
