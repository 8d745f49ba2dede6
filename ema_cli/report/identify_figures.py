"""Figures and the run folder of `ema identify`: convergence, fit, JSON/CSV tables, manifest.

The figure functions take an ``IdentificationResult`` and return a Figure (no file I/O);
:func:`write_identification` writes the whole output folder through ``report.rundir``;
:func:`write_identification_summary` writes the folders of an
``identify.torque.run.summarize_identification``; :func:`write_example_csv` writes identification
data as a CSV.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

import matplotlib
import numpy as np
from matplotlib.figure import Figure
from matplotlib.lines import Line2D

from ema_cli.model.transmission import shaft_torque
from ema_cli.report.figures import subplots
from ema_cli.report.rundir import manifest, write_csv, write_figure, write_json

if TYPE_CHECKING:
    from ema_cli.identify.torque.data import IdentData
    from ema_cli.identify.torque.run import IdentificationResult, IdentificationSummary

LOG_FLOOR_DECADES = 30  # J plots on a log axis are floored this many decades below the start
REL_FLOOR_PCT = 1e-14  # distances to the optimum below this (rounding) are drawn at it [%]
TARGET_PCT = 0.01  # the improved GA's accuracy target, drawn on the distance plots [%]
PLOT_UNITS = {"kL": ("kL", "N·m/rad", 1.0), "alpha": ("alpha", "mrad", 1e3),
              "c": ("c", "N·m·s/rad", 1.0)}
"""Display label, unit and SI->display factor of each parameter."""
MAX_FIT_POINTS = 20_000  # scatter at most this many samples in fit.png [points]
OUTPUT_FILES = ("identification.json", "runs.csv", "history.csv", "convergence.png", "fit.png",
                "manifest.json")


def _title(res: IdentificationResult) -> str:
    s = res.settings
    data = ("synthetic, " + f"{res.data.damping} damping, noise {res.data.noise_pct:g} %"
            if res.data.truth is not None else Path(s.data or "").name)
    return f"{s.method} · model {s.model} · {data} · {len(res.runs)} run(s)"


def _run_color(k: int, n: int) -> Any:
    return matplotlib.colormaps["viridis"](0.85 * k / max(n - 1, 1))


def convergence_figure(res: IdentificationResult) -> Figure:
    """Top: best and mean J vs generation (log) and each parameter vs generation with the truth
    and the least-squares optimum marked. Bottom: the best-ever point's excess cost over the
    optimum and its relative distance to the optimum per parameter (log), with the 0.01 %
    target. For ``method="exact"`` (no GA history) the profile ``Jp(alpha)`` is shown instead."""
    names = res.names
    hists = [r.history for r in res.runs if r.history is not None]
    if not hists:
        return _profile_only_figure(res)
    n_col = 1 + len(names)
    fig, axes = subplots(2, n_col, figsize=(5.0 * n_col, 8.4), sharex=True)
    opt = res.optimum
    n_h = len(hists)
    starts = [float(h.mean[0]) for h in hists if np.isfinite(h.mean[0]) and h.mean[0] > 0]
    floor = (max(starts) if starts else 1.0) * 10.0 ** (-LOG_FLOOR_DECADES)
    floored = False

    ax = axes[0, 0]
    for k, h in enumerate(hists):
        g = np.arange(h.best.shape[0])
        floored |= bool(np.any(h.best < floor))
        ax.plot(g, np.maximum(h.best, floor), color=_run_color(k, n_h), lw=1.2)
        ax.plot(g, np.maximum(h.mean, floor), color=_run_color(k, n_h), lw=0.7, ls=":")
    handles = [Line2D([], [], color="0.2", lw=1.2, label="best of generation"),
               Line2D([], [], color="0.2", lw=0.7, ls=":", label="population mean")]
    if opt.cost > floor:
        ax.axhline(opt.cost, color="C3", ls="--", lw=1.0)
        handles.append(Line2D([], [], color="C3", ls="--", label="least-squares optimum"))
    ax.set_yscale("log")
    ax.set_ylabel("J = Σ(T_meas − T_model)²  [N²·m²]")
    ax.set_title("Cost vs generation" + (f" (floored at {floor:.0e})" if floored else ""))
    ax.legend(handles=handles, fontsize=8, loc="upper right")

    ax = axes[1, 0]
    at_floor = False
    for k, h in enumerate(hists):
        excess = h.best_ever - opt.cost
        at_floor |= bool(np.any(excess < floor))
        ax.plot(np.arange(excess.shape[0]), np.maximum(excess, floor), color=_run_color(k, n_h),
                lw=1.2)
    ax.set_yscale("log")
    ax.set_xlabel("generation")
    ax.set_ylabel("J_best-ever − J_LS  [N²·m²]")
    ax.set_title("Excess cost over the least-squares optimum"
                 + (f"\n(rounding level: ≤ {floor:.0e} drawn at {floor:.0e})" if at_floor else ""))

    truth = res.truth
    for j, n in enumerate(names):
        label, unit, f = PLOT_UNITS[n]
        ax = axes[0, 1 + j]
        for k, h in enumerate(hists):
            ax.plot(np.arange(h.x_best.shape[0]), h.x_best[:, j] * f, color=_run_color(k, n_h),
                    lw=1.0)
        ax.plot([], [], color=_run_color(0, n_h), lw=1.0,
                label="best of generation (a line per run)")
        if truth is not None:
            ax.axhline(truth[n] * f, color="k", ls="--", lw=1.0, label="truth")
        ax.axhline(opt.x[j] * f, color="C3", ls=":", lw=1.4, label="least-squares optimum")
        ax.set_ylabel(f"{label} [{unit}]")
        ax.set_title(f"{label} vs generation (search range {res.problem.lower[j] * f:g}–"
                     f"{res.problem.upper[j] * f:g})")
        ax.legend(fontsize=8, loc="best")

        ax = axes[1, 1 + j]
        rel_floor = REL_FLOOR_PCT
        for k, h in enumerate(hists):
            rel = 100.0 * np.abs(h.x_best_ever[:, j] - opt.x[j]) / abs(opt.x[j])
            ax.plot(np.arange(rel.shape[0]), np.maximum(rel, rel_floor),
                    color=_run_color(k, n_h), lw=1.0)
        ax.axhline(TARGET_PCT, color="0.3", ls="-.", lw=1.0, label=f"{TARGET_PCT:g} % target")
        if truth is not None and truth[n] != opt.x[j]:
            gap = 100.0 * abs(truth[n] - opt.x[j]) / abs(opt.x[j])
            if gap > rel_floor:
                ax.axhline(gap, color="k", ls="--", lw=1.0, label="truth's distance")
        ax.set_yscale("log")
        ax.set_xlabel("generation")
        ax.set_ylabel(f"|{label} − {label}_LS| / {label}_LS  [%]")
        ax.set_title(f"Best-ever {label}: distance to the optimum")
        ax.legend(fontsize=8, loc="upper right")
    for a in axes.flat:
        a.grid(True, alpha=0.3)
    fig.suptitle(_title(res))
    fig.tight_layout()
    return fig


def _profile_only_figure(res: IdentificationResult) -> Figure:
    fig, ax = subplots(figsize=(7, 4.6))
    _profile_axes(ax, res)
    ax.set_title("Least-squares profile over alpha (exact method: no GA generations)")
    fig.suptitle(_title(res))
    fig.tight_layout()
    return fig


def _profile_axes(ax: Any, res: IdentificationResult) -> None:
    opt = res.optimum
    a_scale = PLOT_UNITS["alpha"][2]
    ax.plot(opt.alpha_grid * a_scale, opt.profile, "C0", lw=1.2, label="profile Jp(α)")
    ax.axvline(opt.x[1] * a_scale, color="C3", ls=":", lw=1.2,
               label=f"LS optimum α = {opt.x[1] * a_scale:.5g} mrad")
    if res.truth is not None:
        ax.axvline(res.truth["alpha"] * a_scale, color="k", ls="--", lw=1.0, label="truth")
    ax.set_yscale("log" if np.all(opt.profile > 0) else "linear")
    ax.set_xlabel("alpha [mrad]")
    ax.set_ylabel("min over kL (c) of J [N²·m²]")
    ax.legend(fontsize=8, loc="best")
    ax.grid(True, alpha=0.3)


def fit_figure(res: IdentificationResult) -> Figure:
    """Measured and identified torque vs deflection (the dead-zone characteristic), the
    residuals vs time, and the least-squares profile over alpha."""
    best = min(res.runs, key=lambda r: r.cost)
    p = res.problem.full_params(best.x)
    data = res.data
    model = res.problem.model_torque(best.x)
    resid = data.torque - model
    a_scale = PLOT_UNITS["alpha"][2]
    step = max(1, data.n_samples // MAX_FIT_POINTS)
    fig, axes = subplots(1, 3, figsize=(16, 4.8))

    ax = axes[0]
    dth = data.dth[::step] * a_scale
    ax.plot(dth, data.torque[::step], "o", color="0.6", ms=3.0, mew=0, label="measured")
    ax.plot(dth, model[::step], ".", color="C0", ms=1.2, alpha=0.8,
            label="identified model (with c·dω)")
    lim = float(np.max(np.abs(data.dth)))
    xs = np.linspace(-lim, lim, 401)
    spring = shaft_torque(xs, np.zeros_like(xs), p["kL"], p["alpha"], 0.0, "paper")
    ax.plot(xs * a_scale, spring, "C3", lw=1.4,
            label=f"kL·DZ(dθ, α): kL = {p['kL']:.4g}, α = {p['alpha'] * a_scale:.4g} mrad")
    for s in (-1, 1):
        ax.axvline(s * p["alpha"] * a_scale, color="C3", ls=":", lw=0.9)
    ax.set_xlabel("transmission deflection dθ [mrad]")
    ax.set_ylabel("transmission torque T [N·m]")
    ax.set_title("Dead-zone characteristic")
    ax.legend(fontsize=8, loc="upper left")

    ax = axes[1]
    rms = float(np.sqrt(np.mean(resid**2)))
    ax.plot(data.t[::step], resid[::step], color="C2", lw=0.6,
            label=f"T_meas − T_model (RMS {rms:.3g} N·m)")
    ax.axhline(0.0, color="0.4", lw=0.6)
    ax.set_xlabel("time [s]")
    ax.set_ylabel("residual torque [N·m]")
    ax.set_title(f"Residuals (J = {best.cost:.4g} N²·m²)")
    ax.legend(fontsize=8, loc="upper left")

    ax = axes[2]
    _profile_axes(ax, res)
    ax.set_title("Least-squares profile (the certificate)")
    for a in axes:
        a.grid(True, alpha=0.3)
    fig.suptitle(_title(res))
    fig.tight_layout()
    return fig


def write_identification(
    res: IdentificationResult, out: Path, command: str = "identify", **fields: Any
) -> list[str]:
    """Write the identification folder: identification.json, runs.csv, history.csv,
    convergence.png, fit.png and manifest.json (``fields`` are added to the manifest).
    Returns the file names written."""
    out = Path(out)
    write_json(out / "identification.json", res.to_json())
    write_csv(out / "runs.csv", res.runs_frame(), float_format="%.12g")
    write_csv(out / "history.csv", res.history_frame(), float_format="%.12g")
    write_figure(out / "convergence.png", convergence_figure(res))
    write_figure(out / "fit.png", fit_figure(res))
    write_json(out / "manifest.json", manifest(
        command, seed=res.settings.seed, settings=res.settings.model_dump(mode="json"),
        seeds=f"np.random.SeedSequence({res.settings.seed}).spawn({res.settings.runs})",
        wall_time_s=res.wall_time_s, outputs=list(OUTPUT_FILES), **fields))
    return list(OUTPUT_FILES)


def write_identification_summary(summary: IdentificationSummary, out: Path) -> None:
    """Write the identify folder of every run of ``summary`` (``identify.torque.run.
    summarize_identification``) under ``out`` (the paper-mode run's in ``out/ga-paper``)."""
    for sub, res in summary.results.items():
        write_identification(res, Path(out) / sub, command="identify (library)")


def write_example_csv(path: str | Path, data: IdentData) -> None:
    """Write ``data`` as an identification CSV with the canonical columns (for examples/tests)."""
    write_csv(Path(path), data.to_frame(), float_format="%.17g")
