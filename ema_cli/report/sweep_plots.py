"""Which figures a sweep gets: overlays vs time and metrics vs the swept value, per axis, with
their titles and file names (the drawing itself is in ``report.sweep_figures``)."""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import pandas as pd

from ema_cli.report.markdown import md_cell
from ema_cli.report.rundir import write_figure
from ema_cli.report.sweep_tables import FINISHED, axis_unit, metric_label
from ema_cli.sweep.run import SweepResult

if TYPE_CHECKING:
    from matplotlib.figure import Figure

    from ema_cli.sweep.plan import AxisInfo

MAX_GROUPS_PER_AXIS = 3  # overlays per axis when other axes vary: first, middle, last value
MAX_METRIC_LINES = 10  # most lines (combinations of the other axes) in one metric plot
OVERLAYS = {
    "errors": ("tracking error", [("err_pos_deg", "position error θref − θload [deg]"),
                                  ("err_vel_deg_s", "velocity error ωref − ωload [deg/s]")],
               None),
    "response": ("response", [("theta_load_deg", "load position [deg]"),
                              ("omega_load_deg_s", "load velocity [deg/s]")],
                 ["theta_ref_deg", "omega_ref_deg_s"]),
}


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


def write_figures(result: SweepResult, folder: Path, stop: Any = None) -> list[Path]:
    """Draw and write the sweep's figures into ``folder`` -> their paths; ``stop``: a
    ``threading.Event`` that ends the drawing before the next figure once set."""
    paths = []
    for name, fig in _figures(result):  # one at a time: each is closed once written
        if stop is not None and stop.is_set():
            break
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
            who = f"{plan.cfg.name} ({plan.cfg.actuator_label()})"
            title = (f"{who}: {what} of position and velocity, one curve per {per}"
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
    unit = "" if isinstance(value, str) else f" {axis_unit(info)}"
    return f"baseline ({info.name} = {md_cell(value)}{unit})"


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
    who = f"{plan.cfg.name} ({plan.cfg.actuator_label()})"
    title = f"{who}: metrics vs {info.name}\ninput: {plan.signal.describe()}; " \
            f"{info.description}"
    zipped = plan.cfg.sweep.mode == "zip" and len(plan.axes) > 1
    if zipped:
        title = (f"{who}: metrics per run (axes zipped: "
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
