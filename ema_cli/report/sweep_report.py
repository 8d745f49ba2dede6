"""A sweep's output folder: resolved config, manifest, metrics.csv, signals, figures, summary.

Layout of ``results/sweep/<name>/<stamp>_<hash>/`` (or ``--out``)::

    config.resolved.yaml      the validated config, every default filled in
    manifest.json             version, git commit, seed, job counts, timings, per-job status
    metrics.csv               one row per job: swept values (paper units) + every metric
    signals.parquet           the recorded signals of every job (outputs.timeseries), long
                              layout: job, swept values, t_s, one column per signal (edge units)
    timeseries/<job>.csv      the same per job, only if outputs.per_job_csv (slow for big sweeps)
    figures/*.png             overlays vs time per axis, metrics vs magnitude per axis
    summary.md                the metrics table and the figures

Every file is written atomically (temporary sibling + rename); signals.parquet is streamed into
its temporary sibling as chunks finish (:class:`SignalsWriter`) and renamed into place only
when the sweep completes, so an interrupted sweep leaves neither a partial file nor the
temporary one. :func:`run_sweep` runs a sweep (``sweep.run.compute_sweep``) and writes this
folder as it goes.

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
import time
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import pandas as pd
import yaml

from ema_cli import __version__
from ema_cli.errors import EmaError
from ema_cli.files import RESULTS_ROOT, AtomicFile
from ema_cli.report.rundir import (
    CACHE_NAME,
    MARKER,
    check_output,
    finish_output,
    manifest,
    prepare_output,
    write_csv,
    write_figure,
    write_json,
    write_text,
)
from ema_cli.sim.tables import METRIC_BY_EDGE, N_SIGNALS, SIGNALS, Column
from ema_cli.sweep.cache import DEFAULT_CACHE_DIR
from ema_cli.sweep.run import JOB_COLUMN, TIME_COLUMN, SweepResult, compute_sweep
from ema_cli.units import DEG, RPM

if TYPE_CHECKING:
    from matplotlib.figure import Figure

    from ema_cli.config.study import StudyConfig
    from ema_cli.sweep.plan import AxisInfo, Plan

SIGNALS_FILE = "signals.parquet"
ROW_GROUP_BYTES = 32 * 2**20  # target uncompressed size of one row group of signals.parquet
PARQUET_COMPRESSION = "none"  # measured fastest (floats compress little); exact whatever the codec
PARQUET_COMPRESSION_LEVEL: int | None = None  # codec level (zstd); None: the codec's default
PARQUET_BYTE_STREAM_SPLIT = False  # BYTE_STREAM_SPLIT encoding for the signal columns
PARQUET_THREAD = True  # encode row groups in a thread of their own (two buffers)
TILE_ROWS = 2**14  # samples converted to columns by one numpy call (2.2 MB of signals) [-]
PARQUET_BATCH_VALUES = 65536  # values the writer encodes at a time (pyarrow's default: 1024)
PARQUET_PAGE_BYTES = 4 * 2**20  # data page size (pyarrow's default: 1 MiB)
MAX_GROUPS_PER_AXIS = 3  # overlays per axis when other axes vary: first, middle, last value
MAX_METRIC_LINES = 10  # most lines (combinations of the other axes) in one metric plot
MAX_SUMMARY_ROWS = 200  # rows of the metrics table in summary.md (metrics.csv has all)
CSV_FORMAT = "%.9g"  # float format of every CSV (as `ema simulate` writes them)
FINISHED = ("ok", "diverged")
OVERLAYS = {
    "errors": ("tracking error", [("err_pos_deg", "position error θref − θload [deg]"),
                                  ("err_vel_deg_s", "velocity error ωref − ωload [deg/s]")],
               None),
    "response": ("response", [("theta_load_deg", "load position [deg]"),
                              ("omega_load_deg_s", "load velocity [deg/s]")],
                 ["theta_ref_deg", "omega_ref_deg_s"]),
}


SHORT_LABELS = {
    "iae_pos_deg_s": "IAE position [deg·s]",
    "ise_pos_deg2_s": "ISE position [deg²·s]",
    "itae_pos_deg_s2": "ITAE position [deg·s²]",
    "rms_err_pos_deg": "RMS position error [deg]",
    "max_abs_err_pos_deg": "max abs position error [deg]",
    "iae_vel_deg": "IAE velocity [deg]",
    "ise_vel_deg2_s": "ISE velocity [deg²/s]",
    "itae_vel_deg_s": "ITAE velocity [deg·s]",
    "rms_err_vel_deg_s": "RMS velocity error [deg/s]",
    "max_abs_err_vel_deg_s": "max abs velocity error [deg/s]",
    "ss_err_pos_deg": "steady-state error, last 10 % [deg]",
    "overshoot_pct": "overshoot [% of step]",
    "rise_time_s": "rise time 10-90 % [s]",
    "settling_time_s": "settling time 2 % [s]",
    "t50_s": "time to 50 % (lag) [s]",
    "p2p_err_pos_deg": "residual oscillation p-p, last 20 % [deg]",
    "p2p_err_vel_deg_s": "velocity oscillation p-p, last 20 % [deg/s]",
    "peak_current_a": "peak current [A]",
    "peak_voltage_cmd_v": "peak voltage demand [V]",
    "peak_load_rate_deg_s": "peak load rate [deg/s]",
    "peak_torque_shaft_nm": "peak shaft torque [N·m]",
    "t_end_s": "time reached [s]",
}
"""Short metric names with edge units, for figure panels and table headers."""


def metric_label(edge: str) -> str:
    """A metric's short name with its edge unit, e.g. ``RMS velocity error [deg/s]``."""
    if edge in SHORT_LABELS:
        return SHORT_LABELS[edge]
    col = METRIC_BY_EDGE[edge]
    unit = col.si_unit
    if math.isclose(col.factor, 1 / DEG):
        unit = unit.replace("rad", "deg")
    elif math.isclose(col.factor, 1 / DEG**2):
        unit = unit.replace("rad^2", "deg^2")
    return f"{col.description} [{unit}]"


def default_cache_dir(out: Path | None) -> Path:
    """The job cache of outputs written to ``out``: the shared ``results/.cache/sweep`` when
    they go under ``results/`` (``out`` None included), else ``<out>/.cache`` (nothing is
    written outside an explicit output folder)."""
    if out is not None:
        try:
            Path(out).resolve().relative_to(RESULTS_ROOT.resolve())
        except ValueError:
            return Path(out) / CACHE_NAME
    return DEFAULT_CACHE_DIR


def run_sweep(
    cfg: StudyConfig,
    out: Path | None = None,
    n_jobs: int | None = None,
    backend: str | None = None,
    force: bool = False,
    progress: bool = True,
    *,
    scheduler: str | None = None,
    chunk_size: int | None = None,
    cache_dir: Path | None = None,
    base_dir: Path | None = None,
    source: str = "config",
    overrides: Sequence[tuple[str, Any]] = (),
    write: bool = True,
    reuse_finished: bool = False,
    figures: str = "draw",
) -> SweepResult:
    """Run a sweep end to end (``sweep.run.compute_sweep``) and write its outputs.

    out        output folder; None: ``results/sweep/<name>/<stamp>_<hash>/``. An existing folder is
               reused only if it holds an earlier run of the same sweep (resume in place).
    cache_dir  job cache; None: :func:`default_cache_dir` when writing (``results/.cache/
               sweep``, or ``OUT/.cache`` when ``out`` is outside results/), no cache otherwise
    overrides  the ``--set`` pairs, recorded in the manifest
    write      False: write nothing (no folder, and no cache unless ``cache_dir`` is given);
               the recorded signals stay readable from the result (kept in memory)
    reuse_finished  ``out`` belongs to a run being resumed (``ema reproduce``): if it holds the
               finished run of this very sweep, it is read (metrics from the job cache, signals
               from its signals.parquet), never rewritten; otherwise the usual policy applies

    figures    draw: the figures are drawn before this returns; none: no figures (the
               manifest says so); background: drawn in a thread while the caller prints, the
               folder finished by :func:`finish_sweep`, which the caller must then call

    The other arguments are ``compute_sweep``'s. The folder is created once the sweep is
    planned, before any job runs; signals.parquet is streamed as chunks finish and renamed
    into place when the sweep ends. On Ctrl-C (or an error) metrics.csv, summary.md and the
    manifest of the finished jobs are written, the unfinished signals file is deleted, and the
    exception is re-raised. A failed job's error text goes into the manifest.
    """
    t_start = time.perf_counter()
    folder: Path | None = None
    writer: SignalsWriter | None = None
    if write and out is not None and not Path(out).is_dir():
        check_output(Path(out), "sweep")  # a file, or below one: refused before the cache is
    if cache_dir is None and write:
        cache_dir = default_cache_dir(out)

    reused = False

    def on_start(plan: Plan) -> None:
        nonlocal folder, writer, reused
        if write and reuse_finished and out is not None and finished_sweep(Path(out), plan):
            folder, reused = Path(out), True
            return
        if write:
            folder = prepare_folder(plan, out, overrides)
            if plan.cfg.outputs.timeseries and plan.dec > 0:
                writer = SignalsWriter(folder / SIGNALS_FILE, plan)

    def on_signals(jobs: Sequence[int], rows: Sequence[int], signals: np.ndarray) -> None:
        if writer is not None:
            writer.add(jobs, rows, signals)

    def on_finish(result: SweepResult, aborted: bool) -> None:
        result.folder = folder
        if folder is None:
            return
        if reused:  # a finished run of this sweep: read, never rewritten
            if (folder / SIGNALS_FILE).is_file():
                result.signals_file = folder / SIGNALS_FILE
            return
        timings = result.timings
        t2 = time.perf_counter()
        failed: EmaError | None = None
        try:
            if writer is not None and not aborted:
                try:
                    result.signals_file = writer.commit()
                except EmaError as exc:  # e.g. disk full: the other outputs are still written
                    failed = exc
            write_outputs(result, partial=aborted or failed is not None,
                          figures=figures == "draw")
        except KeyboardInterrupt:  # Ctrl-C while writing: the manifest still says so
            result.interrupted = True
            raise
        finally:
            if writer is not None:
                writer.discard()  # after a commit: nothing left to delete
            timings["outputs"] = time.perf_counter() - t2
            timings["total"] = time.perf_counter() - t_start
            write_manifest(result, overrides, failed.message if failed else None)
        if failed is not None:
            raise failed
        if aborted:
            return
        if figures == "background" and result.plan.cfg.outputs.figures:
            result.pending = _FigureThread(result, overrides)
        else:
            _finish_if_complete(result)

    return compute_sweep(cfg, n_jobs, backend, force, progress, scheduler=scheduler,
                         chunk_size=chunk_size, cache_dir=cache_dir, base_dir=base_dir,
                         source=source, on_start=on_start, on_signals=on_signals,
                         on_finish=on_finish,
                         keep_signals=not (write and cfg.outputs.timeseries))


class _FigureThread:
    """The figures of a finished sweep, drawn in a thread of this process (Agg, no pyplot
    state shared with another thread) while the caller prints its summary; the manifest and
    the finished mark are written when :func:`finish_sweep` joins it. (A forked
    ``figure_worker`` cannot serve here: numba's native threads are running by then.)"""

    def __init__(self, result: SweepResult, overrides: Sequence[tuple[str, Any]]) -> None:
        import threading

        self.result, self.overrides = result, overrides
        self.paths: list[Path] = []
        self.error: BaseException | None = None
        self.seconds = 0.0
        self.thread = threading.Thread(target=self._run, name="ema-figures", daemon=True)
        self.thread.start()

    def _run(self) -> None:
        t0 = time.perf_counter()
        try:
            assert self.result.folder is not None
            self.paths = _write_figures(self.result, self.result.folder / "figures")
        except BaseException as exc:  # noqa: BLE001 - re-raised in the caller's thread
            self.error = exc
        self.seconds = time.perf_counter() - t0

    def join(self) -> None:
        """Wait for the figures, then write the manifest and mark the folder finished."""
        self.thread.join()
        result = self.result
        result.figures = self.paths
        result.timings["figures"] = self.seconds
        error = None
        if self.error is not None:
            error = f"the figures could not be drawn: {type(self.error).__name__}: " \
                    f"{' '.join(str(self.error).split())[:200]}"
        if self.paths:  # summary.md links the figures
            assert result.folder is not None
            write_text(result.folder / "summary.md", summary_markdown(result))
        write_manifest(result, self.overrides, error)
        if error is not None:
            raise EmaError(error, 1)
        _finish_if_complete(result)


def finish_sweep(result: SweepResult) -> None:
    """Wait for figures drawn in the background (``run_sweep(figures="background")``), write
    the final manifest and mark the folder finished; nothing to do otherwise."""
    pending = getattr(result, "pending", None)
    if pending is not None:
        result.pending = None
        pending.join()


def save_sweep(result: SweepResult, out: Path | None = None,
               overrides: Sequence[tuple[str, Any]] = ()) -> Path:
    """Write the folder ``ema sweep`` writes for a sweep computed without one (the Python
    API's ``Sweep.save``) -> the folder; ``out`` None: a new one under ``results/sweep/<name>/``."""
    t0 = time.perf_counter()
    plan = result.plan
    folder = result.folder = prepare_folder(plan, out, overrides)
    if plan.cfg.outputs.timeseries and plan.dec > 0:
        writer = SignalsWriter(folder / SIGNALS_FILE, plan)
        try:
            status = result.metrics["status"]
            for j in plan.jobs:
                if status.iloc[j.index] in FINISHED:
                    writer.add([j.index], [0], result.signals(j.index)[None])
            result.signals_file = writer.commit()
        finally:
            writer.discard()
    write_outputs(result)
    result.timings["outputs"] = time.perf_counter() - t0
    write_manifest(result, overrides)
    _finish_if_complete(result)
    return folder


def _finish_if_complete(result: SweepResult) -> None:
    """Mark the folder finished (``rundir.finish_output``: never resumed nor rewritten) once
    every job finished: none pending, none failed, not interrupted."""
    counts = result.counts()
    if (result.folder is not None and not result.interrupted and not counts["pending"]
            and not counts["failed"]):
        finish_output(result.folder)


def finished_sweep(folder: Path, plan: Plan) -> bool:
    """True if ``folder`` holds the finished ``ema sweep`` run of ``plan`` (same sweep key)."""
    try:
        mark = json.loads((folder / MARKER).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return False
    return (isinstance(mark, dict) and mark.get("command") == "sweep"
            and mark.get("fingerprint") == plan.key and mark.get("finished") is True)


def remove_stale_temporaries(folder: Path) -> None:
    """Delete the temporary files (``.<name>.<12 hex>.tmp``, ``files.AtomicFile``) an earlier,
    killed run left in ``folder`` and its figures/ and timeseries/ (resuming it: no other
    process writes there)."""
    import re

    ours = re.compile(r"\..+\.[0-9a-f]{12}\.tmp")
    for sub in (folder, folder / "figures", folder / "timeseries"):
        try:
            entries = list(sub.iterdir())
        except OSError:
            continue
        for p in entries:
            if ours.fullmatch(p.name) and p.is_file() and not p.is_symlink():
                with contextlib.suppress(OSError):
                    p.unlink()


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
        width = 2 + len(swept) + N_SIGNALS  # columns of 8 bytes or fewer
        self.group_jobs = max(1, min(len(plan.jobs), ROW_GROUP_BYTES // (self.n_out * 8 * width)))
        self._buffers: list[np.ndarray] = []  # two [N_SIGNALS, group_jobs * n_out], edge units
        self._buf: np.ndarray | None = None  # the one being filled
        self._sent: np.ndarray | None = None  # the one last handed to the encoder
        self._factors = np.array([[c.factor] for c in SIGNALS])  # SI -> edge units
        self._jobs: list[int] = []  # job index of each job in the buffer
        self._pool: Any = None  # the encoder thread
        self._pending: Any = None  # the row group it is writing (a Future)
        self._index = np.repeat(np.arange(self.group_jobs, dtype=np.int32), self.n_out)
        self._t = np.tile(np.arange(self.n_out) * (plan.dec * plan.dt), self.group_jobs)
        self.schema = signals_schema(plan, swept, self._text)
        self._file = AtomicFile(path)
        self._writer = None
        plain = [c.edge for c in SIGNALS if c.edge not in DICTIONARY_SIGNALS]
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
            self._buffers.append(np.empty((N_SIGNALS, self.group_jobs * self.n_out)))
            return self._buffers[-1]
        return self._buffers[0] if self._sent is self._buffers[1] else self._buffers[1]

    def _convert(self, src: np.ndarray, a: int) -> None:
        """SI ``src[m, n_out, N_SIGNALS]`` into the buffer's columns from sample ``a`` on, in
        edge units: one numpy call per tile of :data:`TILE_ROWS` samples (the tile stays in
        the CPU cache while it is transposed)."""
        flat = src.reshape(-1, N_SIGNALS)
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
        columns += [pa.array(self._buf[k, :n]) for k in range(N_SIGNALS)]
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


def edge_unit(col: Column) -> str:
    """The unit of a signal or metric column at the edge (``deg``, ``rpm``, ``N*m``, ...)."""
    if math.isclose(col.factor, 1 / DEG):
        return col.si_unit.replace("rad", "deg")
    if math.isclose(col.factor, 1 / DEG**2):
        return col.si_unit.replace("rad^2", "deg^2")
    if math.isclose(col.factor, 1 / RPM):
        return "rpm"
    return col.si_unit


def _swept_units(plan: Plan) -> dict[str, str]:
    units: dict[str, str] = {}
    for info in plan.axes:
        for c in info.columns:
            if c.endswith("_pct"):
                units[c] = "%"
            elif info.kind == "parameter" or c == info.columns[-1] and info.kind != "placement":
                units[c] = _unit_of(info)
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
                        metadata=meta(edge_unit(c), c.description)) for c in SIGNALS]
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


def prepare_folder(plan: Plan, out: Path | None, overrides: Sequence[tuple[str, Any]]) -> Path:
    """Create the output folder before any job runs (so a bad ``--out`` loses nothing).

    The one ``--out`` policy (``rundir.prepare_output``): a new or empty folder, or an earlier
    unfinished run of the same sweep (same ``plan.key``), which is resumed in place (the
    temporary files a killed run left there are deleted first). A sweep whose every job
    finished is marked finished: it is never rewritten. Anything else is refused, never
    overwritten.
    """
    folder, resumed = prepare_output("sweep", plan.cfg.name, plan.key, out, resume=True)
    if resumed:
        remove_stale_temporaries(folder)
    write_text(folder / "config.resolved.yaml",
               yaml.safe_dump(plan.cfg.model_dump(mode="json"), sort_keys=False))
    write_json(folder / "manifest.json", {  # provisional: identifies the sweep for a resume
        "command": "sweep", "name": plan.cfg.name, "sweep_key": plan.key, "status": "running",
        "n_jobs": len(plan.jobs), "overrides": [list(o) for o in overrides]})
    return folder


def write_manifest(result: SweepResult, overrides: Sequence[tuple[str, Any]],
                   error: str | None = None) -> None:
    """manifest.json: provenance, job counts, timings and every job's status and error;
    ``error``: why the outputs are incomplete (e.g. signals.parquet could not be written)."""
    plan, folder = result.plan, result.folder
    assert folder is not None
    counts = result.counts()
    if result.interrupted:
        state = "interrupted"
    elif counts["failed"] or counts["pending"] or error:
        state = "incomplete"
    else:
        state = "complete"
    status, errors = list(result.metrics["status"]), list(result.metrics["error"])
    jobs = [{"job": j.id, "label": j.label, "key": j.key, "status": status[j.index],
             **({"error": errors[j.index]} if errors[j.index] else {})} for j in plan.jobs]
    write_json(folder / "manifest.json", manifest(
        "sweep", name=plan.cfg.name, description=plan.cfg.description, sweep_key=plan.key,
        status=state, seed=plan.cfg.seed, input=plan.signal.describe(),
        duration_s=plan.duration, dt_s=plan.dt, n_steps=plan.n_steps,
        output_interval_s=plan.output_interval if plan.dec else None,
        job_counts={"total": len(plan.jobs), "unique_runs": plan.n_unique,
                    "computed": result.computed, "cached": result.cached, **counts},
        wall_time_s=result.timings.get("total"), timings_s=result.timings,
        backend=result.backend, workers=result.workers,
        cache_dir=result.cache.root if result.cache is not None else None,
        cache_corrupt_entries=result.cache_corrupt,
        signals_cache=(result.signals_rule.describe()
                       if result.signals_rule is not None and result.cache is not None else None),
        signals_file=(str(result.signals_file.relative_to(folder))
                      if result.signals_file is not None else None),
        relative_scales=plan.scales, warnings=result.warnings, notes=plan.notes,
        overrides=[list(o) for o in overrides], figures=[str(p.relative_to(folder))
                                                         for p in result.figures],
        **({"error": error} if error else {}), jobs=jobs))


def write_outputs(result: SweepResult, partial: bool = False, figures: bool = True) -> None:
    """Write metrics.csv, the per-job CSVs (if asked), the figures and summary.md (then call
    :func:`write_manifest`; signals.parquet is already in place). ``partial`` (an aborted
    sweep): only metrics.csv and summary.md; ``figures`` False: no figures (none asked, or
    drawn elsewhere).
    """
    folder = result.folder
    assert folder is not None
    write_csv(folder / "metrics.csv", result.metrics, float_format=CSV_FORMAT)
    if not partial:
        if result.plan.cfg.outputs.per_job_csv and result.plan.dec > 0:
            _write_job_csvs(result, folder / "timeseries")
        if figures:
            result.figures = _write_figures(result, folder / "figures")
    write_text(folder / "summary.md", summary_markdown(result))


def _write_job_csvs(result: SweepResult, folder: Path) -> None:
    """timeseries/<job>.csv for every finished job (t_s, then every signal in edge units):
    read row group by row group from signals.parquet when it was written."""
    columns = [TIME_COLUMN, *(c.edge for c in SIGNALS)]
    if result.signals_file is None:
        df = result.metrics
        for j in result.plan.jobs:
            if df["status"].iloc[j.index] in FINISHED:
                write_csv(folder / f"{j.id}.csv", result.timeseries(j.id),
                          float_format=CSV_FORMAT)
        return
    import pyarrow.parquet as pq

    pf = pq.ParquetFile(result.signals_file)
    for g in range(pf.num_row_groups):
        table = pf.read_row_group(g, columns=[JOB_COLUMN, *columns]).to_pandas()
        for job, rows in table.groupby(JOB_COLUMN, sort=False, observed=True):
            write_csv(folder / f"{job}.csv", rows[columns], float_format=CSV_FORMAT)


# --------------------------------------------------------------------------------- figures


def _finished(result: SweepResult) -> pd.DataFrame:
    df = result.metrics.copy()
    df["_index"] = range(len(df))
    df["_baseline"] = [j.baseline for j in result.plan.jobs]
    return df[df["status"].isin(FINISHED)]


def _evenly(items: list[Any], k: int) -> list[Any]:
    """At most ``k`` items, evenly spaced, first and last included."""
    if len(items) <= k:
        return items
    idx = np.unique(np.round(np.linspace(0, len(items) - 1, k)).astype(int))
    return [items[i] for i in idx]


def _point_label(result: SweepResult, index: int, axis: int) -> str:
    """The part of a job's label that belongs to one axis."""
    job = result.plan.jobs[index]
    return job.parts[axis] if axis < len(job.parts) else job.label


def _others_label(result: SweepResult, index: int, axis: int) -> str:
    """The label parts of every other axis (what stays fixed along one curve family)."""
    return ", ".join(p for k, p in enumerate(result.plan.jobs[index].parts) if k != axis)


def _groups(result: SweepResult, df: pd.DataFrame, axis: int) -> list[pd.DataFrame]:
    """Rows sharing the values of every other axis (grid), or all rows (zip / one axis)."""
    plan = result.plan
    rows = df[~df["_baseline"]]
    if len(plan.axes) == 1 or plan.cfg.sweep.mode == "zip":
        return [rows] if len(rows) else []
    others = [k for k in range(len(plan.axes)) if k != axis]
    key = rows["_index"].map(lambda i: tuple(plan.jobs[i].point_index[k] for k in others))
    return [g for _, g in rows.groupby(key, sort=True)]


def _slug(text: str) -> str:
    """A file-name-safe version of ``text`` ('%' -> 'pct')."""
    text = text.replace("%", "pct")
    keep = "".join(c if c.isalnum() or c in "-_." else "-" for c in text)
    return "-".join(p for p in keep.split("-") if p)[:80]


def sweep_figures(result: SweepResult, kinds: Sequence[str] | None = None
                  ) -> list[tuple[str, Figure]]:
    """The sweep's figures as (file stem, Figure), as ``ema sweep`` draws them: ``kinds`` of
    errors, response, metrics (default: ``outputs.figures``). The caller closes them."""
    return list(_figures(result, kinds))


def _write_figures(result: SweepResult, folder: Path) -> list[Path]:
    paths = []
    for name, fig in _figures(result):  # one at a time: each is closed once written
        path = folder / f"{name}.png"
        write_figure(path, fig)
        paths.append(path)
    return paths


def _figures(result: SweepResult, kinds: Sequence[str] | None = None
             ) -> Iterator[tuple[str, Figure]]:
    plan = result.plan
    wanted = plan.cfg.outputs.figures if kinds is None else kinds
    df = _finished(result)
    if not wanted or df.empty:
        return
    axes = plan.axes[:1] if plan.cfg.sweep.mode == "zip" else plan.axes
    for info in axes:
        for kind in ("errors", "response"):
            if kind in wanted and plan.dec > 0:
                yield from _overlays(result, df, info, kind)
        if "metrics" in wanted:
            yield from _metric_plots(result, df, info)


def _baseline_series(result: SweepResult, df: pd.DataFrame) -> list[tuple[str, pd.DataFrame]]:
    base = df[df["_baseline"]]
    if base.empty:
        return []
    return [("baseline (swept nonlinearities off)", result.timeseries(int(base["_index"].iloc[0])))]


def _overlays(result: SweepResult, df: pd.DataFrame, info: AxisInfo,
              kind: str) -> Iterator[tuple[str, Figure]]:
    """Overlays vs time; the curves are read from signals.parquet once it is written."""
    plan = result.plan
    what, columns, reference = OVERLAYS[kind]
    zip_mode = plan.cfg.sweep.mode == "zip"
    for g, group in enumerate(_evenly(_groups(result, df, info.index), MAX_GROUPS_PER_AXIS)):
        subsets: list[tuple[str, str, pd.DataFrame]] = [("", "", group)]
        if info.group_column is not None:  # one overlay per placement, then per shared value
            subsets = [(str(name), _slug(str(name)), sub)
                       for name, sub in group.groupby(info.group_column, sort=False)]
            if info.unit:
                unit = "% of the baseline's peak signal" if info.unit == "%" else info.unit
                shared = [(f"all at {v:g} {unit}", f"at-{v:g}{_slug(info.unit)}", sub)
                          for v, sub in group.groupby(info.x_column, sort=True) if len(sub) > 1]
                subsets += _evenly(shared, MAX_GROUPS_PER_AXIS)
        for tag, file_tag, sub in subsets:
            idx = _evenly(list(sub["_index"]), plan.cfg.outputs.max_curves)
            series = _baseline_series(result, df)
            for i in idx:
                label = (plan.jobs[i].label if zip_mode else
                         _point_label(result, i, info.index))
                series.append((label, result.timeseries(int(i))))
            others = "" if zip_mode else _others_label(result, int(idx[0]), info.index)
            per = "run" if zip_mode else info.name
            title = (f"{plan.cfg.name}: {what} of position and velocity, one curve per {per}"
                     f"{' (' + tag + ')' if tag else ''}\ninput: {plan.signal.describe()}"
                     f"{'; ' + others if others else ''}\n{info.description}")
            from ema_cli.report.sweep_figures import overlay_figure  # matplotlib: lazily

            fig = overlay_figure(series, title, columns, legend_title=per, reference=reference)
            name = f"{kind}_{info.name}" + (f"_{file_tag}" if file_tag else "") + (
                f"_g{g}" if len(_groups(result, df, info.index)) > 1 else "")
            yield name, fig


def _baseline_label(info: AxisInfo, baseline: pd.Series | None) -> str:
    """``baseline (gap1 = 1.024 N*m/rad)``: the baseline's value on this axis, when it has one."""
    if baseline is None or info.kind == "placement":
        return "baseline (swept nonlinearities off)"
    value = baseline[info.columns[-1]]
    unit = "" if isinstance(value, str) else f" {_unit_of(info)}"
    return f"baseline ({info.name} = {_cell(value)}{unit})"


def _unit_of(info: AxisInfo) -> str:
    """The unit of the axis's last column (the absolute magnitude for relative axes)."""
    if info.kind == "parameter":
        return info.unit
    from ema_cli.model.nonlinearities import lookup

    return lookup(info.targets[0]).unit


def _metric_plots(result: SweepResult, df: pd.DataFrame,
                  info: AxisInfo) -> Iterator[tuple[str, Figure]]:
    from ema_cli.report.sweep_figures import category_figure, metric_figure  # matplotlib

    plan = result.plan
    metrics = [(m, metric_label(m)) for m in plan.cfg.outputs.metrics]
    rows = df[~df["_baseline"]].copy()
    base = df[df["_baseline"]]
    baseline = base.iloc[0] if len(base) else None
    multi = len(plan.axes) > 1 and plan.cfg.sweep.mode == "grid"
    x_label = info.name + (f" [{info.unit}]" if info.unit else "")
    if info.unit == "%":
        x_label = "dead-zone half-width [% of the baseline's peak signal]"
    title = f"{plan.cfg.name}: metrics vs {info.name}\ninput: {plan.signal.describe()}; " \
            f"{info.description}"
    zipped = plan.cfg.sweep.mode == "zip" and len(plan.axes) > 1
    if zipped:
        title = (f"{plan.cfg.name}: metrics per run (axes zipped: "
                 f"{', '.join(a.name for a in plan.axes)})\ninput: {plan.signal.describe()}")
    if not info.numeric:
        prefix = f"{info.targets[0]} = "
        rows["_category"] = [
            "\n".join(plan.jobs[i].parts) if zipped
            else _point_label(result, i, info.index).removeprefix(prefix)
            for i in rows["_index"]]
        if multi:
            rows = rows[rows["_index"].isin(_groups(result, df, info.index)[0]["_index"])]
            title += f"; {_others_label(result, int(rows['_index'].iloc[0]), info.index)}"
        if baseline is not None:
            b = baseline.copy()
            b["_category"] = "baseline"
            rows = pd.concat([b.to_frame().T, rows])
        yield f"metrics_{info.name}", category_figure(
            rows, "_category", "run" if zipped else info.name, metrics, title)
        return
    targets: list[tuple[str, pd.DataFrame]] = [("", rows)]
    group_col = info.group_column
    if info.group_column is not None and not info.unit:  # mixed units: one figure per target
        targets = [(str(t), sub) for t, sub in rows.groupby(info.group_column, sort=False)]
        group_col = None
    for tag, sub in targets:
        if multi:
            sub = sub.copy()
            sub["_others"] = [_others_label(result, i, info.index) for i in sub["_index"]]
            keep = _evenly(list(dict.fromkeys(sub["_others"])), MAX_METRIC_LINES)
            sub = sub[sub["_others"].isin(keep)]
            group_col = "_others" if group_col is None else group_col
        xl = x_label
        if tag:
            unit = sub[f"{info.name}_unit"].iloc[0]
            xl = f"{tag} magnitude [{unit}]"
        fig = metric_figure(sub, info.x_column, xl, metrics,
                            title + (f" ({tag})" if tag else ""), info.log, group_col,
                            None if multi else baseline,
                            legend_title=info.name if group_col == info.group_column else
                            "other axes", baseline_label=_baseline_label(info, baseline))
        yield f"metrics_{info.name}" + (f"_{_slug(tag)}" if tag else ""), fig


# --------------------------------------------------------------------------------- summary


def _cell(v: Any) -> str:
    if isinstance(v, float | np.floating):
        return "n/a" if not np.isfinite(v) else f"{v:.4g}"
    return str(v).replace("|", "\\|")


def summary_markdown(result: SweepResult) -> str:
    """summary.md: what was run, the job counts, the metrics table and the figures."""
    plan = result.plan
    cfg = plan.cfg
    counts = result.counts()
    lines = [f"# Sweep `{cfg.name}`", ""]
    if cfg.description:
        lines += [cfg.description.strip(), ""]
    lines += [
        f"- input: {plan.signal.describe()}; duration {plan.duration:g} s, dt {plan.dt:g} s"
        + (f", time series every {plan.output_interval:g} s" if plan.dec else ""),
        f"- sweep: {cfg.sweep.mode} over " + "; ".join(a.description for a in plan.axes),
        f"- jobs: {len(plan.jobs)} ({counts['ok']} ok, {counts['diverged']} diverged, "
        f"{counts['failed']} failed, {counts['pending']} not run); {result.computed} runs "
        f"computed, {result.cached} taken from the cache",
    ]
    if result.signals_file is not None:
        lines.append(f"- recorded signals: `{result.signals_file.name}`, one row per job and "
                     "sample (e.g. `pandas.read_parquet(path, filters=[('job', '==', "
                     f"'{plan.jobs[0].id}')])`)")
    if plan.scales:
        lines.append("- relative magnitudes are % of the baseline's peak signal: " + ", ".join(
            f"{k} {v:.4g}" for k, v in plan.scales.items()))
    lines += [f"- note: {n}" for n in plan.notes]
    lines += [f"- warning: {w}" for w in result.warnings]
    if result.interrupted:
        lines.append("- **interrupted**: re-run the same command to finish (cached jobs are kept)")
    cols = ["job", "label", "status"] + list(cfg.outputs.metrics)
    shown = result.metrics.head(MAX_SUMMARY_ROWS)
    lines += ["", "## Metrics", "", "| " + " | ".join(
        [c if c in ("job", "label", "status") else _cell(metric_label(c)) for c in cols]) + " |",
        "|" + "---|" * len(cols)]
    for _, row in shown.iterrows():
        lines.append("| " + " | ".join(_cell(row[c]) for c in cols) + " |")
    if len(result.metrics) > MAX_SUMMARY_ROWS:
        lines.append(f"\n({len(result.metrics) - MAX_SUMMARY_ROWS} more rows in metrics.csv)")
    failed = result.metrics[result.metrics["status"] == "failed"]
    if len(failed):
        lines += ["", "## Failed jobs", ""]
        lines += [f"- {r.job} ({r.label}): {r.error}" for r in failed.itertuples()]
    if result.figures and result.folder is not None:
        lines += ["", "## Figures", ""]
        for p in result.figures:
            rel = p.relative_to(result.folder).as_posix()
            lines += [f"### {p.stem}", "", f"![{p.stem}]({rel})", ""]
    return "\n".join(lines) + "\n"
