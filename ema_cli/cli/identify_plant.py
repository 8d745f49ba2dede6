"""`ema identify plant` and `ema identify validate`: a rigid axis identified from a closed-loop
record (IDIM-LS, then output error in closed loop), and the fitted model checked against another
record. Heavy imports inside the functions."""

from __future__ import annotations

import functools
from pathlib import Path
from typing import Annotated, Any

import typer

from ema_cli.cli.common import console, handle_errors, out_help, parse_assignments
from ema_cli.errors import EmaError
from ema_cli.progress import report as report_stage

COLUMNS_HELP = ("Map a role of the record, repeatable: ROLE=NAME[:UNIT], roles time, position, "
                "reference, actuation, disturbance, gain (default the EMPS names t, qm, qg, "
                "vir, gtau); e.g. position=x:mm, actuation=u:V.")


def _pairs(columns: list[str] | None, set_: list[str] | None, law: str | None,
           delay: str | None, window: str | None, split: float | None,
           validate: Path | None, free: list[str] | None = None) -> list[tuple[str, Any]]:
    from ema_cli.cli.identify_logs import _free_pairs, parse_window

    pairs: list[tuple[str, Any]] = [(f"columns.{r}", s)
                                    for r, s in parse_assignments(columns, "--columns")]
    if set_:
        pairs.append(("set", list(set_)))
    if law is not None:
        pairs.append(("law", law))
    if delay is not None:
        pairs.append(("delay", "auto" if delay == "auto" else _int(delay, "--delay")))
    if window is not None:
        pairs.append(("window", parse_window(window)))
    if split is not None:
        pairs.append(("split", split))
    if validate is not None:
        pairs.append(("validate_data", str(validate)))
    return pairs + _free_pairs(free)


def _int(text: str, option: str) -> int:
    try:
        v = int(text)
    except ValueError:
        raise EmaError(f"{option}: expected a whole number of samples or auto, got "
                       f"{text!r}") from None
    if v < 0:
        raise EmaError(f"{option}: expected >= 0 samples, got {v}")
    return v


def _print(ident: Any, folder: Path) -> None:
    from ema_cli.cli.output import print_table
    from ema_cli.report.plant_report import EDGE, axis_of, parameters_table

    fit = ident.result
    lf = fit.best
    axis = axis_of(fit)
    if fit.controller is not None:
        console.print(f"controller check: {fit.controller.summary()}; delay used: {fit.delay}")
    else:
        console.print(f"mode: {fit.mode}")
    console.print(f"law: {fit.chosen} ({fit.choice})")
    rows = []
    for r in parameters_table(lf, axis):
        rows.append((r["parameter"], f"{r['value']:.6g} {r['unit']}",
                     f"[{r['ci95_low']:.6g}, {r['ci95_high']:.6g}]",
                     r["status"] if len(r["status"]) < 40 else r["status"][:37] + "...",
                     f"{r['idim_ls']:.6g}"))
    print_table(f"ema identify plant · {Path(str(fit.settings.data)).name} · law {fit.chosen}",
                ("param", "value", "95 % interval", "status", "IDIM-LS"), rows,
                caption=f"intervals: cluster-robust (CR3, {lf.clusters} blocks of "
                        f"{lf.block_s:.3g} s)", optional=("IDIM-LS",), where="plant.json")
    ok, bad = lf.determined()
    console.print(("[green]determined[/]" if ok else
                   f"[red]NOT DETERMINED[/]: {', '.join(bad)}") + "; adequacy: "
                  + ("[green]ADEQUATE[/]" if lf.adequacy.verdict == "ADEQUATE" else
                     f"[red]{lf.adequacy.verdict}[/]" if lf.adequacy.verdict == "NOT ADEQUATE"
                     else f"[yellow]{lf.adequacy.verdict}[/]"))
    for reason in lf.adequacy.reasons:
        console.print(f"  {reason}")
    fu, ff = EDGE[axis]["force"]
    worst = lf.adequacy.ranges.get("force", [])[:3]
    if worst:
        console.print("  force residual worst at " + ", ".join(
            f"{a:.3g}-{b:.3g} s (x{r:.2g})" for a, b, r in worst) + "; by motion: " + ", ".join(
            f"{k} {v * ff:.3g} {fu}" for k, v in lf.adequacy.motion.items()))
    e = {k: v.as_dict() for k, v in fit.errors.items()}
    console.print("benchmark errors (fitted samples): " + "; ".join(
        f"{k}: force {d['force']:.4g} %" + (f", position {d['position']:.4g} %"
                                            if d["position"] == d["position"] else "")
        for k, d in e.items()))
    if fit.split is not None:
        s = {k: v.as_dict() for k, v in fit.split["errors"].items()}
        console.print(f"time split (fitted before {fit.split['t_split_s']:.4g} s, scored after): "
                      + "; ".join(f"{k}: force {d['force']:.4g} %" for k, d in s.items()))
    if ident.validation is not None:
        v = ident.validation
        for note in v.notes:
            console.print(f"note: {note}")
        console.print(f"validation on {v.record.source}: " + "; ".join(
            f"{k}: force {d.force_pct:.4g} %" + (
                f", RMS position {v.rms_position_m[k] * 1e6:.4g} um" if v.controller else "")
            for k, d in v.errors.items()))
    console.print(f"{fit.timings['total']:.1f} s ({fit.kernel['calls']} kernel calls, "
                  f"{fit.kernel['lanes']} simulations) -> {folder}")


def plant(
    data: Annotated[Path, typer.Argument(help="The closed-loop record: .csv, .parquet or .mat "
                                              "(the EMPS layout by default).")],
    actuator: Annotated[Path, typer.Option(
        "--actuator", help="Actuator description (YAML): a rigid axis, an amplifier drive, "
                           "load friction, the discrete controller that ran the record.")],
    config: Annotated[Path | None, typer.Option(
        "--config", help="YAML settings (keys of the options below).")] = None,
    columns: Annotated[list[str] | None, typer.Option("--columns", help=COLUMNS_HELP)] = None,
    law: Annotated[str | None, typer.Option(
        "--law", help="Friction law: auto (default: per-direction when the data call for it), "
                      "symmetric or per-direction.")] = None,
    delay: Annotated[str | None, typer.Option(
        "--delay", help="The controller's computation delay in samples, or auto (the delay "
                        "the controller check finds; default).")] = None,
    window: Annotated[str | None, typer.Option(
        "--window", help="Fit only the samples with T0 <= t <= T1, e.g. 0,20 [s].")] = None,
    split: Annotated[float | None, typer.Option(
        "--split", help="Share of the samples a second fit uses, the rest scoring it (time-"
                        "split validation; default 0.7; 0: none).")] = None,
    validate: Annotated[Path | None, typer.Option(
        "--validate", help="Another record the fitted model is simulated against.")] = None,
    free: Annotated[list[str] | None, typer.Option(
        "--free", help="Free a further parameter of the description's friction law with "
                       "bounds, NAME=LO,HI in SI (e.g. Fs_L=0,50, vs_L=1e-4,0.1, "
                       "sigma0_L=1e4,1e8); repeatable.")] = None,
    set_: Annotated[list[str] | None, typer.Option(
        "--set", help="Override the description, e.g. actuator.load.mass=90; repeatable.")] = None,
    out: Annotated[Path | None, typer.Option("--out", help=out_help())] = None,
) -> None:
    """Identify a rigid axis from a closed-loop record: IDIM-LS (the baseline), the controller
    checked against the log, output error in closed loop, intervals that hold on real data,
    an adequacy report, validation on a time split (and --validate LOG2)."""
    _plant(data, actuator, config, columns, law, delay, window, split, validate, set_, out,
           free)


@functools.partial(handle_errors, label="identify")
def _plant(data: Path, actuator: Path, config: Path | None, columns: list[str] | None,
           law: str | None, delay: str | None, window: str | None, split: float | None,
           validate: Path | None, set_: list[str] | None, out: Path | None,
           free: list[str] | None = None) -> None:
    from ema_cli.api.identify_plant import identify_plant, plant_inputs, plant_settings
    from ema_cli.report.rundir import check_output

    pairs = [("data", str(data)), ("actuator", str(actuator)),
             *_pairs(columns, set_, law, delay, window, split, validate, free)]
    settings = plant_settings(config, pairs)
    check_output(out, "identify", plant_inputs(settings))
    # through the API (cli -> api -> compute), which runs the fit and the validation
    ident = identify_plant(config=config, overrides=pairs, progress=report_stage)
    report_stage("writing files and figures")
    folder = ident.save(out)
    _print(ident, folder)


def validate_cmd(
    folder: Annotated[Path, typer.Argument(help="A folder `ema identify plant` wrote.")],
    data: Annotated[Path, typer.Argument(help="The record to validate on.")],
    columns: Annotated[list[str] | None, typer.Option("--columns", help=COLUMNS_HELP)] = None,
) -> None:
    """Simulate a fitted plant (a folder `ema identify plant` wrote) and its IDIM-LS baseline
    against another record: the benchmark's relative errors and the RMS position error."""
    _validate(folder, data, columns)


@functools.partial(handle_errors, label="identify")
def _validate(folder: Path, data: Path, columns: list[str] | None) -> None:
    from ema_cli.api.identify_plant import validate_folder

    v = validate_folder(folder, data,
                        dict(parse_assignments(columns, "--columns")) or None).result
    console.print(f"validation on {v.record.source} ({v.record.n} samples); " + (
        f"controller check: {v.controller.summary()}" if v.controller is not None else
        "inverse model: the force predicted from the measured motion"))
    for note in v.notes:
        console.print(f"note: {note}")
    for k, e in v.errors.items():
        d = e.as_dict()
        if v.controller is None:
            console.print(f"{k}: force prediction {d['force']:.4g} %")
            continue
        console.print(f"{k}: position {d['position']:.4g} %, velocity {d['velocity']:.4g} %, "
                      f"acceleration {d['acceleration']:.4g} %, force {d['force']:.4g} %; RMS "
                      f"position error {v.rms_position_m[k] * 1e6:.4g} um")
