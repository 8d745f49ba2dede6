"""`ema identify --closed-loop --data LOG.parquet|.mat --columns ... --window ...` through typer's
CliRunner: as far as the log reaches the fit (the fit stubbed), the options and the same keys
in a YAML config give the log the loader gives; misuse is one line, nothing written; and one
real short fit of a renamed, rescaled, windowed Parquet log (~9 s) lands on the truth.
"""

from __future__ import annotations

import re

import numpy as np
import pytest
import scipy.io as sio
from typer.testing import CliRunner

from ema_cli.cli.main import app
from ema_cli.errors import EmaError
from ema_cli.identify.closed_loop.problem import load_log
from ema_cli.units import DEG, RPM

runner = CliRunner()
N = 800  # samples at 1 kHz from t = 5 s [-]
STUB = "stub: the log reached the fit"
MAP = {"t_s": "time:ms", "theta_ref_deg": "ref:rad", "theta_load_deg": "pos:rad",
       "omega_motor_rpm": "wm:rad/s"}  # the column map of log.parquet


ESTIMATE = re.compile(r"^estimated time ~[^:]+: a closed-loop fit of the \S+ s log: .*? on \d+ "
                      r"cores? ")
"""The fit's estimate line, printed before it starts when it is above 10 s (the 0.8 s logs
here at 8 starts: ~11 s); these tests are about what reaches the fit."""


def invoke(*args):
    r = runner.invoke(app, [*map(str, args)])
    return r, ESTIMATE.sub("", " ".join(r.output.split()))


@pytest.fixture()
def caught(monkeypatch):
    """Replace the fit by a stub that keeps what it was given and stops with one line."""
    seen = {}

    def stub(settings, log=None):
        seen["settings"], seen["log"] = settings, log
        raise EmaError(STUB)

    monkeypatch.setattr("ema_cli.identify.closed_loop.ga_fit.run_closed_loop", stub)
    return seen


@pytest.fixture()
def logs(tmp_path):
    """The same log as a Parquet file (renamed, ms, rad, rad/s) and as a CSV in ema's names."""
    import pandas as pd

    k = np.arange(N)
    t = 5.0 + k / 1000
    ref = np.round(5 * np.sin(2 * np.pi * 2 * k / 1000) * 256) / 256  # [deg], binary fractions
    load = np.round(4.8 * np.sin(2 * np.pi * 2 * k / 1000 - 0.3) * 256) / 256
    wm = np.round(600 * np.cos(2 * np.pi * 2 * k / 1000 - 0.3) * 16) / 16  # [rpm]
    pd.DataFrame({"t_s": t, "theta_ref_deg": ref, "theta_load_deg": load,
                  "omega_motor_rpm": wm}).to_csv(tmp_path / "ema.csv", index=False)
    pd.DataFrame({"time": k.astype(float) + 5000.0, "ref": ref * DEG, "pos": load * DEG,
                  "wm": wm * RPM, "other": np.zeros(N)}).to_parquet(tmp_path / "log.parquet")
    return tmp_path


def test_parquet_with_column_map_and_window_reaches_the_fit(logs, caught, tmp_path):
    out = tmp_path / "never"
    cols = [x for ch, spec in MAP.items() for x in ("--columns", f"{ch}={spec}")]
    r, text = invoke("identify", "--closed-loop", "--data", logs / "log.parquet", *cols,
                     "--window", "5.2,5.6", "--out", out)
    assert r.exit_code == 2 and text == f"error: {STUB}", text
    assert not out.exists()
    s, log = caught["settings"], caught["log"]
    assert s.columns["t_s"] == "time:ms" and s.window == (5.2, 5.6)
    # time 5000 + k ms -> 5 + k/1000 s; the window keeps k = 200 .. 600
    ref = load_log(logs / "ema.csv", window=(5.2, 5.6))
    assert log.n == 401 and ref.n == 401 and log.t0 == ref.t0
    assert log.t0 == pytest.approx(5.2, abs=1e-12)
    np.testing.assert_allclose(log.t, np.arange(401) / 1000, rtol=0, atol=1e-12)
    # ms: one division by 1000 against the CSV's decimal 5.xxx: 1 ulp of 6 s apart at most
    np.testing.assert_allclose(log.t, ref.t, rtol=0, atol=8.9e-16 * 2)
    assert np.array_equal(log.theta_ref, ref.theta_ref)  # rad written as the loader's deg*DEG
    assert set(log.channels) == {"theta_load_deg", "omega_motor_rpm"}
    for c in log.channels:
        assert np.array_equal(log.channels[c], ref.channels[c]), c


def test_yaml_columns_and_window_give_the_same_log(logs, caught, tmp_path):
    cfg = tmp_path / "cl.yaml"
    cfg.write_text(f"data: {logs / 'log.parquet'}\nwindow: [5.2, 5.6]\ncolumns:\n"
                   "  t_s: time:ms\n  theta_ref_deg: ref:rad\n  theta_load_deg: pos:rad\n")
    r, text = invoke("identify", cfg, "--closed-loop", "--out", tmp_path / "never")
    assert text == f"error: {STUB}", text
    log = caught["log"]
    assert log.n == 401 and set(log.channels) == {"theta_load_deg"}  # wm not mapped: not read


def test_mat_file_through_the_cli(logs, caught, tmp_path):
    import pandas as pd

    df = pd.read_csv(logs / "ema.csv")
    sio.savemat(tmp_path / "log.mat", {"rec": {c: df[c].to_numpy()[:, None] for c in df}})
    r, text = invoke("identify", "--closed-loop", "--data", tmp_path / "log.mat",
                     "--out", tmp_path / "never")
    assert text == f"error: {STUB}", text
    ref = load_log(logs / "ema.csv")
    assert np.array_equal(caught["log"].t, ref.t)
    assert np.array_equal(caught["log"].channels["omega_motor_rpm"],
                          ref.channels["omega_motor_rpm"])


@pytest.mark.parametrize("change, args, expect", [
    ({"theta_load_deg": "pos:rpm"}, [], "columns.theta_load_deg: 'rpm' is a unit of speed; "
     "theta_load_deg takes angle units: deg, rad, mrad"),
    ({"torque": "pos"}, [], "columns.torque: unknown channel 'torque'; expected one of t_s, "
     "theta_ref_deg"),
    ({"theta_load_deg": "angle:rad"}, [], "--columns theta_load_deg=angle:rad: data file "
     "'{d}/log.parquet' has no column 'angle'; it has time, ref, pos, wm, other"),
    ({"t_s": "other"}, [], "column 'other' (t_s) must be strictly increasing; it is not at "
     "row 2"),
    ({}, ["--window", "5.2"], "--window: expected T0,T1 (two times in seconds, e.g. 0.5,2.5), "
     "got '5.2'"),
    ({}, ["--window", "5.6,5.2"], "--window: expected T0 < T1"),
    ({}, ["--window", "0,1"], "--window 0,1: the window passes the ends of data file "
     "'{d}/log.parquet', which spans 5 .. 5.799 s"),
    ({}, ["--window", "5.0,5.03"], "--window 5,5.03: the window keeps 31 sample(s)"),
])
def test_bad_map_or_window_one_line_nothing_written(logs, tmp_path, change, args, expect):
    out = tmp_path / "never"
    cols = [x for ch, spec in {**MAP, **change}.items() for x in ("--columns", f"{ch}={spec}")]
    r, text = invoke("identify", "--closed-loop", "--data", logs / "log.parquet", *cols, *args,
                     "--out", out)
    assert r.exit_code == 2, text
    assert text.startswith("error:") and expect.format(d=logs) in text, text
    assert not out.exists()


@pytest.mark.parametrize("args, expect", [
    (["--friction-sweep", "--data", "x.csv", "--columns", "t_s=a"],  # its own channels only
     "columns.t_s: unknown channel 't_s'; expected one of omega_rpm, torque_nm"),
    (["--friction-sweep", "--data", "x.csv", "--window", "0,1"],
     "--window applies to --closed-loop, not to --friction-sweep"),
    (["--data", "x.csv", "--window", "0,1"],
     "--window applies to --closed-loop, not to the torque-data identification"),
])
def test_options_of_other_modes(tmp_path, args, expect):
    r, text = invoke("identify", *args, "--out", tmp_path / "never")
    assert r.exit_code == 2 and expect in text, text


def test_real_short_fit_of_a_renamed_parquet_log_in_other_units(tmp_path):
    """The whole way: a noise-free 2 s synthetic log (from 7 s, ms, rad, rad/s, mA) as Parquet,
    mapped back and windowed to its first second, fitted with tight bounds and a tiny GA (the
    budget of test_identify_logs_cli.py): ~10 s on 2 cores, measured."""
    import json

    import pandas as pd

    from ema_cli.identify.make_data import closed_loop_log

    syn = closed_loop_log({}, 0.0, 0, duration_s=2.0)
    c = syn.columns
    pd.DataFrame({"time": c["t_s"] * 1000 + 7000, "cmd": c["theta_ref_deg"] * DEG,
                  "pos": c["theta_load_deg"] * DEG, "wm": c["omega_motor_rpm"] * RPM,
                  "i": c["current_a"] * 1000}).to_parquet(tmp_path / "syn.parquet")
    cols = ["t_s=time:ms", "theta_ref_deg=cmd:rad", "theta_load_deg=pos:rad",
            "omega_motor_rpm=wm:rad/s", "current_a=i:mA"]
    free = ["kL=560,620", "alpha=0.0028,0.0032", "Fc=0.019,0.021", "sigma2=9e-5,1.1e-4"]
    out = tmp_path / "fit"
    r, text = invoke("identify", "--closed-loop", "--data", tmp_path / "syn.parquet",
                     *[x for s in cols for x in ("--columns", s)], "--window", "7,8",
                     *[x for s in free for x in ("--free", s)], "--pop", "8", "--generations",
                     "2", "--set", "ga_dt_s=1e-4", "--set", "profile_points=5", "--out", out)
    assert r.exit_code == 0, text
    js = json.loads((out / "identification.json").read_text())
    assert js["data"]["n_samples"] == 1001 and js["data"]["t0_s"] == 7.0
    assert js["data"]["duration_s"] == pytest.approx(1.0, abs=1e-12)
    assert js["data"]["channels"] == ["theta_load_deg", "omega_motor_rpm", "current_a"]
    # noise-free data from the same simulator and step, which followed the chirp itself where
    # the fit follows a cubic spline through its samples (within 4.2e-7 rad): the polish lands
    # on the truth within 5e-5 relative (measured: Fc -3.8e-6, the largest)
    for name in ("kL", "alpha", "Fc", "sigma2"):
        assert js["parameters"][name]["value"] == pytest.approx(syn.truth[name], rel=5e-5), name
