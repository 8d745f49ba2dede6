"""Run and write a reproduction: study sweeps, identification, paper figures, threshold plots,
claims.csv, REPORT.md, manifest.

``api.reproduce.run_experiment`` runs the batch (its sweeps and identification write their
folders under ``out``; the rest is computed by ``analysis.reproduce``);
:func:`write_reproduction` writes the report from the computed ``Reproduction`` (nothing here
simulates).
"""

from __future__ import annotations

from pathlib import Path

import pandas as pd

from ema_cli.analysis.claims import verdicts_frame
from ema_cli.analysis.reproduce import (
    Reproduction,
)
from ema_cli.config.base import check_plain_name
from ema_cli.config.experiment import StudySpec
from ema_cli.model.nonlinearities import lookup
from ema_cli.report.figures import overlay_figure
from ema_cli.report.markdown import md_cell, md_table
from ema_cli.report.rundir import manifest, write_csv, write_figure, write_json, write_text
from ema_cli.report.threshold_figures import threshold_figure

FIGURE_METRICS = ("t50_s", "overshoot_pct", "settling_time_s", "p2p_err_pos_deg",
                  "ss_err_pos_deg", "iae_pos_deg_s", "peak_load_rate_deg_s",
                  "peak_voltage_cmd_v", "peak_current_a")
"""Metrics listed under each figure of REPORT.md."""


def under(out: Path, *names: str) -> Path:
    """``out/name/...`` where every name is a plain file or folder name (ids and figure names
    come from the experiment file; the schema has checked them, this keeps every join safe)."""
    for name in names:
        check_plain_name(name, "an output file or folder name")
    return out.joinpath(*names)


def study_figure(rep: Reproduction, spec: StudySpec):
    """Our version of one paper figure: every run of the study overlaid."""
    res = rep.sweeps[spec.id]
    df = res.metrics
    series = []
    for i in range(len(df)):
        if df["status"].iloc[i] not in ("ok", "diverged"):
            continue
        series.append((str(df["label"].iloc[i]), res.timeseries(i)))
    if spec.plot == "errors":
        return overlay_figure(series, spec.caption)
    fig = overlay_figure(series, spec.caption, columns=("theta_load_deg", "omega_load_deg_s"),
                         ylabels=("load angle [deg]", "load speed [deg/s]"))
    ts = series[0][1]
    ax_pos = fig.axes[0]
    ax_pos.plot(ts["t_s"], ts["theta_ref_deg"], "k:", lw=1, label="reference")
    ax_pos.legend(fontsize=8, loc="best")
    return fig


def write_reproduction(rep: Reproduction, out: Path, wall: float) -> Path:
    """Write every output of a reproduction into ``out``; returns REPORT.md's path."""
    exp = rep.exp
    for spec in exp.studies:
        write_figure(under(out, spec.figure), study_figure(rep, spec))
    for t in rep.thresholds:
        pl_label = f"{t.spec.vary} [{lookup(t.spec.vary).unit}]"
        title = f"Threshold '{t.spec.id}': {t.spec.vary}, {t.input_desc}"
        write_figure(under(out, f"threshold_{t.spec.id}.png"),
                     threshold_figure(t.result, t.criteria, pl_label, title))
    claims = verdicts_frame(rep.verdicts)
    write_csv(out / "claims.csv", claims)
    thr_rows = [{
        "id": t.spec.id, "vary": t.spec.vary, "value": t.value, "unit": t.unit,
        "raw_threshold": t.result.threshold, "bracket_lo": t.result.bracket[0],
        "bracket_hi": t.result.bracket[1], "relative_width": t.result.rel_width,
        "status": t.result.status, "simulations": t.result.n_sims,
        "requirements": "; ".join(map(str, t.criteria)),
        "paper_value": t.spec.paper_value,
    } for t in rep.thresholds]
    if thr_rows:
        write_csv(out / "thresholds.csv", pd.DataFrame(thr_rows))
    if rep.ranking is not None:
        write_csv(out / "ranking.csv", rep.ranking)
    if rep.sensitivity_ranking is not None:
        write_csv(out / "sensitivity_ranking.csv", rep.sensitivity_ranking, float_format="%.6g")
    for sid, df in rep.studies.items():
        write_csv(under(out, "tables", f"{sid}_metrics.csv"), df, float_format="%.9g")
    report = out / "REPORT.md"
    write_text(report, render_report(rep, wall))
    write_json(out / "manifest.json", manifest(
        "reproduce", experiment=str(rep.path), wall_time_s=wall, timings=rep.timings,
        claims={"total": len(rep.verdicts), "failed": [v.claim.id for v in rep.failed]},
        scalars=rep.scalars))
    return report


def sensitivity_section(rep: Reproduction) -> list[str]:
    """REPORT.md's global-sensitivity ranking: per input and metric the factors by Sobol ST
    (or Morris mu*) with the one-at-a-time rank, and the verdict against the paper."""
    spec, res, table = rep.exp.sensitivity, rep.sensitivity, rep.sensitivity_ranking
    if spec is None or res is None or table is None:
        return []
    key = "ST" if res.method == "sobol" else "mu_star"
    cfg = res.cfg
    tr = " of log10(metric)" if cfg.sensitivity.transform == "log10" else ""
    lines = ["## Ranking of the nonlinearities by global sensitivity", "",
             f"`ema sensitivity {spec.config}` ({res.method}, n = {res.n}: "
             f"{res.design.n_rows:,} one-second runs per input, {len(cfg.factors)} factors over "
             f"the ranges of the config; indices{tr}). Beside each factor its rank in the "
             "one-at-a-time ranking above (worst IAE ratio at the paper's magnitudes), where a "
             f"study varies it. The paper: {spec.paper}", ""]
    oat = rep.ranking
    if oat is not None and len(oat):
        lines += [f"One-at-a-time ranking (first to last): "
                  f"{', '.join(f'{spec.studies.get(str(s), str(s))}' for s in oat['study'])}.",
                  ""]
    for (inp, metric), t in table.groupby(["input", "metric"], sort=False):
        top = t.head(6)
        cols = ["rank", "factor", key, f"{key}_conf", "oat_rank"]
        if key == "ST":
            cols.insert(4, "S1")
        lines += [f"**Input {inp}, `{metric}`** (first six):", "", md_table(top[cols]), ""]
    mine = table[(table["input"] == spec.input) & (table["metric"] == spec.metric)]
    first = str(mine["factor"].iloc[0])
    rank = int(rep.scalars["sensitivity.paper_first_rank"])
    agree = "agrees" if first == spec.paper_first else "differs"
    lines += [f"On input {spec.input}, `{spec.metric}`: the global ranking puts **{first}** "
              f"first ({key} {float(mine[key].iloc[0]):.3g}) and {spec.paper_first} "
              f"{_ordinal(rank)} ({key} "
              f"{rep.scalars['sensitivity.paper_first_st']:.3g}); the paper names "
              f"**{spec.paper_first}** — our model {agree}.", ""]
    for f in ("indices", "convergence"):
        name = f"{f}_{spec.input}.png"
        if (res.folder is not None and (res.folder / name).is_file()) or res.folder is None:
            lines += [f"![{f}](sensitivity/{name})", ""]
    return lines


def _ordinal(k: int) -> str:
    return f"{k}{'th' if 10 <= k % 100 <= 20 else {1: 'st', 2: 'nd', 3: 'rd'}.get(k % 10, 'th')}"


def render_report(rep: Reproduction, wall: float) -> str:
    """REPORT.md: figures with the paper's captions, claims, thresholds, identification."""
    exp = rep.exp
    n, nf = len(rep.verdicts), len(rep.failed)
    lines = [f"# Reproduction: {exp.paper or exp.name}", "",
             exp.description.strip(), "",
             f"**{n - nf} of {n} claims PASS**" + (f", {nf} FAIL" if nf else "") +
             f" · wall time {wall:.1f} s · generated by `ema reproduce {rep.path}`", ""]
    lines += ["## Claims", "",
              "Each of the paper's statements, the assertion that checks it on our model, the "
              "number we computed and the verdict.", ""]
    rows = [{"claim": v.claim.id, "figure": v.claim.figure, "paper says": v.claim.paper,
             "we assert": v.claim.statement, "computed": v.measured,
             "result": ("**PASS**" if v.passed else "**FAIL**") +
                       (f" ({v.error})" if v.error else "")} for v in rep.verdicts]
    if rows:
        lines += [md_table(pd.DataFrame(rows)), ""]
    if rep.thresholds:
        lines += ["## Thresholds", "",
                  "Computed by bracketing and bisection on batched simulations "
                  "(`ema threshold`), beside the paper's values read off its figures.", ""]
        rows = []
        for t in rep.thresholds:
            pv = t.spec.paper_value
            if pv is None:
                verdict = "n/a"
            elif t.spec.direction == "max":
                verdict = "paper's limit is safe" if t.value >= pv else "paper's limit is too lax"
            else:
                verdict = "paper's limit is safe" if t.value <= pv else "paper's limit is too lax"
            rows.append({"threshold": t.spec.id, "paper": t.spec.paper,
                         "paper value": md_cell(pv) if pv is not None else "-",
                         "ours": f"{t.value:.4g} {t.unit}",
                         "criterion": "; ".join(map(str, t.criteria)),
                         "bracket": f"[{t.result.bracket[0]:.4g}, {t.result.bracket[1]:.4g}]",
                         "simulations": t.result.n_sims, "comparison": verdict})
        lines += [md_table(pd.DataFrame(rows)), ""]
        for t in rep.thresholds:
            if t.tuned is not None and t.tuning is not None:
                lines += [f"Threshold `{t.spec.id}` runs with the controller tuned by `ema tune "
                          f"{t.tuning['config']}` ({t.tuning['method'].upper()}, "
                          f"{t.tuning['evaluations']} evaluations, {t.tuning['wall_s']:.0f} s; "
                          f"cost {t.tuning['cost']:.4g} of the default controller's 1, every "
                          "constraint met): "
                          + ", ".join(f"{k} = {v:.5g}" for k, v in t.tuned.items()) + ".", ""]
            if t.spec.compare_to is not None:
                lines += [f"`{t.spec.id}` is {rep.scalars[t.spec.id + '_ratio']:.3g} times "
                          f"`{t.spec.compare_to}`.", ""]
        for t in rep.thresholds:
            lines += [f"![threshold {t.spec.id}](threshold_{t.spec.id}.png)", ""]
    if rep.ranking is not None and exp.ranking is not None:
        lines += ["## Ranking of the nonlinearities", "",
                  f"Worst ratio of `{exp.ranking.metric}` to the study's baseline at the paper's "
                  f"magnitudes. The paper: {exp.ranking.paper}", "",
                  md_table(rep.ranking), ""]
        first = str(rep.ranking["study"].iloc[0])
        agree = "agrees" if first == exp.ranking.paper_first else "differs"
        lines += [f"Our model ranks **{first}** first; the paper names "
                  f"**{exp.ranking.paper_first}** — our model {agree}.", ""]
    lines += sensitivity_section(rep)
    if rep.identification is not None:
        lines += ["## Identification (paper §3.1)", ""]
        lines += [md_table(pd.DataFrame([{"quantity": k, "value": md_cell(v)}
                                          for k, v in rep.identification.items()
                                          if not isinstance(v, dict | list)])), ""]
        for f in ("convergence.png", "fit.png"):
            lines += [f"![{f}](identification/{f})", ""]
    lines += ["## Figures", ""]
    for spec in exp.studies:
        df = rep.studies[spec.id]
        cols = ["label", *[c for c in FIGURE_METRICS if c in df.columns]]
        lines += [f"### {spec.caption}", "", f"![{spec.id}]({spec.figure})", "",
                  f"*Paper:* {spec.shows}" if spec.shows else "", "",
                  md_table(df[cols]), ""]
    return "\n".join(lines) + "\n"
