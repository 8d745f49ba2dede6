"""The job cache (SQLite rows + signal files) and the chunk planning of the executor."""

from __future__ import annotations

import numpy as np
import pytest

from ema_cli.errors import EmaError
from ema_cli.sim.tables import N_METRICS, N_SIGNALS
from ema_cli.sweep.cache import DB_NAME, JobCache
from ema_cli.sweep.execute import chunk_sizes, resolve_backend, resolve_workers


def test_store_then_lookup_round_trips_bit_for_bit(tmp_path):
    cache = JobCache(tmp_path)
    rng = np.random.default_rng(1)
    m = rng.standard_normal((3, N_METRICS))
    m[1, 4] = np.nan
    s = rng.standard_normal((3, 11, N_SIGNALS))
    cache.store(["a1", "b2", "c3"], m, s, dec=10)
    found = JobCache(tmp_path).lookup(["a1", "b2", "c3", "zz"])  # a new connection reads it
    assert sorted(found) == ["a1", "b2", "c3"]
    for r, k in enumerate(["a1", "b2", "c3"]):
        np.testing.assert_array_equal(found[k], m[r])  # NaN == NaN here, bits identical
        np.testing.assert_array_equal(cache.load_signals(k, 10), s[r])
        assert cache.has_signals(k, 10, 11) and not cache.has_signals(k, 10, 12)
        assert not cache.has_signals(k, 5, 11)  # another decimation is another file
    assert not list(tmp_path.rglob("*.tmp"))  # no temporary files left behind


def test_store_replaces_a_row_and_keeps_one_per_key(tmp_path):
    cache = JobCache(tmp_path)
    cache.store(["k"], np.zeros((1, N_METRICS)), None, 0)
    cache.store(["k"], np.ones((1, N_METRICS)), None, 0)
    np.testing.assert_array_equal(cache.load_metrics("k"), np.ones(N_METRICS))
    n = cache._db.execute("SELECT COUNT(*) FROM jobs").fetchone()[0]
    assert n == 1


def test_unreadable_signal_file_counts_as_missing(tmp_path):
    cache = JobCache(tmp_path)
    cache.store(["k"], np.zeros((1, N_METRICS)), np.zeros((1, 5, N_SIGNALS)), 2)
    cache.signals_path("k", 2).write_bytes(b"garbage")
    assert cache.load_signals("k", 2) is None and not cache.has_signals("k", 2, 5)


def test_cache_in_an_unusable_place_is_a_clear_error(tmp_path):
    blocker = tmp_path / "file"
    blocker.write_text("x")
    with pytest.raises(EmaError, match="cannot create the job cache"):
        JobCache(blocker / "cache")
    (tmp_path / "c").mkdir()
    (tmp_path / "c" / DB_NAME).write_text("not a database")
    with pytest.raises(EmaError, match="cannot be used"):
        JobCache(tmp_path / "c")


def test_chunk_sizes_cover_every_job_and_respect_the_caps():
    # 1000 jobs of 1e5 steps on 2 workers: 4 chunks per worker -> 8 chunks of 125
    assert chunk_sizes(1000, 100_000, 2, "loky", 0) == [125] * 8
    # threads: same count of chunks, each big enough for every thread
    assert chunk_sizes(3, 100_000, 2, "threads", 0) == [2, 1]
    # the job-steps cap: 1e7-step jobs -> 3e7 // 1e7 = 3 per single-thread chunk
    assert chunk_sizes(30, 10_000_000, 1, "serial", 0) == [3] * 10
    # the signal-memory cap: 7e5 samples x 17 signals x 8 B = 95 MB per job -> 2 per 256 MiB
    assert chunk_sizes(8, 1_000, 1, "serial", 700_000) == [2] * 4
    assert chunk_sizes(10, 1_000, 2, "loky", 0, chunk_size=4) == [4, 4, 2]
    assert chunk_sizes(0, 1_000, 2, "loky", 0) == []


def test_backend_and_worker_resolution():
    assert resolve_backend("auto", 2) == "threads"
    assert resolve_backend("loky", 1) == "serial" and resolve_backend("threads", 1) == "serial"
    assert resolve_backend("dask", 1) == "dask"
    with pytest.raises(EmaError, match="unknown backend 'mpi'"):
        resolve_backend("mpi", 2)
    assert resolve_workers(3) == 3 and resolve_workers(-1) >= 1
    with pytest.raises(EmaError, match="n_jobs must be >= 1"):
        resolve_workers(0)
