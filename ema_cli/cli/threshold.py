"""`ema threshold`: the largest (or smallest) nonlinearity magnitude within metric limits."""

from __future__ import annotations

import time
from pathlib import Path
from typing import Annotated

import typer
import yaml
from rich.table import Table

from ema_cli.analysis.threshold import find_threshold, simulation_evaluator
from ema_cli.cli.common import console, handle_errors, parse_assignments
from ema_cli.cli.main import app
from ema_cli.config.criteria import DEFAULT_RTOL, Criterion
from ema_cli.config.loader import input_signal, load_config
from ema_cli.config.schema import StudyConfig
from ema_cli.errors import EmaError
from ema_cli.model.nonlinearities import lookup
from ema_cli.report.rundir import (
    manifest,
    new_run_dir,
    write_csv,
    write_figure,
    write_json,
    write_text,
)
from ema_cli.report.threshold_figures import threshold_figure


@app.command("threshold")
@handle_errors
def threshold_cmd(
    config: Annotated[Path, typer.Argument(help="YAML study config: plant, input, simulation.")],
    vary: Annotated[str, typer.Option(
        "--vary", help="Nonlinearity whose magnitude is searched (paper name or type@location).")],
    range_: Annotated[tuple[float, float], typer.Option(
        "--range", help="Search range LO HI, in the unit of `ema locations`.")],
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
        "--rtol", help="Stop when the bracket is this narrow, relative.")] = DEFAULT_RTOL,
    set_: Annotated[list[str] | None, typer.Option(
        "--set", help="Override a config value by dotted path; repeatable.")] = None,
    out: Annotated[Path | None, typer.Option("--out", help="Output folder.")] = None,
) -> None:
    """Find by bracketing and refinement the threshold magnitude of one nonlinearity at which
    tracking metrics stay within their limits; writes threshold.json, history.csv, threshold.png."""
    criteria = [Criterion.parse(r) for r in (require or [])]
    if metric is not None or limit is not None:
        if metric is None or limit is None:
            raise EmaError("--metric and --limit go together")
        crit = Criterion(metric, "<=", limit)
        crit.check()
        criteria.insert(0, crit)
    pl = lookup(vary)
    cfg = load_config(config, parse_assignments(set_, "--set"), model=StudyConfig)
    signal = input_signal(cfg.input, config.parent, cfg.load)
    nls = {k: v for k, v in cfg.nonlinearities.items() if k != vary}
    ev = simulation_evaluator(vary, cfg.plant_overrides(), nls, signal, cfg.simulation.duration_s,
                              cfg.simulation.dt_s, cfg.friction_reading)
    t0 = time.perf_counter()
    res = find_threshold(ev, criteria, range_[0], range_[1], direction,  # type: ignore[arg-type]
                         log=not linear, rtol=rtol)
    wall = time.perf_counter() - t0
    summary = res.summary()
    summary.update(vary=vary, unit=pl.unit, requirements=[str(c) for c in criteria],
                   input=signal.describe())
    if pl.unit == "deg" and cfg.input.kind == "step" and cfg.input.amplitude_deg:
        summary["threshold_percent_of_input"] = 100 * res.threshold / abs(cfg.input.amplitude_deg)
    folder = new_run_dir(f"threshold-{cfg.name}", {"cfg": cfg.model_dump(), "s": summary}, out)
    write_text(folder / "config.resolved.yaml",
               yaml.safe_dump(cfg.model_dump(mode="json"), sort_keys=False))
    write_json(folder / "threshold.json", summary)
    write_csv(folder / "history.csv", res.history, float_format="%.9g")
    title = (f"{cfg.name}: threshold of {vary} ({pl.type} @ {pl.location}), "
             f"{signal.describe()}")
    write_figure(folder / "threshold.png", threshold_figure(
        res, criteria, f"{vary} [{pl.unit}]", title, log=not linear))
    write_json(folder / "manifest.json", manifest("threshold", seed=cfg.seed, wall_time_s=wall,
                                                  **summary))
    table = Table(title=f"Threshold of {vary} [{pl.unit}]")
    for c in ("status", "threshold", "bracket", "rel. width", "simulations"):
        table.add_column(c)
    table.add_row(res.status, f"{res.threshold:.5g}",
                  f"[{res.bracket[0]:.5g}, {res.bracket[1]:.5g}]", f"{res.rel_width:.2g}",
                  str(res.n_sims))
    console.print(table)
    if "threshold_percent_of_input" in summary:
        console.print(f"= {summary['threshold_percent_of_input']:.3g} % of the "
                      f"{cfg.input.amplitude_deg:g} deg input")
    console.print(f"{res.n_sims} simulations in {wall:.2f} s -> {folder}")
