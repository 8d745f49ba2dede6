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
its temporary sibling as chunks finish (``sweep_parquet.SignalsWriter``) and renamed into place
only when the sweep completes, so an interrupted sweep leaves neither a partial file nor the
temporary one. This module is the folder: :class:`SweepFolder` is the sink
``api.study.run_sweep`` hands to ``sweep.run.compute_sweep``; :func:`save_sweep` writes a sweep
computed without a folder. Its rooms: ``sweep_parquet`` (signals.parquet), ``sweep_tables``
(metric labels, per-job CSVs), ``sweep_plots`` (which figures), ``sweep_figures`` (drawing
them), ``sweep_summary`` (summary.md).
"""

from __future__ import annotations

import json
import time
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import yaml

from ema_cli.errors import EmaError
from ema_cli.files import RESULTS_ROOT
from ema_cli.report.rundir import (
    CACHE_NAME,
    MARKER,
    finish_output,
    manifest,
    prepare_output,
    remove_stale_temporaries,
    write_csv,
    write_json,
    write_text,
)
from ema_cli.report.rundir import FINISHED as KEPT  # the folder holds the finished run
from ema_cli.report.sweep_parquet import SIGNALS_FILE, SignalsWriter
from ema_cli.report.sweep_plots import sweep_figures, write_figures
from ema_cli.report.sweep_summary import summary_markdown
from ema_cli.report.sweep_tables import CSV_FORMAT, FINISHED, metric_label, write_job_csvs
from ema_cli.sweep.cache import DEFAULT_CACHE_DIR
from ema_cli.sweep.run import SweepResult

if TYPE_CHECKING:
    from ema_cli.sweep.plan import Plan

__all__ = ["SIGNALS_FILE", "BackgroundFigures", "SweepFolder", "default_cache_dir",
           "finish_sweep", "finished_sweep", "metric_label", "prepare_folder",
           "remove_stale_temporaries", "save_sweep", "stop_drawing", "sweep_figures",
           "sweep_inputs",
           "write_manifest", "write_outputs"]


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


class SweepFolder:
    """The sink of one sweep's output folder, handed to ``sweep.run.compute_sweep`` as its
    hooks: :meth:`start` creates (or resumes) the folder once the sweep is planned, before any
    job runs; :meth:`add` streams finished jobs' signals into signals.parquet; :meth:`finish`
    writes metrics.csv, summary.md, the figures and the manifest. It takes results, never
    simulates.

    out        output folder; None: ``results/sweep/<name>/<stamp>_<hash>/``. An existing folder
               is reused only if it holds an earlier run of the same sweep (resume in place).
    overrides  the ``--set`` pairs, recorded in the manifest
    figures    draw: drawn in :meth:`finish`; none: no figures (the manifest says so);
               background: drawn in a thread while the caller prints, the folder finished by
               :func:`finish_sweep`, which the caller must then call
    reuse_finished  ``out`` belongs to a run being resumed (``ema reproduce``): if it holds the
               finished run of this very sweep, it is read (metrics from the job cache, signals
               from its signals.parquet), never rewritten; otherwise the usual policy applies

    On Ctrl-C (or an error) :meth:`finish` writes metrics.csv, summary.md and the manifest of
    the finished jobs and deletes the unfinished signals file; a failed job's error text goes
    into the manifest.
    """

    def __init__(self, out: Path | None, overrides: Sequence[tuple[str, Any]] = (),
                 figures: str = "draw", reuse_finished: bool = False) -> None:
        if figures not in ("draw", "none", "background"):
            raise ValueError(f"figures must be draw, none or background, got {figures!r}")
        self.out, self.overrides, self.figures = out, overrides, figures
        self.reuse_finished = reuse_finished
        self.folder: Path | None = None
        self.writer: SignalsWriter | None = None
        self.reused = False
        self.t_start = time.perf_counter()

    def start(self, plan: Plan) -> None:
        """Create (or resume, or recognise as finished) the folder of ``plan``."""
        out = self.out
        if self.reuse_finished and out is not None and finished_sweep(Path(out), plan):
            self.folder, self.reused = Path(out), True
            return
        self.folder, state = prepare_folder(plan, out, self.overrides)
        if state == KEPT:  # the finished run of this sweep: read, never rewritten
            self.reused = True
            return
        if plan.cfg.outputs.timeseries and plan.dec > 0:
            self.writer = SignalsWriter(self.folder / SIGNALS_FILE, plan)

    def add(self, jobs: Sequence[int], rows: Sequence[int], signals: np.ndarray) -> None:
        """Stream the recorded signals of finished jobs (``sweep.run.OnSignals``)."""
        if self.writer is not None:
            self.writer.add(jobs, rows, signals)

    def finish(self, result: SweepResult, aborted: bool) -> None:
        """Write the folder's files for ``result`` (``aborted``: the finished jobs only)."""
        result.folder = folder = self.folder
        if folder is None:
            return
        if self.reused:  # a finished run of this sweep: read, never rewritten
            if (folder / SIGNALS_FILE).is_file():
                result.signals_file = folder / SIGNALS_FILE
            return
        writer, timings = self.writer, result.timings
        t2 = time.perf_counter()
        failed: EmaError | None = None
        try:
            if writer is not None and not aborted:
                try:
                    result.signals_file = writer.commit()
                except EmaError as exc:  # e.g. disk full: the other outputs are still written
                    failed = exc
            write_outputs(result, partial=aborted or failed is not None,
                          figures=self.figures == "draw")
        except KeyboardInterrupt:  # Ctrl-C while writing: the manifest still says so
            result.interrupted = True
            raise
        finally:
            if writer is not None:
                writer.discard()  # after a commit: nothing left to delete
            timings["outputs"] = time.perf_counter() - t2
            timings["total"] = time.perf_counter() - self.t_start
            write_manifest(result, self.overrides, failed.message if failed else None)
        if failed is not None:
            raise failed
        if aborted:
            return
        if self.figures == "background" and result.plan.cfg.outputs.figures:
            result.pending = BackgroundFigures(result, self.overrides)
        else:
            finish_if_complete(result)


class BackgroundFigures:
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
        self.stop = threading.Event()
        self.done = threading.Event()  # set by the thread as it ends (``Thread.join`` once
        # interrupted by a signal may return while the thread still runs)
        self.thread = threading.Thread(target=self._run, name="ema-figures", daemon=True)
        _DRAWING.add(self)  # before it starts: an interrupt at any instant can stop it
        self.thread.start()

    def _run(self) -> None:
        t0 = time.perf_counter()
        try:
            assert self.result.folder is not None
            self.paths = write_figures(self.result, self.result.folder / "figures", self.stop)
        except BaseException as exc:  # noqa: BLE001 - re-raised in the caller's thread
            self.error = exc
        finally:
            self.seconds = time.perf_counter() - t0
            self.done.set()

    def cancel(self) -> None:
        """Stop drawing after the figure being written (it is written whole) and wait for the
        thread: an interrupted command leaves no half-written file behind (and no thread in
        native code when the process exits). The folder stays unfinished (the same command
        completes it)."""
        self.stop.set()
        t0 = time.perf_counter()
        while not self.done.wait(0.05):
            if self.thread.ident is None and time.perf_counter() - t0 > 1.0:
                break  # never started (interrupted in Thread.start)
        _DRAWING.discard(self)

    def join(self) -> None:
        """Wait for the figures, then write the manifest and mark the folder finished."""
        self.done.wait()
        _DRAWING.discard(self)
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
        finish_if_complete(result)


_DRAWING: set[BackgroundFigures] = set()
"""The figure threads of this process still drawing (:func:`stop_drawing`)."""


def stop_drawing() -> None:
    """Stop every figure thread still drawing, after the figure it writes (an interrupted
    command: its folder is left unfinished, every file in it whole)."""
    for pending in list(_DRAWING):
        pending.cancel()


def finish_sweep(result: SweepResult) -> None:
    """Wait for figures drawn in the background (``SweepFolder(figures="background")``), write
    the final manifest and mark the folder finished; nothing to do otherwise."""
    pending = getattr(result, "pending", None)
    if pending is not None:
        pending.join()  # interrupted here, it stays pending: cancel_sweep stops the thread
        result.pending = None


def save_sweep(result: SweepResult, out: Path | None = None,
               overrides: Sequence[tuple[str, Any]] = ()) -> Path:
    """Write the folder ``ema sweep`` writes for a sweep computed without one (the Python
    API's ``Sweep.save``) -> the folder; ``out`` None: a new one under ``results/sweep/<name>/``."""
    t0 = time.perf_counter()
    plan = result.plan
    folder, state = prepare_folder(plan, out, overrides)
    result.folder = folder
    if state == KEPT:  # the finished run of this sweep: kept as it is
        return folder
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
    finish_if_complete(result)
    return folder


def finish_if_complete(result: SweepResult) -> None:
    """Mark the folder finished (``rundir.finish_output``: kept as it is, never rewritten) once
    every job finished: none pending, none failed, not interrupted."""
    counts = result.counts()
    if (result.folder is not None and not result.interrupted and not counts["pending"]
            and not counts["failed"]):
        finish_output(result.folder)


def sweep_inputs(plan: Plan, overrides: Sequence[tuple[str, Any]] = ()) -> Any:
    """The inputs (``report.run_inputs.RunInputs``) the marker of a sweep's folder records:
    every leaf of the resolved config (its parallel settings aside), and the sweep's key (its
    ordered job keys: the simulator's source and the files the config refers to)."""
    from ema_cli.report.run_inputs import run_inputs

    cfg = plan.cfg.model_dump(mode="json", by_alias=True, exclude={"parallel"})
    return run_inputs(cfg, sets=overrides).with_components(**{"sweep jobs (key)": plan.key})


def finished_sweep(folder: Path, plan: Plan) -> bool:
    """True if ``folder`` holds the finished ``ema sweep`` run of ``plan`` (same inputs)."""
    try:
        mark = json.loads((folder / MARKER).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return False
    return (isinstance(mark, dict) and mark.get("command") == "sweep"
            and mark.get("fingerprint") == sweep_inputs(plan).fingerprint
            and mark.get("finished") is True)


def prepare_folder(plan: Plan, out: Path | None, overrides: Sequence[tuple[str, Any]]
                   ) -> tuple[Path, str]:
    """Create the output folder before any job runs (so a bad ``--out`` loses nothing) ->
    (folder, state: ``rundir.NEW``, ``RESUMED`` or ``FINISHED``).

    The one ``--out`` policy (``rundir.prepare_output``): a new or empty folder, or an earlier
    unfinished run of the same sweep (same inputs, :func:`sweep_inputs`), which is resumed in
    place (the temporary files a killed run left there are deleted first), or the finished run
    of the same sweep, kept as it is (nothing is written). Anything else is refused, never
    overwritten.
    """
    folder, state = prepare_output("sweep", plan.cfg.name, sweep_inputs(plan, overrides), out)
    if state == KEPT:
        return folder, state
    write_text(folder / "config.resolved.yaml",
               yaml.safe_dump(plan.cfg.model_dump(mode="json"), sort_keys=False))
    write_json(folder / "manifest.json", {  # provisional: identifies the sweep for a resume
        "command": "sweep", "name": plan.cfg.name, "sweep_key": plan.key, "status": "running",
        "n_jobs": len(plan.jobs), "overrides": [list(o) for o in overrides]})
    return folder, state


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
            write_job_csvs(result, folder / "timeseries")
        if figures:
            result.figures = write_figures(result, folder / "figures")
    write_text(folder / "summary.md", summary_markdown(result))
