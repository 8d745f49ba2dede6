"""Helpers shared by the CLI commands: error handling, console, KEY=VALUE parsing, run folders."""

from __future__ import annotations

import functools
import sys
from collections.abc import Callable
from typing import Any, TypeVar

import typer
from rich.console import Console
from rich.markup import escape

from ema_cli.errors import EmaError

console = Console(highlight=False)
err_console = Console(stderr=True, highlight=False, soft_wrap=True)

F = TypeVar("F", bound=Callable[..., Any])


def handle_errors(fn: F) -> F:
    """Turn EmaError (and Ctrl-C) into one clear message and an exit code, never a traceback.

    The message is printed literally (escaped), so ``[dask]`` or ``[deg]`` survive rich markup.
    """

    @functools.wraps(fn)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        try:
            return fn(*args, **kwargs)
        except EmaError as exc:
            err_console.print(f"[bold red]error:[/] {escape(exc.message)}")
            raise typer.Exit(exc.exit_code) from None
        except KeyboardInterrupt:
            err_console.print("[yellow]interrupted[/]: finished work was kept")
            raise typer.Exit(130) from None

    return wrapper  # type: ignore[return-value]


def parse_assignments(items: list[str] | None, option: str) -> list[tuple[str, str]]:
    """Parse repeated ``NAME=VALUE`` options, naming ``option`` in any error."""
    out = []
    for item in items or []:
        if "=" not in item:
            raise EmaError(f"{option} expects NAME=VALUE, got {item!r}")
        key, value = item.split("=", 1)
        key, value = key.strip(), value.strip()
        if not key or not value:
            raise EmaError(f"{option} expects NAME=VALUE, got {item!r}")
        out.append((key, value))
    return out


def is_interactive() -> bool:
    """True when stdout is a terminal (progress bars are shown only then)."""
    return sys.stdout.isatty()
