"""`ema simulate`: one run of the reference EMA, with CSVs, a manifest and a tracking figure."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Any

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
from ema_cli.units import fmt_num

HEAVY_MODULES = ("numpy", "ema_cli._numba", "ema_cli.config.loader", "ema_cli.sim.runner",
                 "ema_cli.api.simulation", "ema_cli.report.simulate_report",
                 "ema_cli.report.figures", "yaml")
"""What a simulation imports (numpy, numba, pydantic, matplotlib): timed as "imports"."""

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
TRANSLATIONAL_SUMMARY = {"ss_err_pos_deg": ("ss_err_pos_mm", "mm"),
                         "p2p_err_pos_deg": ("p2p_err_pos_mm", "mm"),
                         "iae_pos_deg_s": ("iae_pos_mm_s", "mm*s"),
                         "rms_err_vel_deg_s": ("rms_err_vel_mm_s", "mm/s"),
                         "peak_voltage_cmd_v": ("peak_voltage_cmd_v", "V"),
                         "peak_load_rate_deg_s": ("peak_load_rate_mm_s", "mm/s")}
"""The summary's load-side rows on a translational axis (mm, mm/s)."""


def check_nl_options(items: list[tuple[str, str]]) -> None:
    """Validate ``--nl NAME=VALUE`` pairs up front so errors name the option."""
    from ema_cli.config.loader import parse_value
    from ema_cli.model.nonlinearities import lookup, nonlinearity_updates
    from ema_cli.model.params import resolve

    base = resolve()
    for name, value in items:
        try:
            lookup(name)
            nonlinearity_updates(name, parse_value(value), base)
        except EmaError as exc:
            raise EmaError(f"--nl {name}={value}: {exc.message}") from None


NOT_REACHED = {"rise_time_s": "not reached", "t50_s": "not reached",
               "settling_time_s": "not settled within {duration:g} s"}
"""What a NaN of a time metric means (the response never got there in the simulated time)."""


def metrics_rows(row: dict[str, float], duration_s: float) -> list[tuple[str, str]]:
    """The key metrics of one run: (what, value with its unit or in words)."""
    rows = []
    for key, label, unit in SUMMARY_METRICS:
        if key not in row:
            key, unit = TRANSLATIONAL_SUMMARY.get(key, (key, unit))
        if key not in row:
            continue  # a metric this actuator does not have (a current without a motor)
        word = NOT_REACHED.get(key, "n/a").format(duration=duration_s)
        rows.append((label, fmt_num(row[key], unit, nan=word)))
    return rows


def print_metrics(row: dict[str, float], title: str, duration_s: float) -> None:
    """Print the key metrics of one run (a table at any console width)."""
    from ema_cli.cli.output import print_table

    print_table(title, ("metric", "value"), metrics_rows(row, duration_s))


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
    out: Annotated[Path | None, typer.Option("--out", help=out_help())] = None,
) -> None:
    """Simulate one configuration and write timeseries.csv, metrics.csv, manifest.json and
    tracking.png. Exits 1 if the run diverged (its outputs are still written)."""
    import time

    from ema_cli.report import figure_worker

    t_start = time.perf_counter()
    # the figure is drawn in a forked child that imports matplotlib meanwhile (None: in-process)
    worker = figure_worker.start()
    try:
        folder, run = _simulate(config, step, duration, dt, nl, set_, out, worker)
    except BaseException:
        if worker is not None:
            worker.cancel()
        raise
    row = run.summary
    print_metrics(row, run.title, run.config.simulation.duration_s)
    kernel = run.timings["simulation"]
    console.print(f"{run.batch.n_steps:,} steps in {kernel * 1e3:.1f} ms "
                  f"(total {time.perf_counter() - t_start:.2f} s) -> {folder}")
    if run.diverged:  # the outputs are written; the exit code says the run failed
        raise EmaError(f"the run diverged at t = {row['t_end_s']:.4g} s (a non-finite or "
                       "runaway state): try a smaller --dt, or check the parameters", 1)


def _simulate(config: Path | None, step: float | None, duration: float | None,
              dt: float | None, nl: list[str] | None, set_: list[str] | None, out: Path | None,
              worker: Any) -> tuple[Path, Any]:
    import importlib
    import time

    check_number(step, "--step")
    check_number(duration, "--duration", low=0.0, low_open=True)
    check_number(dt, "--dt", low=0.0, low_open=True)
    nl_items = parse_assignments(nl, "--nl")
    overrides = parse_assignments(set_, "--set")
    from ema_cli.report.rundir import check_output

    check_output(out, "simulate")  # a file, a folder of another command: refused at once
    t_start = time.perf_counter()
    for module in HEAVY_MODULES:  # imported here, timed as one part of the run
        if worker is None or "figures" not in module:  # the worker imports matplotlib
            importlib.import_module(module)
    t_imports = time.perf_counter() - t_start
    check_nl_options(nl_items)
    if out is not None:  # checked before the simulation: its inputs against the folder's
        from ema_cli.api.simulation import simulation_inputs

        check_output(out, "simulate", simulation_inputs(
            config, overrides, nl=dict(nl_items), step_deg=step, duration_s=duration, dt_s=dt))
    from ema_cli.api.simulation import simulate
    from ema_cli.progress import report

    report("simulating")
    run = simulate(config, overrides, nl=dict(nl_items), step_deg=step, duration_s=duration,
                   dt_s=dt)
    run.timings["imports"] = t_imports
    for w in run.warnings:
        err_console.print(f"[yellow]warning:[/] {w}")
    report("writing files and the figure")
    return run.save(out, worker=worker), run
