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
    out: Annotated[Path | None, typer.Option("--out", help=out_help())] = None,
    backend: BackendOpt = None,
    n_jobs: NJobsOpt = None,
    scheduler: SchedulerOpt = None,
) -> None:
    """From LOG to a signed-off controller: identify the actuator (closed-loop fit), tune the
    controller on the fitted actuator (the tuning config's scenarios), run the acceptance spec
    with the tuned gains on the fitted actuator and on every corner of the identified 95 %
    intervals. Verdict PASS (exit 0) only if every case passes; FAIL (exit 1) if any fails;
    INCONCLUSIVE (exit 3) if the fit's optimum is not confirmed or a parameter is not
    determined. Writes design.md, design.json, identification/, tune/, acceptance/<case>/."""
    from ema_cli.api.design import design
    from ema_cli.cli.output import print_table
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
                                                  spec=spec, budget=budget))
    res = as_options(lambda: design(log, config, pairs, tune_config=tune_config, spec=spec,
                                    budget=budget, stage=report_stage,
                                    tune_log=lambda text: err_console.print(text,
                                                                            highlight=False),
                                    backend=backend, n_jobs=n_jobs, scheduler=scheduler),
                     anywhere=False, tune_config="--tune-config", spec="--spec",
                     budget="--budget", **BACKEND_OPTIONS)
    print_retries(res.execution)
    report_stage("writing files and figures")
    folder = res.save(out)
    js = res.to_json()
    verdict = js["verdict"]
    style = {"PASS": "bold green", "FAIL": "bold red", "INCONCLUSIVE": "bold yellow"}[verdict]
    console.print(f"[{style}]{verdict}[/]: ema design {log}")
    import textwrap

    from ema_cli.cli.output import width

    for why in js["inconclusive_because"]:
        console.print(textwrap.fill(f"inconclusive: {why}", width(), subsequent_indent="  "),
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
    cases = js["acceptance"]["cases"]
    names = [n for n in ident["parameters"] if any(n in c["sides"] for c in cases)]
    crows = []
    for c in cases:
        sides = "".join({"low": "-", "high": "+"}[c["sides"][n]] for n in names) if c[
            "sides"] else "estimate"
        failed = [t if r == "FAIL" else f"{t} (inconclusive)"
                  for t, r in c["test_results"].items() if r != "PASS"]
        crows.append([c["case"], sides, c["verdict"], ", ".join(failed) or "-"])
    print_table(f"acceptance ({len(js['acceptance']['tests'])} tests per case)",
                ["case", " ".join(names), "verdict", "tests not passed"], crows,
                justify=["left", "left", "left", "left"], wrap=["tests not passed"],
                caption="corners: - low / + high end of each 95 % interval")
    for n in js["notes"]:
        err_console.print(textwrap.fill(f"note: {n}", width(), subsequent_indent="  "),
                          highlight=False)
    n_pass = sum(c["passed"] for c in cases)
    console.print(f"{verdict}: {n_pass} of {len(cases)} cases pass in "
                  f"{js['timings_s']['total']:.0f} s -> {folder}", highlight=False)
    if res.exit_code:
        raise typer.Exit(res.exit_code)
