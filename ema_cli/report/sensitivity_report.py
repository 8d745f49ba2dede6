"""A sensitivity study's output folder: indices, convergence, samples, figures, summary, manifest.

Layout of ``results/sensitivity/<name>/<stamp>_<hash>/`` (or ``--out``)::

    config.resolved.yaml     the validated config, every default filled in
    indices.csv              input, metric, transform, factor, S1, S1_conf, ST, ST_conf,
                             mu_star, mu_star_conf, sigma, mu (the other method's columns empty)
    convergence.csv          the same on nested prefixes of the design (column n)
    samples.parquet          one row per simulation: input, row, key, status, factor values,
                             metrics (edge units)
    indices_<input>.png      bar charts with confidence intervals, one panel per metric
    convergence_<input>.png  the indices vs n (doubling) with confidence bands
    summary.md               the ranking per input and metric, the figures
    manifest.json            version, git commit, seed, method, n, runs, timings

``api.sensitivity.run_sensitivity`` runs a study (``sensitivity.run.compute_sensitivity``) and
has this module write the folder (:func:`prepare_folder`, :func:`write_outputs`); nothing here
simulates. The folder follows the one ``--out`` policy (``rundir.prepare_output``): an unfinished
study of the same inputs (same config, method and n) is resumed in place; its samples come from
the job cache (``OUT/.cache`` for an ``--out`` outside results/, else ``results/.cache/sweep``),
so only the unfinished ones run.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import yaml
from matplotlib.figure import Figure

from ema_cli.config.base import check_plain_name
from ema_cli.config.sensitivity import SensitivityConfig
from ema_cli.report.figures import subplots
from ema_cli.report.markdown import md_cell
from ema_cli.report.run_inputs import RunInputs, run_inputs
from ema_cli.report.rundir import (
    FINISHED,
    finish_output,
    manifest,
    prepare_output,
    write_csv,
    write_figure,
    write_json,
    write_text,
)
from ema_cli.report.sweep_tables import metric_label
from ema_cli.sensitivity.analyze import ranking
from ema_cli.sensitivity.run import SensitivityResult

COMMAND = "sensitivity"
NEGLIGIBLE_ST = 0.02  # a factor with ST below this is listed as without influence [-]
CSV_FORMAT = "%.9g"


def fingerprint(cfg: SensitivityConfig, method: str, n: int,
                overrides: Sequence[tuple[str, Any]] = ()) -> RunInputs:
    """The study's inputs, its identity for resuming (``report.run_inputs.RunInputs``): every
    leaf of its config (parallel settings aside), the method and n."""
    doc = cfg.model_dump(mode="json", by_alias=True, exclude={"parallel"})
    return run_inputs(doc, sets=overrides, options={"method": method, "n": n})


def _metric_name(metric: str, transform: str) -> str:
    label = metric_label(metric)
    return f"log10 of {label}" if transform == "log10" else label


def indices_figure(res: SensitivityResult, input_name: str) -> Figure:
    """One panel per metric: Sobol S1 and ST (or Morris mu* and sigma) per factor as bars with
    their confidence intervals, factors sorted by ST (mu*)."""
    df = res.indices
    df = df[df["input"] == input_name]
    metrics = list(res.cfg.metrics)
    sobol = res.method == "sobol"
    fig, axes = subplots(1, len(metrics), figsize=(6.5 * len(metrics), 0.45 * res.design.d + 2.5),
                         squeeze=False)
    for ax, metric in zip(axes[0], metrics, strict=True):
        t = df[df["metric"] == metric]
        t = ranking(t, res.method).iloc[::-1]  # most influential at the top
        y = np.arange(len(t))
        h = 0.38
        if sobol:
            ax.barh(y + h / 2, t["ST"], h, xerr=t["ST_conf"], color="C0", capsize=3,
                    label="total ST")
            ax.barh(y - h / 2, t["S1"], h, xerr=t["S1_conf"], color="C1", capsize=3,
                    label="first order S1")
            ax.axvline(NEGLIGIBLE_ST, color="0.5", lw=0.8, ls=":",
                       label=f"ST = {NEGLIGIBLE_ST} (no influence below)")
            ax.set_xlabel(f"Sobol index [-] (bars: {res.cfg.sensitivity.conf_level:.0%} CI)")
        else:
            ax.barh(y + h / 2, t["mu_star"], h, xerr=t["mu_star_conf"], color="C0", capsize=3,
                    label="mu* (mean |EE|)")
            ax.barh(y - h / 2, t["sigma"], h, color="C2", label="sigma (spread of EE)")
            ax.set_xlabel("elementary effect [metric / factor range] (bars: "
                          f"{res.cfg.sensitivity.conf_level:.0%} CI)")
        ax.set_yticks(y, t["factor"])
        ax.set_title(_metric_name(metric, res.cfg.sensitivity.transform), fontsize=10)
        ax.grid(True, axis="x", alpha=0.3)
        ax.legend(fontsize=8, loc="lower right")
    what = "Sobol indices" if sobol else "Morris elementary effects"
    fig.suptitle(f"{res.cfg.name}, input {input_name}: {what} ({res.method}, n = {res.n}, "
                 f"{res.design.n_rows:,} runs)")
    fig.subplots_adjust(left=0.12, right=0.98, bottom=0.12, top=0.88, wspace=0.35)
    return fig


def convergence_figure(res: SensitivityResult, input_name: str) -> Figure:
    """One panel per metric: ST (Sobol) or mu* (Morris) of every factor against the design
    size n, doubling, with its confidence band."""
    df = res.convergence
    metrics = list(res.cfg.metrics)
    fig, axes = subplots(1, len(metrics), figsize=(6.5 * len(metrics), 5.0), squeeze=False)
    key = "ST" if res.method == "sobol" else "mu_star"
    for ax, metric in zip(axes[0], metrics, strict=True):
        if df.empty:
            continue
        t = df[(df["input"] == input_name) & (df["metric"] == metric)]
        for k, f in enumerate(res.design.factors):
            s = t[t["factor"] == f.name].sort_values("n")
            if s.empty:
                continue
            x, v, c = s["n"].to_numpy(), s[key].to_numpy(), s[f"{key}_conf"].to_numpy()
            color = f"C{k % 10}"
            ax.plot(x, v, "o-", color=color, lw=1.3, ms=3, label=f.name)
            ax.fill_between(x, v - c, v + c, color=color, alpha=0.15)
        ax.set_xscale("log", base=2)
        ax.set_xlabel("base samples n" if res.method == "sobol" else "trajectories r")
        ax.set_ylabel("total Sobol index ST [-]" if key == "ST" else "mu* [metric per range]")
        ax.set_title(_metric_name(metric, res.cfg.sensitivity.transform), fontsize=10)
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=7, ncol=2, loc="best")
    fig.suptitle(f"{res.cfg.name}, input {input_name}: convergence as n doubles (nested "
                 "designs, bands: confidence intervals)")
    fig.subplots_adjust(left=0.07, right=0.98, bottom=0.11, top=0.88, wspace=0.25)
    return fig


def figures(res: SensitivityResult) -> list[tuple[str, Figure]]:
    """(file name, Figure) of every figure of the folder."""
    out = []
    for r in res.inputs:
        check_plain_name(r.name, "an input name")
        out.append((f"indices_{r.name}.png", indices_figure(res, r.name)))
        if not res.convergence.empty:
            out.append((f"convergence_{r.name}.png", convergence_figure(res, r.name)))
    return out


def summary_markdown(res: SensitivityResult, names: Sequence[str]) -> str:
    """summary.md: the study, then per input and metric the factors ranked with their indices,
    the factors without influence, and the figures."""
    cfg = res.cfg
    sobol = res.method == "sobol"
    lines = [f"# {cfg.name}: global sensitivity ({res.method}, n = {res.n})", ""]
    if cfg.description:
        lines += [cfg.description.strip(), ""]
    lines += [f"{len(res.design.factors)} factors, {res.design.n_rows:,} runs per input "
              f"({res.computed:,} computed, {res.cached:,} from the job cache); metrics "
              f"{', '.join(f'`{m}`' for m in cfg.metrics)}"
              + (" analysed as log10" if cfg.sensitivity.transform == "log10" else "")
              + f"; confidence level {cfg.sensitivity.conf_level:g}.", ""]
    lines += ["| factor | varies | range | scale |", "|---|---|---|---|"]
    for f in cfg.factors:
        lines.append(f"| {f.label} | {f.target} | {f.range[0]:g} .. {f.range[1]:g} {f.unit} | "
                     f"{f.scale} |")
    lines.append("")
    ix = res.indices
    for r in res.inputs:
        lines += [f"## Input {r.name}", ""]
        for metric in cfg.metrics:
            t = ix[(ix["input"] == r.name) & (ix["metric"] == metric)]
            lines += [f"### {_metric_name(metric, cfg.sensitivity.transform)}", ""]
            if t[["ST" if sobol else "mu_star"]].isna().all().all():
                lines += ["Not analysed (see the notes).", ""]
                continue
            ranked = ranking(t, res.method)
            if sobol:
                lines += ["| rank | factor | ST | ± | S1 | ± |", "|---|---|---|---|---|---|"]
                for _, row in ranked.iterrows():
                    lines.append(f"| {row['rank']} | {row['factor']} | {md_cell(row['ST'])} | "
                                 f"{md_cell(row['ST_conf'])} | {md_cell(row['S1'])} | "
                                 f"{md_cell(row['S1_conf'])} |")
                small = ranked[ranked["ST"] < NEGLIGIBLE_ST]["factor"].tolist()
                lines += ["", f"Without influence (ST < {NEGLIGIBLE_ST}): "
                              f"{', '.join(small) or 'none'}.", ""]
            else:
                lines += ["| rank | factor | mu* | ± | sigma | mu |", "|---|---|---|---|---|---|"]
                for _, row in ranked.iterrows():
                    lines.append(f"| {row['rank']} | {row['factor']} | "
                                 f"{md_cell(row['mu_star'], 4)} | "
                                 f"{md_cell(row['mu_star_conf'], 4)} | "
                                 f"{md_cell(row['sigma'], 4)} | "
                                 f"{md_cell(row['mu'], 4)} |")
                lines.append("")
        for n in names:
            if n.endswith(f"_{r.name}.png"):
                lines += [f"![{n}]({n})", ""]
        for note in r.notes:
            lines += [f"Note: {note}", ""]
    return "\n".join(lines) + "\n"


def write_manifest(res: SensitivityResult, overrides: Sequence[tuple[str, Any]],
                   names: Sequence[str] = (), status: str | None = None) -> None:
    """manifest.json: provenance, the study, per-input run counts and timings."""
    assert res.folder is not None
    if status is None:
        status = ("interrupted" if res.interrupted else
                  "complete" if res.complete else "incomplete")
    cfg = res.cfg
    write_json(res.folder / "manifest.json", manifest(
        COMMAND, name=cfg.name, description=cfg.description, status=status, seed=cfg.seed,
        method=res.method, n=res.n, n_factors=res.design.d, transform=cfg.sensitivity.transform,
        runs_per_input=res.design.n_rows, runs_total=res.n_runs,
        factors=[f.model_dump(mode="json") for f in cfg.factors], metrics=list(cfg.metrics),
        inputs=[{"name": r.name, "input": r.input.model_dump(mode="json"),
                 "computed": r.sweep.computed, "cached": r.sweep.cached,
                 "backend": r.sweep.backend, "workers": r.sweep.workers,
                 "counts": r.sweep.counts(), "notes": r.notes} for r in res.inputs],
        computed=res.computed, cached=res.cached, timings_s=res.timings,
        wall_time_s=res.timings.get("total"), outputs=list(names),
        overrides=[list(o) for o in overrides]))


def write_outputs(res: SensitivityResult, overrides: Sequence[tuple[str, Any]] = ()) -> list[str]:
    """Write every output of a finished study into ``res.folder`` -> the names written."""
    folder = res.folder
    assert folder is not None
    names = ["config.resolved.yaml", "indices.csv", "convergence.csv", "samples.parquet"]
    write_csv(folder / "indices.csv", res.indices, float_format=CSV_FORMAT)
    write_csv(folder / "convergence.csv", res.convergence, float_format=CSV_FORMAT)
    from ema_cli.files import atomic_write

    samples = res.samples
    atomic_write(folder / "samples.parquet", lambda p: samples.to_parquet(p, index=False))
    for name, fig in figures(res):
        write_figure(folder / name, fig)
        names.append(name)
    write_text(folder / "summary.md", summary_markdown(res, names))
    names += ["summary.md", "manifest.json"]
    write_manifest(res, overrides, names)
    return names


def prepare_folder(res: SensitivityResult, out: Path | None,
                   overrides: Sequence[tuple[str, Any]]) -> Path:
    """Create (or resume) the output folder before any simulation runs (the finished study of
    the same inputs: kept as it is, nothing written)."""
    folder, state = prepare_output(COMMAND, res.cfg.name,
                                   fingerprint(res.cfg, res.method, res.n, overrides), out)
    res.folder = folder
    if state == FINISHED:
        return folder
    write_text(folder / "config.resolved.yaml",
               yaml.safe_dump(res.cfg.model_dump(mode="json"), sort_keys=False))
    write_manifest(res, overrides, status="running")
    return folder


def finished_study(folder: Path, fp: RunInputs) -> bool:
    """True if ``folder`` holds the finished ``ema sensitivity`` study with fingerprint ``fp``."""
    import json

    from ema_cli.report.rundir import MARKER

    try:
        mark = json.loads((folder / MARKER).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return False
    return (isinstance(mark, dict) and mark.get("command") == COMMAND
            and mark.get("fingerprint") == fp.fingerprint and mark.get("finished") is True)


def save_sensitivity(res: SensitivityResult, out: Path | None = None,
                     overrides: Sequence[tuple[str, Any]] = ()) -> Path:
    """Write the folder ``ema sensitivity`` writes for a study computed without one (the
    Python API's ``Sensitivity.save``) -> the folder."""
    prepare_folder(res, out, overrides)
    assert res.folder is not None
    if finished_study(res.folder, fingerprint(res.cfg, res.method, res.n, overrides)):
        return res.folder  # the finished study of the same inputs: kept as it is
    write_outputs(res, overrides)
    if res.complete:
        finish_output(res.folder)
    return res.folder

