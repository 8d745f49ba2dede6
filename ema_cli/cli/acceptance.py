"""`ema acceptance`: the actuator acceptance battery of a spec, PASS/FAIL (exit 1 on a FAIL)."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Annotated

import typer

from ema_cli.cli.common import console, err_console, handle_errors, out_help, parse_assignments
from ema_cli.progress import report as report_stage

NO_CROSSOVER = {"gain_margin": "no phase crossover", "phase_margin": "no gain crossover"}
"""What an infinite margin means."""


def _value(v: object, fmt_value: Callable) -> str:
    """A verdict's measured value with its unit, or in words (an infinite margin)."""
    import math

    value = v.value  # type: ignore[attr-defined]
    if isinstance(value, float) and math.isinf(value) and v.metric in NO_CROSSOVER:  # type: ignore[attr-defined]
        return NO_CROSSOVER[v.metric]  # type: ignore[attr-defined]
    return f"{fmt_value(value)} {v.unit}"  # type: ignore[attr-defined]


def print_verdicts(verdicts: list, fmt_value: Callable, fmt_limit: Callable) -> str:
    """One line per limit (PASS/FAIL, test: metric (condition), value, limit, with units);
    when those lines are wider than the console, grouped by test with the test's name on its
    own line -> the layout used (``lines`` or ``grouped``)."""
    from rich.markup import escape

    from ema_cli.cli.output import width

    rows = [(v, f"{v.test}: {v.metric} ({v.condition})", _value(v, fmt_value),
             f"{fmt_limit(v)} {v.unit}") for v in verdicts]
    w = [max(len(r[k]) for r in rows) for k in (1, 2)] if rows else [0, 0]
    if 6 + w[0] + 2 + w[1] + 2 + max((len(r[3]) for r in rows), default=0) <= width():
        for v, what, value, limit in rows:
            mark = "[green]PASS[/]" if v.passed else "[bold red]FAIL[/]"
            console.print(f"{mark}  {escape(what):<{w[0]}}  {value:>{w[1]}}  "
                          f"{escape(limit)}", highlight=False, soft_wrap=True)
        return "lines"
    import textwrap

    test = None
    for v, _, value, limit in rows:
        if v.test != test:
            test = v.test
            console.print(f"[bold]{escape(test)}[/]", highlight=False)
        mark = "[green]PASS[/]" if v.passed else "[bold red]FAIL[/]"
        text = f"{v.metric} ({v.condition}): {value}, limit {limit}"
        lines = textwrap.wrap(text, max(width() - 8, 20))
        console.print(f"  {mark}  {escape(lines[0])}", highlight=False)
        for line in lines[1:]:
            console.print(f"        {escape(line)}", highlight=False)
    return "grouped"


@handle_errors
def acceptance_cmd(
    spec: Annotated[Path, typer.Argument(
        help="Acceptance spec (YAML), e.g. configs/acceptance.yaml.")],
    only: Annotated[list[str] | None, typer.Option(
        "--only", help="Run only this test of the spec; repeatable.")] = None,
    set_: Annotated[list[str] | None, typer.Option(
        "--set", help="Override a spec value by dotted path, e.g. actuator.plant.alpha=0.003 "
                      "or tests.step-small.limits.overshoot.max=10; repeatable.")] = None,
    out: Annotated[Path | None, typer.Option("--out", help=out_help())] = None,
) -> None:
    """Run the acceptance battery of SPEC on its actuator (step specifications, frequency
    response, margins, threshold, hysteresis and free play, load deflection, dynamic stiffness,
    no-load rate); writes acceptance.md (PASS/FAIL table with value, limit and unit),
    acceptance.csv, one figure per test and a manifest. Exit code 1 if any limit is not met."""
    from ema_cli.api.acceptance import acceptance
    from ema_cli.report.rundir import check_output

    if not spec.is_file():
        from ema_cli.errors import EmaError

        raise EmaError(f"spec '{spec}' is not a file (an acceptance spec, e.g. "
                       "configs/acceptance.yaml)")
    check_output(out, "acceptance")

    def progress(run: object) -> None:
        err_console.print(f"  {run.name} ({run.kind}) {run.wall_s:.2f} s")  # type: ignore[attr-defined]

    res = acceptance(spec, parse_assignments(set_, "--set"), only=only, progress=progress)
    report_stage("writing files and figures")
    folder = res.save(out)
    from ema_cli.report.acceptance_report import fmt_limit, fmt_value

    console.print(f"[bold]{res.title}[/]")
    print_verdicts(res.verdicts, fmt_value, fmt_limit)
    for r in res.runs:
        for n in r.notes:
            err_console.print(f"note: {r.name}: {n}")
    verdict = ("PASS" if res.passed else f"FAIL ({len(res.failed)} of {len(res.verdicts)} "
               "limits not met)")
    console.print(f"{verdict}: {len(res.runs)} tests in {res.wall_time_s:.1f} s -> {folder}")
    if not res.passed:
        raise typer.Exit(1)
