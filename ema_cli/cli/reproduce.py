"""`ema reproduce`: run an experiment batch (the paper), check its claims, write REPORT.md."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from ema_cli.cli.common import (
    check_jobs,
    console,
    err_console,
    handle_errors,
    is_interactive,
    out_help,
    parse_assignments,
)


@handle_errors
def reproduce_cmd(
    experiment: Annotated[Path, typer.Argument(
        help="Experiment batch, e.g. experiments/paper2020.yaml.")],
    out: Annotated[Path | None, typer.Option("--out", help=out_help(
        "an unfinished run of the same experiment there is resumed (finished sweep jobs are "
        "not recomputed)"))] = None,
    n_jobs: Annotated[int | None, typer.Option(
        "--n-jobs", help="Parallel workers for the sweeps (-1 or default: all cores).")] = None,
    set_: Annotated[list[str] | None, typer.Option(
        "--set", help="Override a value of the experiment file by dotted path (list items by "
                      "index), e.g. studies.0.id=fig2; repeatable.")] = None,
) -> None:
    """Run every study, threshold and identification of the batch, evaluate its claims and
    write REPORT.md, claims.csv, the figures and a manifest. Exits 1 if any claim fails."""
    from ema_cli.api.reproduce import reproduce
    from ema_cli.cli.output import print_table
    from ema_cli.files import shown
    from ema_cli.units import fmt_num

    n_jobs = check_jobs(n_jobs, "--n-jobs")
    overrides = parse_assignments(set_, "--set")
    run = reproduce(experiment, overrides, out=out, n_jobs=n_jobs, progress=is_interactive(),
                    log=lambda m: err_console.print(f"[dim]{m}[/]"))
    rep, wall = run.reproduction, run.wall_s
    print_table(f"{rep.exp.name}: claims", ("claim", "result", "computed"),
                [(v.claim.id, "PASS" if v.passed else "FAIL",
                  v.measured if not v.error else v.error) for v in rep.verdicts],
                justify=["left"] * 3,
                styles=[None if v.passed else "bold red" for v in rep.verdicts])
    for t in rep.thresholds:
        console.print(f"threshold {t.spec.id}: {fmt_num(t.value, t.unit, nan='not found')}"
                      + (f" (paper: {t.spec.paper_value:g})" if t.spec.paper_value else ""))
    console.print(f"{len(rep.verdicts) - len(rep.failed)}/{len(rep.verdicts)} claims pass "
                  f"in {wall:.1f} s -> {shown(run.report)}")
    if rep.failed:
        raise typer.Exit(1)
