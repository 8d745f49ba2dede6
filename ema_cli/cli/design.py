"""`ema design LOG`: identify the actuator from a closed-loop log, tune its controller on the
fitted actuator, sign it off on the fit and the corners of its 95 % intervals.

Exit codes: 0 PASS, 1 FAIL, 3 INCONCLUSIVE (the fit cannot carry a sign-off), 2 bad input."""

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
def design_cmd(
    log: Annotated[Path, typer.Argument(
        help="Closed-loop log (CSV, Parquet or MATLAB .mat), as ema identify --closed-loop "
             "reads it.")],
    config: Annotated[Path | None, typer.Argument(
        help="Design config (YAML) with identify: settings and tune: overrides, e.g. "
             "configs/design.yaml (default: none).")] = None,
    tune_config: Annotated[Path | None, typer.Option(
        "--tune-config", help="Tuning config whose scenarios, variables, cost and "
                              "constraints are used (default: configs/tune.yaml).")] = None,
    spec: Annotated[Path | None, typer.Option(
        "--spec", help="Acceptance spec (default: configs/acceptance.yaml).")] = None,
    set_: Annotated[list[str] | None, typer.Option(
        "--set", help="identify.KEY=V (a setting of ema identify --closed-loop, e.g. "
                      "identify.shooting.starts=4) or tune.KEY=V (a key of the tuning "
                      "config, e.g. tune.optimiser.pop=16); repeatable.")] = None,
    budget: Annotated[int | None, typer.Option(
        "--budget", help="Candidate evaluations of the tuning (default: the tuning "
                         "config's optimiser.budget).")] = None,
    corners: Annotated[str, typer.Option(
        "--corners", help="auto: the interval corners only while they can change the verdict "
                          "(none after a FAIL, none on a fit that cannot carry a sign-off); "
                          "all: every corner.")] = "auto",
    out: Annotated[Path | None, typer.Option("--out", help=out_help())] = None,
    backend: BackendOpt = None,
    n_jobs: NJobsOpt = None,
    scheduler: SchedulerOpt = None,
) -> None:
    """From LOG to a signed-off controller: identify the actuator (closed-loop fit), tune the
    controller on the fitted actuator against the acceptance spec (its tests run inside the
    search, its limits are the constraints, with a margin), run the spec's battery with the
    tuned gains on the fitted actuator and on the corners of the identified 95 % intervals
    while they can change the verdict. PASS (exit 0) only if every case passes; FAIL (exit 1)
    names the requirements the tuned controller misses, why and what to relax; INCONCLUSIVE
    (exit 3) if the fit's optimum is not confirmed or a parameter is not determined. Writes
    design.md, design.json, identification/, tune/, acceptance/<case>/."""
    from ema_cli.api.design import design
    from ema_cli.errors import EmaError
    from ema_cli.report.rundir import check_output

    if config is not None and not config.is_file():
        raise EmaError(f"config '{config}' is not a file (a design config, e.g. "
                       "configs/design.yaml)")
    pairs = parse_assignments(set_, "--set")
    n_jobs = backend_options(backend, n_jobs, scheduler)
    if out is not None:  # its inputs against the folder's, before the identification
        from ema_cli.api.design import design_inputs

        check_output(out, "design", design_inputs(log, config, pairs, tune_config=tune_config,
                                                  spec=spec, budget=budget, corners=corners))
    res = as_options(lambda: design(log, config, pairs, tune_config=tune_config, spec=spec,
                                    budget=budget, corners=corners, stage=report_stage,
                                    tune_log=lambda text: err_console.print(text,
                                                                            highlight=False),
                                    backend=backend, n_jobs=n_jobs, scheduler=scheduler),
                     anywhere=False, tune_config="--tune-config", spec="--spec",
                     budget="--budget", corners="--corners", **BACKEND_OPTIONS)
    print_retries(res.execution)
    report_stage("writing files and figures")
    folder = res.save(out)
    print_design(res.to_json(), str(log), folder)
    if res.exit_code:
        raise typer.Exit(res.exit_code)


def print_design(js: dict, log: str, folder: Path) -> None:
    """The console's account of a design: the verdict and its reasons (each once), the
    identified actuator, the tuned controller, the requirements missed, the cases grouped by
    outcome, the notes, the last line."""
    import textwrap

    from ema_cli.api.design import case_list
    from ema_cli.cli.output import print_table, width
    from ema_cli.cli.requirements import print_blocking, print_shortfalls

    verdict = js["verdict"]
    style = {"PASS": "bold green", "FAIL": "bold red", "INCONCLUSIVE": "bold yellow"}[verdict]
    console.print(f"[{style}]{verdict}[/]: ema design {log}")
    # a value the battery could not measure: what makes the verdict INCONCLUSIVE, or beside
    # a FAIL, not the verdict's reason
    word = "inconclusive" if verdict == "INCONCLUSIVE" else "not measured"
    for why in js["inconclusive_because"]:
        console.print(textwrap.fill(f"{word}: {why}", width(), subsequent_indent="  "),
                      highlight=False)
    ident = js["identification"]
    print_table("identified actuator (SI)", ["parameter", "value", "95 % interval", "unit"],
                [[n, f"{p['value']:.5g}", f"[{p['ci95'][0]:.5g}, {p['ci95'][1]:.5g}]",
                  p["unit"]] for n, p in ident["parameters"].items()],
                justify=["left", "right", "left", "left"])
    tr = js["tuning"]
    rows = [[g, f"{tr['gains_before'][g]:.4g}", f"{a:.4g}"] for g, a in
            tr["gains_after"].items()]
    rows.append(["cost", f"{tr['cost_before']:.4g}", f"{tr['cost_after']:.4g}"])
    print_table(f"tuned controller ({tr['evaluations']} evaluations)",
                ["gain", "before", "after"], rows)
    for flag in tr["on_bounds"]:
        console.print(textwrap.fill(f"on a bound: {flag}", width(), subsequent_indent="  "),
                      highlight=False)
    cases = js["acceptance"]["cases"]
    print_shortfalls(js["requirements"]["unmet"],
                     "requirements the tuned controller misses on the fitted actuator")
    groups: dict[tuple[str, str], list[str]] = {}
    for c in cases:
        failed = [t if r == "FAIL" else f"{t} (inconclusive)"
                  for t, r in c["test_results"].items() if r != "PASS"]
        groups.setdefault((c["verdict"], ", ".join(failed) or "-"), []).append(c["case"])
    corners = js["acceptance"]["corners"]
    print_table(f"acceptance ({len(js['acceptance']['tests'])} tests per case)",
                ["cases", "verdict", "tests not passed"],
                [[case_list(names, len(cases)), v, failed]
                 for (v, failed), names in groups.items()],
                justify=["left", "left", "left"], wrap=["tests not passed"],
                caption=corners["not_run_because"] or None)
    for n in js["notes"]:
        err_console.print(textwrap.fill(f"note: {n}", width(), subsequent_indent="  "),
                          highlight=False)
    print_blocking(js["requirements"]["unmeetable"])  # the answer last: what no gains meet
    n_pass = sum(c["passed"] for c in cases)
    console.print(f"{verdict}: {n_pass} of {len(cases)} cases pass ({corners['run']} of "
                  f"{corners['planned']} corners run) in {js['timings_s']['total']:.0f} s -> "
                  f"{folder}", highlight=False)
