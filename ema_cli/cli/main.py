"""The `ema` command: a typer app with one module per command."""

from __future__ import annotations

import typer

from ema_cli import __version__

app = typer.Typer(
    name="ema",
    help="Nonlinear analysis of electromechanical actuators: simulate, sweep, identify, reproduce.",
    no_args_is_help=True,
    pretty_exceptions_enable=False,
    add_completion=False,
)


def _version(value: bool) -> None:
    if value:
        typer.echo(f"ema {__version__}")
        raise typer.Exit()


@app.callback()
def _root(
    version: bool = typer.Option(False, "--version", callback=_version, is_eager=True,
                                 help="Print the version and exit."),
) -> None:
    """ema: how much backlash, dead zone, saturation and friction can an actuator tolerate?"""


def _register() -> None:
    # Each command module adds itself to `app`; importing them here keeps main.py thin.
    import importlib
    import pkgutil

    import ema_cli.cli as pkg

    for mod in sorted(m.name for m in pkgutil.iter_modules(pkg.__path__)):
        if mod not in ("main", "common"):
            importlib.import_module(f"ema_cli.cli.{mod}")


_register()


def main() -> None:
    """Console-script entry point."""
    app()
