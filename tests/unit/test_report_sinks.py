"""report/ is a sink: every writer takes computed results and a folder and never simulates.

Each result is computed once (small cases, the kernel working), then the kernel entry
(``sim.runner.entry_point``, through which every batched simulation runs) is patched to raise,
and every writer and figure of the sweep, sensitivity, reproduce, simulate and threshold
routes runs on the saved results: they must finish and write the numbers they were given.
"""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest
from matplotlib.figure import Figure

from ema_cli import api
from ema_cli.sim import runner

SHORT = {"simulation": {"duration_s": 0.05}}
STEP = {"kind": "step", "amplitude_deg": 1.0}

STUDY = """name: tiny
input: {kind: step, amplitude_deg: 0.1}
simulation: {duration_s: 0.1}
sweep:
  axes:
    - nonlinearity: deadzone2
      values: [0.001, 0.1]
"""

EXPERIMENT = """name: tinybatch
studies:
  - id: figA
    config: tiny.yaml
    figure: figA.png
    caption: "Figure A: dead band"
claims:
  - id: osc
    paper: p
    statement: oscillation at 0.1 deg
    check: {kind: value, study: figA, where: {deadzone2_deg: 0.1}, metric: p2p_err_pos_deg,
            op: ">", value: 0.0}
"""

SENSITIVITY = {
    "name": "small",
    "inputs": [{"name": "s01", "kind": "step", "amplitude_deg": 0.1}],
    "simulation": {"duration_s": 0.05, "dt_s": 1.0e-5, "output_interval_s": None},
    "factors": [{"nonlinearity": "deadzone1", "range": [0.01, 1.0], "scale": "log"},
                {"name": "kpp", "parameter": "Kpp", "range": [40.0, 60.0]}],
    "metrics": ["iae_pos_deg_s"],
    "sensitivity": {"method": "morris", "n_morris": 2},
    "parallel": {"n_jobs": 1},
}


class KernelCalled(AssertionError):
    """Raised by the patched kernel entry: a writer tried to simulate."""


def _refuse(*args, **kwargs):
    raise KernelCalled("a report writer called the simulation kernel")


@pytest.fixture(scope="module")
def results(tmp_path_factory):
    """Every result, computed once with the working kernel."""
    tmp = tmp_path_factory.mktemp("computed")
    (tmp / "tiny.yaml").write_text(STUDY)
    (tmp / "exp.yaml").write_text(EXPERIMENT)
    return {
        "simulate": api.simulate({**SHORT, "input": STEP}),
        "sweep": api.sweep({"name": "sink", **SHORT, "input": STEP,
                            "sweep": {"axes": [{"nonlinearity": "deadzone2",
                                                "values": [0.01, 0.1]}], "baseline": True},
                            "outputs": {"figures": ["metrics", "errors", "response"],
                                        "per_job_csv": True}}, n_jobs=1),
        "sensitivity": api.sensitivity(SENSITIVITY),
        "threshold": api.threshold({**SHORT, "input": STEP}, "deadzone2", (1e-3, 0.5),
                                   metric="ss_err_pos_deg", limit=0.02, rtol=0.2),
        "reproduce": api.reproduce(tmp / "exp.yaml", out=tmp / "run", n_jobs=1),
    }


@pytest.fixture
def no_kernel(monkeypatch):
    monkeypatch.setattr(runner, "entry_point", _refuse)


@pytest.fixture(scope="module")
def saved(results, tmp_path_factory):
    """Every result plotted and saved once with the kernel entry raising -> (figures, path)."""
    out = tmp_path_factory.mktemp("saved")
    done = {}
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(runner, "entry_point", _refuse)
        for name, res in results.items():
            figs = res.plot()
            done[name] = (figs if isinstance(figs, list) else [figs], res.save(out / name))
    return done


def test_the_patch_stops_a_simulation(no_kernel):
    with pytest.raises(KernelCalled):
        api.simulate({**SHORT, "input": STEP})


@pytest.mark.parametrize("name", ["simulate", "sweep", "sensitivity", "threshold", "reproduce"])
def test_save_and_plot_never_simulate(saved, name):
    figs, path = saved[name]
    assert figs and all(isinstance(f, Figure) for f in figs)
    folder = path if path.is_dir() else path.parent
    assert any(folder.iterdir())


def test_sweep_folder_holds_the_computed_numbers(results, saved):
    sw, (_, folder) = results["sweep"], saved["sweep"]
    back = pd.read_csv(folder / "metrics.csv")
    # metrics.csv is written with %.9g: 9 significant digits, rel 5e-9
    np.testing.assert_allclose(back["iae_pos_deg_s"], sw.metrics["iae_pos_deg_s"], rtol=5e-9)
    signals = pd.read_parquet(folder / "signals.parquet")
    first = signals[signals["job"] == sw.jobs[0]]["theta_load_deg"].to_numpy()
    np.testing.assert_array_equal(first, sw.signal("theta_load_deg", 0))  # float64, exact
    assert len(list((folder / "timeseries").glob("*.csv"))) == 3
    kinds = {p.name.split("_")[0] for p in (folder / "figures").glob("*.png")}
    assert kinds == {"metrics", "errors", "response"}
    man = json.loads((folder / "manifest.json").read_text())
    assert man["status"] == "complete" and man["job_counts"]["total"] == 3


def test_sensitivity_folder_holds_the_computed_indices(results, saved):
    sens, (_, folder) = results["sensitivity"], saved["sensitivity"]
    back = pd.read_csv(folder / "indices.csv")
    np.testing.assert_allclose(back["mu_star"], sens.indices["mu_star"], rtol=5e-9)


def test_reproduction_report_from_the_computed_claims(results, saved):
    rep, (_, report) = results["reproduce"], saved["reproduce"]
    assert rep.passed and list(rep.metrics["id"]) == ["osc"]
    assert report.name == "REPORT.md" and "osc" in report.read_text()
    claims = pd.read_csv(report.parent / "claims.csv")
    assert list(claims["id"]) == ["osc"] and list(claims["result"]) == ["PASS"]
