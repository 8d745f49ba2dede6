"""`ema margins`: gain and phase margins of the position and speed loops (linear limit)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from ema_cli.cli.common import console, err_console, handle_errors, out_help, parse_assignments
from ema_cli.cli.output import print_table
from ema_cli.units import fmt_num


def margins_cells(m: object) -> tuple[str, str, str, str]:
    """Gain margin, its frequency, phase margin, its frequency, with units, or in words when
    the loop never crosses -180 deg (no phase crossover) or 0 dB (no gain crossover)."""
    from ema_cli.vocab import margin_text

    gm, fg, pm, fp = (getattr(m, k) for k in ("gm_db", "f_gm_hz", "pm_deg", "f_pm_hz"))
    return (margin_text(gm, "gain_margin"), fmt_num(fg, "Hz", nan="-", inf="-"),
            margin_text(pm, "phase_margin"), fmt_num(fp, "Hz", nan="-", inf="-"))


@handle_errors
def margins_cmd(
    config: Annotated[Path | None, typer.Argument(
        help="YAML study config (default: the bundled defaults).")] = None,
    set_: Annotated[list[str] | None, typer.Option(
        "--set", help="Override a config value by dotted path, e.g. plant.Kpp=60; "
                      "repeatable.")] = None,
    out: Annotated[Path | None, typer.Option("--out", help=out_help())] = None,
) -> None:
    """Stability margins of the position and speed loops of the linear limit (saturations,
    dead zones, backlash removed; friction viscous; controller continuous), each loop broken at
    its feedback with the other closed; writes margins.json, loops.csv and margins.png."""
    from ema_cli.api.margins import margins
    from ema_cli.progress import report
    from ema_cli.report.rundir import check_output

    pairs = parse_assignments(set_, "--set")
    if out is not None:
        from ema_cli.api.margins import margins_inputs

        check_output(out, "margins", margins_inputs(config, pairs))
    report("linear model and margins")
    res = margins(config, pairs)
    report("writing files and figures")
    folder = res.save(out)
    rows = [(loop, *margins_cells(m)) for loop, m in res.result.items()]
    print_table(res.title, ("loop", "gain margin", "at", "phase margin", "at"), rows)
    for n in res.notes:
        err_console.print(f"note: {n}")
    console.print(f"-> {folder}")
