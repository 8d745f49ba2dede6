"""`ema yield`: the share of built actuators that pass an acceptance battery under
manufacturing tolerances and wear, with an exact interval, what drives the failures and the
worst case."""

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

VERDICT_EXIT = {"PASS": 0, "FAIL": 1, "INCONCLUSIVE": 3}


def min_yield_verdict(lo: float, hi: float, target: float) -> str:
    """PASS when the whole interval is at or above ``target``, FAIL when it lies wholly below,
    else INCONCLUSIVE (more units needed)."""
    if lo >= target:
        return "PASS"
    if hi < target:
        return "FAIL"
    return "INCONCLUSIVE"


@handle_errors
def yield_cmd(
    spec: Annotated[Path, typer.Argument(
        help="Acceptance spec (YAML), e.g. configs/acceptance.yaml.")],
    tolerances: Annotated[Path, typer.Option(
        "--tolerances", help="Tolerance file (YAML): run-config paths and their laws, e.g. "
                             "configs/tolerances.yaml.")],
    n: Annotated[int, typer.Option(
        "--n", help="Units to sample (with --target-halfwidth: the most units).")] = 200,
    seed: Annotated[int, typer.Option("--seed", help="Seed of the sampled units.")] = 0,
    ci: Annotated[float, typer.Option(
        "--ci", help="Confidence of the intervals (exact Clopper-Pearson).")] = 0.95,
    target_halfwidth: Annotated[float | None, typer.Option(
        "--target-halfwidth", help="Sample in blocks until the yield's interval has at most "
                                   "this half width (a share, e.g. 0.02), or --n units.")] = None,
    method: Annotated[str, typer.Option(
        "--method", help="random | sobol (scrambled Sobol points).")] = "random",
    k: Annotated[float | None, typer.Option(
        "--k", help="Worst-case box: +-k sd of normal laws (default: the file's, 3).")] = None,
    worst_budget: Annotated[int, typer.Option(
        "--worst-budget", help="Units the worst-case search (differential evolution) may "
                               "evaluate per test, after the box's corners.")] = 48,
    no_worst: Annotated[bool, typer.Option(
        "--no-worst", help="Skip the worst-case search.")] = False,
    block: Annotated[int, typer.Option(
        "--block", help="Units per block (one checkpoint; every test batched over them).")] = 100,
    min_yield: Annotated[float | None, typer.Option(
        "--min-yield", help="A required yield (a share): PASS (exit 0) when the interval lies "
                            "at or above it, FAIL (exit 1) when wholly below, else "
                            "INCONCLUSIVE (exit 3).")] = None,
    set_: Annotated[list[str] | None, typer.Option(
        "--set", help="Override a spec value by dotted path, e.g. actuator.plant.Kpp=60; "
                      "repeatable.")] = None,
    out: Annotated[Path | None, typer.Option("--out", help=out_help(
        "an interrupted run of the same inputs there is resumed (finished blocks are kept), "
        "on any backend"))] = None,
    backend: BackendOpt = None,
    n_jobs: NJobsOpt = None,
    scheduler: SchedulerOpt = None,
) -> None:
    """Sample N units from the tolerances, run every test of SPEC on each (batched across
    units), and report the yield with its exact interval, per test and per limit (a unit with
    an INCONCLUSIVE limit is counted apart, never as a pass), which tolerances drive each
    failing limit, and the worst unit inside the tolerance box. Writes yield.json,
    samples.parquet, yield.md, convergence.png, one distribution figure per test, snapshots and
    a manifest. Exit 0, or with --min-yield 0/1/3 (PASS/FAIL/INCONCLUSIVE)."""
    from ema_cli.api.production import production_yield
    from ema_cli.errors import EmaError
    for what, path in (("spec", spec), ("--tolerances", tolerances)):
        if not path.is_file():
            raise EmaError(f"{what} '{path}' is not a file")
    if min_yield is not None and not 0.0 < min_yield <= 1.0:
        raise EmaError(f"--min-yield must be a share in (0, 1], got {min_yield}")

    def progress(s: dict) -> None:
        err_console.print(f"  {s['n']} units: yield {100 * s['yield']:.1f} % "
                          f"[{100 * s['ci_low']:.1f}, {100 * s['ci_high']:.1f}], "
                          f"{s['n_fail']} fail, {s['n_inconclusive']} inconclusive "
                          f"({s['elapsed_s']:.0f} s)", highlight=False)

    pairs = parse_assignments(set_, "--set")
    n_jobs = backend_options(backend, n_jobs, scheduler)
    res = as_options(lambda: production_yield(
        spec, tolerances, pairs, n=n, seed=seed, level=ci, target_halfwidth=target_halfwidth,
        method=method, k=k, block=block, worst_budget=None if no_worst else worst_budget,
        out=out, checkpoint=True, progress=progress, backend=backend, n_jobs=n_jobs,
        scheduler=scheduler), anywhere=False,
        level="--ci", target_halfwidth="--target-halfwidth", worst_budget="--worst-budget",
        method="--method", block="--block", n="--n", seed="--seed", k="--k", **BACKEND_OPTIONS)
    print_retries(res.execution)
    from ema_cli.progress import report

    report("writing files and figures")
    folder = res.save()
    from ema_cli.report.yield_report import console_lines, headline

    console.print(f"[bold]{res.title}[/]")
    console.print(headline(res), highlight=False)
    for name, r in res.tests.items():
        if r.n_pass < r.n:
            lo, hi = r.interval
            console.print(f"  {name}: {100 * r.value:.1f} % [{100 * lo:.1f}, {100 * hi:.1f}] "
                          f"({r.n_fail} fail, {r.n_inconclusive} inconclusive)",
                          highlight=False)
    for line in console_lines(res):
        console.print(line, highlight=False)
    console.print(f"-> {folder} (yield.md: per limit, drivers, the worst case)",
                  highlight=False)
    if min_yield is not None:
        lo, hi = res.overall.interval
        word = min_yield_verdict(lo, hi, min_yield)
        console.print(f"{word}: required yield {100 * min_yield:g} %, interval "
                      f"[{100 * lo:.1f}, {100 * hi:.1f}] %", highlight=False)
        if VERDICT_EXIT[word]:
            raise typer.Exit(VERDICT_EXIT[word])
