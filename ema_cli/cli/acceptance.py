"""`ema acceptance`: the actuator acceptance battery of a spec, PASS, FAIL or INCONCLUSIVE
(exit 0, 1 or 3)."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Annotated

import typer

from ema_cli.cli.common import (
    as_options,
    console,
    err_console,
    handle_errors,
    out_help,
    parse_assignments,
)
from ema_cli.progress import report as report_stage

MARKS = {"PASS": "[green]PASS[/]", "FAIL": "[bold red]FAIL[/]",
         "INCONCLUSIVE": "[bold yellow]INCONCLUSIVE[/]"}
"""The console's mark of each result (each row style distinct)."""
MARK_WIDTH = len("INCONCLUSIVE")


def _value(v: object, fmt_value: Callable) -> str:
    """A verdict's value with its unit: measured, the bound it is known by ("> 2 Hz"), or in
    words (an infinite margin)."""
    from ema_cli.report.acceptance_report import fmt_measured

    return fmt_measured(v, with_unit=True)


def _mark(v: object) -> str:
    result = v.result  # type: ignore[attr-defined]
    return MARKS[result] + " " * (MARK_WIDTH - len(result))


def print_verdicts(verdicts: list, fmt_value: Callable, fmt_limit: Callable) -> str:
    """One line per limit (PASS/FAIL/INCONCLUSIVE, test: metric (condition), value, limit,
    with units; an INCONCLUSIVE line is followed by its reason); when those lines are wider
    than the console, grouped by test with the test's name on its own line -> the layout used
    (``lines`` or ``grouped``)."""
    from rich.markup import escape

    from ema_cli.cli.output import width

    rows = [(v, f"{v.test}: {v.metric} ({v.condition})", _value(v, fmt_value),
             f"{fmt_limit(v)} {v.unit}") for v in verdicts]
    w = [max(len(r[k]) for r in rows) for k in (1, 2)] if rows else [0, 0]
    import textwrap

    pad = MARK_WIDTH + 2
    if pad + w[0] + 2 + w[1] + 2 + max((len(r[3]) for r in rows), default=0) <= width():
        for v, what, value, limit in rows:
            console.print(f"{_mark(v)}  {escape(what):<{w[0]}}  {value:>{w[1]}}  "
                          f"{escape(limit)}", highlight=False, soft_wrap=True)
            if v.reason:
                for line in textwrap.wrap(f"-> {v.reason}", max(width() - pad, 20)):
                    console.print(f"{' ' * pad}[yellow]{escape(line)}[/]", highlight=False)
        return "lines"
    test = None
    for v, _, value, limit in rows:
        if v.test != test:
            test = v.test
            console.print(f"[bold]{escape(test)}[/]", highlight=False)
        text = f"{v.metric} ({v.condition}): {value}, limit {limit}"
        lines = textwrap.wrap(text, max(width() - pad - 2, 20))
        console.print(f"  {_mark(v)}  {escape(lines[0])}", highlight=False)
        for line in lines[1:]:
            console.print(f"  {' ' * pad}{escape(line)}", highlight=False)
        if v.reason:
            for line in textwrap.wrap(f"-> {v.reason}", max(width() - pad - 2, 20)):
                console.print(f"  {' ' * pad}[yellow]{escape(line)}[/]", highlight=False)
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
    no-load rate); writes acceptance.md (PASS/FAIL/INCONCLUSIVE table with value, limit and
    unit), acceptance.csv, one figure per test and a manifest. A value outside the range the
    test can measure is only a bound: its row is INCONCLUSIVE unless the bound alone decides,
    with the reason naming the setting to change. Overall: FAIL if any limit fails, else
    INCONCLUSIVE if any row is, else PASS. Exit code: 0 PASS, 1 FAIL, 2 bad usage or input,
    3 INCONCLUSIVE."""
    from ema_cli.api.acceptance import acceptance
    from ema_cli.report.rundir import check_output

    if not spec.is_file():
        from ema_cli.errors import EmaError

        raise EmaError(f"spec '{spec}' is not a file (an acceptance spec, e.g. "
                       "configs/acceptance.yaml)")
    pairs = parse_assignments(set_, "--set")
    if out is not None:  # its inputs against the folder's, before the battery
        from ema_cli.api.acceptance import acceptance_inputs

        check_output(out, "acceptance", as_options(
            lambda: acceptance_inputs(spec, pairs, only=only), only="--only"))

    def progress(run: object) -> None:
        err_console.print(f"  {run.name} ({run.kind}) {run.wall_s:.2f} s")  # type: ignore[attr-defined]

    res = as_options(lambda: acceptance(spec, pairs, only=only, progress=progress),
                     only="--only")
    report_stage("writing files and figures")
    folder = res.save(out)
    from ema_cli.report.acceptance_report import fmt_limit, fmt_value

    console.print(f"[bold]{res.title}[/]")
    print_verdicts(res.verdicts, fmt_value, fmt_limit)
    for r in res.runs:
        for n in r.notes:
            err_console.print(f"note: {r.name}: {n}")
    from ema_cli.report.acceptance_report import verdict_line

    word = res.verdict
    console.print(f"{MARKS[word]}{verdict_line(res)[len(word):]} ({len(res.runs)} tests in "
                  f"{res.wall_time_s:.1f} s) -> {folder}", highlight=False)
    if res.exit_code:
        raise typer.Exit(res.exit_code)
