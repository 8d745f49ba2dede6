"""`ema margins`: gain and phase margins of the position and speed loops (linear limit)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from ema_cli.cli.common import console, err_console, handle_errors, out_help, parse_assignments


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
    from rich.table import Table

    from ema_cli.api.margins import margins
    from ema_cli.report.rundir import check_output

    check_output(out, "margins")
    res = margins(config, parse_assignments(set_, "--set"))
    folder = res.save(out)
    table = Table(title=res.title)
    for c in ("loop", "gain margin [dB]", "at [Hz]", "phase margin [deg]", "at [Hz]"):
        table.add_column(c, justify="left" if c == "loop" else "right")
    for loop, m in res.result.items():
        table.add_row(loop, f"{m.gm_db:.4g}", f"{m.f_gm_hz:.4g}", f"{m.pm_deg:.4g}",
                      f"{m.f_pm_hz:.4g}")
    console.print(table)
    for n in res.notes:
        err_console.print(f"note: {n}")
    console.print(f"-> {folder}")
