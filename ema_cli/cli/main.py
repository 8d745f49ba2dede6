"""The `ema` command: a typer app; every command is registered here, explicitly.

Start-up matters (``ema --help`` should answer at once), so the command modules import only
typer and the CLI helpers at module level; numpy, numba, pandas, matplotlib and the compute code
are imported inside the command bodies, when a command actually runs.
"""

from __future__ import annotations

import typer

from ema_cli import __version__
from ema_cli.cli import identify, locations, reproduce, simulate, sweep, threshold

app = typer.Typer(
    name="ema",
    help="Nonlinear analysis of electromechanical actuators: simulate, sweep, identify, reproduce.",
    no_args_is_help=True,
    pretty_exceptions_enable=False,
    add_completion=False,
    rich_markup_mode=None,  # help texts are literal: "[deg]" and "[s]" are units, not markup
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


COMMANDS = (
    ("simulate", simulate.simulate_cmd),
    ("sweep", sweep.sweep_cmd),
    ("validate", sweep.validate_cmd),
    ("show", sweep.show_cmd),
    ("threshold", threshold.threshold_cmd),
    ("identify", identify.identify_cmd),
    ("reproduce", reproduce.reproduce_cmd),
    ("locations", locations.locations_cmd),
    ("params", locations.params_cmd),
)
"""(name, function) of every command, in the order ``ema --help`` lists them."""

for _name, _fn in COMMANDS:
    app.command(_name)(_fn)


FAST_EXIT = frozenset({"simulate", "validate", "show", "threshold", "locations", "params"})
"""Commands that start no worker processes: once they have finished (every file written and
closed, output flushed) the process ends at once. The interpreter's own teardown of numba,
LLVM and matplotlib takes ~0.45 s and does nothing these commands need; commands that may start
worker pools (sweep, identify, reproduce) exit normally so that the pools are shut down."""


def main() -> None:
    """Console-script entry point."""
    import os
    import sys

    command = next((a for a in sys.argv[1:] if not a.startswith("-")), None)
    try:
        app()
    except SystemExit as exc:
        if command not in FAST_EXIT or "pytest" in sys.modules:
            raise
        code = exc.code
        if code is not None and not isinstance(code, int):
            print(code, file=sys.stderr)
            code = 1
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(code or 0)
