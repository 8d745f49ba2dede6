"""The `ema` command: a typer app; every command is registered here, explicitly.

Start-up matters (``ema --help`` should answer at once), so the command modules import only
typer and the CLI helpers at module level; numpy, numba, pandas, matplotlib and the compute code
are imported inside the command bodies, when a command actually runs.
"""

from __future__ import annotations

import typer

from ema_cli import __version__
from ema_cli.cli import (
    acceptance,
    compiling,
    design,
    duty,
    freqresp,
    identify,
    identify_plant,
    locations,
    margins,
    production,
    reproduce,
    sensitivity,
    simulate,
    sweep,
    threshold,
    tune,
)
from ema_cli.cli.groups import command_group

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
    ("margins", margins.margins_cmd),
    ("freqresp", freqresp.freqresp_cmd),
    ("acceptance", acceptance.acceptance_cmd),
    ("yield", production.yield_cmd),
    ("duty", duty.duty_cmd),
    ("tune", tune.tune_cmd),
    ("sensitivity", sensitivity.sensitivity_cmd),
    ("identify", identify.identify_cmd),
    ("design", design.design_cmd),
    ("reproduce", reproduce.reproduce_cmd),
    ("locations", locations.locations_cmd),
    ("params", locations.params_cmd),
    ("compile", compiling.compile_cmd),
)
"""(name, function) of every command, in the order ``ema --help`` lists them. A command with
subcommands in ``GROUPS`` is a group whose default (no subcommand named) is this function."""

IDENTIFY_COMMANDS = (
    ("torque", identify.torque_cmd),
    ("closed-loop", identify.closed_loop_cmd),
    ("friction-sweep", identify.friction_sweep_cmd),
    ("make-data", identify.make_data_cmd),
    ("plant", identify_plant.plant),
    ("validate", identify_plant.validate_cmd),
)
"""The subcommands of `ema identify`, in the order its help lists them: one line each."""

GROUPS = {
    "identify": (IDENTIFY_COMMANDS,
                 "Identify the actuator's parameters: from torque data (torque), a closed-loop "
                 "log (closed-loop), a friction sweep (friction-sweep), a rigid axis's measured "
                 "record (plant; validate checks it on another record); make-data writes "
                 "synthetic data to try them on. `ema identify [CONFIG] [OPTIONS]` without a "
                 "command runs the torque identification, or a log mode with --closed-loop, "
                 "--friction-sweep or --make-data KIND (the spelling of earlier versions). "
                 "Each command's --help lists its options."),
}
"""(subcommands, help) of each command that is a group (cli/groups.py)."""

SHORT_HELP = {
    "simulate": "Simulate one configuration: signals, metrics, a figure.",
    "sweep": "Run every job of a sweep config, in parallel, cached.",
    "validate": "Check a config against its schema (nothing is run).",
    "show": "Print the resolved config, every default filled in.",
    "threshold": "Find the magnitude at which a metric crosses a limit.",
    "margins": "Gain and phase margins of the position and speed loops.",
    "freqresp": "Frequency response of the load angle by simulation.",
    "acceptance": "Run an acceptance battery: PASS, FAIL or INCONCLUSIVE.",
    "duty": "A mission profile: winding temperature, RMS, life, a verdict.",
    "yield": "Production yield over toleranced units, with its interval.",
    "tune": "Tune the controller's free variables to the scenarios.",
    "sensitivity": "Global sensitivity of metrics to factors (Sobol, Morris).",
    "identify": "Identify the actuator from torque data, a log or a record.",
    "design": "From a log to a controller signed off against a spec.",
    "reproduce": "Reproduce the paper: studies, thresholds, claims.",
    "locations": "The nine nonlinearity locations of the paper.",
    "params": "The model parameter table (SI units).",
    "compile": "Compile every kernel into the cache (first run only).",
}
"""Each command's one-line summary in ``ema --help``: whole at 80 columns (the docstring's
first sentence, cut by the help formatter, is not)."""

for _name, _fn in COMMANDS:
    if _name in GROUPS:
        _subs, _help = GROUPS[_name]
        app.add_typer(command_group(_name, _fn, _subs, _help), name=_name,
                      short_help=SHORT_HELP[_name])
    else:
        app.command(_name, short_help=SHORT_HELP[_name])(_fn)


FAST_EXIT = frozenset({"simulate", "validate", "show", "threshold", "margins", "freqresp",
                       "acceptance", "duty", "tune", "locations", "params"})
"""Commands that start no worker processes: once they have finished (every file written and
closed, output flushed) the process ends at once. The interpreter's own teardown of numba,
LLVM and matplotlib takes ~0.45 s and does nothing these commands need; commands that may start
worker pools (sweep, identify, reproduce) exit normally so that the pools are shut down."""


def _interrupt(signum: int, frame: object) -> None:
    """SIGINT (Ctrl-C) and SIGTERM: stop where the program runs (finished work kept, temporary
    files removed); ``handle_errors`` exits 130 or 143."""
    import signal

    from ema_cli.errors import SIGNALLED, Terminated

    SIGNALLED.append(signum)
    raise Terminated if signum == signal.SIGTERM else KeyboardInterrupt


def run(args: list[str] | None = None) -> int:
    """Run the command line -> exit code. Usage errors (a bad option value, an unknown option
    or command) are one line, ``error: ...``, exit code 2, as every other bad input."""
    # typer's public exception base (typer >= 0.29 vendors click: its ClickException, UsageError
    # and NoArgsIsHelpError all derive from typer.TyperException); the kind is read from the
    # exception itself, never from a private module
    try:
        result = app(args=args, standalone_mode=False)
    except typer.TyperException as exc:
        kinds = {c.__name__ for c in type(exc).__mro__}
        message = " ".join(exc.format_message().split())
        if "NoArgsIsHelpError" in kinds:  # `ema` alone: the help
            typer.echo(exc.format_message())
            return 0
        if "UsageError" in kinds:
            ctx = getattr(exc, "ctx", None)
            hint = f" (see `{ctx.command_path} --help`)" if ctx is not None else ""
            typer.echo(f"error: {message}{hint}", err=True)
            return 2
        typer.echo(f"error: {message}", err=True)
        return int(getattr(exc, "exit_code", 1))
    except typer.Exit as exc:
        return exc.exit_code
    except typer.Abort:
        import signal

        from ema_cli.errors import SIGNALLED

        typer.echo("interrupted", err=True)
        return 143 if signal.SIGTERM in SIGNALLED else 130
    from ema_cli.cli.common import REPORTED, interrupted
    from ema_cli.errors import SIGNALLED

    if result == 130 and SIGNALLED and not REPORTED:  # typer's own code for a signal that
        return interrupted()  # came before the command ran (Ctrl-C, or SIGTERM: 143)
    return result if isinstance(result, int) else 0


def main() -> None:
    """Console-script entry point."""
    import os
    import signal
    import sys
    import warnings

    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, _interrupt)
    # numpy overflow warnings and matplotlib layout advice are not for the user of a command:
    # what matters is reported (divergence, limits) in the command's own words
    warnings.simplefilter("ignore", RuntimeWarning)
    warnings.filterwarnings("ignore", category=UserWarning, module="matplotlib")
    command = next((a for a in sys.argv[1:] if not a.startswith("-")), None)
    try:
        code = run(sys.argv[1:])
    except KeyboardInterrupt:  # a signal after the command's own handling, before this line
        from ema_cli.errors import SIGNALLED

        code = 143 if signal.SIGTERM in SIGNALLED else 130
    # the command is done (its folder finished, or left to complete): a signal now changes
    # nothing, and the interpreter's teardown (which shuts down worker pools) would restore
    # the default handlers, whose death by signal hides the exit code: ignored from here
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, signal.SIG_IGN)
    if command in FAST_EXIT:
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(code)
    sys.exit(code)
