"""`ema sensitivity`: global sensitivity of the metrics to the factors (Morris or Sobol, SALib)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from ema_cli.cli.common import (
    check_number,
    console,
    err_console,
    handle_errors,
    out_help,
    parse_assignments,
)
from ema_cli.errors import EmaError

TOP_FACTORS = 3  # factors named per input and metric in the closing lines


@handle_errors
def sensitivity_cmd(
    config: Annotated[Path, typer.Argument(
        help="YAML sensitivity config (factors, metrics, inputs), e.g. configs/sensitivity.yaml.")],
    method: Annotated[str | None, typer.Option(
        "--method", help="morris (elementary effects) | sobol (S1, ST with confidence "
                         "intervals); default: sensitivity.method.")] = None,
    n: Annotated[int | None, typer.Option(
        "--n", help="Sobol base samples (a power of two: n*(D+2) runs per input) or Morris "
                    "trajectories (n*(D+1) runs); default: sensitivity.n_sobol / n_morris.")
    ] = None,
    set_: Annotated[list[str] | None, typer.Option(
        "--set", help="Override a config value by dotted path, e.g. factors.0.range=[0.01,2], "
                      "sensitivity.transform=none; repeatable.")] = None,
    n_jobs: Annotated[int | None, typer.Option(
        "--n-jobs", "-j", help="Workers (processes or threads); -1: all cores.")] = None,
    backend: Annotated[str | None, typer.Option(
        "--backend", help="auto | loky (processes) | threads (in this process) | dask.")] = None,
    scheduler: Annotated[str | None, typer.Option(
        "--scheduler", help="Dask scheduler address for --backend dask.")] = None,
    out: Annotated[Path | None, typer.Option("--out", help=out_help(
        "an unfinished study of the same inputs there is resumed (finished samples come from "
        "the job cache)"))] = None,
    progress: Annotated[bool, typer.Option(
        "--progress/--no-progress", help="Show a progress bar with ETA (stderr).")] = True,
) -> None:
    """Global sensitivity: sample the factors (Morris or Saltelli/Sobol), run every sample as a
    cached, resumable sweep job, and write indices.csv, convergence.csv, samples.parquet, bar
    charts with confidence intervals, the convergence figure and summary.md."""
    from ema_cli.api.sensitivity import sensitivity

    if method is not None and method not in ("morris", "sobol"):
        raise EmaError(f"--method must be morris or sobol, got {method!r}")
    check_number(n, "--n", low=1)
    from ema_cli.cli.common import check_jobs
    from ema_cli.limits import BACKENDS

    n_jobs = check_jobs(n_jobs, "--n-jobs", scheduler)
    if backend is not None and backend not in BACKENDS:
        raise EmaError(f"--backend must be one of {', '.join(BACKENDS)}; got {backend!r}")
    overrides = parse_assignments(set_, "--set")
    run = sensitivity(config, overrides, method=method, n=n, n_jobs=n_jobs, backend=backend,
                      scheduler=scheduler, progress=progress, out=out, write=True,
                      log=lambda text: err_console.print(text))
    res = run.result
    key = "ST" if res.method == "sobol" else "mu_star"
    for r in res.inputs:
        for metric in res.cfg.metrics:
            top = run.ranking_text(r.name, metric, TOP_FACTORS)
            console.print(f"{r.name} {metric} ({key} ± 95 % CI, no unit): {top}",
                          highlight=False)
            weak = run.imprecise(r.name, metric)
            if weak:
                more = f" and {len(weak) - 3} more" if len(weak) > 3 else ""
                err_console.print(f"[yellow]warning:[/] n = {res.n} is too small to rank "
                                  f"{r.name} {metric}: {'; '.join(weak[:3])}{more}; "
                                  "raise --n (the ± over a fifth of the index, or ST "
                                  "outside [0, 1])", highlight=False)
    for note in res.notes:
        err_console.print(f"[yellow]note:[/] {note}")
    console.print(f"{res.n_runs:,} runs ({res.computed:,} computed, {res.cached:,} cached) in "
                  f"{res.timings.get('total', 0.0):.1f} s -> {res.folder}")
