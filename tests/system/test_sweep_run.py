"""Whole sweeps: equal to `ema simulate`, bit-identical across backends, resumable (also when
the signals were not cached), on Dask."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import yaml
from typer.testing import CliRunner

import ema_cli.sweep.cache as job_cache
import ema_cli.sweep.execute as execute
from ema_cli.api.study import run_sweep
from ema_cli.cli.main import app
from ema_cli.config.loader import load_config
from ema_cli.config.study import StudyConfig
from ema_cli.sim.runner import simulate
from ema_cli.sim.tables import METRICS, PAPER_SIGNALS
from ema_cli.sweep.cache import JobCache
from ema_cli.sweep.execute import WARM_STEPS

runner = CliRunner()
METRIC_COLS = [c.edge for c in METRICS]
DURATION = 0.1  # [s]: short runs keep the suite fast; 10,000 steps of 1e-5 s each
REAL_KERNEL_CALL = execute.simulate_batch


def write_config(tmp_path: Path, **changes) -> Path:
    """A 0.1 deg step study over the transmission dead band (3 values + the baseline)."""
    data = {
        "name": "t",
        "input": {"kind": "step", "amplitude_deg": 0.1},
        "simulation": {"duration_s": DURATION, "dt_s": 1e-5, "output_interval_s": 1e-3},
        "sweep": {"axes": [{"nonlinearity": "deadzone2", "values": [0.001, 0.01, 0.1]}]},
        "outputs": {"timeseries": True, "figures": []},
    }
    for key, value in changes.items():
        data[key] = value
    path = tmp_path / "study.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def sweep(tmp_path: Path, out: str, cfg_path: Path | None = None, **kw):
    cfg_path = cfg_path or write_config(tmp_path)
    kw.setdefault("cache_dir", tmp_path / "cache")
    return run_sweep(load_config(cfg_path, (), StudyConfig), tmp_path / out, progress=False, **kw)


def test_sweep_metrics_equal_ema_simulate(tmp_path):
    cfg_path = write_config(tmp_path)
    res = sweep(tmp_path, "sweep", cfg_path, n_jobs=1)
    table = pd.read_csv(tmp_path / "sweep" / "metrics.csv")
    assert list(table["label"]) == ["baseline", "deadzone2 = 0.001 deg", "deadzone2 = 0.01 deg",
                                    "deadzone2 = 0.1 deg"]
    for i, nl in enumerate([None, "0.001", "0.01", "0.1"]):
        out = tmp_path / f"sim{i}"
        args = ["simulate", str(cfg_path), "--out", str(out)]
        if nl is not None:
            args += ["--nl", f"deadzone2={nl}"]
        r = runner.invoke(app, args)
        assert r.exit_code == 0, r.output
        sim = pd.read_csv(out / "metrics.csv")
        # both CSVs are written with %.9g: the same runs give the same text, hence equal floats
        np.testing.assert_array_equal(table.loc[i, METRIC_COLS].to_numpy(float),
                                      sim.loc[0, METRIC_COLS].to_numpy(float))
        ts_sim = pd.read_csv(out / "timeseries.csv")
        ts_sweep = pd.read_parquet(tmp_path / "sweep" / "signals.parquet",
                                   filters=[("job", "==", res.jobs[i].id)])
        assert list(ts_sweep.columns) == ["job", "deadzone2_deg", *ts_sim.columns]
        assert len(ts_sweep) == 101  # 0.1 s every 1e-3 s (the config's), both ends
        # the CSV has 9 significant digits, the parquet file every bit
        np.testing.assert_allclose(ts_sweep[ts_sim.columns].to_numpy(), ts_sim.to_numpy(),
                                   rtol=1e-8, atol=0)
        # and bit for bit, against the library's one-run simulate
        one = simulate(res.jobs[i].params, res.plan.signal, DURATION, 1e-5, 1e-3)
        np.testing.assert_array_equal(res.metrics.loc[i, METRIC_COLS].to_numpy(float),
                                      one.metrics_frame().loc[0, METRIC_COLS].to_numpy(float))
        np.testing.assert_array_equal(ts_sweep[ts_sim.columns].to_numpy(),
                                      one.signals_frame().to_numpy())


def test_parallel_backends_equal_serial_bit_for_bit(tmp_path):
    ref = sweep(tmp_path, "serial", n_jobs=1, cache_dir=tmp_path / "c0")
    assert ref.backend == "serial" and ref.computed == 4
    for backend in ("threads", "loky"):
        res = sweep(tmp_path, backend, n_jobs=2, backend=backend,
                    cache_dir=tmp_path / f"cache-{backend}")
        assert res.backend == backend and res.workers == 2 and res.computed == 4
        np.testing.assert_array_equal(res.metrics[METRIC_COLS].to_numpy(float),
                                      ref.metrics[METRIC_COLS].to_numpy(float))
        for i in range(4):  # the stored values (edge units), bit for bit
            np.testing.assert_array_equal(res.timeseries(i).to_numpy(),
                                          ref.timeseries(i).to_numpy())


class CountingKernel:
    """Wraps the kernel call of the executor: counts the runs, fails on the chosen call."""

    def __init__(self, fail_on: int | None = None, exc: BaseException | None = None) -> None:
        self.real = REAL_KERNEL_CALL
        self.rows: list[np.ndarray] = []
        self.fail_on, self.exc, self.calls = fail_on, exc, 0

    def __call__(self, P, refs, ref_index, dt, n_steps, *args, **kw):
        if n_steps != WARM_STEPS:
            self.calls += 1
            if self.calls == self.fail_on:
                raise self.exc
            self.rows.extend(np.array(P))
        return self.real(P, refs, ref_index, dt, n_steps, *args, **kw)


def test_interrupted_sweep_resumes_without_recomputing_or_duplicating(tmp_path, monkeypatch):
    cfg_path = write_config(tmp_path)
    first = CountingKernel(fail_on=3, exc=KeyboardInterrupt())
    monkeypatch.setattr(execute, "simulate_batch", first)
    with pytest.raises(KeyboardInterrupt):  # Ctrl-C during the third chunk of one job each
        sweep(tmp_path, "run", cfg_path, n_jobs=1, backend="threads",
              cache_dir=tmp_path / "cache")
    assert len(first.rows) == 2
    partial = pd.read_csv(tmp_path / "run" / "metrics.csv")
    assert list(partial["status"]) == ["ok", "ok", "pending", "pending"]
    assert json.loads((tmp_path / "run" / "manifest.json").read_text())["status"] == "interrupted"
    # no signals file (nor its temporary sibling) for an interrupted sweep
    assert not (tmp_path / "run" / "signals.parquet").exists()
    assert not list((tmp_path / "run").glob(".*.tmp"))

    again = CountingKernel()
    monkeypatch.setattr(execute, "simulate_batch", again)
    res = sweep(tmp_path, "run", cfg_path, n_jobs=1)  # the same --out: resumed in place
    assert res.cached == 2 and res.computed == 2 and len(again.rows) == 2
    done_first = {r.tobytes() for r in first.rows}
    assert not any(r.tobytes() in done_first for r in again.rows)  # nothing computed twice
    table = pd.read_csv(tmp_path / "run" / "metrics.csv")
    assert len(table) == 4 and table["job"].is_unique and (table["status"] == "ok").all()
    sweep(tmp_path, "clean", cfg_path, n_jobs=1, cache_dir=tmp_path / "fresh")
    np.testing.assert_array_equal(table[METRIC_COLS].to_numpy(float),
                                  pd.read_csv(tmp_path / "clean" / "metrics.csv")[METRIC_COLS]
                                  .to_numpy(float))
    man = json.loads((tmp_path / "run" / "manifest.json").read_text())
    assert man["status"] == "complete" and man["job_counts"]["cached"] == 2
    signals = pd.read_parquet(tmp_path / "run" / "signals.parquet")
    assert sorted(signals["job"].unique()) == list(table["job"]) and len(signals) == 4 * 101

    # --force recomputes everything (into a new folder: the finished one is never rewritten);
    # a different sweep may not reuse the folder
    forced = CountingKernel()
    monkeypatch.setattr(execute, "simulate_batch", forced)
    res = sweep(tmp_path, "run2", cfg_path, n_jobs=1, force=True, cache_dir=tmp_path / "cache")
    assert res.computed == 4 and len(forced.rows) == 4
    other = write_config(tmp_path, name="other")
    r = runner.invoke(app, ["sweep", str(other), "--out", str(tmp_path / "run"),
                            "--cache-dir", str(tmp_path / "cache"), "--no-progress"])
    assert r.exit_code == 2 and "already holds a finished `ema sweep` run" in " ".join(
        r.output.split())


def test_exception_in_a_chunk_fails_its_jobs_only_and_a_rerun_finishes(tmp_path, monkeypatch):
    cfg_path = write_config(tmp_path)
    monkeypatch.setattr(execute, "simulate_batch",
                        CountingKernel(fail_on=2, exc=RuntimeError("disk on fire")))
    r = runner.invoke(app, ["sweep", str(cfg_path), "--n-jobs", "1", "--out",
                            str(tmp_path / "run"), "--cache-dir", str(tmp_path / "cache"),
                            "--no-progress"])
    assert r.exit_code == 1, r.output
    assert "1 job(s) failed" in r.output and "Traceback" not in r.output
    man = json.loads((tmp_path / "run" / "manifest.json").read_text())
    failed = [j for j in man["jobs"] if j["status"] == "failed"]
    assert len(failed) == 1 and "RuntimeError: disk on fire" in failed[0]["error"]
    assert man["job_counts"]["ok"] == 3 and man["status"] == "incomplete"
    assert man["job_counts"]["computed"] == 3  # the failed chunk is not counted as computed

    again = CountingKernel()
    monkeypatch.setattr(execute, "simulate_batch", again)
    res = sweep(tmp_path, "run", cfg_path, n_jobs=1)
    assert res.computed == 1 and len(again.rows) == 1 and res.counts()["ok"] == 4


@pytest.mark.parametrize("processes", [False, True])
def test_dask_backend_on_a_local_cluster_equals_local(tmp_path, processes):
    distributed = pytest.importorskip("dask.distributed")
    ref = sweep(tmp_path, "local", n_jobs=1, cache_dir=tmp_path / "c0")
    with distributed.LocalCluster(n_workers=1, threads_per_worker=2, processes=processes,
                                  protocol="tcp", host="127.0.0.1",  # loopback only
                                  dashboard_address=None) as cluster:
        res = sweep(tmp_path, "dask", backend="dask", scheduler=cluster.scheduler_address,
                    cache_dir=tmp_path / "c1", chunk_size=1)
    assert res.backend == "dask" and res.computed == 4 and res.counts()["ok"] == 4
    np.testing.assert_array_equal(res.metrics[METRIC_COLS].to_numpy(float),
                                  ref.metrics[METRIC_COLS].to_numpy(float))
    for i in range(4):
        np.testing.assert_array_equal(res.timeseries(i).to_numpy(), ref.timeseries(i).to_numpy())


def signal_rows(cache: Path, res) -> dict[str, bool]:
    """Which jobs of ``res`` have signals (at its decimation) in ``cache``."""
    rows = JobCache(cache).signal_rows([j.key for j in res.jobs], res.plan.dec)
    return {j.id: j.key in rows for j in res.jobs}


def test_a_rerun_recomputes_exactly_the_jobs_whose_signals_were_not_cached(tmp_path,
                                                                           monkeypatch):
    full = write_config(tmp_path)
    (tmp_path / "p").mkdir()
    part = write_config(tmp_path / "p", sweep={"axes": [{"nonlinearity": "deadzone2",
                                                         "values": [0.001]}]})
    cache = tmp_path / "cache"
    # 1. two jobs (baseline, 0.001) with their signals cached
    monkeypatch.setattr(job_cache, "SIGNALS_MAX_SHARE", float("inf"))
    first = sweep(tmp_path, "part", part, n_jobs=1, cache_dir=cache)
    assert first.signals_cached and all(signal_rows(cache, first).values())
    # 2. the full sweep with signals not cached: 2 from the cache, 2 computed (metrics stored)
    monkeypatch.setattr(job_cache, "SIGNALS_MAX_SHARE", 0.0)
    second = sweep(tmp_path, "full", full, n_jobs=1, cache_dir=cache)
    assert (second.cached, second.computed) == (2, 2) and not second.signals_cached
    assert signal_rows(cache, second) == {"j0000": True, "j0001": True, "j0002": False,
                                          "j0003": False}
    assert sorted(JobCache(cache).lookup([j.key for j in second.jobs])) == sorted(
        j.key for j in second.jobs)  # every job's metrics (and their checksums) are cached
    man = json.loads((tmp_path / "full" / "manifest.json").read_text())
    assert man["signals_cache"]["cached"] is False and man["signals_cache"]["bytes_per_job"] == (
        101 * PAPER_SIGNALS * 8)
    # 3. again: exactly the two jobs without cached signals run, nothing else
    kernel = CountingKernel()
    monkeypatch.setattr(execute, "simulate_batch", kernel)
    third = sweep(tmp_path, "again", full, n_jobs=1, cache_dir=cache)
    assert (third.cached, third.computed) == (2, 2) and len(kernel.rows) == 2
    P = third.plan.P([third.jobs[2], third.jobs[3]])  # deadzone2 = 0.01 and 0.1 deg
    assert sorted(r.tobytes() for r in kernel.rows) == sorted(r.tobytes() for r in P)
    # bit-identical to the same sweep computed from scratch, without any cache
    monkeypatch.setattr(execute, "simulate_batch", REAL_KERNEL_CALL)
    ref = run_sweep(load_config(full, (), StudyConfig), None, n_jobs=1, progress=False,
                    write=False)
    for res in (second, third):
        np.testing.assert_array_equal(res.metrics[METRIC_COLS].to_numpy(float),
                                      ref.metrics[METRIC_COLS].to_numpy(float))
        table = pd.read_parquet(res.signals_file).astype({"job": str}).sort_values(
            ["job", "t_s"], ignore_index=True)
        for i, job in enumerate(res.jobs):
            rows = table[table["job"] == job.id].drop(columns=["job", "deadzone2_deg"])
            np.testing.assert_array_equal(rows.to_numpy(), ref.timeseries(i).to_numpy())


def test_dense_signals_are_not_cached_and_stay_with_the_result(tmp_path):
    """Recording every step: storing the signals would cost more than computing them again."""
    every_step = write_config(tmp_path, simulation={"duration_s": 0.02, "dt_s": 1e-5,
                                                    "output_interval_s": 1e-5})
    cache = tmp_path / "cache"
    first = sweep(tmp_path, "a", every_step, n_jobs=1, cache_dir=cache)
    assert not first.signals_cached and first.signals_rule.share > 1
    assert not any(signal_rows(cache, first).values())
    again = sweep(tmp_path, "b", every_step, n_jobs=1, cache_dir=cache)
    assert (again.cached, again.computed) == (0, 4)  # the signals are needed: recomputed
    pd.testing.assert_frame_equal(pd.read_parquet(first.signals_file),
                                  pd.read_parquet(again.signals_file))
    # no output folder (the Python API) with a cache: the signals are kept with the result
    cfg = load_config(every_step, (), StudyConfig)
    lib = run_sweep(cfg, None, n_jobs=1, progress=False, cache_dir=cache, write=False)
    assert lib.cached == 0 and lib.signals_file is None and len(lib.memory) == 4
    for i in range(4):
        np.testing.assert_array_equal(
            lib.timeseries(i).to_numpy(),
            pd.read_parquet(first.signals_file, filters=[("job", "==", lib.jobs[i].id)])
            .drop(columns=["job", "deadzone2_deg"]).to_numpy())
    metrics_only = run_sweep(cfg.model_copy(update={"outputs": cfg.outputs.model_copy(
        update={"timeseries": False, "figures": []})}), tmp_path / "c", n_jobs=1,
        progress=False, cache_dir=cache)
    assert metrics_only.plan.dec == 0 and (metrics_only.cached, metrics_only.computed) == (4, 0)
