"""Issue 41: yield, tune, design's cases and the closed-loop fit's starts on a Dask cluster
(and loky processes) give the local run's results bit for bit; a worker killed mid-run costs
a retry, not a unit; a checkpointed run resumes on any backend.

The reference is the same computation in this process (threads backend): the claim is
identity, so every comparison is exact (``assert_array_equal``, ``check_exact``), never a
tolerance. The cluster: dask.distributed's LocalCluster started here (2 worker processes, one
thread each, loopback only), shared by the module. Slow tier: starting it and loading the
kernel in each worker takes seconds, the closed-loop fit tens of seconds.
"""

from __future__ import annotations

import json
import os
import signal

import numpy as np
import pandas as pd
import pytest
import yaml
from typer.testing import CliRunner

from ema_cli.api.production import production_yield
from ema_cli.api.tune import tune
from ema_cli.cli.main import app

distributed = pytest.importorskip("dask.distributed")
pytestmark = pytest.mark.slow  # the slow tier: make test-all (CI runs it)

SPEC = {"name": "scale-spec", "actuator": {"config": None, "plant": {}, "nonlinearities": {}},
        "tests": {"step": {"test": "step", "amplitude_deg": 0.1, "duration_s": 0.3,
                           "limits": {"settling_time": {"max": 0.25, "unit": "s"},
                                      "overshoot": {"max": 20, "unit": "%"}}},
                  "margins": {"test": "margins", "loops": ["position", "speed"],
                              "limits": {"gain_margin": {"min": 6, "unit": "dB"}}}}}
"""A two-test battery quick enough for 64 units in seconds (step: a kernel batch; margins:
the linear model), with both limits binding on some units."""
TOL = {"tolerances": {"plant.kL": {"dist": "normal", "mean": 590, "sd": 40},
                      "plant.Kpp": {"dist": "uniform", "low": 40, "high": 90},
                      "nonlinearities.deadzone2": {"dist": "uniform", "low": 0, "high": 0.004}}}
TUNE = {"name": "tiny", "simulation": {"duration_s": 0.3, "dt_s": 5.0e-5},
        "scenarios": {"a": {"input": {"kind": "step", "amplitude_deg": 1.0}},
                      "b": {"input": {"kind": "step", "amplitude_deg": 0.5},
                            "nonlinearities": {"deadzone2": 0.01}}},
        "variables": {"Kpp": {"bounds": [20.0, 100.0], "scale": "log"},
                      "Kps": {"bounds": [0.05, 1.0], "scale": "log"}},
        "constraints": {"overshoot": "off"},
        "optimiser": {"budget": 120, "pop": 12}}
FIT = {"shooting": {"starts": 4, "max_iter": 8, "lengthen_s": []},
       "free": {"kL": [300.0, 900.0], "alpha": [0.0, 0.01]},
       "max_iter": 5, "profile_points": 5, "dt_s": 2.0e-5}
"""A closed-loop fit with 4 starts, cut short (the harness's tiny fit with twice the starts)."""


@pytest.fixture(scope="module")
def cluster():
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  protocol="tcp", host="127.0.0.1",  # loopback only
                                  dashboard_address=None) as c:
        yield c


@pytest.fixture(scope="module")
def local_yield():
    """The reference: 64 units in this process."""
    return production_yield(SPEC, TOL, n=64, block=32, worst_budget=8)


@pytest.fixture(scope="module")
def local_blocks_of_8():
    """The same units in checkpoint blocks of 8 (the estimate's history has a point per
    block)."""
    return production_yield(SPEC, TOL, n=64, block=8, worst_budget=8)


def same_yield(a, b) -> None:
    pd.testing.assert_frame_equal(a.samples, b.samples, check_exact=True)
    assert [{k: v for k, v in h.items() if k != "elapsed_s"} for h in a.history] == [
        {k: v for k, v in h.items() if k != "elapsed_s"} for h in b.history]
    assert a.worst.limits == b.worst.limits and a.drivers == b.drivers
    pd.testing.assert_frame_equal(a.worst.battery, b.worst.battery, check_exact=True)


def test_yield_of_64_units_on_a_dask_cluster_is_the_local_run_bit_for_bit(tmp_path, cluster,
                                                                           local_yield):
    (tmp_path / "spec.yaml").write_text(yaml.safe_dump(SPEC, sort_keys=False))
    (tmp_path / "tol.yaml").write_text(yaml.safe_dump(TOL, sort_keys=False))
    r = CliRunner().invoke(app, ["yield", str(tmp_path / "spec.yaml"), "--tolerances",
                                 str(tmp_path / "tol.yaml"), "--n", "64", "--block", "32",
                                 "--worst-budget", "8", "--backend", "dask", "--scheduler",
                                 cluster.scheduler_address, "--out", str(tmp_path / "y")])
    assert r.exit_code == 0, r.output
    samples = pd.read_parquet(tmp_path / "y" / "samples.parquet")
    pd.testing.assert_frame_equal(samples, local_yield.samples, check_exact=True)
    man = json.loads((tmp_path / "y" / "manifest.json").read_text())
    ex = man["execution"]
    # 64 units in tasks of 16 (4 per block pair), the worst case's 2 tests and its battery
    assert ex["backend"] == "dask" and ex["workers"] == 2 and ex["blocks"] == 4 + 2 + 1
    js = json.loads((tmp_path / "y" / "yield.json").read_text())
    assert js["overall"] == local_yield.to_json()["overall"]
    assert js["worst_case"]["limits"] == json.loads(json.dumps(
        local_yield.to_json()["worst_case"]["limits"]))
    assert 0 < js["overall"]["n_pass"] < 64  # the limits bind: a test that can fail


def test_a_dask_worker_killed_mid_run_costs_a_retry_not_a_unit(cluster, local_blocks_of_8):
    pids = cluster_pids(cluster)
    killed = []

    def kill_one(state):  # after the first block: the others are on the workers
        if not killed:
            os.kill(pids[0], signal.SIGKILL)
            killed.append(pids[0])

    res = production_yield(SPEC, TOL, n=64, block=8, worst_budget=8, backend="dask",
                           scheduler=cluster.scheduler_address, progress=kill_one)
    assert killed
    same_yield(res, local_blocks_of_8)  # every unit, the same bits
    lost = [r for r in res.execution["retries"] if r["why"].startswith("worker lost")]
    assert lost and all(r["block"].startswith("units ") for r in lost)
    cluster.wait_for_workers(2, timeout=60)  # the nanny restarted it, for the next tests


def cluster_pids(cluster) -> list[int]:
    with distributed.Client(cluster.scheduler_address, set_as_default=False) as c:
        return list(c.run(os.getpid).values())


def test_a_loky_worker_killed_mid_run_costs_a_retry_not_a_unit(local_blocks_of_8):
    from joblib.externals.loky import get_reusable_executor

    from ema_cli.sweep.pools import LOKY_IDLE_S

    killed = []

    def kill_one(state):
        if not killed:  # the executor's pool (same arguments: the same pool)
            pool = get_reusable_executor(max_workers=2, timeout=LOKY_IDLE_S, reuse=True)
            pid = next(iter(pool._processes))
            os.kill(pid, signal.SIGKILL)
            killed.append(pid)

    res = production_yield(SPEC, TOL, n=64, block=8, worst_budget=8, backend="loky",
                           n_jobs=2, progress=kill_one)
    assert killed
    same_yield(res, local_blocks_of_8)
    assert any(r["why"].startswith("worker lost") for r in res.execution["retries"])


def test_a_checkpointed_yield_resumes_on_any_backend_with_the_same_units(tmp_path, cluster,
                                                                        local_blocks_of_8):
    out = tmp_path / "run"

    def stop_at(n):
        def progress(state):
            if state["n"] >= n:
                raise KeyboardInterrupt
        return progress

    for n_stop, kw in ((16, {"backend": "loky", "n_jobs": 2}),
                       (40, {"backend": "dask", "scheduler": cluster.scheduler_address})):
        with pytest.raises(KeyboardInterrupt):
            production_yield(SPEC, TOL, n=64, block=8, worst_budget=8, out=out,
                             checkpoint=True, progress=stop_at(n_stop), **kw)
    finished = sorted(p.name for p in (out / "blocks").glob("units_*.parquet"))
    assert len(finished) == 5  # 40 units in blocks of 8: loky's 2, dask's 3 more
    res = production_yield(SPEC, TOL, n=64, block=8, worst_budget=8, out=out,
                           checkpoint=True)  # this process
    assert res.resumed_units == 40
    same_yield(res, local_blocks_of_8)


def test_tune_with_a_small_budget_on_dask_is_the_local_run_bit_for_bit(cluster, monkeypatch):
    import ema_cli.sweep.execute as execute

    ref = tune(TUNE)
    # cut every generation over the workers (a real tuning's generations are larger)
    monkeypatch.setattr(execute, "MIN_BLOCK_CASE_STEPS", 1000)
    res = tune(TUNE, backend="dask", scheduler=cluster.scheduler_address)
    assert res.execution["backend"] == "dask" and res.execution["blocks"] >= 10
    np.testing.assert_array_equal(res.outcome.best.x, ref.outcome.best.x)
    pd.testing.assert_frame_equal(res.history(), ref.history(), check_exact=True)
    for which in ("reference", "before", "after"):
        a, b = res.evaluation(which), ref.evaluation(which)
        np.testing.assert_array_equal(a.metric, b.metric)
        np.testing.assert_array_equal(a.score, b.score)
    assert res.outcome.check_cost == ref.outcome.check_cost


def test_a_closed_loop_fit_with_4_starts_on_dask_is_the_local_run_bit_for_bit(tmp_path,
                                                                               cluster):
    from ema_cli.api.identify_logs import identify_closed_loop, make_identification_data

    make_identification_data(kind="closed-loop", noise_pct=0.5, duration_s=0.6).save(
        tmp_path / "mk")
    log = str(tmp_path / "mk" / "closed_loop.csv")
    ref = identify_closed_loop(FIT, data=log)
    res = identify_closed_loop(FIT, data=log, backend="dask",
                               scheduler=cluster.scheduler_address)
    assert res.execution["backend"] == "dask" and res.execution["blocks"] >= 4
    a, b = ref.result.shooting.search, res.result.shooting.search
    assert a.starts_x.shape[0] == 4
    for x, y in ((a.final_cost, b.final_cost), (a.history, b.history), (a.x, b.x),
                 (ref.result.x, res.result.x)):
        np.testing.assert_array_equal(x, y)

    def answer(fit):  # everything but the wall times and the work counters
        js = fit.result.to_json()
        js.pop("timings_s", None)
        for key in ("timings_s", "kernel_s", "kernel_steps"):
            js["shooting"].pop(key, None)
        return js

    assert json.dumps(answer(ref), sort_keys=True) == json.dumps(answer(res), sort_keys=True)


def test_design_cases_run_as_tasks_and_give_the_local_verdicts(tmp_path, cluster):
    """The acceptance cases of ema design each a task: the same cases, verdicts and values."""
    from ema_cli.api.acceptance import acceptance
    from ema_cli.sweep.executor import Task, executing

    docs = [{**SPEC, "actuator": {"config": None, "plant": {"kL": k, "Kpp": 80.0},
                                  "nonlinearities": {"deadzone2": 0.002}}}
            for k in (450.0, 590.0, 750.0)]
    local = [acceptance(d) for d in docs]
    with executing("dask", scheduler=cluster.scheduler_address) as ex:
        remote = ex.run(Task(acceptance, (d,), f"case {i}") for i, d in enumerate(docs))
    for a, b in zip(local, remote, strict=True):
        assert a.verdict == b.verdict
        assert [(v.test, v.metric, v.value, v.result) for v in a.verdicts] == [
            (v.test, v.metric, v.value, v.result) for v in b.verdicts]

