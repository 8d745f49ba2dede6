"""The job cache: each finished job's SI metrics (and recorded signals), checked on every read.

Layout of the cache folder (``ema sweep`` uses ``results/.cache/sweep``, shared by every sweep
run from the same working directory, so an extended sweep reuses the jobs it shares with
earlier ones; a library sweep that writes no outputs has no cache unless it is given one):

    jobs.sqlite       table ``jobs(key PRIMARY KEY, metrics, crc)``: metrics[N_METRICS] as
                      float64 bytes, SI, the columns of ``sim.tables.METRICS``, and their CRC-32;
                      table ``signals(key, dec, file, row, n_out, crc)``: the job's signals
                      recorded every ``dec`` steps are row ``row`` of ``file``, with their CRC-32
    signals/<kk>/<key>-<random>-d<dec>.npy   signals[n, n_out, N_SIGNALS] of one stored chunk

A job is finished when its metrics row exists. A chunk's signals go into one file (written to a
temporary sibling and renamed into place), then the chunk's rows into both tables in one SQLite
transaction (all rows or none). One file and one transaction per chunk, not per job, keep the
cache cheap (measured: ~0.5 ms per file created, ~10 us per row). A file no row refers to any
more (its jobs were stored again) is deleted.

Every entry is verified before it is served: a metrics blob or a signals row whose CRC-32
(zlib, ~3 GB/s) differs from the one stored beside it, a truncated, unreadable or missing file,
a wrong shape. Such an entry is never used: it is recorded in :attr:`JobCache.corrupt` (the
sweep recomputes the job, which replaces the entry, and reports the count). A row that simply
is not there (a job never run, or run without recording) is missing, not corrupt.

The metrics of every finished job are always cached; its recorded signals only when storing them
costs little next to computing them again (:func:`signals_rule`): a second copy of dense signals
costs more disk time than a re-run spends recomputing the job. A sweep that needs the signals of a
job whose metrics are cached but signals are not recomputes that job (bit-identical).
"""

from __future__ import annotations

import contextlib
import math
import os
import secrets
import sqlite3
import zlib
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ema_cli.errors import EmaError
from ema_cli.files import RESULTS_ROOT, save_array
from ema_cli.sim.tables import N_METRICS, N_SIGNALS, PAPER_SIGNALS

DEFAULT_CACHE_DIR = RESULTS_ROOT / ".cache" / "sweep"
DB_NAME = "jobs.sqlite"
SQLITE_TIMEOUT_S = 60.0  # wait this long for another sweep's transaction on the same cache [s]
LOOKUP_BATCH = 500  # keys per SELECT ... IN (...) query (SQLite's host-parameter limit is 999)
SCHEMA = (
    "CREATE TABLE IF NOT EXISTS jobs (key TEXT PRIMARY KEY, metrics BLOB NOT NULL, "
    "crc INTEGER NOT NULL)",
    "CREATE TABLE IF NOT EXISTS signals (key TEXT NOT NULL, dec INTEGER NOT NULL, "
    "file TEXT NOT NULL, row INTEGER NOT NULL, n_out INTEGER NOT NULL, crc INTEGER NOT NULL, "
    "PRIMARY KEY (key, dec))",
)
SIGNALS_MAX_SHARE = 0.2  # cache a job's signals only if storing them costs <= this share of
# computing the job (so a re-run that reads them saves at least 5x what storing them cost) [-]
STORE_BYTES_PER_S = 0.6e9  # what storing signals costs a sweep: the bench's 136 MB (every 1e-3
# s) made it 0.23 s longer (paired runs, 2 cores; .npy writes + CRC-32 in a thread of their own,
# 0.55 s there: fresh page cache takes 0.4 GB/s on the bench VM, 1.8 GB/s once recycled) [B/s]
KERNEL_CPU_S_PER_STEP = 22e-9  # kernel time per job and integration step on one core: 1.1 s
# for the bench's 1,000 jobs x 1e5 steps on 2 threads (AMD EPYC; a nonlinearity adds ~10 %) [s]
SignalRow = tuple[str, int, int, int]
"""Where a job's signals are: (file relative to ``signals/``, row, n_out, CRC-32)."""


HEADER_READERS = {(1, 0): np.lib.format.read_array_header_1_0,
                  (2, 0): np.lib.format.read_array_header_2_0}


def checksum(data: bytes | np.ndarray) -> int:
    """CRC-32 of a bytes object or of an array's bytes (C order)."""
    return zlib.crc32(data if isinstance(data, bytes) else np.ascontiguousarray(data))


@dataclass(frozen=True)
class SignalsRule:
    """Whether a sweep's recorded signals go into the job cache, and why (for the manifest).

    ``store_s`` / ``kernel_s``: estimated seconds to store one job's signals / to compute the
    job again (wall, ``workers`` threads); ``share`` their ratio; ``cache`` = share <=
    :data:`SIGNALS_MAX_SHARE`.
    """

    cache: bool
    bytes_per_job: int
    store_s: float
    kernel_s: float
    share: float

    def describe(self) -> dict[str, object]:
        """The manifest's record of the decision."""
        return {"cached": self.cache, "bytes_per_job": self.bytes_per_job,
                "estimated_store_s_per_job": self.store_s,
                "estimated_kernel_s_per_job": self.kernel_s,
                "estimated_store_share": round(self.share, 4),
                "rule": f"signals cached when storing them is estimated to cost <= "
                        f"{SIGNALS_MAX_SHARE:.0%} of computing the job again"}


def signals_rule(n_steps: int, n_out: int, workers: int = 1,
                 n_signals: int = PAPER_SIGNALS) -> SignalsRule:
    """Cache a job's signals (``n_out`` samples of ``n_signals`` float64) only when storing them
    is estimated to cost at most :data:`SIGNALS_MAX_SHARE` of recomputing the job (``n_steps``
    kernel steps on ``workers`` threads).

    The estimate uses measured constants (:data:`STORE_BYTES_PER_S`,
    :data:`KERNEL_CPU_S_PER_STEP`); it depends only on the plan and the worker count, so the
    same sweep makes the same decision every time. Both sides scale with the samples per step:
    on 2 workers, signals recorded every 104 or more integration steps are cached (every 2e-3 s
    at dt 1e-5 s: estimated 10 %); the bench's 1e-3 s (100 steps) is just past the line (21 %:
    the measured cost, 0.23 s of 1.1 s) and 1e-4 s far past it (206 %). On 1 worker, whose
    re-run would take twice as long, 52 steps suffice.
    """
    nbytes = n_out * n_signals * 8
    store = nbytes / STORE_BYTES_PER_S
    kernel = n_steps * KERNEL_CPU_S_PER_STEP / max(workers, 1)
    share = store / kernel if kernel > 0 else math.inf
    return SignalsRule(n_out > 0 and share <= SIGNALS_MAX_SHARE, nbytes, store, kernel, share)


class JobCache:
    """Finished jobs on disk, keyed by content hash (see the module docstring).

    ``corrupt`` maps the key of every entry found damaged by this object to what was wrong.
    """

    def __init__(self, root: Path | str | None = None) -> None:
        self.root = Path(root) if root is not None else DEFAULT_CACHE_DIR
        self.corrupt: dict[str, str] = {}
        try:
            self.root.mkdir(parents=True, exist_ok=True)
            self._db = sqlite3.connect(self.root / DB_NAME, timeout=SQLITE_TIMEOUT_S,
                                       check_same_thread=False)
            self._db.execute("PRAGMA synchronous=NORMAL")
            with self._db:
                columns = [r[1] for r in self._db.execute("PRAGMA table_info(jobs)")]
                if columns and "crc" not in columns:  # a cache from before checksums
                    self._db.execute("DROP TABLE jobs")
                for statement in SCHEMA:
                    self._db.execute(statement)
        except OSError as exc:
            raise EmaError(f"cannot create the job cache '{self.root}': {exc.strerror}", 1
                           ) from None
        except sqlite3.Error as exc:
            raise EmaError(f"the job cache '{self.root / DB_NAME}' cannot be used: {exc}", 1
                           ) from None

    def close(self) -> None:
        """Close the database."""
        self._db.close()

    def _query(self, sql: str, keys: Sequence[str], *extra: object) -> list[tuple]:
        """``sql`` (with ``{marks}`` for the keys, then ``extra`` parameters) over all keys."""
        rows: list[tuple] = []
        try:
            for a in range(0, len(keys), LOOKUP_BATCH):
                batch = list(keys[a:a + LOOKUP_BATCH])
                rows += self._db.execute(sql.format(marks=",".join("?" * len(batch))),
                                         [*batch, *extra]).fetchall()
        except sqlite3.Error as exc:
            raise EmaError(f"the job cache '{self.root / DB_NAME}' cannot be read: {exc}", 1
                           ) from None
        return rows

    def _bad(self, key: str, what: str) -> None:
        self.corrupt.setdefault(key, what)

    def lookup(self, keys: Iterable[str]) -> dict[str, np.ndarray]:
        """Verified metrics[N_METRICS] (SI) of those ``keys`` that are finished."""
        found: dict[str, np.ndarray] = {}
        for key, blob, crc in self._query(
                "SELECT key, metrics, crc FROM jobs WHERE key IN ({marks})", list(keys)):
            if len(blob) != N_METRICS * 8:
                self._bad(key, f"metrics row has {len(blob)} bytes, expected {N_METRICS * 8}")
            elif checksum(blob) != crc:
                self._bad(key, "metrics row does not match its checksum")
            else:
                found[key] = np.frombuffer(blob, dtype=np.float64).copy()
        return found

    def load_metrics(self, key: str) -> np.ndarray | None:
        """Verified metrics[N_METRICS] (SI) of one job, or None if not cached (or corrupt)."""
        return self.lookup([key]).get(key)

    def signal_rows(self, keys: Iterable[str], dec: int) -> dict[str, SignalRow]:
        """Where the signals recorded every ``dec`` steps of those ``keys`` that have them are."""
        return {key: (file, row, n_out, crc) for key, file, row, n_out, crc in self._query(
            "SELECT key, file, row, n_out, crc FROM signals WHERE key IN ({marks}) AND dec = ?",
            list(keys), dec)}

    def load_signals(self, key: str, dec: int) -> np.ndarray | None:
        """Verified signals[n_out, N_SIGNALS] (SI) recorded every ``dec`` steps, or None."""
        return self.load_signals_many([key], dec).get(key)

    def load_signals_many(self, keys: Iterable[str], dec: int, n_out: int | None = None,
                          n_signals: int | None = None) -> dict[str, np.ndarray]:
        """Verified signals[n_out, n_signals] (SI) of those ``keys`` that have them.

        ``n_out`` given: a stored row of another length counts as missing (another duration);
        ``n_signals`` given: one of another number of signals too (another actuator's record).
        """
        by_file: dict[str, list[tuple[str, int, int, int]]] = {}
        for key, (file, row, n, crc) in self.signal_rows(keys, dec).items():
            if n_out is None or n == n_out:
                by_file.setdefault(file, []).append((key, row, n, crc))
        found: dict[str, np.ndarray] = {}
        for file, rows in by_file.items():
            found.update(self._read_rows(file, rows, n_signals))
        return found

    def _read_rows(self, file: str, rows: list[tuple[str, int, int, int]],
                   n_signals: int | None = None) -> dict[str, np.ndarray]:
        """Rows of one chunk file, each checked against its CRC-32 (bad ones are recorded)."""
        path = self.root / "signals" / file
        out: dict[str, np.ndarray] = {}
        try:
            with open(path, "rb") as f:
                reader = HEADER_READERS.get(np.lib.format.read_magic(f))
                if reader is None:
                    raise ValueError("unknown .npy format version")
                shape, fortran, dtype = reader(f)
                if (fortran or dtype != np.dtype("<f8") or len(shape) != 3
                        or not 0 < shape[2] <= N_SIGNALS):
                    raise ValueError(f"unexpected array {shape} {dtype}")
                if n_signals is not None and shape[2] != n_signals:
                    return out  # another number of signals: not this run's record
                start = f.tell()
                for key, row, n_out, crc in rows:
                    if row >= shape[0] or shape[1] != n_out:
                        self._bad(key, f"signals file {file} has shape {shape}")
                        continue
                    buf = np.empty((n_out, shape[2]))
                    f.seek(start + row * buf.nbytes)
                    if f.readinto(buf.data) != buf.nbytes:
                        self._bad(key, f"signals file {file} is truncated")
                    elif checksum(buf) != crc:
                        self._bad(key, f"signals row {row} of {file} does not match its checksum")
                    else:
                        out[key] = buf
        except FileNotFoundError:
            for key, *_ in rows:
                self._bad(key, f"signals file {file} is missing")
        except (OSError, ValueError) as exc:
            for key, *_ in rows:
                if key not in out:
                    self._bad(key, f"signals file {file} cannot be read: {exc}")
        return out

    def has_signals(self, key: str, dec: int, n_out: int) -> bool:
        """True if the job's signals recorded every ``dec`` steps, n_out samples, are cached
        and intact."""
        return key in self.load_signals_many([key], dec, n_out)

    def store(self, keys: Sequence[str], metrics: np.ndarray, signals: np.ndarray | None,
              dec: int) -> None:
        """Store finished jobs: metrics[n, N_METRICS], signals[n, n_out, N_SIGNALS] or None.

        The signals file first, then every row in one transaction (all rows or none); files
        that no row refers to any more are deleted afterwards.
        """
        keys = list(keys)
        met_rows = []
        for r, key in enumerate(keys):
            blob = np.ascontiguousarray(metrics[r], dtype=np.float64).tobytes()
            met_rows.append((key, blob, checksum(blob)))
        sig_rows = []
        new_file: Path | None = None
        if signals is not None and dec > 0 and keys:
            signals = np.ascontiguousarray(signals, dtype=np.float64)
            file = f"{keys[0][:2]}/{keys[0]}-{secrets.token_hex(4)}-d{dec}.npy"
            new_file = self.root / "signals" / file
            save_array(new_file, signals)
            sig_rows = [(key, dec, file, r, signals.shape[1], checksum(signals[r]))
                        for r, key in enumerate(keys)]
        try:
            with self._db:
                old = {f for (f,) in self._query(
                    "SELECT DISTINCT file FROM signals WHERE key IN ({marks}) AND dec = ?",
                    keys, dec)} if sig_rows else set()
                self._db.executemany(
                    "INSERT OR REPLACE INTO jobs (key, metrics, crc) VALUES (?, ?, ?)", met_rows)
                self._db.executemany(
                    "INSERT OR REPLACE INTO signals (key, dec, file, row, n_out, crc) "
                    "VALUES (?, ?, ?, ?, ?, ?)", sig_rows)
                used = {f for (f,) in self._query(
                    "SELECT DISTINCT file FROM signals WHERE file IN ({marks})", sorted(old))}
        except BaseException as exc:
            if new_file is not None:
                new_file.unlink(missing_ok=True)
            if isinstance(exc, sqlite3.Error):
                raise EmaError(f"the job cache '{self.root / DB_NAME}' cannot be written: "
                               f"{exc}", 1) from None
            raise
        for file in old - used:  # a failure only costs disk space
            with contextlib.suppress(OSError):
                os.unlink(self.root / "signals" / file)
