"""Matplotlib figures of simulated runs: they take data and return a Figure (no file I/O)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

from matplotlib.figure import Figure


def subplots(nrows: int = 1, ncols: int = 1, figsize: tuple[float, float] = (8.0, 5.0),
             **kwargs: Any) -> tuple[Figure, Any]:
    """``plt.subplots`` without pyplot: a Figure no GUI backend or notebook state knows about
    (cheaper to import, never switches the user's backend, nothing to close)."""
    fig = Figure(figsize=figsize)
    return fig, fig.subplots(nrows, ncols, **kwargs)


LINE_STYLES = (("-", "o"), ("--", "s"), (":", "^"), ("-.", "D"), ((0, (5, 1, 1, 1)), "v"),
               ((0, (1, 3)), "P"))
"""(line style, marker) of the k-th of several curves that may coincide: each stays visible
when another lies exactly on it (different dashes, markers at staggered points)."""


def curve_style(k: int, n_points: int, n_curves: int) -> dict[str, Any]:
    """Matplotlib keywords for the k-th of ``n_curves`` curves of ``n_points`` points: colour
    ``C<k>``, a distinct line style, and markers at points staggered between the curves."""
    ls, marker = LINE_STYLES[k % len(LINE_STYLES)]
    every = max(n_points // 8, n_curves, 1)
    start = (k * every) // max(n_curves, 1)
    return {"color": f"C{k % 10}", "ls": ls, "marker": marker, "ms": 5, "mfc": "none",
            "markevery": (start, every), "lw": 1.4}


def coinciding(curves: Mapping[str, Any], tol: float) -> list[list[str]]:
    """Groups (of two or more labels) of curves that lie on each other: every finite point
    within ``tol`` (in the curves' unit) of the group's first curve. Curves of other lengths
    never coincide."""
    import numpy as np

    groups: list[list[str]] = []
    for name, y in curves.items():
        y = np.asarray(y, dtype=float)
        for g in groups:
            ref = np.asarray(curves[g[0]], dtype=float)
            if ref.shape == y.shape:
                both = np.isfinite(ref) & np.isfinite(y)
                same = np.array_equal(np.isfinite(ref), np.isfinite(y))
                if same and both.any() and float(np.max(np.abs(ref[both] - y[both]))) <= tol:
                    g.append(name)
                    break
        else:
            groups.append([name])
    return [g for g in groups if len(g) > 1]


def coincidence_note(groups: Sequence[Sequence[str]], tol: float, unit: str) -> str:
    """Words for :func:`coinciding`'s groups, e.g. ``0.1 deg = 1 deg = linear model (within
    0.05 dB)``; empty when none coincide."""
    if not groups:
        return ""
    return "; ".join(" = ".join(g) for g in groups) + f" (within {tol:g} {unit})"


def legend_outside(ax: Any, **kwargs: Any) -> Any:
    """A legend to the right of ``ax``, off the data (the figure keeps room for it)."""
    kwargs.setdefault("fontsize", 8)
    return ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0.0, **kwargs)


def tracking_figure(ts: Mapping[str, Any], title: str, axis: str | None = None) -> Figure:
    """Position and velocity: reference and response (top), their errors (bottom), vs time.

    ``ts`` maps edge-unit column names (``t_s``, ``theta_ref_deg`` or ``x_ref_mm``, ...) to
    arrays: a DataFrame or a dict (``BatchResult.signals_frame``, ``api.Simulation.table``);
    ``axis`` rotary (deg, deg/s) or translational (mm, mm/s); None: the table's columns say. The
    motor's line is drawn when the table has it.
    """
    rot = axis == "rotary" if axis is not None else "x_ref_mm" not in ts
    pos, vel = ("deg", "deg/s") if rot else ("mm", "mm/s")
    col = (lambda n: f"{n}_deg") if rot else (lambda n: f"{n}_mm")
    vcol = (lambda n: f"{n}_deg_s") if rot else (lambda n: f"{n}_mm_s")
    names = (("theta_ref", "theta_load", "theta_motor", "omega_ref", "omega_load") if rot
             else ("x_ref", "x_load", "x_motor", "v_ref", "v_load"))
    fig, axes = subplots(2, 2, figsize=(12, 7), sharex=True)
    t = ts["t_s"]
    ax = axes[0, 0]
    ax.plot(t, ts[col(names[0])], "k--", lw=1.2, label="reference")
    ax.plot(t, ts[col(names[1])], "C0", lw=1.4, label="load angle" if rot else "load position")
    if col(names[2]) in ts:
        ax.plot(t, ts[col(names[2])], "C1", lw=0.9, alpha=0.8, label="motor angle / m" if rot
                else "motor angle / ratio")
    ax.set_ylabel(f"position [{pos}]")
    ax.set_title("Position tracking")
    ax.legend(loc="best", fontsize=8)
    ax = axes[0, 1]
    ax.plot(t, ts[vcol(names[3])], "k--", lw=1.2, label="reference")
    ax.plot(t, ts[vcol(names[4])], "C0", lw=1.4, label="load speed" if rot else "load velocity")
    ax.set_ylabel(f"velocity [{vel}]")
    ax.set_title("Velocity tracking")
    ax.legend(loc="best", fontsize=8)
    ax = axes[1, 0]
    ax.plot(t, ts[col("err_pos")], "C3", lw=1.2)
    ax.axhline(0, color="0.6", lw=0.6)
    ax.set_ylabel(f"position error [{pos}]")
    ax.set_xlabel("time [s]")
    ax.set_title("Position error (reference - load)")
    ax = axes[1, 1]
    ax.plot(t, ts[vcol("err_vel")], "C3", lw=1.2)
    ax.axhline(0, color="0.6", lw=0.6)
    ax.set_ylabel(f"velocity error [{vel}]")
    ax.set_xlabel("time [s]")
    ax.set_title("Velocity error (reference - load)")
    for a in axes.flat:
        a.grid(True, alpha=0.3)
    fig.suptitle(title)
    # fixed margins instead of tight_layout: tight_layout draws the figure once more (a fifth
    # of a short `ema simulate`), and this layout never changes
    fig.subplots_adjust(left=0.07, right=0.985, bottom=0.075, top=0.9, wspace=0.2, hspace=0.22)
    return fig


def overlay_figure(
    series: Sequence[tuple[str, Mapping[str, Any]]],
    title: str,
    columns: tuple[str, str] = ("err_pos_deg", "err_vel_deg_s"),
    ylabels: tuple[str, str] = ("position error [deg]", "velocity error [deg/s]"),
    legend_title: str | None = None,
) -> Figure:
    """Paper-style overlay: one curve per run of two signals vs time (e.g. Figs 2-10)."""
    fig, axes = subplots(2, 1, figsize=(10, 7), sharex=True)
    for k, (label, ts) in enumerate(series):
        style = "--" if label.startswith("baseline") else "-"
        for ax, col in zip(axes, columns, strict=True):
            ax.plot(ts["t_s"], ts[col], style, color=f"C{k % 10}", lw=1.2, label=label)
    for ax, lab in zip(axes, ylabels, strict=True):
        ax.set_ylabel(lab)
        ax.grid(True, alpha=0.3)
        ax.axhline(0, color="0.6", lw=0.6)
    axes[0].legend(title=legend_title, fontsize=8, loc="best")
    axes[-1].set_xlabel("time [s]")
    fig.suptitle(title)
    fig.tight_layout()
    return fig
