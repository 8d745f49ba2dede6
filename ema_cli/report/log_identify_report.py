"""Figures and run folders of the log identifications: ``ema identify --closed-loop``,
``--friction-sweep`` and ``--make-data``.

Figure functions take a result and return a Figure; the ``write_*`` functions write a whole
folder through ``report.rundir`` (atomic writes; the caller prepares and finishes the folder).
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from matplotlib.figure import Figure

from ema_cli.identify.closed_loop.problem import CHANNELS, make_grid
from ema_cli.report.figures import subplots
from ema_cli.report.markdown import md_cell
from ema_cli.report.rundir import (
    manifest,
    write_columns,
    write_csv,
    write_figure,
    write_json,
    write_text,
)
from ema_cli.units import RPM

if TYPE_CHECKING:
    from ema_cli.identify.closed_loop.ga_fit import ClosedLoopFit
    from ema_cli.identify.friction.sweep import FrictionFit
    from ema_cli.identify.make_data import SyntheticLog

CHANNEL_LABELS = {"theta_load_deg": "load angle", "omega_motor_rpm": "motor speed",
                  "current_a": "armature current", "voltage_cmd_v": "voltage demand"}


def channel_figure(fit: ClosedLoopFit, channel: str) -> Figure:
    """Measured and fitted ``channel`` vs time (top) and the residual (bottom), edge units.
    A multiple-shooting fit shows the fit itself (the segments, each from its fitted start
    state) and the fitted model run from rest over the whole log (a check)."""
    p = fit.problem
    j = p.channels.index(channel)
    f = CHANNELS[channel][1]
    unit = CHANNELS[channel][2]
    t = p.log.t
    y = p.measured[j] / f
    yh = fit.prediction[j] / f
    seg = segment_prediction(fit)
    fig, (a0, a1) = subplots(2, 1, figsize=(11, 6.5), sharex=True)
    a0.plot(t, y, ".", color="0.55", ms=1.5, label="measured")
    if seg is None:
        a0.plot(t, yh, "C0", lw=0.9, label="fitted model")
    else:
        ys = seg[j] / f
        ms = fit.shooting
        first = ms.search.sp.seg.first if ms.fit_first is None else ms.fit_first
        n_seg, n_long = first.shape[0], ms.search.sp.seg.n
        cut = ("" if n_seg == n_long else
               f" (the estimate's {n_long} cut into parts for the covariance)")
        a0.plot(t, yh, "C0", lw=0.8, alpha=0.7,
                label="fitted model run from rest over the whole log (a check)")
        a0.plot(t, ys, "C1", lw=0.9, label=f"the fit: {n_seg} segments{cut}, each simulated "
                "from its fitted start state")
        if n_seg <= 40:  # where each segment starts (more would hide the signals)
            starts = t[first[1:]]
            for a in (a0, a1):
                for ts in starts:
                    a.axvline(ts, color="0.8", lw=0.6, zorder=0)
            a0.plot([], [], color="0.8", lw=0.6, label="segment starts")
        rms_run = float(np.sqrt(np.mean((y - yh) ** 2)))
        a1.plot(t, y - yh, color="C0", lw=0.5, alpha=0.5,
                label=f"measured − whole-log run (RMS {rms_run:.3g} {unit})")
    a0.set_ylabel(f"{CHANNEL_LABELS[channel]} [{unit}]")
    a0.set_title(f"{CHANNEL_LABELS[channel]}: measured and fitted")
    a0.legend(fontsize=8, loc="upper left")
    yf = yh if seg is None else seg[j] / f
    rms = float(np.sqrt(np.mean((y - yf) ** 2)))
    a1.plot(t, y - yf, color="C2", lw=0.6,
            label=f"measured − {'model' if seg is None else 'the fit (segments)'} "
                  f"(RMS {rms:.3g} {unit})")
    scale = p.scales[j] / f
    a1.axhline(scale, color="C3", ls=":", lw=0.9, label=f"±scale s_c = {scale:.3g} {unit}")
    a1.axhline(-scale, color="C3", ls=":", lw=0.9)
    a1.axhline(0.0, color="0.4", lw=0.6)
    a1.set_xlabel("time since the log's first sample [s]")
    a1.set_ylabel(f"residual [{unit}]")
    a1.set_title("Residual")
    a1.legend(fontsize=8, loc="upper left")
    for a in (a0, a1):
        a.grid(True, alpha=0.3)
    fig.suptitle(f"ema identify --closed-loop · {p.log.source}")
    fig.tight_layout()
    return fig


def alpha_profile_figure(fit: ClosedLoopFit) -> Figure:
    """The cost along alpha: slice (others at the optimum) and profile (others re-fitted,
    linearised), with the estimate, its 95 % interval and the truth when known."""
    p = fit.problem
    ja = p.names.index("alpha")
    fig, ax = subplots(figsize=(8.5, 5.0))
    g = fit.alpha_grid * 1e3
    ax.plot(g, fit.alpha_slice, "C0", lw=1.2, marker=".", ms=3,
            label="slice: other parameters at the optimum")
    ax.plot(g, fit.alpha_profile, "C1", lw=1.0, ls="--",
            label="profile: others re-fitted (linearised)")
    a = fit.x[ja] * 1e3
    ax.axvline(a, color="C3", lw=1.0, label=f"estimate α = {a:.5g} mrad")
    lo, hi = fit.uncertainty.ci_low[ja] * 1e3, fit.uncertainty.ci_high[ja] * 1e3
    if np.isfinite(lo) and np.isfinite(hi):
        ax.axvspan(lo, hi, color="C3", alpha=0.15, label="95 % interval")
    truth = p.log.truth
    if truth is not None and "alpha" in truth:
        ax.axvline(truth["alpha"] * 1e3, color="k", ls=":", lw=1.0, label="truth")
    if np.all(fit.alpha_slice > 0):
        ax.set_yscale("log")
    ax.set_xlabel("half backlash α [mrad]")
    ax.set_ylabel("cost J = Σ ((y − ŷ)/s_c)²  [-]")
    ax.set_title("Cost along alpha (non-smooth where backlash switches contact)")
    ax.legend(fontsize=8, loc="best")
    ax.grid(True, alpha=0.3)
    fig.tight_layout()
    return fig


def fitted_config(fit: ClosedLoopFit, reference: str) -> dict[str, Any]:
    """A run config (``ema simulate``) of the fitted actuator following the logged command."""
    p = fit.problem
    plant: dict[str, Any] = {k: v for k, v in p.fixed.items()}
    for n, v in zip(p.names, fit.x, strict=True):
        plant[n] = float(v)
    if "friction" not in plant and fit.params["friction"] == 1.0:
        plant["friction"] = 1
    grid = make_grid(p.log.t, p.dt, 1)
    duration = grid.n_steps * p.dt
    return {
        "name": "fitted",
        "description": f"the actuator identified by ema identify --closed-loop from "
                       f"{p.log.source}, following the logged command",
        "plant": plant,
        "input": {"kind": "csv", "path": reference},
        "simulation": {"duration_s": float(duration), "dt_s": p.dt,
                       "output_interval_s": float(grid.dec * p.dt)},
    }


def _search_text(fit: ClosedLoopFit) -> str:
    """How the optimum was searched, and the verdict on it (summary.md)."""
    ms = fit.shooting
    if ms is None:
        return ("Search: GA on the first " + (f"{fit.horizons[0]:g} s" if fit.horizons else "-")
                + " of the log, least-squares polish over the horizons " + ", ".join(
                    f"{s['horizon_s']:g} s (J {s['J']:.6g})" for s in fit.stages) + ".")
    s = ms.search
    verdict = ("**Optimum confirmed**" if ms.confirmed else
               "**Optimum NOT confirmed**: " + "; ".join(ms.reasons))
    pol = ms.polish
    kept = ("not run" if not pol.get("x") else "its optimum agrees with the estimate" if
            pol.get("agrees") else "differs: " + "; ".join(pol.get("why_not", [])))
    tie = ms.tie
    tie_text = ("Each segment's motor angle free (no motor speed fitted, or "
                "shooting.tie_motor_angle: false). " if tie is None else
                f"Motor angles tied to the integrated motor speed: {tie['joins']} joins at "
                f"{tie['rms_over_se']:.3g} x their standard error (p = {tie['p_value']:.2g}). ")
    seg = (f"{s.sp.seg.n} segments of the log" if not s.lengths else
           f"segments lengthened to {s.lengths[-1]:g} s ({s.sp.seg.n} of them"
           + ("" if ms.covariance_segments == s.sp.seg.n else
              f"; the covariance on {ms.covariance_segments} parts") + ")")
    if ms.fell_back:
        seg += (" (the longest segments did not fit at the fine step: the estimate is from "
                "the last length with enough segments for the covariance)")
    return (tie_text +
            f"Search: multiple shooting, {seg}, {len(s.starts_x)} "
            f"Sobol starts, joint Levenberg-Marquardt with successive halving; the "
            f"{len(s.final_cost)} finishing starts end at J = "
            + ", ".join(f"{c:.6g}" for c in s.final_cost) + f" ({s.agree} agree). "
            f"Whole-log polish from rest (a check): {kept}. Estimate from the {ms.source}."
            f"\n\n{verdict}.")


def closed_loop_summary(fit: ClosedLoopFit) -> str:
    """summary.md of a closed-loop identification."""
    js = fit.to_json()
    lines = [f"# ema identify --closed-loop: {fit.problem.log.source}", "",
             f"{fit.problem.log.n:,} samples over {fit.problem.log.duration:g} s; channels "
             + ", ".join(fit.problem.channels) + f"; cost J = {fit.cost:.6g} "
             f"({len(fit.residuals):,} weighted residuals).", "",
             "| parameter | value | unit | SE | 95 % interval | determined |"
             + (" truth | error % |" if "truth" in js else ""),
             "|---|---|---|---|---|---|" + ("---|---|" if "truth" in js else "")]
    for n, v in js["parameters"].items():
        det = "yes" if v["determined"] else "**NOT DETERMINED**: " + "; ".join(
            v["not_determined_because"])
        row = (f"| {n} | {md_cell(v['value'], 6)} | {v['unit']} | "
               f"{md_cell(v['standard_error'], 6)} | "
               f"[{md_cell(v['ci95'][0], 6)}, {md_cell(v['ci95'][1], 6)}] | {det} |")
        if "truth" in js:
            t = js["truth"].get(n)
            e = js["error_pct_vs_truth"].get(n)
            row += f" {'' if t is None else md_cell(t, 6)} | {'' if e is None else f'{e:+.3g}'} |"
        lines.append(row)
    lines += ["", "Fit RMS per channel: " + ", ".join(
        f"{c} {v:.4g} {CHANNELS[c][2]}" for c, v in js["fit_rms"].items()), "",
        "Correlations: " + "; ".join(
            f"{a}–{b} {fit.uncertainty.corr[i, k]:+.3f}"
            for i, a in enumerate(fit.names) for k, b in enumerate(fit.names) if k > i), "",
        _search_text(fit), "",
        "Timings: " + ", ".join(f"{k} {v:.2f}" for k, v in fit.timings.items())
        + f"; kernel throughput in the GA {fit.ga_throughput / 1e6:.1f} M steps/s.", ""]
    if fit.warnings:
        lines += ["Warnings:", *[f"- {w}" for w in fit.warnings], ""]
    lines += ["`fitted.yaml` runs the fitted actuator on the logged command: "
              "`ema simulate fitted.yaml`.", ""]
    return "\n".join(lines)


def segment_prediction(fit: ClosedLoopFit) -> np.ndarray | None:
    """The multiple-shooting fit's own prediction [n_ch, n] (SI), or None (``--method ga``)."""
    sh = fit.shooting
    return None if sh is None else sh.segment_prediction


def closed_loop_fit_columns(fit: ClosedLoopFit) -> dict[str, np.ndarray]:
    """fit.csv of a closed-loop identification: ``t_s``, then each fitted channel measured and
    simulated at the fit from rest over the whole log (``theta_load_deg``,
    ``theta_load_model_deg``, ...) and, for a multiple-shooting fit, as its segments predict
    it (``theta_load_segments_deg``, ...: the fit itself), edge units."""
    fits = {"t_s": fit.problem.log.t}
    seg = segment_prediction(fit)
    for j, c in enumerate(fit.problem.channels):
        f = CHANNELS[c][1]
        stem, unit = c.rsplit("_", 1)
        fits[c] = fit.problem.measured[j] / f
        fits[f"{stem}_model_{unit}"] = fit.prediction[j] / f
        if seg is not None:
            fits[f"{stem}_segments_{unit}"] = seg[j] / f
    return fits


def write_closed_loop(fit: ClosedLoopFit, out: Path, **fields: Any) -> list[str]:
    """Write a closed-loop identification folder -> the files written."""
    import yaml

    out = Path(out)
    files = ["identification.json"]
    write_json(out / "identification.json", fit.to_json())
    for c in fit.problem.channels:
        name = f"fit_{c}.png"
        write_figure(out / name, channel_figure(fit, c))
        files.append(name)
    if fit.alpha_grid is not None:
        write_figure(out / "alpha_profile.png", alpha_profile_figure(fit))
        write_columns(out / "alpha_profile.csv", {
            "alpha_rad": fit.alpha_grid, "J_slice": fit.alpha_slice,
            "J_profile_linearised": fit.alpha_profile}, float_format="%.12g")
        files += ["alpha_profile.png", "alpha_profile.csv"]
    # the command as the fit fed it to the simulator (a cubic command: its table, 8 points
    # per log interval), so that `ema simulate fitted.yaml` runs the fit's own simulation
    t_ref, ref = fit.problem.command_table()
    write_columns(out / "reference.csv", {"t_s": t_ref, "theta_ref_deg": np.degrees(ref)},
                  float_format="%.17g")
    write_text(out / "fitted.yaml", yaml.safe_dump(fitted_config(fit, "reference.csv"),
                                                  sort_keys=False))
    write_columns(out / "fit.csv", closed_loop_fit_columns(fit), float_format="%.12g")
    if fit.history is not None:
        h = fit.history
        write_columns(out / "history.csv", {
            "generation": np.arange(h.best.shape[0]), "evaluations": h.evaluations,
            "best_J": h.best, "mean_J": h.mean, "best_ever_J": h.best_ever,
            **{f"best_ever_{n}": h.x_best_ever[:, j] for j, n in enumerate(fit.names)}},
            float_format="%.12g")
        files.append("history.csv")
    write_text(out / "summary.md", closed_loop_summary(fit))
    files += ["reference.csv", "fitted.yaml", "fit.csv", "summary.md", "manifest.json"]
    write_json(out / "manifest.json", manifest(
        "identify --closed-loop", seed=fit.settings.seed,
        settings=fit.settings.model_dump(mode="json"), outputs=files, **fields))
    return files


def friction_figure(fit: FrictionFit) -> Figure:
    """Measured and fitted static friction curve vs motor speed, and the residuals."""
    d = fit.data
    fig, (a0, a1) = subplots(1, 2, figsize=(13, 5.0))
    rpm = d.omega / RPM
    a0.plot(rpm, d.torque, "o", color="0.5", ms=4, label="measured")
    lim = float(np.max(np.abs(d.omega)))
    w = np.geomspace(lim * 1e-4, lim, 400)
    for sign, label in ((1.0, "fitted static LuGre curve"), (-1.0, None)):
        a0.plot(sign * w / RPM, fit.model(sign * w), "C0", lw=1.2, label=label)
    a0.set_xscale("symlog", linthresh=float(np.min(np.abs(rpm))))
    a0.set_xlabel("motor speed [rpm]")
    a0.set_ylabel("friction torque [N·m]")
    p = fit.params
    a0.set_title(f"Fc {p['Fc']:.4g} N·m, Fs {p['Fs']:.4g} N·m, vs {p['vs']:.4g} rad/s, "
                 f"σ2 {p['sigma2']:.3g} N·m·s/rad", fontsize=9)
    a0.legend(fontsize=8, loc="upper left")
    r = d.torque - fit.model()
    a1.plot(rpm, r, "o", color="C2", ms=4,
            label=f"measured − model (RMS {np.sqrt(np.mean(r**2)):.3g} N·m)")
    a1.axhline(0.0, color="0.4", lw=0.6)
    a1.set_xscale("symlog", linthresh=float(np.min(np.abs(rpm))))
    a1.set_xlabel("motor speed [rpm]")
    a1.set_ylabel("residual torque [N·m]")
    a1.set_title("Residuals")
    a1.legend(fontsize=8, loc="upper left")
    for a in (a0, a1):
        a.grid(True, alpha=0.3)
    fig.suptitle(f"ema identify --friction-sweep · {d.source}")
    fig.tight_layout()
    return fig


def friction_summary(fit: FrictionFit) -> str:
    """summary.md of a friction-sweep identification."""
    js = fit.to_json()
    lines = [f"# ema identify --friction-sweep: {fit.data.source}", "",
             f"{fit.data.n} speeds; residual std {js['cost']['residual_std_nm']:.4g} N·m; "
             f"delta = {fit.delta:g} (fixed).", "",
             "| parameter | value | unit | SE | 95 % interval | determined |",
             "|---|---|---|---|---|---|"]
    for n, v in js["parameters"].items():
        det = "yes" if v["determined"] else "**NOT DETERMINED**: " + "; ".join(
            v["not_determined_because"])
        lines.append(f"| {n} | {md_cell(v['value'], 6)} | {v['unit']} | "
                     f"{md_cell(v['standard_error'], 6)}"
                     f" | [{md_cell(v['ci95'][0], 6)}, {md_cell(v['ci95'][1], 6)}] | {det} |")
    lines += ["", f"sigma0: {js['sigma0']}.", ""]
    if fit.warnings:
        lines += ["Warnings:", *[f"- {w}" for w in fit.warnings], ""]
    return "\n".join(lines)


def friction_fit_columns(fit: FrictionFit) -> dict[str, np.ndarray]:
    """fit.csv of a friction-sweep identification: ``omega_rpm``, ``torque_nm`` (measured),
    ``torque_model_nm`` (the fitted static curve)."""
    return {"omega_rpm": fit.data.omega / RPM, "torque_nm": fit.data.torque,
            "torque_model_nm": fit.model()}


def synthetic_figure(log: SyntheticLog) -> Figure:
    """Synthetic data: every column against the first (time, or motor speed), one panel each."""
    names = list(log.columns)
    x, ys = names[0], names[1:]
    fig, axes = subplots(len(ys), 1, figsize=(10, 1.8 + 1.6 * len(ys)), sharex=True,
                         squeeze=False)
    for ax, y in zip(axes[:, 0], ys, strict=True):
        ax.plot(log.columns[x], log.columns[y], lw=0.9)
        ax.set_ylabel(y)
        ax.grid(True, alpha=0.3)
    axes[-1, 0].set_xlabel(x)
    fig.suptitle(f"ema identify --make-data {log.kind}: {log.description}", fontsize=9)
    fig.tight_layout()
    return fig


def write_friction_sweep(fit: FrictionFit, out: Path, settings: dict[str, Any],
                         **fields: Any) -> list[str]:
    """Write a friction-sweep identification folder -> the files written."""
    out = Path(out)
    files = ["identification.json", "friction_fit.png", "fit.csv", "summary.md",
             "manifest.json"]
    write_json(out / "identification.json", fit.to_json())
    write_figure(out / "friction_fit.png", friction_figure(fit))
    write_columns(out / "fit.csv", friction_fit_columns(fit), float_format="%.12g")
    write_text(out / "summary.md", friction_summary(fit))
    write_json(out / "manifest.json", manifest("identify --friction-sweep", settings=settings,
                                               outputs=files, **fields))
    return files


def write_synthetic(log: SyntheticLog, out: Path, settings: dict[str, Any]) -> list[str]:
    """Write synthetic data: ``<kind>.csv``, ``<kind>.truth.json`` and the manifest."""
    import pandas as pd

    out = Path(out)
    stem = log.kind.replace("-", "_")
    write_csv(out / f"{stem}.csv", pd.DataFrame(log.columns), float_format="%.17g")
    write_json(out / f"{stem}.truth.json", log.sidecar())
    files = [f"{stem}.csv", f"{stem}.truth.json", "manifest.json"]
    write_json(out / "manifest.json", manifest("identify --make-data", settings=settings,
                                               seed=settings.get("seed"), outputs=files))
    return files
