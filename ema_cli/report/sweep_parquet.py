"""signals.parquet: a sweep's recorded signals streamed into one columnar file as jobs finish.

Why Parquet for the signals: one typed, columnar file instead of one CSV per job
(a 401-job sweep spent 85.7 s of 92.6 s writing 620 MB of CSV text). pandas
(``pd.read_parquet``), polars, DuckDB and R (arrow) read it natively; a reader loads only the
columns it names and skips the row groups whose job-id statistics exclude the jobs it filters
on; floats stay binary float64, exact. netCDF or Zarr would need xarray and a
dimensioned layout for no gain here. The file's schema metadata (key ``ema``) records the ema
version, the sweep, the time grid and every column's unit.

How it is written (measured with experiments/bench_sweep.py, 1,000 jobs, 2 cores, medians of
fresh processes; every choice exact, float64 bit for bit): uncompressed, because the float
columns barely compress (snappy 0.82x of the size, BYTE_STREAM_SPLIT + lz4/zstd 0.66x) and every
codec cost more time than the bytes it saved, even on this VM where fresh page cache takes only
0.4 GB/s (1e-4 s recording, paired runs: snappy +0.29 s, BYTE_STREAM_SPLIT + lz4 +0.79 s); the
signals converted to edge units and transposed into columns one tile (``TILE_ROWS`` samples,
all signals) per numpy call; each full row group encoded and written by a thread of its own
while the next is filled and the next chunk computes (pyarrow releases the GIL: 0.95 s instead
of 1.7 s for 1.36 GB alone); dictionary encoding for the job id, the swept values, ``t_s`` and
the reference signals only (the same for every job: 24 MB less at no measurable cost); page
size, batch size and row-group size made no measurable difference.
"""

from __future__ import annotations

import contextlib
import json
import math
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ema_cli import __version__
from ema_cli.errors import EmaError
from ema_cli.files import AtomicFile
from ema_cli.report.sweep_tables import axis_unit
from ema_cli.sim.tables import SIGNALS, Column, edge_unit  # noqa: F401 (re-exported)
from ema_cli.sweep.run import JOB_COLUMN, TIME_COLUMN

if TYPE_CHECKING:
    from ema_cli.sweep.plan import Plan

SIGNALS_FILE = "signals.parquet"
ROW_GROUP_BYTES = 32 * 2**20  # target uncompressed size of one row group of signals.parquet
PARQUET_COMPRESSION = "none"  # measured fastest (floats compress little); exact whatever the codec
PARQUET_COMPRESSION_LEVEL: int | None = None  # codec level (zstd); None: the codec's default
PARQUET_BYTE_STREAM_SPLIT = False  # BYTE_STREAM_SPLIT encoding for the signal columns
PARQUET_THREAD = True  # encode row groups in a thread of their own (two buffers)
TILE_ROWS = 2**14  # samples converted to columns by one numpy call (2.2 MB of signals) [-]
PARQUET_BATCH_VALUES = 65536  # values the writer encodes at a time (pyarrow's default: 1024)
PARQUET_PAGE_BYTES = 4 * 2**20  # data page size (pyarrow's default: 1 MiB)

class SignalsWriter:
    """Streams a sweep's recorded signals into ``signals.parquet`` as jobs finish.

    Long layout, one row per job and sample: ``job`` (id, dictionary-encoded), the swept
    values (metrics.csv's columns and units; a column mixing numbers and words such as 'off'
    is text), ``t_s``, then every signal of ``sim.tables.SIGNALS`` in edge units
    (``theta_load_deg``, ``omega_motor_rpm``, ...), float64. A job's rows are contiguous, in
    time order; jobs come in the order they finish (cached ones first, then each chunk's: job
    order for a fresh sweep on one machine). Jobs are gathered into row
    groups of about ``ROW_GROUP_BYTES``; ``job``, the swept values and ``t_s`` carry
    statistics (row-group filtering by job), the signals none (they cost time and no reader
    filters on them). Rows go into a temporary sibling: :meth:`commit` renames it into place,
    :meth:`discard` (or any error while writing) deletes it. A full row group is handed to the
    encoder thread (two buffers: the next one fills meanwhile); an error there is raised by the
    next :meth:`add` or :meth:`commit`.
    """

    def __init__(self, path: Path, plan: Plan) -> None:
        import pyarrow as pa
        import pyarrow.parquet as pq

        self.path = path
        self.plan = plan
        self.n_out = plan.n_steps // plan.dec + 1
        self.rows = 0
        self._pa = pa
        self._numeric: dict[str, np.ndarray] = {}
        self._text: dict[str, list[str | None]] = {}
        self._swept = list(dict.fromkeys(c for info in plan.axes for c in info.columns))
        for c in self._swept:
            values = [j.values.get(c, math.nan) for j in plan.jobs]
            if any(isinstance(v, str) for v in values):
                self._text[c] = [v if isinstance(v, str) else None if math.isnan(v) else
                                 repr(float(v)) for v in values]
            else:
                self._numeric[c] = np.array(values, dtype=np.float64)
        swept = self._swept
        self.columns = SIGNALS[:plan.n_signals]  # the signals the sweep records
        n_sig = len(self.columns)
        width = 2 + len(swept) + n_sig  # columns of 8 bytes or fewer
        self.group_jobs = max(1, min(len(plan.jobs), ROW_GROUP_BYTES // (self.n_out * 8 * width)))
        self._buffers: list[np.ndarray] = []  # two [n_sig, group_jobs * n_out], edge units
        self._buf: np.ndarray | None = None  # the one being filled
        self._sent: np.ndarray | None = None  # the one last handed to the encoder
        self._factors = np.array([[c.factor] for c in self.columns])  # SI -> edge units
        self._jobs: list[int] = []  # job index of each job in the buffer
        self._pool: Any = None  # the encoder thread
        self._pending: Any = None  # the row group it is writing (a Future)
        self._index = np.repeat(np.arange(self.group_jobs, dtype=np.int32), self.n_out)
        self._t = np.tile(np.arange(self.n_out) * (plan.dec * plan.dt), self.group_jobs)
        self.schema = signals_schema(plan, swept, self._text)
        self._file = AtomicFile(path)
        self._writer = None
        plain = [c.edge for c in self.columns if c.edge not in DICTIONARY_SIGNALS]
        try:
            self._writer = pq.ParquetWriter(
                self._file.tmp, self.schema, compression=PARQUET_COMPRESSION,
                compression_level=PARQUET_COMPRESSION_LEVEL,
                write_batch_size=PARQUET_BATCH_VALUES, data_page_size=PARQUET_PAGE_BYTES,
                use_dictionary=[JOB_COLUMN, *swept, TIME_COLUMN, *DICTIONARY_SIGNALS],
                column_encoding=(dict.fromkeys(plain, "BYTE_STREAM_SPLIT")
                                 if PARQUET_BYTE_STREAM_SPLIT else None),
                write_statistics=[JOB_COLUMN, *swept, TIME_COLUMN])
            if PARQUET_THREAD:
                from concurrent.futures import ThreadPoolExecutor

                self._pool = ThreadPoolExecutor(1, thread_name_prefix="ema-parquet")
        except BaseException as exc:
            self.discard()
            self._raise(exc)

    def _raise(self, exc: BaseException) -> None:
        if isinstance(exc, OSError):
            raise EmaError(f"cannot write '{self.path}': {exc}", 1) from None
        raise exc

    def add(self, jobs: Sequence[int], rows: Sequence[int], signals: np.ndarray) -> None:
        """Append job ``jobs[i]``'s SI ``signals[rows[i]]`` ([n_out, N_SIGNALS])."""
        try:
            rows = np.asarray(rows, dtype=np.int64)
            i = 0
            while i < len(rows):
                if self._buf is None:
                    self._buf = self._free_buffer()
                # a run of consecutive rows that fits the row group
                m = min(self.group_jobs - len(self._jobs), len(rows) - i)
                r0 = int(rows[i])
                run = rows[i:i + m] - r0 == np.arange(m)
                if not run.all():
                    m = int(np.argmin(run))  # >= 1: run[0] is True
                self._convert(signals[r0:r0 + m], len(self._jobs) * self.n_out)
                self._jobs.extend(jobs[i:i + m])
                i += m
                if len(self._jobs) == self.group_jobs:
                    self._flush()
        except BaseException as exc:
            self.discard()
            self._raise(exc)

    def _free_buffer(self) -> np.ndarray:
        """The buffer the row group being written does not use (two in all: :meth:`_flush`
        waits for the previous row group before it hands on the next)."""
        if len(self._buffers) < 2:
            self._buffers.append(np.empty((len(self.columns), self.group_jobs * self.n_out)))
            return self._buffers[-1]
        return self._buffers[0] if self._sent is self._buffers[1] else self._buffers[1]

    def _convert(self, src: np.ndarray, a: int) -> None:
        """SI ``src[m, n_out, N_SIGNALS]`` into the buffer's columns from sample ``a`` on, in
        edge units: one numpy call per tile of :data:`TILE_ROWS` samples (the tile stays in
        the CPU cache while it is transposed)."""
        flat = src.reshape(-1, len(self.columns))
        for b in range(0, len(flat), TILE_ROWS):
            tile = flat[b:b + TILE_ROWS]
            np.multiply(tile.T, self._factors, out=self._buf[:, a + b:a + b + len(tile)])

    def _wait(self) -> None:
        """Wait for the row group being written (re-raises its error)."""
        pending, self._pending = self._pending, None
        if pending is not None:
            pending.result()

    def _flush(self) -> None:
        """Write the buffered jobs as one row group: in the encoder thread, while the next
        row group is filled (and the next chunk computed)."""
        m = len(self._jobs)
        if m == 0 or self._buf is None or self._writer is None:
            return
        table = self._table(m)
        self._wait()  # one row group in flight: the other buffer is free again
        if self._pool is not None:
            self._pending = self._pool.submit(self._writer.write_table, table,
                                              row_group_size=table.num_rows)
        else:
            self._writer.write_table(table, row_group_size=table.num_rows)
        self.rows += table.num_rows
        self._jobs = []
        self._sent, self._buf = self._buf, None

    def _table(self, m: int) -> Any:
        """The buffered ``m`` jobs as an Arrow table (the signal columns are views of the
        buffer: no copy)."""
        assert self._buf is not None
        pa = self._pa
        n = m * self.n_out
        index = pa.array(self._index[:n])
        jobs = np.array(self._jobs)

        def text(values: list[str | None]) -> Any:
            code = {v: k for k, v in enumerate(dict.fromkeys(v for v in values if v is not None))}
            codes = np.repeat(np.array([code.get(v, -1) for v in values], dtype=np.int32),
                              self.n_out)  # -1: no value (null)
            return pa.DictionaryArray.from_arrays(pa.array(codes, mask=codes < 0),
                                                  pa.array(list(code), pa.string()))

        columns: list[Any] = [pa.DictionaryArray.from_arrays(
            index, pa.array([self.plan.jobs[i].id for i in jobs], pa.string()))]
        for c in self._swept:
            if c in self._numeric:
                columns.append(pa.array(np.repeat(self._numeric[c][jobs], self.n_out)))
            else:
                columns.append(text([self._text[c][i] for i in jobs]))
        columns.append(pa.array(self._t[:n]))
        columns += [pa.array(self._buf[k, :n]) for k in range(len(self.columns))]
        return pa.Table.from_arrays(columns, schema=self.schema)

    def commit(self) -> Path:
        """Write the last row group, close the file and rename it into place."""
        try:
            self._flush()
            self._wait()
            assert self._writer is not None
            self._writer.close()
            self._writer = None
            self._stop()
            return self._file.commit()
        except BaseException as exc:
            self.discard()
            self._raise(exc)
            raise  # not reached

    def _stop(self) -> None:
        """End the encoder thread once the row group it writes is done (errors ignored)."""
        with contextlib.suppress(Exception):
            self._wait()
        if self._pool is not None:
            self._pool.shutdown()
            self._pool = None

    def discard(self) -> None:
        """Close and delete the unfinished file (a no-op after :meth:`commit`)."""
        self._stop()  # first: the encoder thread may be writing into the file
        if self._writer is not None:
            writer, self._writer = self._writer, None
            with contextlib.suppress(Exception):  # the file is deleted anyway
                writer.close()
        self._file.discard()


DICTIONARY_SIGNALS = ("theta_ref_deg", "omega_ref_deg_s", "torque_load_nm")
"""Signals the same for every job of most sweeps (the input, the external torque):
dictionary-encoded, they shrink to almost nothing."""


def _swept_units(plan: Plan) -> dict[str, str]:
    units: dict[str, str] = {}
    for info in plan.axes:
        for c in info.columns:
            if c.endswith("_pct"):
                units[c] = "%"
            elif info.kind == "parameter" or c == info.columns[-1] and info.kind != "placement":
                units[c] = axis_unit(info)
            elif c.endswith("_magnitude"):
                units[c] = info.unit or f"see {info.name}_unit"
    return units


def signals_schema(plan: Plan, swept: Sequence[str], text: Any) -> Any:
    """The Arrow schema of signals.parquet, with units and provenance in its metadata."""
    import pyarrow as pa

    units = _swept_units(plan)
    dict_text = pa.dictionary(pa.int32(), pa.string())

    def meta(unit: str | None, description: str) -> dict[str, str]:
        return {"description": description, **({"unit": unit} if unit else {})}

    fields = [pa.field(JOB_COLUMN, dict_text, nullable=False,
                       metadata=meta(None, "job id, as in metrics.csv"))]
    for c in swept:  # floats are never null (NaN is a value): no definition levels to write
        fields.append(pa.field(c, dict_text if c in text else pa.float64(),
                               nullable=c in text,
                               metadata=meta(units.get(c), "swept value, as in metrics.csv")))
    fields.append(pa.field(TIME_COLUMN, pa.float64(), nullable=False,
                           metadata=meta("s", "time")))
    fields += [pa.field(c.edge, pa.float64(), nullable=False,
                        metadata=meta(edge_unit(c), c.description))
               for c in SIGNALS[:plan.n_signals]]
    info = {
        "ema_version": __version__, "sweep": plan.cfg.name, "sweep_key": plan.key,
        "layout": "long: one row per job and sample; filter on 'job' for one run",
        "jobs": len(plan.jobs), "samples_per_job": plan.n_steps // plan.dec + 1,
        "dt_s": plan.dt, "output_interval_s": plan.dec * plan.dt,
        "duration_s": plan.duration, "input": plan.signal.describe(),
        "units": {f.name: f.metadata[b"unit"].decode() for f in fields
                  if f.metadata and b"unit" in f.metadata},
    }
    return pa.schema(fields, metadata={"ema": json.dumps(info)})
