"""The run folder of ``ema identify plant`` (and ``validate``): JSON, Markdown, CSVs, figures.

Figures and tables speak the axis' units: a translational axis in mm, mm/s, N, kg (never deg
or N*m), a rotary one in deg, N*m, kg*m^2. Figure functions return Figures; ``write_plant``
writes a folder through ``report.rundir`` (atomic writes).
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from matplotlib.figure import Figure

from ema_cli.report.figures import subplots
from ema_cli.report.markdown import md_cell
from ema_cli.report.rundir import manifest, write_columns, write_figure, write_json, write_text

if TYPE_CHECKING:
    from ema_cli.identify.plant.fit import LawFit, PlantFit
    from ema_cli.identify.plant.validation import PlantValidation

TERM_UNITS = {
    "translational": {"M": "kg", "Fv": "N*s/m", "Fc": "N", "OF": "N"},
    "rotary": {"M": "kg*m^2", "Fv": "N*m*s/rad", "Fc": "N*m", "OF": "N*m"},
}
"""A term's SI unit per axis, by its family (``Fv+`` -> ``Fv``)."""
EDGE = {"translational": {"position": ("mm", 1e3), "force": ("N", 1.0), "velocity": ("mm/s", 1e3),
                          "small": ("um", 1e6)},
        "rotary": {"position": ("deg", 180 / np.pi), "force": ("N*m", 1.0),
                   "velocity": ("deg/s", 180 / np.pi), "small": ("mdeg", 180e3 / np.pi)}}
"""Edge units of the channels per axis: (unit, factor from SI)."""


def axis_of(fit: PlantFit) -> str:
    """``translational`` or ``rotary``."""
    return "rotary" if fit.axis == "rotary" else "translational"


EXTRA_UNITS = {"translational": {"Fs": "N", "Fc": "N", "vs": "m/s", "sigma0": "N/m",
                                 "sigma1": "N*s/m", "Fv": "N*s/m", "delta": "-", "offset": "N"},
               "rotary": {"Fs": "N*m", "Fc": "N*m", "vs": "rad/s", "sigma0": "N*m/rad",
                          "sigma1": "N*m*s/rad", "Fv": "N*m*s/rad", "delta": "-",
                          "offset": "N*m"}}
"""Units of kernel parameters freed as themselves (``--free``), by their stem."""


def term_unit(name: str, axis: str) -> str:
    """The SI unit of a term (or a freed kernel parameter) on an axis."""
    stem = name.rstrip("+-")
    if stem in TERM_UNITS[axis]:
        return TERM_UNITS[axis][stem]
    return EXTRA_UNITS[axis].get(name.split("_")[0], "")


def parameters_table(lf: LawFit, axis: str) -> list[dict[str, Any]]:
    """One row per parameter of a law's fit: value, unit, SE, 95 % interval (cluster-robust),
    status (determined | zero within its interval | NOT DETERMINED: why), IDIM-LS start."""
    u = lf.uncertainty
    rows = []
    n_idim = lf.start.theta.size
    for j, n in enumerate(u.names):
        status = lf.status(j)
        rows.append({"parameter": n, "value": float(u.x[j]), "unit": term_unit(n, axis),
                     "standard_error": float(u.se[j]), "ci95_low": float(u.ci_low[j]),
                     "ci95_high": float(u.ci_high[j]), "status": status,
                     "idim_ls": float(lf.start.theta[j]) if j < n_idim else float("nan"),
                     "idim_ls_std": float(lf.start.std[j]) if j < n_idim else float("nan")})
    return rows


def plant_json(fit: PlantFit) -> dict[str, Any]:
    """Everything the run measured, SI with units."""
    axis = axis_of(fit)
    laws = {}
    for name, lf in fit.laws.items():
        ok, bad = lf.determined()
        laws[name] = {
            "parameters": parameters_table(lf, axis),
            "determined": ok, "not_determined": bad,
            "covariance": "cluster-robust (CR3 delete-one-cluster jackknife) over "
                          f"{lf.clusters} time blocks of {lf.block_s:.3g} s",
            "correlation": lf.uncertainty.corr.tolist(),
            "adequacy": lf.adequacy.as_dict(),
            "fit": {"iterations": lf.fit.iterations, "converged": lf.fit.converged,
                    "status": lf.fit.status,
                    "channel_levels": {"force_n": lf.fit.levels[0],
                                       "position_m": lf.fit.levels[1]}},
        }
    split = None
    if fit.split is not None:
        split = {**{k: v for k, v in fit.split.items() if k != "errors"},
                 "errors_pct": {k: v.as_dict() for k, v in fit.split["errors"].items()}}
    rec = fit.record
    return {
        "settings": fit.settings.model_dump(mode="json"),
        "delay_samples": fit.delay,
        "models": ({"output error": fit.best.estimate,
                    "IDIM-LS": dict(zip(fit.baseline.names, map(float, fit.baseline.theta),
                                        strict=True))} if fit.controller is not None else
                   {f"IDIM-LS ({fit.chosen})": fit.best.estimate}),
        "record": {"source": rec.source, "samples": rec.n, "sample_interval_s": rec.h_s,
                   "duration_s": float(rec.t_s[-1]), "names": rec.names,
                   "gain": fit.extras["gain"], "gain_from": fit.extras["gain_from"],
                   "fitted_samples": int(np.count_nonzero(fit.use))},
        "axis": axis,
        "mode": fit.mode,
        "controller_check": (None if fit.controller is None else
                             {**fit.controller.as_dict(), "delay_used": fit.delay}),
        "baseline_idim_ls": fit.baseline.as_dict(),
        "chosen_law": fit.chosen, "why": fit.choice,
        "laws": laws,
        "benchmark_errors_pct": {k: v.as_dict() for k, v in fit.errors.items()},
        "time_split_validation": split,
        "timings_s": fit.timings, "kernel": fit.kernel,
    }


def _fmt(v: float, digits: int = 6) -> str:
    return "n/a" if not np.isfinite(v) else f"{v:.{digits}g}"


def plant_markdown(fit: PlantFit, validation: PlantValidation | None = None) -> str:
    """plant.md: the verdict in two parts, the parameters, the errors beside IDIM-LS."""
    axis = axis_of(fit)
    lf = fit.best
    ok, bad = lf.determined()
    a = lf.adequacy
    lines = [f"# Plant identification: {md_cell(Path(str(fit.settings.data)).name)}", "",
             f"Record: {fit.record.n} samples every {fit.record.h_s * 1e3:.4g} ms "
             f"({fit.record.t_s[-1]:.4g} s), {int(np.count_nonzero(fit.use))} fitted. "
             + (f"Controller check: {md_cell(fit.controller.summary())}; delay used: "
                f"{fit.delay} sample(s)." if fit.controller is not None else
                f"Mode: {md_cell(fit.mode)}."), "",
             f"**Law: {fit.chosen}** ({md_cell(fit.choice)}).", "",
             f"**Determined: {'yes' if ok else 'NO (' + ', '.join(bad) + ')'}** - 95 % "
             f"intervals from the cluster-robust covariance (CR3 jackknife over {lf.clusters} "
             f"time blocks of {lf.block_s:.3g} s; the residuals are coloured).", "",
             f"**Adequacy: {a.verdict}** - " + md_cell("; ".join(a.reasons)), "",
             "| parameter | value | unit | 95 % interval | status | IDIM-LS |",
             "|---|---|---|---|---|---|"]
    for r in parameters_table(lf, axis):
        lines.append(f"| {r['parameter']} | {_fmt(r['value'])} | {r['unit']} | "
                     f"[{_fmt(r['ci95_low'])}, {_fmt(r['ci95_high'])}] | {md_cell(r['status'])} "
                     f"| {_fmt(r['idim_ls'])} +- {_fmt(r['idim_ls_std'], 3)} |")
    lines += ["", "## The benchmark's relative errors [%] on the fitted samples", "",
              "| model | position | velocity | acceleration | force |", "|---|---|---|---|---|"]
    for k, e in fit.errors.items():
        d = e.as_dict()
        lines.append(f"| {k} | " + " | ".join(_fmt(d[c], 4) for c in
                                               ("position", "velocity", "acceleration",
                                                "force")) + " |")
    if fit.split is not None:
        s = fit.split
        lines += ["", f"## Time-split validation: fitted before t = {s['t_split_s']:.4g} s, "
                  f"scored after ({s['held_out_samples']} samples the fit did not use)", "",
                  "| model | position | velocity | acceleration | force |", "|---|---|---|---|---|"]
        for k, e in s["errors"].items():
            d = e.as_dict()
            lines.append(f"| {k} | " + " | ".join(_fmt(d[c], 4) for c in
                                                   ("position", "velocity", "acceleration",
                                                    "force")) + " |")
    if validation is not None:
        lines += ["", "## Validation on another record", "", validation_markdown(validation)]
    lines += ["", "## Adequacy", "", "| channel | fit [%] |", "|---|---|"]
    lines += [f"| {k} | {v:.4g} |" for k, v in a.fit_pct.items()]
    lines += ["", "| omitted term | t | lowers the force residual by | missed |",
              "|---|---|---|---|"]
    lines += [f"| {md_cell(o.name)} ({md_cell(o.meaning)}) | {o.t:.3g} | {100 * o.gain:.3g} % "
              f"| {'yes' if o.missed else 'no'} |" for o in a.omitted]
    lines += ["", "| residual test | worst | at lag | bound | share of lags beyond |",
              "|---|---|---|---|---|"]
    lines += [f"| {t.name} | {t.worst:.3g} | {t.lag} | {t.bound:.3g} | {100 * t.outside:.0f} % |"
              for t in a.tests]
    fu, ff = EDGE[axis]["force"]
    lines += ["", "Force residual RMS by motion: " + ", ".join(
        f"{k} {v * ff:.3g} {fu}" for k, v in a.motion.items()) + "."]
    for ch, rng in a.ranges.items():
        if rng:
            spans = ", ".join(f"{t0:.3g}-{t1:.3g} s (x{r:.2g})" for t0, t1, r in rng[:8])
            lines.append(f"Where the {ch} residual exceeds twice its median block RMS: {spans}.")
    return "\n".join(lines) + "\n"


def validation_markdown(v: PlantValidation) -> str:
    """The errors of the fit and of the IDIM-LS baseline on another record."""
    check = ("controller check: " + md_cell(v.controller.summary()) if v.controller is not None
             else "inverse model: the force predicted from the measured motion")
    lines = [f"Record {md_cell(v.record.source)}: {v.record.n} samples; {check}.", "",
             *[f"Note: {md_cell(n)}" for n in v.notes], *([""] if v.notes else []),
             "| model | position | velocity | acceleration | force | RMS position error |",
             "|---|---|---|---|---|---|"]
    for k, e in v.errors.items():
        d = e.as_dict()
        lines.append(f"| {k} | " + " | ".join(_fmt(d[c], 4) + " %" for c in
                                               ("position", "velocity", "acceleration", "force"))
                     + f" | {_fmt(v.rms_position_m[k] * 1e6, 4)} um |")
    return "\n".join(lines)


def channels_figure(t: np.ndarray, measured: dict[str, np.ndarray],
                    sims: dict[str, dict[str, np.ndarray]], axis: str, title: str,
                    use: np.ndarray | None = None) -> Figure:
    """Force (measured and each model) and each model's residuals: force and position error,
    against time, in the axis' units; the residual axes scaled to the samples ``use`` (the
    fitted ones: the controller's start-up left out), the others shaded."""
    fu, ff = EDGE[axis]["force"]
    su, sf = EDGE[axis]["small"]
    fig, ax = subplots(3, 1, figsize=(10.0, 8.0), sharex=True)
    ax[0].plot(t, measured["F"] * ff, color="0.6", lw=1.6, label="measured")
    for k, (name, s) in enumerate(sims.items()):
        ax[0].plot(t, s["F"] * ff, color=f"C{k}", lw=0.9, ls="-" if k == 0 else "--",
                   label=f"model: {name}")
        rF = (measured["F"] - s["F"]) * ff
        ax[1].plot(t, rF, color=f"C{k}", lw=0.7,
                   label=f"{name}: RMS {_fmt(float(np.sqrt(np.nanmean(rF ** 2))), 3)} {fu}")
        if np.all(np.isnan(s["q"])):
            continue
        rq = (measured["q"] - s["q"]) * sf
        ax[2].plot(t, rq, color=f"C{k}", lw=0.7,
                   label=f"{name}: RMS {_fmt(float(np.sqrt(np.nanmean(rq ** 2))), 3)} {su}")
    if use is not None and use.any() and not use.all():
        for a, key, f in ((ax[1], "F", ff), (ax[2], "q", sf)):
            worst = max(float(np.nanmax(np.abs(measured[key][use] - s[key][use]), initial=0.0))
                        * f for s in sims.values())
            if np.isfinite(worst) and worst > 0:
                a.set_ylim(-1.15 * worst, 1.15 * worst)
        edges = np.flatnonzero(np.diff(np.r_[0, (~use).astype(int), 0]))
        for k0, k1 in zip(edges[::2], edges[1::2], strict=True):
            for a in ax:
                a.axvspan(t[k0], t[min(k1, t.size - 1)], color="0.85", zorder=0,
                          label="not fitted" if (a is ax[0] and k0 == edges[0]) else None)
    ax[0].set_ylabel(f"actuation force [{fu}]")
    ax[1].set_ylabel(f"force residual\nmeasured - simulated [{fu}]")
    ax[2].set_ylabel(f"position residual\nmeasured - simulated [{su}]")
    ax[2].set_xlabel("time [s]")
    if all(np.all(np.isnan(s["q"])) for s in sims.values()):
        ax[2].text(0.5, 0.5, "inverse model: no simulated position (no closed loop to run)",
                   transform=ax[2].transAxes, ha="center", va="center", color="0.4")
    for a in ax:
        a.grid(alpha=0.3)
        if a.get_legend_handles_labels()[0]:
            a.legend(loc="upper right", fontsize=8)
    ax[0].set_title(title)
    fig.tight_layout()
    return fig


def residual_tests_figure(lf: LawFit) -> Figure:
    """The residual tests of a fit: autocorrelations and cross-correlations with their 95 %
    bounds (module ``identify.plant.adequacy``)."""
    fig, ax = subplots(2, 2, figsize=(10.0, 6.0))
    for a, t in zip(ax.ravel(), lf.adequacy.tests, strict=False):
        lag0 = 0 if "x" in t.name.split(":")[0] else 1
        lags = np.arange(lag0, lag0 + t.values.size)
        a.vlines(lags, 0, t.values, color="C0", lw=1.2)
        a.axhline(t.bound, color="C3", ls="--", lw=1, label=f"95 % bound +-{t.bound:.2g}")
        a.axhline(-t.bound, color="C3", ls="--", lw=1)
        a.axhline(0, color="0.3", lw=0.6)
        a.set_title(t.name, fontsize=9)
        a.set_xlabel("lag [samples]")
        a.set_ylabel("correlation [-]")
        a.legend(fontsize=7, loc="upper right")
        a.grid(alpha=0.3)
    fig.suptitle(f"Residual tests, law {lf.law}: coloured residuals are why the intervals are "
                 "cluster-robust", fontsize=10)
    fig.tight_layout()
    return fig


def fit_columns(fit: PlantFit) -> dict[str, np.ndarray]:
    """fit.csv: time, measured and simulated (fit, IDIM-LS) force and position, edge units."""
    axis = axis_of(fit)
    pu, pf = EDGE[axis]["position"]
    fu, ff = EDGE[axis]["force"]
    r, b, bl = fit.record, fit.best, fit.baseline_sim
    return {"t_s": r.t_s, f"force_measured_{fu}": r.force_n * ff,
            f"force_fit_{fu}": b.F * ff, f"force_idim_{fu}": bl["F"] * ff,
            f"position_measured_{pu}": r.q_m * pf, f"position_fit_{pu}": b.q * pf,
            f"position_idim_{pu}": bl["q"] * pf, "fitted": fit.use.astype(int)}


def fitted_description(fit: PlantFit) -> dict[str, Any]:
    """The actuator description with the fitted values (SI with units), delay and law."""
    import yaml

    desc = yaml.safe_load(Path(fit.settings.actuator).read_text())
    if isinstance(desc, dict) and set(desc) == {"actuator"}:
        desc = desc["actuator"]
    est = fit.best.estimate
    axis = axis_of(fit)
    fu = "N" if axis == "translational" else "N*m"
    vu = "N*s/m" if axis == "translational" else "N*m*s/rad"
    load = dict(desc.get("load", {}))
    load["mass" if axis == "translational" else "inertia"] = est["M"]
    if "OF" in est:
        load["offset"] = f"{est['OF']:.10g} {fu}"
    elif "offset" in load:
        load["offset"] = f"0 {fu}"
    desc["load"] = load
    fr = dict(desc.get("friction", {}))
    site = dict(fr.get("load", {}))
    if "Fc" in est:
        site["coulomb"] = f"{est['Fc']:.10g} {fu}"
        site["viscous"] = f"{est['Fv']:.10g} {vu}"
        site.pop("negative", None)
    else:
        site["coulomb"] = f"{est['Fc+']:.10g} {fu}"
        site["viscous"] = f"{est['Fv+']:.10g} {vu}"
        site["negative"] = {"coulomb": f"{est['Fc-']:.10g} {fu}",
                            "viscous": f"{est['Fv-']:.10g} {vu}"}
    site.pop("static", None)
    for name, key, unit in (("Fs_L", "static", fu), ("vs_L", "stribeck_velocity",
                                                    "m/s" if axis == "translational" else "rad/s"),
                            ("sigma0_L", "bristle_stiffness",
                             "N/m" if axis == "translational" else "N*m/rad"),
                            ("sigma1_L", "bristle_damping",
                             "N*s/m" if axis == "translational" else "N*m*s/rad")):
        if name in est:
            site[key] = f"{est[name]:.10g} {unit}"
    fr["load"] = site
    desc["friction"] = fr
    if fit.controller is not None:
        ctrl = dict(desc.get("controller", {}))
        ctrl["delay_samples"] = fit.delay
        desc["controller"] = ctrl
    desc["description"] = (f"{desc.get('description', '')} Fitted by ema identify plant on "
                           f"{Path(str(fit.settings.data)).name} (law {fit.chosen}).").strip()
    return desc


def write_plant(fit: PlantFit, out: Path, validation: PlantValidation | None = None,
                **fields: Any) -> list[str]:
    """Write the folder: plant.json, plant.md, parameters.csv, fit.csv, actuator_fitted.yaml,
    fit.png, residual_tests.png (and validation.json, validation.png) and manifest.json."""
    import yaml

    from ema_cli.report.rundir import write_csv

    axis = axis_of(fit)
    js = plant_json(fit)
    if validation is not None:
        js["validation"] = {"source": validation.record.source,
                            "errors_pct": {k: v.as_dict() for k, v in validation.errors.items()},
                            "rms_position_m": validation.rms_position_m,
                            "notes": validation.notes,
                            "controller_check": validation.controller.as_dict()}
    write_json(out / "plant.json", js)
    write_text(out / "plant.md", plant_markdown(fit, validation))
    import pandas as pd

    write_csv(out / "parameters.csv", pd.DataFrame(parameters_table(fit.best, axis)), index=False)
    write_columns(out / "fit.csv", fit_columns(fit), float_format="%.10g")
    write_text(out / "actuator_fitted.yaml",
               yaml.safe_dump({"actuator": fitted_description(fit)}, sort_keys=False))
    r = fit.record
    if fit.controller is None:  # the inverse model: predicted force, no simulated motion
        nanq = np.full(r.n, np.nan)
        sims = {f"IDIM-LS ({fit.chosen})": {"F": fit.best.F, "q": nanq}}
    else:
        sims = {f"fit ({fit.chosen})": {"F": fit.best.F, "q": fit.best.q},
                "IDIM-LS (benchmark reference model)": fit.baseline_sim}
    write_figure(out / "fit.png", channels_figure(
        r.t_s, {"F": r.force_n, "q": r.q_m}, sims, axis,
        ("Closed-loop simulation from the reference" if fit.controller is not None else
         "Inverse model (force from the measured motion)")
        + f" vs the record {Path(str(fit.settings.data)).name}", fit.use))
    write_figure(out / "residual_tests.png", residual_tests_figure(fit.best))
    files = ["plant.json", "plant.md", "parameters.csv", "fit.csv", "actuator_fitted.yaml",
             "fit.png", "residual_tests.png"]
    if validation is not None and validation.sims:
        v = validation
        write_figure(out / "validation.png", channels_figure(
            v.record.t_s, {"F": v.record.force_n, "q": v.record.q_m},
            {f"fit ({fit.chosen})": v.sims["output error"],
             "IDIM-LS (benchmark reference model)": v.sims["IDIM-LS"]}, axis,
            f"Validation: the fitted model on {v.record.source.split(chr(39))[1]}"
            if "'" in v.record.source else "Validation"))
        files.append("validation.png")
    if validation is not None:
        write_text(out / "validation.md", validation_markdown(validation) + "\n")
        files.append("validation.md")
    write_json(out / "manifest.json", manifest("identify plant", timings_s=fit.timings,
                                               kernel=fit.kernel, **fields))
    return files + ["manifest.json"]


def write_validation(v: PlantValidation, out: Path, axis: str) -> list[str]:
    """A validation's own folder: validation.md, validation.json, validation.png (when the
    models were simulated) and manifest.json."""
    write_text(out / "validation.md", "# Validation\n\n" + validation_markdown(v) + "\n")
    write_json(out / "validation.json", {
        "source": v.record.source, "errors_pct": {k: e.as_dict() for k, e in v.errors.items()},
        "rms_position_m": v.rms_position_m, "notes": v.notes,
        "controller_check": None if v.controller is None else v.controller.as_dict()})
    files = ["validation.md", "validation.json"]
    if v.sims:
        write_figure(out / "validation.png", channels_figure(
            v.record.t_s, {"F": v.record.force_n, "q": v.record.q_m},
            {k: {"F": s["F"], "q": s["q"]} for k, s in v.sims.items()}, axis,
            f"Validation on {v.record.source}"))
        files.append("validation.png")
    write_json(out / "manifest.json", manifest("identify validate"))
    return files + ["manifest.json"]
