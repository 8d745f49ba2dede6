"""The executor (ema_cli/sweep/executor.py): submission order, lazy submission, retries of a
lost worker's block, a block failing twice reported with its label, user errors passed on.

Tasks here are plain functions (sleeps, arithmetic, a worker that kills itself), so the
executor's bookkeeping is checked without the kernel; the kernel's bits across backends are
tests/system/test_scale.py's (slow tier: a Dask cluster)."""

from __future__ import annotations

import os
import pickle
import signal
import time
from pathlib import Path

import numpy as np
import pytest

from ema_cli.errors import EmaError
from ema_cli.sweep.executor import (
    MAX_ATTEMPTS,
    BlockFailed,
    Executor,
    Failure,
    Task,
    current,
    executing,
    split,
)


def square_after(x: int, delay: float) -> int:
    time.sleep(delay)
    return x * x


def die_once(marker: str, x: int) -> int:
    """Kill this worker process the first time (``marker`` does not exist yet)."""
    m = Path(marker)
    if not m.exists():
        m.write_text("ran")
        os.kill(os.getpid(), signal.SIGKILL)
    return 10 * x


def die(_x: int) -> None:
    os.kill(os.getpid(), signal.SIGKILL)


def user_error(what: str) -> None:
    raise EmaError(f"a sampled unit is not valid: {what}", 1)


def test_loky_orders_draws_lazily_and_passes_user_errors_on():
    """One loky pool for the three (starting one costs seconds): the results come in
    submission order whatever finishes first; tasks are drawn a few per worker ahead and a
    caller that stops cancels the rest; an EmaError raised in a worker stops the run with its
    message and exit code, unretried (it would fail again)."""
    delays = [0.2, 0.1, 0.0, 0.15, 0.05]  # later tasks finish first
    drawn = []

    def tasks():
        for i in range(1000):
            drawn.append(i)
            yield Task(square_after, (i, 0.01), f"block {i}")

    with Executor("loky", 2) as ex:
        out = list(ex.map(Task(square_after, (i, d), f"block {i}")
                          for i, d in enumerate(delays)))
        assert out == [(i, i * i) for i in range(5)]
        unordered = list(ex.map([Task(square_after, (i, d), f"b{i}")
                                 for i, d in enumerate(delays)], ordered=False))
        assert sorted(unordered) == out and ex.blocks == 10 and ex.retries == []
        assert len(ex.task_seconds) == 5 and min(ex.task_seconds) >= 0.0

        results = ex.map(tasks())
        assert [next(results) for _ in range(3)] == [(0, 0), (1, 1), (2, 4)]
        results.close()
        # one block per loky worker in flight, as many held for the order: 3 + 2 * 2 at most
        assert len(drawn) <= 3 + 4

        with pytest.raises(EmaError) as err:
            list(ex.map([Task(user_error, ("kL = -1",), "units 0-15")]))
    assert err.value.message == "a sampled unit is not valid: kL = -1"
    assert err.value.exit_code == 1 and ex.retries == []
    e = pickle.loads(pickle.dumps(EmaError("x", 3)))
    assert (e.message, e.exit_code) == ("x", 3)


@pytest.mark.slow  # restarts the loky pool (seconds each on a loaded machine)
def test_a_worker_killed_costs_a_retry_not_a_block(tmp_path):
    with Executor("loky", 2) as ex:
        tasks = [Task(square_after, (i, 0.05), f"units {i}") for i in range(3)]
        tasks.insert(1, Task(die_once, (str(tmp_path / "m"), 7), "units 70-79"))
        out = [v for _, v in ex.map(tasks)]
    assert out == [0, 70, 1, 4]  # every block, in order
    retried = [label for label, why in ex.retries]
    assert "units 70-79" in retried and all("worker lost" in why for _, why in ex.retries)
    assert ex.describe()["retries"][0]["block"] in {t.label for t in tasks}


@pytest.mark.slow  # restarts the loky pool twice
def test_a_block_lost_twice_is_reported_with_its_units():
    with Executor("loky", 1) as ex:
        with pytest.raises(BlockFailed) as err:
            list(ex.map([Task(die, (1,), "units 200-215")]))
        assert err.value.exit_code == 1
        assert err.value.message.startswith(f"units 200-215: failed {MAX_ATTEMPTS} times "
                                            "(2 workers lost while it ran)")
        # a caller that carries on gets the failure in its place, never a hole
        got = list(ex.map([Task(square_after, (3, 0.0), "a"), Task(die, (1,), "b")],
                          failures="return"))
    assert got[0] == (0, 9) and isinstance(got[1][1], Failure) and got[1][1].label == "b"


def test_in_process_runs_each_task_here_with_numba_threads():
    with executing("threads", 2) as ex:
        assert current() is ex and not ex.remote
        assert ex.run([Task(square_after, (k, 0.0), "x") for k in range(3)]) == [0, 1, 4]
        with executing() as inner:  # no backend of its own: the outer one
            assert inner is ex
    assert current() is not ex  # the context ends with the block


def test_split_is_one_block_here_and_one_per_worker_elsewhere():
    with executing("threads", 2):
        assert split(10) == [(0, 10)]
    with executing("loky", 3):
        assert split(10) == [(0, 4), (4, 7), (7, 10)]
        assert split(10, min_items=4) == [(0, 5), (5, 10)]  # 2 blocks of >= 4
        assert split(1) == [(0, 1)]


def test_the_api_refuses_bad_execution_arguments_naming_them():
    from ema_cli.api._inputs import backend_args

    for args, text in ((("mpi", None, None), "backend must be one of auto, loky, threads, "
                                              "dask"),
                       (("loky", 0, None), "n_jobs must be >= 1"),
                       (("threads", None, "tcp://h:8786"), "scheduler is for backend dask"),
                       (("dask", None, None), "needs a scheduler address"),
                       (("dask", None, "no address"), "is not a dask scheduler address")):
        with pytest.raises(EmaError, match=text):
            backend_args(*args)


def test_serial_kernels_give_the_parallel_kernels_bits():
    from ema_cli.model.params import resolve, to_row
    from ema_cli.sim.runner import serial_kernels, simulate_batch
    from ema_cli.sim.signals import InputSignal

    P = np.array([to_row(resolve({"kL": k})) for k in (400.0, 590.0, 800.0)])
    ref = InputSignal("step", 0.02)
    a = simulate_batch(P, [ref], None, 1e-4, 2000, 10, parallel=True)
    with serial_kernels():
        b = simulate_batch(P, [ref], None, 1e-4, 2000, 10, parallel=True)
    np.testing.assert_array_equal(a.metrics, b.metrics)
    np.testing.assert_array_equal(a.signals, b.signals)


def test_a_worker_with_other_ema_sources_refuses_the_block(tmp_path):
    """The client's code key (version + a hash of every source) travels with each Dask block;
    a worker whose installed ema differs refuses it with a user error naming both, since its
    bits could differ; the hash moves with one byte of one source."""
    from ema_cli.sweep.pools import call, code_key, source_fingerprint

    (tmp_path / "a.py").write_text("x = 1\n")
    (tmp_path / "sub").mkdir()
    (tmp_path / "sub" / "b.py").write_text("y = 2\n")
    (tmp_path / "notes.txt").write_text("not a source")
    before = source_fingerprint(tmp_path)
    assert len(before) == 12 and source_fingerprint(tmp_path) == before
    (tmp_path / "notes.txt").write_text("changed")  # not a source: the same key
    assert source_fingerprint(tmp_path) == before
    (tmp_path / "sub" / "b.py").write_text("y = 3\n")
    assert source_fingerprint(tmp_path) != before

    assert call(square_after, (3, 0.0), "process", code_key()).value == 9
    with pytest.raises(EmaError, match=r"worker process runs ema 0\.\d.*\+[0-9a-f]{12}, this "
                                       r"process ema 0\.0\.0\+000000000000 .*same ema") as err:
        call(square_after, (3, 0.0), "process", "0.0.0+000000000000")
    assert err.value.exit_code == 1


def test_joblib_parallel_runs_after_the_executor_in_one_process():
    """The loky pool is joblib's own reusable one: a joblib Parallel after the executor (the
    torque GA's runs after a yield in one session) reuses or replaces it, never breaks."""
    from joblib import Parallel, delayed

    with Executor("loky", 2) as ex:
        assert ex.run([Task(square_after, (k, 0.0), f"b{k}") for k in range(3)]) == [0, 1, 4]
    assert Parallel(n_jobs=2)(delayed(square_after)(k, 0.0) for k in range(3)) == [0, 1, 4]
