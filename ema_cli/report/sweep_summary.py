"""summary.md of a sweep: what was run, the job counts, the metrics table and the figures."""

from __future__ import annotations

from ema_cli.report.markdown import md_table
from ema_cli.report.sweep_tables import metric_label
from ema_cli.sweep.run import SweepResult

MAX_SUMMARY_ROWS = 200  # rows of the metrics table in summary.md (metrics.csv has all)


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
    if result.signals_file is not None:
        lines.append(f"- recorded signals: `{result.signals_file.name}`, one row per job and "
                     "sample (e.g. `pandas.read_parquet(path, filters=[('job', '==', "
                     f"'{plan.jobs[0].id}')])`)")
    if plan.scales:
        lines.append("- relative magnitudes are % of the baseline's peak signal: " + ", ".join(
            f"{k} {v:.4g}" for k, v in plan.scales.items()))
    lines += [f"- note: {n}" for n in plan.notes]
    lines += [f"- warning: {w}" for w in result.warnings]
    if result.interrupted:
        lines.append("- **interrupted**: re-run the same command to finish (cached jobs are kept)")
    cols = ["job", "label", "status"] + list(cfg.outputs.metrics)
    shown = result.metrics.head(MAX_SUMMARY_ROWS)
    headers = [c if c in ("job", "label", "status") else metric_label(c) for c in cols]
    lines += ["", "## Metrics", "", md_table(shown, cols, headers)]
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
