"""`ema sensitivity` end to end on a small study: the files and their content, each sample's
metrics against a direct simulation of its factor values, resuming an interrupted Sobol run
without recomputing finished samples, the Python API, and bad input on the command line."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

from ema_cli import api
from ema_cli.api.sensitivity import run_sensitivity
from ema_cli.cli.main import app
from ema_cli.config.loader import load_config
from ema_cli.config.sensitivity import SensitivityConfig
from ema_cli.sensitivity.analyze import indices

runner = CliRunner()

STUDY = {
    "name": "small",
    "inputs": [{"name": "s01", "kind": "step", "amplitude_deg": 0.1},
               {"name": "s5", "kind": "step", "amplitude_deg": 5.0}],
    "simulation": {"duration_s": 0.1, "dt_s": 1.0e-5, "output_interval_s": None},
    "factors": [{"nonlinearity": "deadzone1", "range": [0.01, 1.0], "scale": "log"},
                {"nonlinearity": "gap1", "range": [0.3, 10.0], "scale": "log"},
                {"name": "kpp", "parameter": "Kpp", "range": [40.0, 60.0]}],
    "metrics": ["iae_pos_deg_s", "p2p_err_pos_deg"],
    "sensitivity": {"n_sobol": 16, "n_morris": 4, "num_resamples": 50},
    "parallel": {"n_jobs": 1, "chunk_size": 16},
}


def write_study(tmp_path, **changes):
    import yaml

    path = tmp_path / "study.yaml"
    path.write_text(yaml.safe_dump({**STUDY, **changes}), encoding="utf-8")
    return path


def test_sobol_writes_everything(tmp_path):
    cfg_path = write_study(tmp_path)
    out = tmp_path / "out"
    r = runner.invoke(app, ["sensitivity", str(cfg_path), "--out", str(out), "--no-progress"])
    assert r.exit_code == 0, r.output
    names = {p.name for p in out.iterdir()}
    assert {"config.resolved.yaml", "indices.csv", "convergence.csv", "samples.parquet",
            "indices_s01.png", "indices_s5.png", "convergence_s01.png", "convergence_s5.png",
            "summary.md", "manifest.json"} <= names
    ix = pd.read_csv(out / "indices.csv")
    assert list(ix.columns[:4]) == ["input", "metric", "transform", "factor"]
    assert {"S1", "S1_conf", "ST", "ST_conf", "mu_star", "sigma"} <= set(ix.columns)
    assert len(ix) == 2 * 2 * 3  # inputs x metrics x factors
    samples = pd.read_parquet(out / "samples.parquet")
    assert len(samples) == 2 * 16 * (3 + 2)
    assert set(samples["status"]) == {"ok"}
    # the indices are the analysis of the sample values the folder holds (same code path)
    cfg = load_config(cfg_path, (), SensitivityConfig)
    from ema_cli.sensitivity.run import factor_ranges
    from ema_cli.sensitivity.sampling import sample

    design = sample(factor_ranges(cfg), "sobol", 16, cfg.seed)
    np.testing.assert_allclose(samples[samples["input"] == "s01"][["deadzone1", "gap1", "kpp"]],
                               design.values)
    y = samples[samples["input"] == "s5"]["iae_pos_deg_s"].to_numpy()
    want = indices(design, y, 0.95, 50, cfg.seed)
    got = ix[(ix["input"] == "s5") & (ix["metric"] == "iae_pos_deg_s")]
    np.testing.assert_allclose(got[["S1", "ST", "ST_conf"]].to_numpy(),
                               want[["S1", "ST", "ST_conf"]].to_numpy(), rtol=1e-8)
    man = json.loads((out / "manifest.json").read_text())
    assert man["status"] == "complete" and man["runs_total"] == 160
    assert man["computed"] == 160 and man["method"] == "sobol" and man["n"] == 16
    assert "gap1" in (out / "summary.md").read_text()
    # a finished study is never rewritten: the same inputs keep it, others are refused
    before = {p: p.stat().st_mtime_ns for p in out.iterdir() if p.is_file()}
    r = runner.invoke(app, ["sensitivity", str(cfg_path), "--out", str(out), "--no-progress"])
    assert r.exit_code == 0, r.output
    assert {p: p.stat().st_mtime_ns for p in out.iterdir() if p.is_file()} == before
    r = runner.invoke(app, ["sensitivity", str(cfg_path), "--out", str(out), "--no-progress",
                            "--n", "8"])
    assert r.exit_code == 2 and "finished `ema sensitivity` run of other inputs" in r.output


def test_each_sample_is_the_simulation_of_its_factor_values(tmp_path):
    """Rows of samples.parquet against `api.simulate` with the same magnitudes (brute force)."""
    res = api.sensitivity(write_study(tmp_path), method="morris")
    s = res.metrics
    assert len(s) == 2 * 4 * (3 + 1)
    for k in (0, 5, 13):
        row = s[s["input"] == "s5"].iloc[k]
        run = api.simulate({"input": {"kind": "step", "amplitude_deg": 5.0},
                            "simulation": STUDY["simulation"]},
                           {"plant.Kpp": float(row["kpp"])},
                           nl={"deadzone1": float(row["deadzone1"]),
                               "gap1": float(row["gap1"])})
        for m in ("iae_pos_deg_s", "p2p_err_pos_deg"):
            assert float(run.metrics[m].iloc[0]) == pytest.approx(float(row[m]), rel=1e-12)
    ix = res.indices
    assert ix["S1"].isna().all() and (ix["mu_star"] >= 0).all()
    assert res.ranking("s5", "iae_pos_deg_s")[0] in ("gap1", "kpp", "deadzone1")
    long = res.to_pandas("long")
    assert set(long["quantity"]) == {"mu", "mu_star", "mu_star_conf", "sigma"}
    assert len(res.plot("convergence")) == 2 and res.plot()[0].axes
    folder = res.save(tmp_path / "saved")
    assert (folder / "indices.csv").is_file() and (folder / "summary.md").is_file()


def test_an_interrupted_sobol_run_resumes_without_recomputing(tmp_path, monkeypatch):
    import ema_cli.sweep.execute as execute

    cfg = load_config(write_study(tmp_path), (), SensitivityConfig)
    out = tmp_path / "out"  # outside results/: the job cache is out/.cache
    evaluated: list[int] = []
    real_run_chunk = execute.run_chunk

    def counting(P, *args, **kwargs):
        evaluated.append(len(P))
        if len(evaluated) == 3 and interrupt:
            raise KeyboardInterrupt  # Ctrl-C during the third kernel call
        return real_run_chunk(P, *args, **kwargs)

    monkeypatch.setattr(execute, "run_chunk", counting)
    interrupt = True
    with pytest.raises(KeyboardInterrupt):
        run_sensitivity(cfg, out, progress=False)
    man = json.loads((out / "manifest.json").read_text())
    assert man["status"] == "interrupted"
    finished = sum(evaluated[:2])  # two chunks of 16 finished and were cached
    assert finished == 32
    evaluated.clear()
    interrupt = False
    res = run_sensitivity(cfg, out, progress=False)
    assert res.cached == finished and res.computed == 160 - finished
    assert sum(evaluated) == 160 - finished  # only the unfinished samples ran
    assert json.loads((out / "manifest.json").read_text())["status"] == "complete"
    # the same indices as an uninterrupted run of the same study
    fresh = run_sensitivity(cfg, None, write=False, progress=False)
    pd.testing.assert_frame_equal(res.indices, fresh.indices)


@pytest.mark.parametrize(("args", "needle"), [
    (["--n", "100"], "--n must be a power of two for Sobol sampling"),
    (["--method", "fast"], "--method must be morris or sobol"),
    (["--n", "0"], "--n must be >= 1"),
    (["--set", "factors.0.nonlinearity=deadzone7"], "factors.0.nonlinearity: unknown "
                                                    "nonlinearity 'deadzone7'"),
    (["--set", "factors.1.range=[5,1]"], "factors.1.range: inverted range [5, 1]"),
])
def test_bad_input_is_one_line(tmp_path, args, needle):
    out = tmp_path / "x"
    r = runner.invoke(app, ["sensitivity", str(write_study(tmp_path)), *args, "--out", str(out),
                            "--no-progress"])
    assert r.exit_code == 2, r.output
    assert needle in r.output and "Traceback" not in r.output, r.output
    assert not out.exists()


def test_a_finished_study_is_kept_by_a_resumed_reproduction(tmp_path):
    """``reuse_finished`` (what `ema reproduce` passes): a finished folder of the same study is
    not rewritten; its indices come back from the job cache, nothing is recomputed."""
    cfg = load_config(write_study(tmp_path), (), SensitivityConfig)
    out = tmp_path / "out"
    first = run_sensitivity(cfg, out, progress=False)
    stamp = (out / "indices.csv").stat().st_mtime_ns
    again = run_sensitivity(cfg, out, progress=False, reuse_finished=True)
    assert again.computed == 0 and again.cached == 160 and again.folder == out
    assert (out / "indices.csv").stat().st_mtime_ns == stamp
    pd.testing.assert_frame_equal(again.indices, first.indices)


def test_validate_knows_a_sensitivity_config():
    from pathlib import Path

    cfg = Path(__file__).resolve().parents[2] / "configs" / "sensitivity.yaml"
    r = runner.invoke(app, ["validate", str(cfg)])
    assert r.exit_code == 0, r.output
    text = " ".join(r.output.split())
    assert "valid sensitivity study; 10 factors, 2 input(s), sobol n = 4096 -> 98,304 runs" in text
