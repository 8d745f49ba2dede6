"""A sweep's output folder: resolved config, manifest, metrics.csv, time series, figures, summary.

Layout of ``results/<name>/<stamp>_<hash>/`` (or ``--out``)::

    config.resolved.yaml      the validated config, every default filled in
    manifest.json             version, git commit, seed, job counts, timings, per-job status
    metrics.csv               one row per job: swept values (paper units) + every metric
    timeseries/<job>.csv      decimated signals of each job (edge units), if asked
    figures/*.png             overlays vs time per axis, metrics vs magnitude per axis
    summary.md                the metrics table and the figures

Every file is written atomically (temporary sibling + rename). :func:`run_sweep` runs a sweep
(``sweep.run.compute_sweep``) and writes this folder as it goes.
"""

from __future__ import annotations

import json
import math
import time
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import pandas as pd
import yaml

from ema_cli.errors import EmaError
from ema_cli.report.rundir import (
    manifest,
    new_run_dir,
    write_csv,
    write_figure,
    write_json,
    write_text,
)
from ema_cli.sim.tables import METRIC_BY_EDGE
from ema_cli.sweep.run import SweepResult, compute_sweep
from ema_cli.units import DEG

if TYPE_CHECKING:
    from ema_cli.config.schema import StudyConfig
    from ema_cli.sweep.plan import AxisInfo, Plan

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
) -> SweepResult:
    """Run a sweep end to end (``sweep.run.compute_sweep``) and write its outputs.

    out        output folder; None: ``results/<name>/<stamp>_<hash>/``. An existing folder is
               reused only if it holds an earlier run of the same sweep (resume in place).
    overrides  the ``--set`` pairs, recorded in the manifest
    write      False: write nothing (no folder); the time series stay readable from the cache

    The other arguments are ``compute_sweep``'s. The folder is created once the sweep is
    planned, before any job runs; on Ctrl-C the outputs of the finished jobs are written and
    KeyboardInterrupt is re-raised. A failed job's error text goes into the manifest.
    """
    t_start = time.perf_counter()
    folder: Path | None = None

    def on_start(plan: Plan) -> None:
        nonlocal folder
        if write:
            folder = prepare_folder(plan, out, overrides)

    def on_finish(result: SweepResult, aborted: bool) -> None:
        result.folder = folder
        if folder is None:
            return
        timings = result.timings
        t2 = time.perf_counter()
        try:
            write_outputs(result, partial=aborted)
        except KeyboardInterrupt:  # Ctrl-C while writing: the manifest still says so
            result.interrupted = True
            raise
        finally:
            timings["outputs"] = time.perf_counter() - t2
            timings["total"] = time.perf_counter() - t_start
            write_manifest(result, overrides)

    return compute_sweep(cfg, n_jobs, backend, force, progress, scheduler=scheduler,
                         chunk_size=chunk_size, cache_dir=cache_dir, base_dir=base_dir,
                         source=source, on_start=on_start, on_finish=on_finish)


def prepare_folder(plan: Plan, out: Path | None, overrides: Sequence[tuple[str, Any]]) -> Path:
    """Create the output folder before any job runs (so a bad ``--out`` loses nothing).

    An existing non-empty ``out`` is reused only if its manifest is an earlier run of the same
    sweep (resume in place); anything else is refused, never overwritten.
    """
    if out is not None and out.exists():
        if not out.is_dir():
            raise EmaError(f"--out '{out}' is a file; expected a folder")
        if any(out.iterdir()):
            prev = _read_manifest(out)
            if prev.get("command") != "sweep" or prev.get("sweep_key") != plan.key:
                raise EmaError(f"output folder '{out}' exists and holds another run; choose "
                               "another --out (run folders are never overwritten)")
    folder = new_run_dir(plan.cfg.name, plan.key, out)
    write_text(folder / "config.resolved.yaml",
               yaml.safe_dump(plan.cfg.model_dump(mode="json"), sort_keys=False))
    write_json(folder / "manifest.json", {  # provisional: identifies the sweep for a resume
        "command": "sweep", "name": plan.cfg.name, "sweep_key": plan.key, "status": "running",
        "n_jobs": len(plan.jobs), "overrides": [list(o) for o in overrides]})
    return folder


def _read_manifest(folder: Path) -> dict[str, Any]:
    try:
        return json.loads((folder / "manifest.json").read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return {}


def write_manifest(result: SweepResult, overrides: Sequence[tuple[str, Any]]) -> None:
    """manifest.json: provenance, job counts, timings and every job's status and error."""
    plan, folder = result.plan, result.folder
    assert folder is not None
    counts = result.counts()
    if result.interrupted:
        state = "interrupted"
    elif counts["failed"] or counts["pending"]:
        state = "incomplete"
    else:
        state = "complete"
    df = result.metrics
    jobs = [{"job": j.id, "label": j.label, "key": j.key, "status": df["status"].iloc[j.index],
             **({"error": df["error"].iloc[j.index]} if df["error"].iloc[j.index] else {})}
            for j in plan.jobs]
    write_json(folder / "manifest.json", manifest(
        "sweep", name=plan.cfg.name, description=plan.cfg.description, sweep_key=plan.key,
        status=state, seed=plan.cfg.seed, input=plan.signal.describe(),
        duration_s=plan.duration, dt_s=plan.dt, n_steps=plan.n_steps,
        output_interval_s=plan.output_interval if plan.dec else None,
        job_counts={"total": len(plan.jobs), "unique_runs": plan.n_unique,
                    "computed": result.computed, "cached": result.cached, **counts},
        wall_time_s=result.timings.get("total"), timings_s=result.timings,
        backend=result.backend, workers=result.workers, cache_dir=result.cache.root,
        relative_scales=plan.scales, warnings=plan.warnings, notes=plan.notes,
        overrides=[list(o) for o in overrides], figures=[str(p.relative_to(folder))
                                                         for p in result.figures],
        jobs=jobs))


def write_outputs(result: SweepResult, partial: bool = False) -> None:
    """Write metrics.csv, the time series, the figures and summary.md (then call
    :func:`write_manifest`). ``partial`` (an aborted sweep): only metrics.csv and summary.md.
    """
    folder = result.folder
    assert folder is not None
    write_csv(folder / "metrics.csv", result.metrics, float_format=CSV_FORMAT)
    if not partial:
        if result.plan.cfg.outputs.timeseries and result.plan.dec > 0:
            _write_timeseries(result, folder / "timeseries")
        result.figures = _write_figures(result, folder / "figures")
    write_text(folder / "summary.md", summary_markdown(result))


def _write_timeseries(result: SweepResult, folder: Path) -> None:
    df = result.metrics
    for j in result.plan.jobs:
        path = folder / f"{j.id}.csv"
        if df["status"].iloc[j.index] in FINISHED:
            write_csv(path, result.timeseries(j.id), float_format=CSV_FORMAT)


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


def _write_figures(result: SweepResult, folder: Path) -> list[Path]:
    plan = result.plan
    if not plan.cfg.outputs.figures:
        return []
    wanted = plan.cfg.outputs.figures
    df = _finished(result)
    paths: list[Path] = []
    if df.empty:
        return paths
    axes = plan.axes[:1] if plan.cfg.sweep.mode == "zip" else plan.axes
    for info in axes:
        for kind in ("errors", "response"):
            if kind in wanted and plan.dec > 0:
                paths += _overlays(result, df, info, kind, folder)
        if "metrics" in wanted:
            paths += _metric_plots(result, df, info, folder)
    return paths


def _baseline_series(result: SweepResult, df: pd.DataFrame) -> list[tuple[str, pd.DataFrame]]:
    base = df[df["_baseline"]]
    if base.empty:
        return []
    return [("baseline (swept nonlinearities off)", result.timeseries(int(base["_index"].iloc[0])))]


def _overlays(result: SweepResult, df: pd.DataFrame, info: AxisInfo, kind: str,
              folder: Path) -> list[Path]:
    plan = result.plan
    what, columns, reference = OVERLAYS[kind]
    zip_mode = plan.cfg.sweep.mode == "zip"
    paths = []
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
            path = folder / f"{name}.png"
            write_figure(path, fig)
            paths.append(path)
    return paths


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


def _metric_plots(result: SweepResult, df: pd.DataFrame, info: AxisInfo,
                  folder: Path) -> list[Path]:
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
        fig = category_figure(rows, "_category", "run" if zipped else info.name, metrics, title)
        path = folder / f"metrics_{info.name}.png"
        write_figure(path, fig)
        return [path]
    targets: list[tuple[str, pd.DataFrame]] = [("", rows)]
    group_col = info.group_column
    if info.group_column is not None and not info.unit:  # mixed units: one figure per target
        targets = [(str(t), sub) for t, sub in rows.groupby(info.group_column, sort=False)]
        group_col = None
    paths = []
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
        path = folder / (f"metrics_{info.name}" + (f"_{_slug(tag)}" if tag else "") + ".png")
        write_figure(path, fig)
        paths.append(path)
    return paths


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
    if plan.scales:
        lines.append("- relative magnitudes are % of the baseline's peak signal: " + ", ".join(
            f"{k} {v:.4g}" for k, v in plan.scales.items()))
    lines += [f"- note: {n}" for n in plan.notes]
    lines += [f"- warning: {w}" for w in plan.warnings]
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
