"""`ema duty`: a mission profile through the actuator -> winding temperature, RMS current and
torque, life, a verdict (exit 0 PASS, 1 FAIL, 3 INCONCLUSIVE)."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Annotated, Any

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


def _summary_rows(res: Any) -> list[list[str]]:
    from ema_cli.units import ZERO_CELSIUS, fmt_num

    th, st, run = res.run.thermal, res.run.stats, res.run
    rows = [["peak winding / housing",
             f"{th.peak_w - ZERO_CELSIUS:.1f} / {th.peak_h - ZERO_CELSIUS:.1f} degC"],
            ["winding limit", f"{res.limits.winding_k - ZERO_CELSIUS:g} degC "
                              f"({res.limits.class_name})"],
            ["method error (estimate)", f"+-{th.error_k:.2g} K"],
            ["RMS / peak current", f"{st.rms_current:.3g} / {st.peak_current:.3g} A"],
            ["continuous current", f"{run.continuous_current:.3g} A (S1 at "
                                   f"{_ambient(res):g} degC, the limit)"],
            ["current margin", fmt_num(st.margin) + " x (the winding reaches its limit)"],
            ["RMS / peak motor torque", f"{st.rms_torque:.3g} / {st.peak_torque:.3g} N*m"]]
    if math.isfinite(st.l10_s):
        rows.append(["L10 life", f"{st.l10_s / 3600:.3g} h ({st.l10_revs:.3g} rev, "
                                 f"P_eq {st.equivalent_load:.3g} "
                                 f"{'N*m' if res.axis == 'rotary' else 'N'})"])
    rows.append(["insulation life used", f"{100 * th.life_h / res.limits.insulation_life_h:.3g}"
                                         " % per pass (10 K rule)"])
    rows.append(["energy per pass", f"{st.energy / 3600:.4g} Wh"])
    h = res.hot_summary()
    if h is not None:
        bw, rt = h["bandwidth_hz"], h["no_load_rate_deg_s"]
        rows.append(["bandwidth cold / hot", f"{fmt_num(bw['cold']['value'])} / "
                                             f"{fmt_num(bw['hot']['value'])} Hz (1 deg)"])
        rows.append(["no-load rate cold / hot", f"{fmt_num(rt['cold']['value'])} / "
                                                f"{fmt_num(rt['hot']['value'])} deg/s"])
    if res.reference is not None:
        r = res.reference
        rows.append(["full resolution", f"peak {r.peak_w - ZERO_CELSIUS:.2f} degC, multirate "
                                        f"{th.peak_w - r.peak_w:+.3f} K ({r.wall_s:.0f} s)"])
    return rows


def _ambient(res: Any) -> float:
    from ema_cli.units import ZERO_CELSIUS

    return res.expanded.blocks[res.expanded.order[0]].ambient_k - ZERO_CELSIUS


@handle_errors
def duty_cmd(
    profile: Annotated[Path, typer.Argument(
        help="Mission profile (YAML), e.g. configs/duty/tvc.yaml.")],
    actuator: Annotated[Path | None, typer.Argument(
        help="Actuator: a run config or an actuator description (configs/actuators/); "
             "default: the profile's actuator section.")] = None,
    set_: Annotated[list[str] | None, typer.Option(
        "--set", help="Override a profile value by dotted path, e.g. ambient=50 or "
                      "segments.0.sine.cycles=100 or actuator.plant.R=0.6; repeatable.")] = None,
    full_resolution: Annotated[bool, typer.Option(
        "--full-resolution", help="Also simulate the whole profile at the mechanical step, "
                                  "the thermal network inside the kernel (minutes per hour of "
                                  "profile), and compare.")] = False,
    hot: Annotated[bool, typer.Option(
        "--hot/--no-hot", help="The hot actuator's bandwidth and no-load rate beside the "
                               "cold one's.")] = True,
    out: Annotated[Path | None, typer.Option("--out", help=out_help())] = None,
) -> None:
    """Run the mission PROFILE on the actuator: winding and housing temperature over the whole
    profile (the thermal network exact over hours, the mechanics simulated once per distinct
    segment), peak and RMS current and torque, the torque-speed points against the drive's
    envelope, the equivalent load and L10 life, the insulation life used, energy, the hot
    actuator's bandwidth and no-load rate; a verdict against the profile's limits (default: the
    winding at most its insulation's limit). Writes duty.md, duty.json, temperature.png,
    envelope.png, trace.parquet and a manifest. Exit code: 0 PASS, 1 FAIL, 2 bad usage or
    input, 3 INCONCLUSIVE."""
    from ema_cli.api.duty import duty
    from ema_cli.errors import EmaError
    from ema_cli.report.rundir import check_output

    if not profile.is_file():
        raise EmaError(f"profile '{profile}' is not a file (a mission profile, e.g. "
                       "configs/duty/tvc.yaml)")
    if actuator is not None and not actuator.is_file():
        raise EmaError(f"actuator '{actuator}' is not a file (a run config or an actuator "
                       "description, e.g. configs/actuators/paper_ema.yaml)")
    pairs = parse_assignments(set_, "--set")
    if out is not None:
        from ema_cli.api.duty import duty_inputs

        check_output(out, "duty", as_options(
            lambda: duty_inputs(profile, actuator, pairs, full_resolution=full_resolution,
                                hot=hot)))

    res = as_options(lambda: duty(profile, actuator, pairs, full_resolution=full_resolution,
                                  hot=hot))
    report_stage("writing files and figures")
    folder = res.save(out)
    from ema_cli.cli.acceptance import MARKS, print_verdicts
    from ema_cli.cli.output import print_table
    from ema_cli.report.acceptance_report import fmt_limit, fmt_value

    console.print(f"[bold]{res.title}[/]: {res.expanded.duration / 3600:.3g} h, "
                  f"{len(res.expanded.blocks)} distinct segment(s); thermal element: "
                  f"{res.thermal_source}", highlight=False)
    print_verdicts(res.verdicts, fmt_value, fmt_limit)
    print_table(None, ["", "value"], _summary_rows(res), justify=["left", "left"],
                wrap=["value"])
    for n in res.run.notes:
        err_console.print(f"note: {n}")
    console.print(f"{MARKS[res.verdict]} ({res.wall_time_s:.1f} s) -> {folder}",
                  highlight=False)
    if res.exit_code:
        raise typer.Exit(res.exit_code)
