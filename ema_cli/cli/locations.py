"""`ema locations` and `ema params`: the nine nonlinearity locations and the parameter table."""

from __future__ import annotations

from ema_cli.cli.common import handle_errors


@handle_errors
def locations_cmd() -> None:
    """The nine nonlinearity locations of the paper: type, location, unit, default, meaning."""
    from ema_cli.cli.output import print_table
    from ema_cli.model.nonlinearities import PLACEMENTS

    rows = [(pl.alias or "", pl.type, pl.location, pl.unit, pl.default, pl.meaning,
             pl.paper_sweep) for pl in PLACEMENTS]
    print_table("Nonlinearities (--nl NAME=VALUE, or type@location=VALUE)",
                ("name", "type", "location", "unit", "default", "magnitude means",
                 "paper sweep"), rows, justify=["left"] * 7,
                wrap=("magnitude means", "paper sweep"))


@handle_errors
def params_cmd() -> None:
    """The model parameter table (SI), as `--set plant.NAME=VALUE` takes it."""
    import math

    from ema_cli.cli.output import print_table
    from ema_cli.model.params import PARAMS, resolve

    values = resolve()
    rows = []
    for p in PARAMS:
        v = values[p.name]
        if p.choices:
            text = next(k for k, x in p.choices.items() if x == v)
        else:
            text = "off" if math.isinf(v) else f"{v:.6g}"
        rows.append((p.name, text + ("" if p.default is not None else " (derived)"), p.unit,
                     p.description))
    print_table("Model parameters (SI; --set plant.NAME=VALUE)",
                ("name", "value", "unit", "description"), rows,
                justify=["left", "right", "left", "left"], optional=("description",),
                where="docs/model.md", wrap=("description",))
