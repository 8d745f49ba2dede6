"""The job cache (SQLite rows + chunk signal files, checksummed) and the chunk planning of the
executor."""

from __future__ import annotations

import numpy as np
import pytest

from ema_cli.errors import EmaError
from ema_cli.sim.tables import N_METRICS, PAPER_SIGNALS
from ema_cli.sweep.cache import DB_NAME, SIGNALS_MAX_SHARE, JobCache, signals_rule
from ema_cli.sweep.execute import chunk_sizes, resolve_backend, resolve_workers


def stored(tmp_path, n=3, n_out=11, dec=10):
    """A cache holding ``n`` jobs (keys k0, k1, ...) with random metrics and signals."""
    cache = JobCache(tmp_path)
    rng = np.random.default_rng(1)
    m = rng.standard_normal((n, N_METRICS))
    s = rng.standard_normal((n, n_out, PAPER_SIGNALS))
    keys = [f"k{r}" for r in range(n)]
    cache.store(keys, m, s, dec=dec)
    return cache, keys, m, s


def signals_file(cache: JobCache, key: str, dec: int = 10):
    (file, row, n_out, _), = cache.signal_rows([key], dec).values()
    return cache.root / "signals" / file, row, n_out


def test_store_then_lookup_round_trips_bit_for_bit(tmp_path):
    cache, keys, m, s = stored(tmp_path)
    m[1, 4] = np.nan
    cache.store(keys, m, s, dec=10)  # stored again: the first chunk file is deleted
    found = JobCache(tmp_path).lookup([*keys, "zz"])  # a new connection reads it
    assert sorted(found) == keys
    for r, k in enumerate(keys):
        np.testing.assert_array_equal(found[k], m[r])  # NaN == NaN here, bits identical
        np.testing.assert_array_equal(cache.load_signals(k, 10), s[r])
        assert cache.has_signals(k, 10, 11) and not cache.has_signals(k, 10, 12)
        assert not cache.has_signals(k, 5, 11)  # another decimation is another entry
    many = cache.load_signals_many(keys, 10, 11)
    assert all(np.array_equal(many[k], s[r]) for r, k in enumerate(keys))
    assert len(list((tmp_path / "signals").rglob("*.npy"))) == 1  # one file per stored chunk
    assert not list(tmp_path.rglob("*.tmp"))  # no temporary files left behind
    assert cache.corrupt == {}


def test_store_replaces_a_row_and_keeps_one_per_key(tmp_path):
    cache = JobCache(tmp_path)
    cache.store(["k"], np.zeros((1, N_METRICS)), None, 0)
    cache.store(["k"], np.ones((1, N_METRICS)), None, 0)
    np.testing.assert_array_equal(cache.load_metrics("k"), np.ones(N_METRICS))
    n = cache._db.execute("SELECT COUNT(*) FROM jobs").fetchone()[0]
    assert n == 1


def test_a_flipped_byte_in_a_signals_row_is_detected_and_not_served(tmp_path):
    cache, keys, m, s = stored(tmp_path)
    path, row, n_out = signals_file(cache, "k1")
    data = bytearray(path.read_bytes())
    pos = len(data) - (3 - row) * n_out * PAPER_SIGNALS * 8 + 100  # inside row 1's bytes
    data[pos] ^= 0x01
    path.write_bytes(bytes(data))
    fresh = JobCache(tmp_path)
    got = fresh.load_signals_many(keys, 10, 11)
    assert sorted(got) == ["k0", "k2"]  # the other rows of the file are intact and served
    np.testing.assert_array_equal(got["k2"], s[2])
    assert list(fresh.corrupt) == ["k1"] and "checksum" in fresh.corrupt["k1"]
    assert fresh.load_signals("k1", 10) is None and not fresh.has_signals("k1", 10, 11)
    # storing the job again replaces the damaged entry
    fresh.store(["k1"], m[1:2], s[1:2], 10)
    np.testing.assert_array_equal(JobCache(tmp_path).load_signals("k1", 10), s[1])


def test_an_edited_metrics_row_is_detected_and_not_served(tmp_path):
    cache, keys, m, _ = stored(tmp_path)
    edited = m[0].copy()
    edited[3] += 1e-9
    with cache._db:
        cache._db.execute("UPDATE jobs SET metrics = ? WHERE key = 'k0'", (edited.tobytes(),))
        cache._db.execute("UPDATE jobs SET metrics = ? WHERE key = 'k2'", (b"short",))
    fresh = JobCache(tmp_path)
    found = fresh.lookup(keys)
    assert sorted(found) == ["k1"]
    np.testing.assert_array_equal(found["k1"], m[1])
    assert sorted(fresh.corrupt) == ["k0", "k2"]
    assert "checksum" in fresh.corrupt["k0"] and "5 bytes" in fresh.corrupt["k2"]


def test_a_truncated_or_missing_signals_file_is_detected(tmp_path):
    cache, keys, _, s = stored(tmp_path)
    path, _, n_out = signals_file(cache, "k0")
    row_bytes = n_out * PAPER_SIGNALS * 8
    path.write_bytes(path.read_bytes()[:-row_bytes // 2])  # half of the last row (k2) cut off
    fresh = JobCache(tmp_path)
    got = fresh.load_signals_many(keys, 10)
    assert sorted(got) == ["k0", "k1"] and np.array_equal(got["k1"], s[1])
    assert list(fresh.corrupt) == ["k2"] and "truncated" in fresh.corrupt["k2"]
    path.write_bytes(b"garbage")
    assert JobCache(tmp_path).load_signals_many(keys, 10) == {}
    path.unlink()
    gone = JobCache(tmp_path)
    assert gone.load_signals("k0", 10) is None and "missing" in gone.corrupt["k0"]
    assert sorted(gone.lookup(keys)) == keys  # the metrics rows are intact


def test_a_cache_from_before_checksums_is_emptied_not_trusted(tmp_path):
    import sqlite3

    with sqlite3.connect(tmp_path / DB_NAME) as db:
        db.execute("CREATE TABLE jobs (key TEXT PRIMARY KEY, metrics BLOB NOT NULL)")
        db.execute("INSERT INTO jobs VALUES ('k', ?)", (np.zeros(N_METRICS).tobytes(),))
    cache = JobCache(tmp_path)
    assert cache.lookup(["k"]) == {}
    cache.store(["k"], np.ones((1, N_METRICS)), None, 0)
    np.testing.assert_array_equal(cache.load_metrics("k"), np.ones(N_METRICS))


def test_cache_in_an_unusable_place_is_a_clear_error(tmp_path):
    blocker = tmp_path / "file"
    blocker.write_text("x")
    with pytest.raises(EmaError, match="cannot create the job cache"):
        JobCache(blocker / "cache")
    (tmp_path / "c").mkdir()
    (tmp_path / "c" / DB_NAME).write_text("not a database")
    with pytest.raises(EmaError, match="cannot be used"):
        JobCache(tmp_path / "c")


def test_signals_are_cached_only_when_storing_them_costs_little_next_to_computing_them():
    # 1 s at dt 1e-5 on 2 workers: every 2e-3 s (200 steps) cached, 1e-3 s (the bench: just
    # past the line) and 1e-4 s not; on 1 worker (a re-run takes twice as long) 1e-3 s is
    sparse, bench, dense = (signals_rule(100_000, n, 2) for n in (501, 1001, 10_001))
    assert sparse.cache and sparse.share < 0.6 * SIGNALS_MAX_SHARE
    assert not bench.cache and bench.share < 1.1 * SIGNALS_MAX_SHARE
    assert not dense.cache and dense.share > 1
    assert signals_rule(100_000, 1001, 1).cache
    assert dense.bytes_per_job == 10_001 * PAPER_SIGNALS * 8
    assert dense.share == pytest.approx(10 * bench.share, rel=1e-3)  # bytes per step decide
    assert not signals_rule(100_000, 0, 1).cache  # nothing recorded
    record = sparse.describe()
    assert record["cached"] is True and "20%" in record["rule"]


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
