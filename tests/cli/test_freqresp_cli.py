"""`ema freqresp` and `api.freqresp`: the files and their content, the summary's bandwidths
against the per-point table, and bad options."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

from ema_cli import api
from ema_cli.analysis.freqresp import crossing
from ema_cli.cli.main import app

runner = CliRunner()


def test_freqresp_writes_everything(tmp_path):
    out = tmp_path / "fr"
    r = runner.invoke(app, ["freqresp", "--amplitudes", "0.5,20", "--f-min", "2",
                            "--f-max", "20", "--n", "8", "--out", str(out)])
    assert r.exit_code == 0, r.output
    for name in ("freqresp.csv", "freqresp.json", "bode.png", "summary.md", "manifest.json"):
        assert (out / name).is_file(), name
    table = pd.read_csv(out / "freqresp.csv")
    assert len(table) == 16 and {"amplitude_deg", "f_hz", "gain_db", "phase_deg",
                                 "thd_pct"} <= set(table.columns)
    data = json.loads((out / "freqresp.json").read_text())
    assert [a["amplitude_deg"] for a in data["amplitudes"]] == [0.5, 20.0]
    for a in data["amplitudes"]:
        rows = table[table["amplitude_deg"] == a["amplitude_deg"]]
        bw = crossing(rows["f_hz"].to_numpy(), rows["gain_db"].to_numpy(), -3.0)
        # the CSV holds 9 significant digits (%.9g): the crossing re-read from it agrees to
        # about that (a gain 5e-9 dB off moves a 6 Hz crossing by ~1e-8 of itself)
        assert a["f_3db_hz"] == pytest.approx(bw, rel=1e-7)
        assert set(a) >= {"f_3db_hz", "f_minus90_hz", "peak_db", "f_peak_hz", "limits"}
    # at 20 deg the 800 deg/s rate limit binds near the bandwidth: reported with its limit
    assert "sat1" in data["amplitudes"][1]["limits"]


def test_the_api_result():
    res = api.freqresp(amplitudes_deg=[1.0], f_min_hz=1.0, f_max_hz=10.0, n=4)
    assert len(res.to_pandas()) == 4 and len(res.metrics) == 1
    gain = res.to_pandas()["gain_db"].to_numpy()
    assert np.all(np.abs(gain - res.to_pandas()["linear_gain_db"].to_numpy()) < 0.1)
    assert res.plot().axes


@pytest.mark.parametrize(("args", "needle"), [
    (["--amplitudes", "0,1"], "--amplitudes must be > 0"),
    (["--amplitudes", "a,b"], "--amplitudes expects numbers"),
    (["--f-min", "nan"], "--f-min must be a finite number"),
    (["--f-min", "50", "--f-max", "5"], "must be below --f-max"),
    (["--n", "1"], "--n must be >= 2"),
    (["--n", "100000"], "--n must be <= 2000"),
])
def test_bad_options(tmp_path, args, needle):
    r = runner.invoke(app, ["freqresp", *args, "--out", str(tmp_path / "x")])
    assert r.exit_code == 2 and needle in r.output, r.output
    assert not (tmp_path / "x").exists()
