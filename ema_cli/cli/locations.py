"""`ema locations` and `ema params`: the nine nonlinearity locations and the parameter table."""

from __future__ import annotations

from ema_cli.cli.common import console, handle_errors


@handle_errors
def locations_cmd() -> None:
    """The nine nonlinearity locations of the paper: type, location, unit, default, meaning."""
    from rich.table import Table

    from ema_cli.model.nonlinearities import PLACEMENTS

    table = Table(title="Nonlinearities (--nl NAME=VALUE, or type@location=VALUE)")
    for col in ("name", "type", "location", "unit", "default"):
        table.add_column(col, no_wrap=True)
    for col in ("magnitude means", "paper sweep"):
        table.add_column(col, overflow="fold")
    for pl in PLACEMENTS:
        table.add_row(pl.alias or "", pl.type, pl.location, pl.unit, pl.default, pl.meaning,
                      pl.paper_sweep)
    console.print(table)


@handle_errors
def params_cmd() -> None:
    """The model parameter table (SI), as `--set plant.NAME=VALUE` takes it."""
    import math

    from rich.table import Table

    from ema_cli.model.params import PARAMS, resolve

    values = resolve()
    table = Table(title="Model parameters (SI; --set plant.NAME=VALUE)")
    for col in ("name", "value", "unit"):
        table.add_column(col, no_wrap=True)
    table.add_column("description", overflow="fold")
    for p in PARAMS:
        v = values[p.name]
        if p.choices:
            text = next(k for k, x in p.choices.items() if x == v)
        else:
            text = "off" if math.isinf(v) else f"{v:.6g}"
        table.add_row(p.name, text + ("" if p.default is not None else " (derived)"), p.unit,
                      p.description)
    console.print(table)
