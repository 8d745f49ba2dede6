"""`ema threshold`: the largest (or smallest) nonlinearity magnitude within metric limits."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from ema_cli.cli.common import as_options, console, handle_errors, out_help, parse_assignments
from ema_cli.cli.output import print_table
from ema_cli.progress import report as report_stage
from ema_cli.units import fmt_num

DEFAULT_RTOL = 1e-3  # mirrors config.criteria.DEFAULT_RTOL (checked by a test), kept import-free


@handle_errors
def threshold_cmd(
    config: Annotated[Path, typer.Argument(help="YAML study config: plant, input, simulation.")],
    vary: Annotated[str, typer.Option(
        "--vary", help="Nonlinearity whose magnitude is searched (paper name or type@location).")],
    range_: Annotated[tuple[float, float], typer.Option(
        "--range", metavar="LO HI", help="Search range LO HI, in the unit of `ema locations`.")],
    metric: Annotated[str | None, typer.Option(
        "--metric", help="Metric column (as in metrics.csv), with --limit.")] = None,
    limit: Annotated[float | None, typer.Option("--limit", help="Limit of --metric.")] = None,
    require: Annotated[list[str] | None, typer.Option(
        "--require", help="Further requirement METRIC<=VALUE (or >=); repeatable.")] = None,
    direction: Annotated[str, typer.Option(
        "--direction", help="max: largest passing value (small is benign, e.g. a dead band); "
                            "min: smallest passing value (large is benign, e.g. stiffness)."),
    ] = "max",
    linear: Annotated[bool, typer.Option(
        "--linear", help="Search a linear grid (default: logarithmic).")] = False,
    rtol: Annotated[float, typer.Option(
        "--rtol", help="Stop when the bracket is this narrow, relative, in (0, 1).")
    ] = DEFAULT_RTOL,
    set_: Annotated[list[str] | None, typer.Option(
        "--set", help="Override a config value by dotted path; repeatable.")] = None,
    out: Annotated[Path | None, typer.Option("--out", help=out_help())] = None,
) -> None:
    """Find by bracketing and refinement the threshold magnitude of one nonlinearity at which
    tracking metrics stay within their limits; writes threshold.json, history.csv, threshold.png."""
    from ema_cli.api.threshold import threshold
    from ema_cli.report.rundir import check_output

    check_output(out, "threshold")  # a file, a folder of another command: refused at once
    pairs = parse_assignments(set_, "--set")
    if out is not None:  # its inputs against the folder's, before the search
        from ema_cli.api.threshold import threshold_inputs

        check_output(out, "threshold", threshold_inputs(
            config, vary, range_, metric=metric, limit=limit, require=require or (),
            direction=direction, log=not linear, rtol=rtol, overrides=pairs))
    res = as_options(lambda: threshold(config, vary, range_, metric=metric, limit=limit,
                                       require=require or (), direction=direction,
                                       log=not linear, rtol=rtol, overrides=pairs),
                     anywhere=False, vary="--vary", range="--range", metric="--metric",
                     limit="--limit", require="--require", direction="--direction",
                     rtol="--rtol")
    report_stage("writing files and figures")
    folder = res.save(out)
    r = res.result
    u = res.unit
    lo, hi = (fmt_num(b, u, 5, nan="none") for b in r.bracket)
    print_table(f"Threshold of {vary} [{u}]",
                ("status", "threshold", "bracket", "relative width", "simulations"),
                [(r.status, fmt_num(r.threshold, u, 5, nan="not found"), f"[{lo}, {hi}]",
                  fmt_num(100 * r.rel_width, "%", 2), f"{r.n_sims:,}")],
                justify=["left"] + ["right"] * 4)
    summary = res.summary
    if "threshold_percent_of_input" in summary:
        console.print(f"= {summary['threshold_percent_of_input']:.3g} % of the "
                      f"{res.config.input.amplitude_deg:g} deg input")
    console.print(f"{r.n_sims} simulations in {res.wall_time_s:.2f} s -> {folder}")
