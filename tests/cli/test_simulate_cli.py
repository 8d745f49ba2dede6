"""`ema simulate`, `ema locations`, `ema params` through typer's CliRunner."""

from __future__ import annotations

import json

import pandas as pd
import pytest
from typer.testing import CliRunner

from ema_cli.cli.main import app

runner = CliRunner()


def invoke(*args: str):
    return runner.invoke(app, list(args), catch_exceptions=False)


def test_simulate_with_nl_and_set_writes_everything(tmp_path):
    out = tmp_path / "run"
    r = invoke("simulate", "--step", "0.1", "--duration", "0.2", "--nl", "deadzone2=0.01",
               "--nl", "saturation2=off", "--set", "plant.Kpp=60", "--out", str(out))
    assert r.exit_code == 0, r.output
    for f in ("timeseries.csv", "metrics.csv", "manifest.json", "tracking.png",
              "config.resolved.yaml"):
        assert (out / f).is_file(), f
    ts = pd.read_csv(out / "timeseries.csv")
    for col in ("t_s", "theta_ref_deg", "theta_load_deg", "theta_motor_deg", "omega_load_deg_s",
                "omega_motor_rpm", "current_a", "voltage_cmd_v", "torque_shaft_nm",
                "torque_friction_nm", "err_pos_deg", "err_vel_deg_s"):
        assert col in ts.columns, col
    assert len(ts) == 2001  # 0.2 s at the default 1e-4 s output interval, both ends
    assert ts["theta_ref_deg"].iloc[-1] == pytest.approx(0.1)
    man = json.loads((out / "manifest.json").read_text())
    p = man["parameters_si"]
    assert p["Kpp"] == 60.0
    assert p["alpha"] == pytest.approx(0.01 * 3.141592653589793 / 180)
    assert p["sat2"] is None  # inf -> null in JSON: removed
    assert man["n_steps"] == 20_000 and man["dt_s"] == 1e-5
    met = pd.read_csv(out / "metrics.csv")
    assert met["max_abs_err_pos_deg"][0] == pytest.approx(0.1)


def test_set_bare_parameter_name_means_plant(tmp_path):
    r = invoke("simulate", "--duration", "0.05", "--set", "kL=600", "--out", str(tmp_path / "a"))
    assert r.exit_code == 0, r.output
    man = json.loads((tmp_path / "a" / "manifest.json").read_text())
    assert man["parameters_si"]["kL"] == 600.0


@pytest.mark.parametrize(("args", "needle"), [
    (["--nl", "deadzone9=1"], "--nl deadzone9=1"),
    (["--nl", "deadzone2=abc"], "--nl deadzone2=abc"),
    (["--nl", "deadzone2=-1"], "--nl deadzone2=-1"),
    (["--nl", "gap1=off"], "gap1"),
    (["--nl", "deadzone2"], "--nl expects NAME=VALUE"),
    (["--set", "plant.nope=3"], "plant.nope"),
    (["--set", "plant.kL=abc"], "plant.kL"),
    (["--set", "bogus.x=3"], "--set bogus.x"),
    (["--dt", "0"], "--dt must be > 0"),
    (["--dt", "nan"], "--dt must be a finite number"),
    (["--step", "inf"], "--step must be a finite number"),
    (["--dt", "0.3", "--duration", "0.2"], "must not exceed the duration"),
    (["--set", "simulation.output_interval_s=1.5e-5"], "whole multiple of dt"),
    (["--set", "input.kind=square"], "input.kind"),
])
def test_bad_values_exit_nonzero_with_a_clear_message(tmp_path, args, needle):
    r = invoke("simulate", *args, "--out", str(tmp_path / "x"))
    assert r.exit_code != 0
    assert needle in r.output, r.output
    assert "Traceback" not in r.output


def test_missing_config_file_is_named(tmp_path):
    r = invoke("simulate", str(tmp_path / "nope.yaml"))
    assert r.exit_code == 2
    assert "nope.yaml" in r.output and "does not exist" in r.output


def test_existing_output_folder_is_not_overwritten(tmp_path):
    (tmp_path / "keep.txt").write_text("mine")
    r = invoke("simulate", "--duration", "0.05", "--out", str(tmp_path))
    assert r.exit_code != 0 and "never overwritten" in r.output
    assert (tmp_path / "keep.txt").read_text() == "mine"


def test_locations_and_params_tables():
    r = invoke("locations")
    assert r.exit_code == 0
    for name in ("deadzone1", "deadzone2", "deadzone3", "deadzone4", "saturation1",
                 "saturation2", "saturation3", "gap1", "friction1"):
        assert name in r.output
    r = invoke("params")
    assert r.exit_code == 0 and "sigma2" in r.output and "derived" in r.output
