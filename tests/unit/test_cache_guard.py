"""numba's cache under several processes (``ema_cli._numba._serialise_cache_saves``): two saves
of two overloads of one function at the same moment must not share a data file, and an entry
whose data holds another signature is a miss, not another variant's machine code."""

from __future__ import annotations

import fcntl
import threading
import time
from types import SimpleNamespace

import pytest
from numba import types
from numba.core import caching

import ema_cli._numba as en


def _payload(*args: object) -> tuple:
    """A reduced compile result as numba's cache stores it: its signature is item 3."""
    return (b"code", None, None, SimpleNamespace(args=tuple(args)), False, (), None, [], ())


def _key(*args: object) -> tuple:
    return (tuple(args), ("magic",), ("stamp",))


def test_a_save_holds_an_exclusive_lock_beside_the_index(tmp_path):
    cf = caching.IndexDataCacheFile(str(tmp_path), "f-1.py311", ("stamp", 1))
    seen = []
    real = cf._save_data

    def probe(name, data):
        # another open file description of the lock file cannot take it meanwhile
        with open(cf._index_path + ".lock", "a") as other, pytest.raises(BlockingIOError):
            fcntl.flock(other, fcntl.LOCK_EX | fcntl.LOCK_NB)
        seen.append(name)
        real(name, data)

    cf._save_data = probe
    cf.save(_key(types.int64), _payload(types.int64))
    assert seen == ["f-1.py311.1.nbc"]


def test_two_overloads_saved_at_once_get_their_own_data_files(tmp_path, monkeypatch):
    """Both saves read the index before either writes it (a 50 ms pause after reading):
    unguarded, both pick data file 1 and the index names one signature for the other's
    code; guarded, the second waits, reads the first's index and picks file 2."""
    real = caching.IndexDataCacheFile._load_index

    def slow(self):
        out = real(self)
        time.sleep(0.05)
        return out

    monkeypatch.setattr(caching.IndexDataCacheFile, "_load_index", slow)
    sigs = [types.int64, types.float64]

    def one(t):
        caching.IndexDataCacheFile(str(tmp_path), "f-1.py311", ("stamp", 1)).save(
            _key(t), _payload(t))

    threads = [threading.Thread(target=one, args=(t,)) for t in sigs]
    for th in threads:
        th.start()
    for th in threads:
        th.join()
    monkeypatch.setattr(caching.IndexDataCacheFile, "_load_index", real)
    cf = caching.IndexDataCacheFile(str(tmp_path), "f-1.py311", ("stamp", 1))
    index = cf._load_index()
    assert sorted(index.values()) == ["f-1.py311.1.nbc", "f-1.py311.2.nbc"]
    for t in sigs:
        assert cf.load(_key(t))[3].args == (t,)


def test_an_entry_holding_another_signature_is_a_miss(tmp_path):
    cf = caching.IndexDataCacheFile(str(tmp_path), "f-1.py311", ("stamp", 1))
    cf.save(_key(types.int64), _payload(types.int64))
    cf._save_data("f-1.py311.1.nbc", _payload(types.float64))  # what the race left
    assert cf.load(_key(types.int64)) is None
    cf.save(_key(types.int64), _payload(types.int64))  # compiled again: replaced
    assert cf.load(_key(types.int64))[3].args == (types.int64,)


def test_entry_matches_judges_only_compile_results():
    assert en.entry_matches(_key(types.int64), _payload(types.int64))
    assert not en.entry_matches(_key(types.int64), _payload(types.float64))
    assert en.entry_matches(_key(types.int64), ("a library", b"bytes"))  # another kind


def test_a_file_system_without_locks_still_saves(tmp_path, monkeypatch):
    def no_locks(*_a):
        raise OSError(37, "No locks available")

    monkeypatch.setattr(fcntl, "flock", no_locks)
    cf = caching.IndexDataCacheFile(str(tmp_path), "f-1.py311", ("stamp", 1))
    cf.save(_key(types.int64), _payload(types.int64))
    assert cf.load(_key(types.int64))[3].args == (types.int64,)
