"""Sweep figures: overlays of runs vs time and metrics vs magnitude (return Figures, no I/O).

Time series are tables in edge units (``SweepResult.timeseries``: one job's rows of
signals.parquet once the sweep has written it, else the recorded arrays); metric tables are rows
of ``metrics.csv``. Labels carry magnitudes with their units; logarithmic magnitudes get log axes.
"""

from __future__ import annotations

import math
import textwrap
from collections.abc import Sequence

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402
from matplotlib.axes import Axes  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402

LOG_Y_DECADES = 2.0  # a metric spanning at least this many decades (all > 0) gets a log y axis
TAIL_FRACTION = 0.2  # the zoom panels show the last 20 % of the run (residual oscillation)
MARKER_MAX_POINTS = 40  # lines with more points than this get small dots, not circles
METRIC_COLUMNS = 4  # metric-vs-magnitude subplots per row
LEGEND_SPACE = 0.84  # metric plots: fraction of the width left of the legend
X_MARGIN = 0.05  # x-axis margin of metric plots, fraction of the range
X_MARGIN_LOG = 1.4  # x-axis margin of logarithmic metric plots, factor
BASELINE_STYLE = {"color": "0.35", "ls": "--", "lw": 1.3}


TITLE_WIDTH = 110  # characters per title line before wrapping


def _title(text: str) -> str:
    """Wrap each line of a figure title to ``TITLE_WIDTH`` characters."""
    return "\n".join(textwrap.fill(line, TITLE_WIDTH) for line in text.split("\n"))


def _curve_style(label: str, k: int) -> dict[str, object]:
    if label.startswith("baseline"):
        return {**BASELINE_STYLE, "label": label}
    return {"color": f"C{k % 10}", "ls": "-", "lw": 1.3, "label": label}


COINCIDE_SHARE = 0.005  # curves closer than this share of the panel's span everywhere coincide


def _note_coinciding(ax: Axes, series: Sequence[tuple[str, pd.DataFrame]], col: str) -> None:
    """Say in the panel's title which curves lie on each other (computed: every sample within
    COINCIDE_SHARE of the span of all curves), so that none seems missing."""
    from ema_cli.report.figures import coinciding

    curves = {label: ts[col].to_numpy(float) for label, ts in series}
    vals = np.concatenate(list(curves.values()))
    vals = vals[np.isfinite(vals)]
    if vals.size < 2 or len(curves) < 2:
        return
    span = float(vals.max() - vals.min())
    groups = coinciding(curves, COINCIDE_SHARE * span) if span > 0 else [list(curves)]
    if groups:
        text = "; ".join(" = ".join(g) for g in groups)
        ax.set_title(textwrap.fill(f"on each other (within {100 * COINCIDE_SHARE:g} % of "
                                   f"the span): {text}", 100), fontsize=8)


def _tail_limits(ax: Axes, series: Sequence[tuple[str, pd.DataFrame]], col: str,
                 t0: float) -> None:
    vals = np.concatenate([ts.loc[ts["t_s"] >= t0, col].to_numpy() for _, ts in series])
    vals = vals[np.isfinite(vals)]
    if vals.size:
        lo, hi = float(vals.min()), float(vals.max())
        pad = 0.08 * (hi - lo) if hi > lo else max(abs(hi), 1e-12) * 0.1
        ax.set_ylim(lo - pad, hi + pad)


def overlay_figure(series: Sequence[tuple[str, pd.DataFrame]], title: str,
                   columns: Sequence[tuple[str, str]], legend_title: str,
                   reference: Sequence[str | None] | None = None) -> Figure:
    """One curve per run of each column vs time: full run (left) and its last 20 % (right).

    ``columns`` are (column, y label with unit) pairs, one row of panels each; ``reference``
    names, per row, a column drawn once in black dotted (e.g. the position reference).
    """
    n = len(columns)
    fig, axes = plt.subplots(n, 2, figsize=(13, 3.4 * n + 0.9), squeeze=False,
                             gridspec_kw={"width_ratios": [1.6, 1]})
    t_end = max(float(ts["t_s"].iloc[-1]) for _, ts in series)
    t0 = (1.0 - TAIL_FRACTION) * t_end
    refs = list(reference) if reference is not None else [None] * n
    for row, ((col, ylabel), ref) in enumerate(zip(columns, refs, strict=True)):
        for side, ax in enumerate(axes[row]):
            if ref is not None:
                ts0 = series[0][1]
                ax.plot(ts0["t_s"], ts0[ref], color="k", ls=":", lw=1.6, label="reference")
            for k, (label, ts) in enumerate(series):
                ax.plot(ts["t_s"], ts[col], **_curve_style(label, k))
            if side == 0:
                _note_coinciding(ax, series, col)
            ax.grid(True, alpha=0.3)
            ax.axhline(0.0, color="0.6", lw=0.6)
            if side == 1:
                ax.set_xlim(t0, t_end)
                _tail_limits(ax, series, col, t0)
                ax.set_title(f"zoom: last {TAIL_FRACTION:.0%} of the run", fontsize=9)
            else:
                ax.set_ylabel(ylabel)
        if row == n - 1:
            for ax in axes[row]:
                ax.set_xlabel("time [s]")
    # the legend below the panels, off the data (it once sat on the curves)
    handles, labels = axes[0, 0].get_legend_handles_labels()
    ncol = min(len(labels), 4) or 1
    height = fig.get_figheight()
    space = (0.35 + 0.2 * math.ceil(len(labels) / ncol)) / height
    fig.suptitle(_title(title))
    fig.tight_layout(rect=(0, space, 1, 1))
    fig.legend(handles, labels, loc="lower center", bbox_to_anchor=(0.5, 0.0), ncol=ncol,
               fontsize=8, title=legend_title, title_fontsize=8, frameon=False)
    return fig


def _log_y(values: np.ndarray) -> bool:
    v = values[np.isfinite(values)]
    return bool(v.size >= 2 and v.min() > 0 and math.log10(v.max() / v.min()) >= LOG_Y_DECADES)


def metric_figure(frame: pd.DataFrame, x_column: str, x_label: str,
                  metrics: Sequence[tuple[str, str]], title: str, logx: bool,
                  group_column: str | None = None, baseline: pd.Series | None = None,
                  legend_title: str | None = None, baseline_label: str = "baseline") -> Figure:
    """Metrics vs a numeric magnitude: one panel per metric, one line per group.

    ``metrics`` are (column, label with unit) pairs; ``baseline`` (a metrics row) is drawn as a
    dashed horizontal line labelled ``baseline_label``. The y axis is logarithmic where a
    metric spans >= 2 decades.
    """
    ncols = min(METRIC_COLUMNS, len(metrics))
    nrows = math.ceil(len(metrics) / ncols)
    fig, axes = plt.subplots(nrows, ncols, figsize=(3.6 * ncols + 0.6, 3.0 * nrows + 0.9),
                             squeeze=False)
    groups = ([(None, frame)] if group_column is None
              else list(frame.groupby(group_column, sort=False)))
    x_all = pd.to_numeric(frame[x_column], errors="coerce").to_numpy(float)
    x_all = x_all[np.isfinite(x_all) & ((x_all > 0) if logx else True)]
    for ax, (col, label) in zip(axes.flat, metrics, strict=False):
        all_y = []
        for k, (name, sub) in enumerate(groups):
            sub = sub.sort_values(x_column)
            x = pd.to_numeric(sub[x_column], errors="coerce").to_numpy(float)
            y = sub[col].to_numpy(float)
            all_y.append(y)
            ax.plot(x, y, "o-" if len(x) <= MARKER_MAX_POINTS else ".-", color=f"C{k % 10}",
                    ms=4 if len(x) <= MARKER_MAX_POINTS else 2, lw=1.3,
                    label=None if name is None else str(name))
        n_nan = int(sum(np.isnan(y).sum() for y in all_y))
        note = ""
        if 0 < n_nan < sum(y.size for y in all_y):  # in the title, off the data
            note = f"\n{n_nan} of {sum(y.size for y in all_y)} runs n/a (e.g. not settled)"
        if baseline is not None and np.isfinite(baseline[col]):
            ax.axhline(float(baseline[col]), label=baseline_label, **BASELINE_STYLE)
            all_y.append(np.array([float(baseline[col])]))
        if logx:
            ax.set_xscale("log")
        if x_all.size:
            lo, hi = float(x_all.min()), float(x_all.max())
            if logx:
                ax.set_xlim(lo / X_MARGIN_LOG, hi * X_MARGIN_LOG)
            elif hi > lo:
                ax.set_xlim(lo - X_MARGIN * (hi - lo), hi + X_MARGIN * (hi - lo))
        if not np.isfinite(np.concatenate(all_y)).any():
            ax.text(0.5, 0.5, "n/a for every run\n(e.g. not settled by the end)",
                    transform=ax.transAxes, ha="center", va="center", fontsize=8, color="0.4")
        if _log_y(np.concatenate(all_y)):
            ax.set_yscale("log")
        ax.set_title(label + note, fontsize=9)
        ax.set_xlabel(x_label, fontsize=8)
        ax.tick_params(labelsize=8)
        ax.grid(True, which="both", alpha=0.3)
    for ax in axes.flat[len(metrics):]:
        ax.set_visible(False)
    handles, labels = axes.flat[0].get_legend_handles_labels()
    fig.suptitle(_title(title))
    if handles:
        fig.tight_layout(rect=(0, 0, LEGEND_SPACE, 1))
        fig.legend(handles, labels, loc="center left", bbox_to_anchor=(LEGEND_SPACE, 0.5),
                   fontsize=8, title=legend_title, title_fontsize=8)
    else:
        fig.tight_layout()
    return fig


def category_figure(frame: pd.DataFrame, category_column: str, x_label: str,
                    metrics: Sequence[tuple[str, str]], title: str) -> Figure:
    """Metrics for a non-numeric axis (e.g. a saturation's limit vs ``off``): grouped bars."""
    ncols = min(METRIC_COLUMNS, len(metrics))
    nrows = math.ceil(len(metrics) / ncols)
    fig, axes = plt.subplots(nrows, ncols, figsize=(3.6 * ncols + 0.6, 3.0 * nrows + 0.9),
                             squeeze=False)
    cats = [str(c) for c in frame[category_column]]
    colors = ["0.55" if c.startswith("baseline") else f"C{k % 10}" for k, c in enumerate(cats)]
    for ax, (col, label) in zip(axes.flat, metrics, strict=False):
        y = frame[col].to_numpy(float)
        ax.bar(range(len(cats)), np.nan_to_num(y, nan=0.0), color=colors)
        for k, v in enumerate(y):
            ax.annotate("n/a" if not np.isfinite(v) else f"{v:.3g}", (k, 0 if not
                        np.isfinite(v) else v), ha="center", va="bottom", fontsize=7)
        multiline = any("\n" in c for c in cats)
        ax.set_xticks(range(len(cats)), cats, fontsize=7 if multiline else 8,
                      rotation=0 if multiline else 20)
        ax.set_title(label, fontsize=9)
        ax.set_xlabel(x_label, fontsize=8)
        ax.tick_params(axis="y", labelsize=8)
        ax.grid(True, axis="y", alpha=0.3)
    for ax in axes.flat[len(metrics):]:
        ax.set_visible(False)
    fig.suptitle(_title(title))
    fig.tight_layout()
    return fig
