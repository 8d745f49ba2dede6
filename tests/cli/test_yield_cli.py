"""`ema yield`: the files, the answer on the console, --min-yield's three exit codes, a run
that resumes, and bad tolerance files refused in one line naming the key (exit 2)."""

from __future__ import annotations

import json

import pandas as pd
import pytest
import yaml
from typer.testing import CliRunner

from ema_cli.cli.main import app

runner = CliRunner()
SPEC = {"name": "one-step", "actuator": {"config": None, "plant": {}, "nonlinearities": {}},
        "tests": {"step": {"test": "step", "amplitude_deg": 0.1, "duration_s": 0.4,
                           "limits": {"settling_time": {"max": 0.3, "unit": "s"}}}}}
TOL = {"tolerances": {"nonlinearities.deadzone2": {"dist": "uniform", "low": 0.0,
                                                    "high": 0.003},
                      "plant.kL": {"dist": "normal", "mean": 590, "sd": 20}}}


@pytest.fixture
def files(tmp_path):
    spec, tol = tmp_path / "spec.yaml", tmp_path / "tol.yaml"
    spec.write_text(yaml.safe_dump(SPEC))
    tol.write_text(yaml.safe_dump(TOL))
    return spec, tol


def _yield(spec, tol, out, *extra):
    return runner.invoke(app, ["yield", str(spec), "--tolerances", str(tol), "--n", "12",
                               "--block", "6", "--worst-budget", "5", "--out", str(out),
                               *extra])


def test_a_run_writes_every_file_and_answers_first(files, tmp_path):
    spec, tol = files
    out = tmp_path / "y"
    r = _yield(spec, tol, out)
    assert r.exit_code == 0, r.output
    lines = r.output.splitlines()  # stderr's progress lines mixed in by the runner
    title = lines.index("one-step: production yield (reference EMA)")
    assert lines[title + 1].startswith("Yield ")
    for name in ("yield.json", "samples.parquet", "yield.md", "convergence.png",
                 "dist_step.png", "spec.resolved.yaml", "tolerances.yaml", "manifest.json"):
        assert (out / name).is_file(), name
    js = json.loads((out / "yield.json").read_text())
    df = pd.read_parquet(out / "samples.parquet")
    assert len(df) == js["overall"]["n"] == 12
    assert js["overall"]["n_pass"] == int((df["result"] == "PASS").sum())
    assert set(df.columns) >= {"unit", "plant.kL", "nonlinearities.deadzone2",
                               "step/settling_time [s]", "step/settling_time result",
                               "step/settling_time margin", "step result", "result"}
    md = (out / "yield.md").read_text()
    assert md.splitlines()[2].startswith("**Yield ")
    assert "## Why units fail" in md and "## Worst case" in md
    w = js["worst_case"]["limits"]["step/settling_time"]
    assert w["found"] and w["values"]["nonlinearities.deadzone2"] == pytest.approx(0.003)
    # the console answers too: the worst unit (the same value as yield.json's), the drivers of
    # a failing limit (when one fails) and where the tables are
    worst = [ln for ln in lines if ln.startswith("  worst unit: step/settling_time ")]
    assert len(worst) == 1 and f"margin {w['margin']:+.3f}" in worst[0]
    if js["overall"]["n_fail"]:
        assert any(ln.startswith("  drivers of step/settling_time") for ln in lines)
    assert "(yield.md: per limit, drivers, the worst case)" in " ".join(r.output.split())


@pytest.mark.parametrize(("required", "code", "word"), [
    ("0.01", 0, "PASS"), ("0.999", 1, "FAIL"), ("0.3", 3, "INCONCLUSIVE")])
def test_min_yield_decides_only_when_the_interval_does(files, tmp_path, required, code,
                                                        word):
    spec, tol = files
    r = _yield(spec, tol, tmp_path / "y", "--min-yield", required, "--no-worst")
    assert r.exit_code == code, r.output
    assert f"{word}: required yield" in r.output


@pytest.mark.parametrize(("tolerances", "key"), [
    ({"tolerances": {"plant.kLL": {"dist": "normal", "mean": 590, "sd": 5}}}, "plant.kLL"),
    ({"tolerances": {"plant.kL": {"dist": "normal", "mean": 590, "sd": -5}}}, "plant.kL"),
    ({"tolerances": {"plant.Jm": {"dist": "uniform", "low": 3e-5, "high": 2e-5}}}, "plant.Jm"),
    ({"tolerances": {"plant.kL": {"dist": "normal", "mean": 590, "sd": 5},
                     "plant.Jm": {"dist": "uniform", "low": 2e-5, "high": 3e-5}},
      "correlation": {"plant.kL, plant.Jm": 1.5}}, "plant.kL, plant.Jm"),
])
def test_a_bad_tolerance_file_is_one_line_naming_the_key(tmp_path, files, tolerances, key):
    spec, _ = files
    bad = tmp_path / "bad.yaml"
    bad.write_text(yaml.safe_dump(tolerances))
    r = _yield(spec, bad, tmp_path / "y")
    assert r.exit_code == 2, r.output
    lines = [x for x in r.output.strip().splitlines() if x.strip()]
    assert len(lines) == 1 and key in lines[0] and "Traceback" not in r.output
    assert not (tmp_path / "y").exists()
