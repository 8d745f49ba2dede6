"""`ema simulate`: one run of the reference EMA, with CSVs, a manifest and a tracking figure."""

from __future__ import annotations

import time
from pathlib import Path
from typing import Annotated

import typer
import yaml
from rich.table import Table

from ema_cli.cli.common import console, err_console, handle_errors, parse_assignments
from ema_cli.cli.main import app
from ema_cli.config.loader import load_config, parse_value, resolve_run
from ema_cli.config.schema import StudyConfig
from ema_cli.errors import EmaError
from ema_cli.model.nonlinearities import lookup, nonlinearity_updates
from ema_cli.model.params import resolve
from ema_cli.report.figures import tracking_figure
from ema_cli.report.rundir import (
    manifest,
    new_run_dir,
    write_csv,
    write_figure,
    write_json,
    write_text,
)
from ema_cli.sim.runner import resolution_warnings, simulate

SUMMARY_METRICS = (
    ("overshoot_pct", "overshoot", "%"),
    ("rise_time_s", "rise time 10-90 %", "s"),
    ("settling_time_s", "settling time 2 %", "s"),
    ("t50_s", "time to 50 %", "s"),
    ("ss_err_pos_deg", "steady-state error", "deg"),
    ("p2p_err_pos_deg", "residual oscillation (p-p, last 20 %)", "deg"),
    ("iae_pos_deg_s", "IAE position", "deg*s"),
    ("rms_err_vel_deg_s", "RMS velocity error", "deg/s"),
    ("peak_current_a", "peak current", "A"),
    ("peak_voltage_cmd_v", "peak voltage demand", "V"),
    ("peak_load_rate_deg_s", "peak load rate", "deg/s"),
)


def check_nl_options(items: list[tuple[str, str]]) -> None:
    """Validate ``--nl NAME=VALUE`` pairs up front so errors name the option."""
    base = resolve()
    for name, value in items:
        try:
            lookup(name)
            nonlinearity_updates(name, parse_value(value), base)
        except EmaError as exc:
            raise EmaError(f"--nl {name}={value}: {exc.message}") from None


def metrics_table(row: dict[str, float], title: str) -> Table:
    """A rich table of the key metrics of one run."""
    table = Table(title=title, show_header=True, header_style="bold")
    table.add_column("metric")
    table.add_column("value", justify="right")
    table.add_column("unit")
    for key, label, unit in SUMMARY_METRICS:
        v = row[key]
        table.add_row(label, "n/a" if v != v else f"{v:.4g}", unit)
    return table


@app.command("simulate")
@handle_errors
def simulate_cmd(
    config: Annotated[Path | None, typer.Argument(
        help="YAML study config (default: the bundled defaults, a 20 deg step).")] = None,
    step: Annotated[float | None, typer.Option(
        "--step", help="Use a step input of this size [deg].")] = None,
    duration: Annotated[float | None, typer.Option(
        "--duration", help="Simulated time [s].")] = None,
    dt: Annotated[float | None, typer.Option("--dt", help="Integration step [s].")] = None,
    nl: Annotated[list[str] | None, typer.Option(
        "--nl", help="Nonlinearity NAME=VALUE in the units of `ema locations` "
                     "(e.g. deadzone2=0.01, saturation2=off); repeatable.")] = None,
    set_: Annotated[list[str] | None, typer.Option(
        "--set", help="Override any config value by dotted path, e.g. plant.kL=600, "
                      "simulation.output_interval_s=1e-3, input.kind=sine; repeatable.")] = None,
    out: Annotated[Path | None, typer.Option(
        "--out", help="Output folder (default: a new folder under results/).")] = None,
) -> None:
    """Simulate one configuration and write timeseries.csv, metrics.csv, manifest.json and
    tracking.png."""
    nl_items = parse_assignments(nl, "--nl")
    check_nl_options(nl_items)
    overrides: list[tuple[str, object]] = list(parse_assignments(set_, "--set"))
    if step is not None:
        overrides += [("input.kind", "step"), ("input.amplitude_deg", step)]
    if duration is not None:
        overrides.append(("simulation.duration_s", duration))
    if dt is not None:
        overrides.append(("simulation.dt_s", dt))
    overrides += [(f"nonlinearities.{k}", v) for k, v in nl_items]
    cfg = load_config(config, overrides, StudyConfig)
    run = resolve_run(cfg, config.parent if config else None)
    if out is not None and out.exists() and any(out.iterdir()):
        raise EmaError(f"output folder '{out}' exists and is not empty; choose another --out")
    for w in resolution_warnings(run.params, run.dt):
        err_console.print(f"[yellow]warning:[/] {w}")

    t0 = time.perf_counter()
    res = simulate(run.params, run.signal, run.duration, run.dt, run.output_interval)
    wall = time.perf_counter() - t0

    folder = new_run_dir(cfg.name, cfg.model_dump(), out)
    metrics = res.metrics_frame()
    ts = res.signals_frame(0)
    write_text(folder / "config.resolved.yaml",
               yaml.safe_dump(cfg.model_dump(mode="json"), sort_keys=False))
    write_csv(folder / "timeseries.csv", ts, float_format="%.9g")
    write_csv(folder / "metrics.csv", metrics, float_format="%.9g")
    nls = ", ".join(f"{k}={v}" for k, v in cfg.nonlinearities.items()) or "no study nonlinearities"
    options = cfg.describe_options()
    title = f"{cfg.name}: {run.signal.describe()}, {nls}" + (f", {options}" if options else "")
    write_figure(folder / "tracking.png", tracking_figure(ts, title))
    write_json(folder / "manifest.json", manifest(
        "simulate", seed=cfg.seed, dt_s=run.dt, duration_s=run.duration,
        output_interval_s=run.output_interval, n_steps=res.n_steps, wall_time_s=wall,
        steps_per_s=res.n_steps / wall if wall > 0 else None,
        diverged=bool(res.diverged[0]), input=run.signal.describe(),
        nonlinearities=dict(cfg.nonlinearities), overrides=[list(o) for o in overrides],
        parameters_si=run.params, warnings=resolution_warnings(run.params, run.dt)))

    row = metrics.iloc[0].to_dict()
    console.print(metrics_table(row, title))
    if res.diverged[0]:
        err_console.print(f"[bold red]diverged[/] at t = {row['t_end_s']:.4g} s "
                          "(non-finite or runaway state); try a smaller --dt")
    console.print(f"{res.n_steps:,} steps in {wall * 1e3:.1f} ms -> {folder}")

