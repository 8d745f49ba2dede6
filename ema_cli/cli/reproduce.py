"""`ema reproduce`: run an experiment batch (the paper), check its claims, write REPORT.md."""

from __future__ import annotations

import time
from pathlib import Path
from typing import Annotated

import typer
from rich.table import Table

from ema_cli.cli.common import console, err_console, handle_errors, is_interactive
from ema_cli.cli.main import app
from ema_cli.report.rundir import new_run_dir


@app.command("reproduce")
@handle_errors
def reproduce_cmd(
    experiment: Annotated[Path, typer.Argument(
        help="Experiment batch, e.g. experiments/paper2020.yaml.")],
    out: Annotated[Path | None, typer.Option(
        "--out", help="Output folder (default: results/<name>/<stamp>/). Re-using one resumes: "
                      "finished sweep jobs are not recomputed.")] = None,
    n_jobs: Annotated[int | None, typer.Option(
        "--n-jobs", help="Parallel workers for the sweeps (default: all cores).")] = None,
) -> None:
    """Run every study, threshold and identification of the batch, evaluate its claims and
    write REPORT.md, claims.csv, the figures and a manifest. Exits 1 if any claim fails."""
    from ema_cli.analysis.reproduce import load_experiment
    from ema_cli.report.reproduce_report import run_experiment, write_reproduction

    exp = load_experiment(experiment)
    folder = out if out is not None else new_run_dir(exp.name, {"exp": exp.model_dump()})
    folder.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    rep = run_experiment(experiment, folder, n_jobs=n_jobs, progress=is_interactive(),
                         log=lambda m: err_console.print(f"[dim]{m}[/]"))
    wall = time.perf_counter() - t0
    report = write_reproduction(rep, folder, wall)
    table = Table(title=f"{exp.name}: claims")
    for c in ("claim", "computed", "result"):
        table.add_column(c, overflow="fold")
    for v in rep.verdicts:
        table.add_row(v.claim.id, v.measured if not v.error else v.error,
                      "[green]PASS[/]" if v.passed else "[bold red]FAIL[/]")
    console.print(table)
    for t in rep.thresholds:
        console.print(f"threshold {t.spec.id}: {t.value:.4g} {t.unit}"
                      + (f" (paper: {t.spec.paper_value:g})" if t.spec.paper_value else ""))
    console.print(f"{len(rep.verdicts) - len(rep.failed)}/{len(rep.verdicts)} claims pass "
                  f"in {wall:.1f} s -> {report}")
    if rep.failed:
        raise typer.Exit(1)
