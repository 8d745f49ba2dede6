"""Helpers shared by the CLI commands: error handling, console, KEY=VALUE parsing, run folders."""

from __future__ import annotations

import functools
import os
import sys
from collections.abc import Callable
from typing import Annotated, Any, TypeVar

import typer
from rich.console import Console
from rich.markup import escape

from ema_cli.errors import SIGNALLED, EmaError

console = Console(highlight=False)
err_console = Console(stderr=True, highlight=False, soft_wrap=True)

F = TypeVar("F", bound=Callable[..., Any])


def sync_width() -> None:
    """Make the consoles follow ``COLUMNS`` as it is when a command starts (rich reads it once,
    when a console is created; a test runner may set it later)."""
    cols = os.environ.get("COLUMNS", "")
    if cols.isdigit() and int(cols) > 0:
        console.width = int(cols)
        err_console.width = int(cols)


def printable(text: str) -> str:
    """``text`` as one printable line: control characters (from a binary file quoted in a
    message) shown as ``?``, line breaks as spaces."""
    import re

    return re.sub(r"[\x00-\x08\x0b-\x1f\x7f]", "?", " ".join(text.split("\n")))


def as_options(call: Callable[[], Any], *, anywhere: bool = True, **options: str) -> Any:
    """Run an API ``call``; its EmaError names arguments (``f_min_hz``), re-raised naming the
    command's options instead (``--f-min``): API errors name arguments, CLI errors options.
    ``anywhere=False``: only the argument the message starts with (a word such as ``metric``
    may also name something else further on)."""
    import re

    try:
        return call()
    except EmaError as exc:
        text = exc.message
        for arg, opt in options.items():
            pattern = rf"(?<![\w.-]){re.escape(arg)}(?![\w])"
            text = re.sub(pattern if anywhere else "^" + pattern, opt, text)
        if text == exc.message:
            raise
        raise EmaError(text) from None


REPORTED: list[int] = []
"""The exit codes :func:`interrupted` has reported (at most one message per command)."""


def interrupted(exc: BaseException | None = None) -> int:
    """Say that the command was interrupted -> its exit code: 143 after SIGTERM, else 130
    (Ctrl-C). Finished work is kept: every file is written atomically, the output folder's
    marker says whether the run finished, and the same command completes it."""
    import contextlib
    import signal

    from ema_cli.errors import Terminated

    term = isinstance(exc, Terminated) or signal.SIGTERM in SIGNALLED
    code = 143 if term else 130
    if not REPORTED:
        with contextlib.suppress(Exception):  # a closed stream: the exit code still says it
            err_console.print(f"[yellow]{'terminated' if term else 'interrupted'}[/]: "
                              "finished work was kept; the same command completes it")
    REPORTED.append(code)
    return code


def handle_errors(fn: F, label: str | None = None) -> F:
    """Turn EmaError (and Ctrl-C, SIGTERM) into one clear message and an exit code, never a
    traceback: 2 (or the error's code) for EmaError, 130 for Ctrl-C, 143 for SIGTERM (also when
    the signal surfaces as another exception, e.g. a worker process it killed).

    The message is printed literally (escaped), so ``[dask]`` or ``[deg]`` survive rich markup.
    Progress lines are labelled ``label`` (default: the function's name without ``_cmd``).
    """
    label = label or fn.__name__.removesuffix("_cmd")

    @functools.wraps(fn)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        from ema_cli.cli.progress import stages

        REPORTED.clear()  # one command, one message
        try:
            try:
                sync_width()
                with stages(label, console, err_console):
                    return fn(*args, **kwargs)
            except (typer.Exit, typer.Abort, typer.TyperException):  # usage errors: typer's
                raise
            except KeyboardInterrupt as exc:
                raise typer.Exit(interrupted(exc)) from None
            except Exception as exc:
                if SIGNALLED:  # raised because of the signal
                    raise typer.Exit(interrupted(exc)) from None
                if isinstance(exc, EmaError):
                    err_console.print(f"[bold red]error:[/] {escape(printable(exc.message))}")
                    raise typer.Exit(exc.exit_code) from None
                if isinstance(exc, MemoryError):
                    err_console.print("[bold red]error:[/] out of memory; ask for less (a "
                                      "shorter simulation.duration_s, a larger "
                                      "simulation.output_interval_s, fewer jobs)")
                    raise typer.Exit(1) from None
                if os.environ.get("EMA_DEBUG"):
                    raise
                text = escape(" ".join(str(exc).split()))[:300]
                err_console.print(f"[bold red]error:[/] unexpected {type(exc).__name__}: "
                                  f"{text} (a bug in ema; set EMA_DEBUG=1 to see the "
                                  "traceback)")
                raise typer.Exit(1) from None
        except KeyboardInterrupt as exc:  # a second signal while the first was reported
            raise typer.Exit(interrupted(exc)) from None

    return wrapper  # type: ignore[return-value]


def parse_assignments(items: list[str] | None, option: str) -> list[tuple[str, str]]:
    """Parse repeated ``NAME=VALUE`` options, naming ``option`` in any error."""
    out = []
    seen: dict[str, str] = {}
    for item in items or []:
        if "=" not in item:
            raise EmaError(f"{option} expects NAME=VALUE, got {item!r}")
        key, value = item.split("=", 1)
        key, value = key.strip(), value.strip()
        if not key or not value:
            raise EmaError(f"{option} expects NAME=VALUE, got {item!r}")
        if key in seen:
            raise EmaError(f"{option} {key} is given twice ({seen[key]} and {value}); give it "
                           "once")
        seen[key] = value
        out.append((key, value))
    return out


OUT_HELP = ("Output folder (default: a new folder under results/). It must be new or empty, or "
            "hold a run of the same command and inputs: unfinished (interrupted), it is "
            "completed; finished, it is kept as it is. Earlier results of other inputs are "
            "never overwritten{resume}.")


def out_help(resume: str = "") -> str:
    """The ``--out`` help text of every command (one policy), with how it resumes if it does."""
    return OUT_HELP.format(resume=f"; {resume}" if resume else "")


def check_number(value: float | int | None, option: str, *, low: float | None = None,
                 high: float | None = None, low_open: bool = False) -> None:
    """Refuse a non-finite or out-of-range numeric option, naming it (None: not given)."""
    if value is None:
        return
    import math

    v = float(value)
    if not math.isfinite(v):
        raise EmaError(f"{option} must be a finite number, got {value}")
    if low is not None and (v <= low if low_open else v < low):
        raise EmaError(f"{option} must be {'>' if low_open else '>='} {low:g}, got {value}")
    if high is not None and v > high:
        raise EmaError(f"{option} must be <= {high:g}, got {value}")


def is_interactive() -> bool:
    """True when stdout is a terminal (progress bars are shown only then)."""
    return sys.stdout.isatty()


BackendOpt = Annotated[str | None, typer.Option(
    "--backend", help="Where the work runs: threads (this process, numba's threads; the "
                      "default) | loky (worker processes) | dask (a cluster: --scheduler). "
                      "Every backend gives the same results, bit for bit.")]
NJobsOpt = Annotated[int | None, typer.Option(
    "--n-jobs", help="Workers: threads or processes (-1: all cores; default all, capped at "
                     "the cores); the dask backend uses every thread of the cluster.")]
SchedulerOpt = Annotated[str | None, typer.Option(
    "--scheduler", help="Dask scheduler address for --backend dask, e.g. "
                        "tcp://host:8786.")]
BACKEND_OPTIONS = {"backend": "--backend", "n_jobs": "--n-jobs", "scheduler": "--scheduler"}
"""The API's execution arguments -> the options naming them (for :func:`as_options`)."""


def backend_options(backend: str | None, n_jobs: int | None, scheduler: str | None
                    ) -> int | None:
    """``--backend``, ``--n-jobs`` and ``--scheduler`` checked, naming the option ->
    ``--n-jobs`` to use (capped at the cores with a note, unless a cluster runs the work)."""
    from ema_cli.limits import BACKENDS

    if backend is not None and backend not in BACKENDS:
        raise EmaError(f"--backend must be one of {', '.join(BACKENDS)}; got {backend!r}")
    if scheduler is not None and backend != "dask":
        raise EmaError("--scheduler is for --backend dask; give --backend dask with it")
    return check_jobs(n_jobs, "--n-jobs", scheduler if backend == "dask" else None)


def print_retries(execution: dict[str, Any] | None) -> None:
    """One note per block that was run again (a lost worker), on stderr."""
    for r in (execution or {}).get("retries", []):
        err_console.print(f"note: {r['block']} run again ({r['why']})", highlight=False)


def check_jobs(n_jobs: int | None, option: str, scheduler: str | None = None) -> int | None:
    """``--n-jobs``: -1 (all cores) or 1 .. MAX_WORKERS -> the count to use, capped at the
    cores available (with a note) unless a cluster ``scheduler`` is given."""
    from ema_cli.limits import MAX_WORKERS, cap_workers

    if n_jobs is not None and n_jobs != -1:
        check_number(n_jobs, option + " (-1: all cores)", low=1, high=MAX_WORKERS)
    n_jobs, note = cap_workers(n_jobs, option, cluster=scheduler is not None)
    if note:
        err_console.print(f"note: {note}", highlight=False)
    return n_jobs
