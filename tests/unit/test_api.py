"""The Python API in a notebook-style session: simulate, sweep a small grid, identify, find a
threshold, plot, save; every result checked against an independent path (the runner called
directly, the files written, the command line)."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest
from matplotlib.figure import Figure

from ema_cli import api
from ema_cli.errors import EmaError
from ema_cli.model.params import resolve
from ema_cli.sim.runner import simulate as runner_simulate
from ema_cli.sim.signals import InputSignal
from ema_cli.sim.tables import PAPER_SIGNALS, SIGNALS
from ema_cli.units import DEG

SHORT = {"simulation": {"duration_s": 0.2}}


@pytest.fixture(autouse=True)
def _in_tmp(tmp_path, monkeypatch):
    """Run every test in an empty folder: nothing may appear there unless saved."""
    monkeypatch.chdir(tmp_path)


def test_simulate_matches_the_runner_and_labels_its_values(tmp_path):
    run = api.simulate(SHORT, {"plant.kL": 600.0}, nl={"deadzone2": 0.01}, step_deg=5.0)
    # the same run through the runner, parameters built by hand
    p = resolve({"kL": 600.0})
    p["alpha"] = 0.01 * DEG
    ref = runner_simulate(p, InputSignal(amplitude=5 * DEG), 0.2)
    assert run.params["kL"] == 600.0
    assert run.params["alpha"] == pytest.approx(0.01 * DEG, rel=1e-15)
    np.testing.assert_array_equal(run.batch.metrics, ref.metrics)
    k = [c.name for c in SIGNALS].index("theta_load")
    np.testing.assert_allclose(run.signal("theta_load_deg"), ref.signals[0, :, k] / DEG,
                               rtol=1e-15)
    np.testing.assert_array_equal(run.signal("theta_load"), run.signal("theta_load_deg"))
    assert run.t[-1] == pytest.approx(0.2) and len(run.t) == 2001
    # edge units: the 5 deg step reads 5 (deg), its rate 0 (deg/s)
    assert run.signal("theta_ref_deg")[-1] == pytest.approx(5.0, rel=1e-12)
    m = run.metrics
    assert isinstance(m, pd.DataFrame) and len(m) == 1
    assert m["overshoot_pct"].iloc[0] == pytest.approx(run.summary["overshoot_pct"])
    with pytest.raises(EmaError, match="unknown signal 'nope'"):
        run.signal("nope")


def test_simulate_tables_in_both_forms():
    run = api.simulate(SHORT)
    wide = run.to_pandas()
    assert list(wide.columns) == ["t_s", *[c.edge for c in SIGNALS[:PAPER_SIGNALS]]]
    long = run.to_pandas("long")
    assert list(long.columns) == ["t_s", "signal", "unit", "value"]
    assert len(long) == len(wide) * PAPER_SIGNALS
    sel = long[long["signal"] == "theta_load_deg"]
    assert set(sel["unit"]) == {"deg"}
    np.testing.assert_array_equal(sel["value"].to_numpy(), wide["theta_load_deg"].to_numpy())
    assert set(long[long["signal"] == "current_a"]["unit"]) == {"A"}


def test_simulate_plot_and_save(tmp_path):
    run = api.simulate(SHORT, step_deg=2.0)
    fig = run.plot()
    assert isinstance(fig, Figure)
    labels = {ax.get_ylabel() for ax in fig.axes} | {ax.get_xlabel() for ax in fig.axes}
    assert {"position [deg]", "velocity [deg/s]", "time [s]"} <= labels
    assert "2 deg step" in fig._suptitle.get_text()
    folder = run.save(tmp_path / "one")
    assert {"timeseries.csv", "metrics.csv", "tracking.png", "manifest.json",
            "config.resolved.yaml"} <= {p.name for p in folder.iterdir()}
    back = pd.read_csv(folder / "metrics.csv")
    for col in ("overshoot_pct", "iae_pos_deg_s", "peak_current_a"):
        assert back[col].iloc[0] == pytest.approx(run.summary[col], rel=1e-8)
    ts = pd.read_csv(folder / "timeseries.csv")
    np.testing.assert_allclose(ts["theta_load_deg"], run.signal("theta_load_deg"),
                               rtol=1e-8, atol=1e-12)
    assert run.save(folder) == folder  # the same run: kept as it is
    with pytest.raises(EmaError, match="other inputs.*never overwritten"):
        api.simulate(SHORT, step_deg=3.0).save(folder)


def test_config_sources_are_equivalent(tmp_path):
    text = "input:\n  kind: step\n  amplitude_deg: 3\nsimulation:\n  duration_s: 0.1\n"
    (tmp_path / "c.yaml").write_text(text)
    a = api.simulate(tmp_path / "c.yaml", {"plant.kL": 550})
    b = api.simulate({"input": {"kind": "step", "amplitude_deg": 3},
                      "simulation": {"duration_s": 0.1}}, [("kL", 550)])
    c = api.simulate(b.config)
    np.testing.assert_array_equal(a.batch.metrics, b.batch.metrics)
    np.testing.assert_array_equal(a.batch.metrics, c.batch.metrics)
    with pytest.raises(EmaError, match="plant.nope"):
        api.simulate(overrides={"plant.nope": 1})
    with pytest.raises(EmaError, match="simulation.dt_s"):
        api.simulate(overrides={"simulation.dt_s": math.nan})


def test_sweep_a_small_grid(tmp_path):
    cfg = {"name": "api-grid", **SHORT, "input": {"kind": "step", "amplitude_deg": 1.0},
           "sweep": {"axes": [{"nonlinearity": "deadzone2", "values": [0.01, 0.1]}],
                     "baseline": True},
           "outputs": {"figures": ["metrics"]}}
    sw = api.sweep(cfg, n_jobs=1)
    assert not any(tmp_path.iterdir()), "a sweep that is not saved writes nothing"
    m = sw.metrics
    assert len(m) == 3 and set(m["status"]) == {"ok"}
    # each job equals a single simulation of the same configuration
    one = api.simulate({**SHORT, "input": {"kind": "step", "amplitude_deg": 1.0}},
                       nl={"deadzone2": 0.1})
    row = m[m["label"].str.contains("0.1")].iloc[0]
    assert row["iae_pos_deg_s"] == pytest.approx(one.summary["iae_pos_deg_s"], rel=1e-12)
    job = row["job"]
    np.testing.assert_allclose(sw.signal("theta_load_deg", job), one.signal("theta_load_deg"),
                               rtol=1e-12)
    long = sw.to_pandas("long")
    assert {"job", "t_s", "signal", "value"} <= set(long.columns)
    assert long["job"].nunique() == 3
    figs = sw.plot("metrics")
    assert figs and all(isinstance(f, Figure) for f in figs)
    folder = sw.save(tmp_path / "grid")
    back = pd.read_csv(folder / "metrics.csv")
    assert len(back) == 3
    assert back["iae_pos_deg_s"].to_numpy() == pytest.approx(m["iae_pos_deg_s"].to_numpy(),
                                                             rel=1e-8)


def test_identify_exact_recovers_the_truth(tmp_path):
    ident = api.identify(method="exact")
    truth = ident.result.data.truth
    for name, value in ident.parameters.items():
        assert value == pytest.approx(truth[name], rel=1e-6), name
    m = ident.metrics
    assert set(m["parameter"]) == set(ident.parameters)
    fit = ident.to_pandas()
    # the fitted model reproduces the noise-free torque data
    np.testing.assert_allclose(fit["torque_model_nm"], fit["torque_nm"], atol=1e-6)
    assert isinstance(ident.plot(), Figure)
    folder = ident.save(tmp_path / "ident")
    assert (folder / "identification.json").is_file()
    with pytest.raises(EmaError, match="ga.pop"):
        api.identify(overrides={"ga.pop": -5})


def test_threshold_brackets_the_limit(tmp_path):
    cfg = {**SHORT, "input": {"kind": "step", "amplitude_deg": 1.0}}
    th = api.threshold(cfg, "deadzone2", (1e-3, 0.5), metric="ss_err_pos_deg", limit=0.02,
                       rtol=0.05)
    assert th.result.status == "found"
    lo, hi = th.result.bracket
    assert lo <= th.value <= hi and (hi - lo) / hi <= 0.05
    # independent check: one simulation on each side of the bracket
    below = api.simulate(cfg, nl={"deadzone2": lo}).summary["ss_err_pos_deg"]
    above = api.simulate(cfg, nl={"deadzone2": hi}).summary["ss_err_pos_deg"]
    assert below <= 0.02 < above
    assert isinstance(th.plot(), Figure)
    assert (th.save(tmp_path / "th") / "threshold.json").is_file()
    with pytest.raises(EmaError, match=r"^range \(LO, HI\) must have LO < HI"):
        api.threshold(cfg, "deadzone2", (0.5, 0.1), metric="ss_err_pos_deg", limit=0.02)
