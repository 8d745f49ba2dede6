"""`ema tune`: tune the controller gains and compensators over scenarios (GA or DE)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from ema_cli.cli.common import (
    BACKEND_OPTIONS,
    BackendOpt,
    NJobsOpt,
    SchedulerOpt,
    as_options,
    backend_options,
    console,
    err_console,
    handle_errors,
    out_help,
    parse_assignments,
    print_retries,
)
from ema_cli.progress import report as report_stage


@handle_errors
def tune_cmd(
    config: Annotated[Path, typer.Argument(
        help="Tuning config (YAML), e.g. configs/tune.yaml.")],
    runs: Annotated[int | None, typer.Option(
        "--runs", help="Independent optimiser runs (seeds seed, seed+1, ...); the best is "
                       "kept (default: the config's optimiser.runs, 1).")] = None,
    method: Annotated[str | None, typer.Option(
        "--method", help="ga (the project's real-coded elitist GA) or de (scipy's "
                         "differential evolution, same budget); default: the config's.")
    ] = None,
    budget: Annotated[int | None, typer.Option(
        "--budget", help="Candidate evaluations per run, each running every scenario "
                         "(default: the config's optimiser.budget).")] = None,
    set_: Annotated[list[str] | None, typer.Option(
        "--set", help="Override a config value by dotted path, e.g. "
                      "variables.Kpp.bounds=[20,100] or optimiser.seed=3; repeatable.")] = None,
    out: Annotated[Path | None, typer.Option("--out", help=out_help())] = None,
    backend: BackendOpt = None,
    n_jobs: NJobsOpt = None,
    scheduler: SchedulerOpt = None,
) -> None:
    """Tune the controller of CONFIG: its free variables (gains and compensator parameters,
    with bounds) minimise the cost over its scenarios (by default the mean ITAE ratio to the
    default controller) subject to its constraints (overshoot, peak current and voltage,
    margins of the linearised loops >= 6 dB / 45 deg by default, no divergence). Writes
    tuned.yaml (runnable with `ema simulate`), scenarios/*.yaml, tuning.csv, runs.csv,
    convergence.png, one before/after figure per scenario and tuning.md."""
    from ema_cli.api.tune import tune
    from ema_cli.errors import EmaError
    from ema_cli.report.rundir import check_output

    if not config.is_file():
        raise EmaError(f"config '{config}' is not a file (a tuning config, e.g. "
                       "configs/tune.yaml)")
    pairs = parse_assignments(set_, "--set")
    n_jobs = backend_options(backend, n_jobs, scheduler)
    if out is not None:  # its inputs against the folder's, before the tuning
        from ema_cli.api.tune import tune_inputs

        check_output(out, "tune", as_options(
            lambda: tune_inputs(config, pairs, method=method, runs=runs, budget=budget),
            method="--method", runs="--runs", budget="--budget"))
    from ema_cli.progress import report

    def progress(run: int, done: int, total: int) -> None:
        report(f"run {run + 1}: evaluations", done, total)

    res = as_options(lambda: tune(config, pairs, method=method, runs=runs, budget=budget,
                                  progress=progress,
                                  log=lambda text: err_console.print(text, highlight=False),
                                  backend=backend, n_jobs=n_jobs, scheduler=scheduler),
                     method="--method", runs="--runs", budget="--budget", **BACKEND_OPTIONS)
    print_retries(res.execution)
    report_stage("writing files and figures")
    folder = res.save(out)
    o = res.outcome
    console.print(f"[bold]{res.title}[/]")
    ref, before, after = (float(e.cost[0]) for e in (o.reference, o.before, o.after))
    console.print(f"cost (relative, no unit): default controller {ref:.4g}, before tuning "
                  f"{before:.4g}, tuned {after:.4g} ({100 * (1 - after / ref):.1f} % lower); "
                  "every constraint met", highlight=False)
    from ema_cli.model.params import BY_NAME
    from ema_cli.units import fmt_num

    console.print("tuned: " + ", ".join(
        f"{k} = {fmt_num(v, BY_NAME[k].unit if k in BY_NAME else '', 5)}"
        for k, v in res.tuned.items()), highlight=False)
    if len(o.runs) > 1:
        console.print(f"{len(o.runs)} runs: costs within {100 * o.cost_spread:.2f} %",
                      highlight=False)
    console.print(f"{int(o.timings['evaluations'])} evaluations in {o.wall_s:.1f} s -> "
                  f"{folder}", highlight=False)
