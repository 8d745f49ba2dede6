"""The job cache: each finished job's SI metrics (and recorded signals) under its content hash.

Layout of the cache folder (default ``results/.cache/sweep``, shared by every sweep run from
the same working directory, so an extended sweep reuses the jobs it shares with earlier ones):

    jobs.sqlite                      table ``jobs(key PRIMARY KEY, metrics)``: metrics[N_METRICS]
                                     as float64 bytes, SI, the columns of ``sim.tables.METRICS``
    signals/<key[:2]>/<key>-d<dec>.npy   signals[n_out, N_SIGNALS] recorded every ``dec`` steps

A job is finished when its metrics row exists. The rows of one chunk are committed in one
SQLite transaction (all or none), after the chunk's signal files, each written to a temporary
sibling and renamed into place. One transaction per chunk instead of one file per job keeps the
cache cheap on slow filesystems (measured: ~0.5 ms per file created, ~10 us per row). Rows
or files that cannot be read or have the wrong shape count as missing and are recomputed.
"""

from __future__ import annotations

import os
import sqlite3
import tempfile
from collections.abc import Iterable, Sequence
from pathlib import Path

import numpy as np

from ema_cli.errors import EmaError
from ema_cli.files import RESULTS_ROOT
from ema_cli.sim.tables import N_METRICS, N_SIGNALS

DEFAULT_CACHE_DIR = RESULTS_ROOT / ".cache" / "sweep"
DB_NAME = "jobs.sqlite"
SQLITE_TIMEOUT_S = 60.0  # wait this long for another sweep's transaction on the same cache [s]
LOOKUP_BATCH = 500  # keys per SELECT ... IN (...) query (SQLite's host-parameter limit is 999)


def _save(path: Path, array: np.ndarray) -> None:
    """np.save to a temporary sibling, then rename into place (atomic on one filesystem)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as f:
            np.save(f, array, allow_pickle=False)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


class JobCache:
    """Finished jobs on disk, keyed by content hash (see the module docstring)."""

    def __init__(self, root: Path | str | None = None) -> None:
        self.root = Path(root) if root is not None else DEFAULT_CACHE_DIR
        try:
            self.root.mkdir(parents=True, exist_ok=True)
            self._db = sqlite3.connect(self.root / DB_NAME, timeout=SQLITE_TIMEOUT_S,
                                       check_same_thread=False)
            self._db.execute("PRAGMA synchronous=NORMAL")
            self._db.execute("CREATE TABLE IF NOT EXISTS jobs "
                             "(key TEXT PRIMARY KEY, metrics BLOB NOT NULL)")
            self._db.commit()
        except OSError as exc:
            raise EmaError(f"cannot create the job cache '{self.root}': {exc.strerror}", 1
                           ) from None
        except sqlite3.Error as exc:
            raise EmaError(f"the job cache '{self.root / DB_NAME}' cannot be used: {exc}", 1
                           ) from None

    def close(self) -> None:
        """Close the database (the object can still read signal files)."""
        self._db.close()

    def signals_path(self, key: str, dec: int) -> Path:
        """Where a job's signals recorded every ``dec`` steps live."""
        return self.root / "signals" / key[:2] / f"{key}-d{dec}.npy"

    def lookup(self, keys: Iterable[str]) -> dict[str, np.ndarray]:
        """Cached metrics[N_METRICS] (SI) of those ``keys`` that are finished."""
        keys = list(keys)
        found: dict[str, np.ndarray] = {}
        try:
            for a in range(0, len(keys), LOOKUP_BATCH):
                batch = keys[a:a + LOOKUP_BATCH]
                marks = ",".join("?" * len(batch))
                for key, blob in self._db.execute(
                        f"SELECT key, metrics FROM jobs WHERE key IN ({marks})", batch):
                    if len(blob) == N_METRICS * 8:
                        found[key] = np.frombuffer(blob, dtype=np.float64).copy()
        except sqlite3.Error as exc:
            raise EmaError(f"the job cache '{self.root / DB_NAME}' cannot be read: {exc}", 1
                           ) from None
        return found

    def load_metrics(self, key: str) -> np.ndarray | None:
        """metrics[N_METRICS] (SI) of one job, or None if it is not cached."""
        return self.lookup([key]).get(key)

    def has_signals(self, key: str, dec: int, n_out: int) -> bool:
        """True if the job's signals recorded every ``dec`` steps are cached, n_out samples."""
        sig = self.load_signals(key, dec, mmap=True)
        return sig is not None and sig.shape == (n_out, N_SIGNALS)

    def load_signals(self, key: str, dec: int, mmap: bool = False) -> np.ndarray | None:
        """signals[n_out, N_SIGNALS] (SI) recorded every ``dec`` steps, or None."""
        try:
            s = np.load(self.signals_path(key, dec), allow_pickle=False,
                        mmap_mode="r" if mmap else None)
        except (OSError, ValueError):
            return None
        return s if s.ndim == 2 and s.shape[1] == N_SIGNALS else None

    def store(self, keys: Sequence[str], metrics: np.ndarray, signals: np.ndarray | None,
              dec: int) -> None:
        """Store finished jobs: metrics[n, N_METRICS], signals[n, n_out, N_SIGNALS] or None.

        Signal files first, then every metrics row in one transaction (all rows or none).
        """
        if signals is not None and dec > 0:
            for r, key in enumerate(keys):
                _save(self.signals_path(key, dec), np.ascontiguousarray(signals[r]))
        rows = [(key, np.ascontiguousarray(metrics[r], dtype=np.float64).tobytes())
                for r, key in enumerate(keys)]
        try:
            with self._db:
                self._db.executemany("INSERT OR REPLACE INTO jobs (key, metrics) VALUES (?, ?)",
                                     rows)
        except sqlite3.Error as exc:
            raise EmaError(f"the job cache '{self.root / DB_NAME}' cannot be written: {exc}", 1
                           ) from None
