"""Threshold plots: each required metric vs the varied magnitude, limit and threshold marked."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from matplotlib.figure import Figure

from ema_cli.analysis.threshold import ThresholdResult
from ema_cli.config.criteria import Criterion
from ema_cli.report.figures import subplots
from ema_cli.sim.tables import METRIC_BY_EDGE


def threshold_figure(result: ThresholdResult, criteria: Sequence[Criterion], vary_label: str,
                     title: str, log: bool = True) -> Figure:
    """One panel per requirement: every simulated magnitude (pass green, fail red), the limit
    (dashed) and the threshold found (vertical line)."""
    fig, axes = subplots(len(criteria), 1, figsize=(9, 3.6 * len(criteria)), squeeze=False)
    h = result.history.sort_values("value")
    for ax, crit in zip(axes[:, 0], criteria, strict=True):
        y = h[crit.metric].to_numpy(dtype=float)
        x = h["value"].to_numpy(dtype=float)
        ax.plot(x, y, "-", color="0.7", lw=1, zorder=1)
        ok = h["passes"].to_numpy(dtype=bool)
        ax.scatter(x[ok], y[ok], s=18, color="C2", label="meets all requirements", zorder=2)
        ax.scatter(x[~ok], y[~ok], s=18, color="C3", marker="x", label="fails", zorder=2)
        ax.axhline(crit.limit, color="k", ls="--", lw=1, label=f"limit {crit}")
        if np.isfinite(result.threshold):
            ax.axvline(result.threshold, color="C0", lw=1.5,
                       label=f"threshold {result.threshold:.4g} ({result.status})")
        if log:
            ax.set_xscale("log")
        finite = y[np.isfinite(y)]
        if log and len(finite) and finite.min() > 0 and finite.max() / finite.min() > 100:
            ax.set_yscale("log")
        col = METRIC_BY_EDGE[crit.metric]
        ax.set_ylabel(crit.metric)
        ax.set_title(col.description, fontsize=9)
        ax.set_xlabel(vary_label)
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=8, loc="best")
    fig.suptitle(title)
    fig.tight_layout()
    return fig
