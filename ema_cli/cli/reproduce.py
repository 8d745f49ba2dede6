"""`ema reproduce`: run an experiment batch (the paper), check its claims, write REPORT.md."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from ema_cli.cli.common import (
    console,
    err_console,
    handle_errors,
    is_interactive,
    out_help,
    parse_assignments,
)
from ema_cli.cli.sweep import check_jobs


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
    import time

    from ema_cli.analysis.reproduce import load_experiment
    from ema_cli.hashing import content_hash
    from ema_cli.report.reproduce_report import run_experiment, write_reproduction
    from ema_cli.report.rundir import finish_output, prepare_output

    n_jobs = check_jobs(n_jobs, "--n-jobs")
    overrides = parse_assignments(set_, "--set")
    exp = load_experiment(experiment, overrides)
    folder, resumed = prepare_output("reproduce", exp.name,
                                     content_hash({"exp": exp.model_dump(mode="json")}, 16),
                                     out, resume=True)
    if resumed:
        err_console.print(f"resuming the unfinished run in {folder}")
    t0 = time.perf_counter()
    rep = run_experiment(experiment, folder, n_jobs=n_jobs, progress=is_interactive(),
                         log=lambda m: err_console.print(f"[dim]{m}[/]"), experiment=exp)
    wall = time.perf_counter() - t0
    report = write_reproduction(rep, folder, wall)
    finish_output(folder)
    from ema_cli.cli.output import print_table
    from ema_cli.units import fmt_num

    print_table(f"{exp.name}: claims", ("claim", "result", "computed"),
                [(v.claim.id, "PASS" if v.passed else "FAIL",
                  v.measured if not v.error else v.error) for v in rep.verdicts],
                justify=["left"] * 3,
                styles=[None if v.passed else "bold red" for v in rep.verdicts])
    for t in rep.thresholds:
        console.print(f"threshold {t.spec.id}: {fmt_num(t.value, t.unit, nan='not found')}"
                      + (f" (paper: {t.spec.paper_value:g})" if t.spec.paper_value else ""))
    console.print(f"{len(rep.verdicts) - len(rep.failed)}/{len(rep.verdicts)} claims pass "
                  f"in {wall:.1f} s -> {report}")
    if rep.failed:
        raise typer.Exit(1)
