"""`ema margins` and `api.margins`: the files, their numbers against analysis.linear and
python-control, and the --out policy."""

from __future__ import annotations

import json

import control
import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

from ema_cli import api
from ema_cli.analysis.linear import linear_model
from ema_cli.cli.main import app

runner = CliRunner()


def test_margins_command_writes_everything(tmp_path):
    out = tmp_path / "m"
    r = runner.invoke(app, ["margins", "--set", "plant.Kpp=70", "--out", str(out)])
    assert r.exit_code == 0, r.output
    data = json.loads((out / "margins.json").read_text())
    res = api.margins(overrides={"plant.Kpp": 70})
    lm = linear_model(res.params, "position")
    gm, pm, _, _ = control.margin(-control.ss(lm.A, lm.B, lm.C, lm.D))
    assert data["position"]["gm_db"] == pytest.approx(20 * np.log10(gm), abs=1e-6)
    assert data["position"]["pm_deg"] == pytest.approx(pm, abs=1e-6)
    assert set(data["speed"]) == {"gm_db", "pm_deg", "f_gm_hz", "f_pm_hz"}
    loops = pd.read_csv(out / "loops.csv")
    assert {"f_hz", "position_gain_db", "speed_phase_deg"} <= set(loops.columns)
    assert (out / "margins.png").stat().st_size > 10_000
    r = runner.invoke(app, ["margins", "--out", str(out)])
    assert r.exit_code == 2 and "never overwritten" in r.output


def test_more_gain_less_margin():
    lo = api.margins(overrides={"plant.Kpp": 30}).result["position"]
    hi = api.margins(overrides={"plant.Kpp": 90}).result["position"]
    assert hi.gm_db < lo.gm_db and hi.f_pm_hz > lo.f_pm_hz


def test_margins_tables_and_plot():
    res = api.margins()
    assert list(res.metrics["loop"]) == ["position", "speed"]
    long = res.to_pandas("long")
    assert set(long["loop"]) == {"position", "speed"} and len(long) == 2 * len(res.f_hz)
    fig = res.plot()
    assert any("Nichols" in ax.get_title() for ax in fig.axes)
