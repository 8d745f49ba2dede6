"""`ema identify --make-data / --closed-loop / --friction-sweep` through typer's CliRunner:
outputs, fitted.yaml runnable with `ema simulate`, mixed modes and bad input refused with one
line naming the option, column or row, and nothing written on error."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

from ema_cli.cli.main import app

runner = CliRunner()


def invoke(*args: str):
    r = runner.invoke(app, [*map(str, args)])
    return r, " ".join(r.output.split())


@pytest.fixture(scope="module")
def logs(tmp_path_factory):
    d = tmp_path_factory.mktemp("logs")
    r, text = invoke("identify", "--make-data", "closed-loop", "--noise", "1", "--seed", "3",
                     "--set", "duration_s=2", "--out", d / "cl")
    assert r.exit_code == 0, text
    r, text = invoke("identify", "--make-data", "friction-sweep", "--noise", "1",
                     "--out", d / "fs")
    assert r.exit_code == 0, text
    return d


def test_make_data_writes_the_log_and_its_truths(logs):
    df = pd.read_csv(logs / "cl" / "closed_loop.csv")
    assert list(df.columns) == ["t_s", "theta_ref_deg", "theta_load_deg", "omega_motor_rpm",
                                "current_a", "voltage_cmd_v"]
    assert len(df) == 2001 and df["t_s"].iloc[-1] == pytest.approx(2.0)
    side = json.loads((logs / "cl" / "closed_loop.truth.json").read_text())
    assert side["truth"]["kL"] == 590.0 and side["truth"]["alpha"] == 0.003
    assert side["all_parameters"]["damping"] == 0.0  # the default contact form
    assert side["all_parameters"]["contact_tau"] == 1e-4  # with its damping ramp [s]
    assert (logs / "fs" / "friction_sweep.csv").is_file()
    # a finished folder is never overwritten
    r, text = invoke("identify", "--make-data", "friction-sweep", "--out", logs / "fs")
    assert r.exit_code == 2 and "results are never overwritten" in text


def test_closed_loop_fit_writes_everything_and_fitted_yaml_runs(logs, tmp_path):
    out = tmp_path / "fit"
    free = ["--free", "kL=560,620", "--free", "alpha=0.0028,0.0032", "--free", "Fc=0.019,0.021",
            "--free", "sigma2=9e-5,1.1e-4"]
    r, text = invoke("identify", "--closed-loop", "--data", logs / "cl" / "closed_loop.csv",
                     *free, "--pop", "8", "--generations", "2", "--set", "ga_dt_s=1e-4",
                     "--set", "profile_points=5", "--out", out)
    assert r.exit_code == 0, text
    for name in ("identification.json", "fit_theta_load_deg.png", "fit_current_a.png",
                 "fit_omega_motor_rpm.png", "fit_voltage_cmd_v.png", "alpha_profile.png",
                 "fitted.yaml", "reference.csv", "summary.md", "manifest.json", "fit.csv"):
        assert (out / name).is_file(), name
    js = json.loads((out / "identification.json").read_text())
    p = js["parameters"]
    assert set(p) == {"kL", "alpha", "Fc", "sigma2"}
    assert p["kL"]["unit"] == "N*m/rad" and p["alpha"]["unit"] == "rad"
    assert abs(p["kL"]["value"] / 590 - 1) < 0.005 and abs(p["alpha"]["value"] / 0.003 - 1) < 0.005
    assert all(v["determined"] for v in p.values())
    assert np.allclose(np.diag(js["correlation"]["matrix"]), 1.0)
    assert set(js["fit_rms"]) == {"theta_load_deg", "omega_motor_rpm", "current_a",
                                  "voltage_cmd_v"}
    # fitted.yaml reproduces the fitted model on the logged command
    r, text = invoke("simulate", out / "fitted.yaml", "--out", tmp_path / "sim")
    assert r.exit_code == 0, text
    sim = pd.read_csv(tmp_path / "sim" / "timeseries.csv")
    fit = pd.read_csv(out / "fit.csv")
    assert np.allclose(sim["theta_load_deg"].to_numpy(), fit["theta_load_model_deg"].to_numpy(),
                       rtol=0, atol=1e-6)


def test_friction_sweep_fit(logs, tmp_path):
    r, text = invoke("identify", "--friction-sweep", "--data", logs / "fs" / "friction_sweep.csv",
                     "--out", tmp_path / "fsfit")
    assert r.exit_code == 0, text
    js = json.loads((tmp_path / "fsfit" / "identification.json").read_text())
    assert set(js["parameters"]) == {"Fc", "Fs", "vs", "sigma2"}
    for n, t in (("Fc", 0.02), ("Fs", 0.03), ("vs", 1.0), ("sigma2", 1e-4)):
        lo, hi = js["parameters"][n]["ci95"]
        assert abs(js["parameters"][n]["value"] / t - 1) < 0.1 and lo < hi
    assert (tmp_path / "fsfit" / "friction_fit.png").is_file()


@pytest.mark.parametrize("args, expect", [
    (["--closed-loop", "--friction-sweep", "--data", "x.csv"],
     "--closed-loop and --friction-sweep cannot be combined"),
    (["--closed-loop", "--data", "x.csv", "--k-range", "1", "2"],
     "--k-range applies to the torque-data identification, not to --closed-loop"),
    (["--make-data", "sine"], "--make-data: expected closed-loop or friction-sweep"),
    (["--make-data", "closed-loop", "--data", "x.csv"], "--make-data writes data; it takes no "
                                                        "--data"),
    (["--closed-loop"], "--closed-loop needs --data LOG.csv"),
    (["--friction-sweep", "--data", "x.csv", "--noise", "1"], "--noise describes synthetic data"),
    (["--friction-sweep", "--data", "x.csv", "--free", "kL=1,2"],
     "--free applies to --closed-loop, not to --friction-sweep"),
    (["--closed-loop", "--data", "x.csv", "--free", "kL=900,300"], "free.kL: needs LO < HI"),
    (["--closed-loop", "--data", "x.csv", "--free", "kL=300"],
     "--free kL: expected NAME=LO,HI"),
    (["--closed-loop", "--data", "x.csv", "--free", "Jx=0,1"],
     "free.Jx: not a parameter a closed-loop fit can free"),
    (["--make-data", "closed-loop", "--set", "plant.kL=-1"], "plant.kL: parameter 'kL' must be"),
])
def test_bad_options_one_line_and_nothing_written(tmp_path, args, expect):
    out = tmp_path / "never"
    r, text = invoke("identify", *args, "--out", out)
    assert r.exit_code == 2, text
    assert text.startswith("error:") and expect in text, text
    assert not out.exists()


def test_bad_log_names_the_row_and_writes_nothing(logs, tmp_path):
    df = pd.read_csv(logs / "cl" / "closed_loop.csv")
    df.loc[500, "t_s"] = df.loc[499, "t_s"]
    bad = tmp_path / "bad.csv"
    df.to_csv(bad, index=False)
    out = tmp_path / "never"
    r, text = invoke("identify", "--closed-loop", "--data", bad, "--out", out)
    assert r.exit_code == 2
    assert "column 't_s' must be strictly increasing; it is not at line 502" in text, text
    assert not out.exists()
    r, text = invoke("identify", "--closed-loop", "--data", logs / "cl" / "closed_loop.csv",
                     "--set", "channels.torque_nm=auto", "--out", out)
    assert r.exit_code == 2 and "channels.torque_nm: unknown channel" in text, text
    assert not out.exists()


def test_free_adds_to_the_default_set_or_the_configs(tmp_path):
    from ema_cli.cli.identify_logs import closed_loop_pairs
    from ema_cli.config.loader import load_config
    from ema_cli.identify.log_settings import ClosedLoopSettings

    pairs = closed_loop_pairs(None, [], ["Fs=0,0.2", "kL=400,800"])
    s = load_config(None, pairs, ClosedLoopSettings)
    assert s.free == {"kL": (400.0, 800.0), "alpha": (0.0, 0.01), "Fc": (0.0, 0.1),
                      "sigma2": (0.0, 0.1), "Fs": (0.0, 0.2)}
    cfg = tmp_path / "cl.yaml"
    cfg.write_text("free: {kL: [500, 700]}\n")
    s = load_config(cfg, closed_loop_pairs(cfg, [], ["vs=0.1,10"]), ClosedLoopSettings)
    assert s.free == {"kL": (500.0, 700.0), "vs": (0.1, 10.0)}
    assert load_config(None, closed_loop_pairs(None, [], None), ClosedLoopSettings).free == {
        "kL": (300.0, 900.0), "alpha": (0.0, 0.01), "Fc": (0.0, 0.1), "sigma2": (0.0, 0.1)}
