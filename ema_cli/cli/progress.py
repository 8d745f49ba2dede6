"""The command line's progress display (stderr): what stage a command is in, k of n.

On a terminal, one line redrawn in place (at most 10 times a second): the command, the stage,
``k/n`` and the elapsed time; it is erased when the command ends. In a pipe or a CI log, one
line per stage as it starts (``identify: GA generation (200) ...``) and, once a stage has run
:data:`LONG_S`, at most one more per tenth of it (``identify: GA generation 100/200 (50 %)``).
A stage is the words of its text before the first number, parenthesis or colon
(:func:`stage_key`): ``joint fit, round 2 of 3 (J = 0.01)`` is stage ``joint fit, round`` at
2/3, so a stage reported again with other numbers does not print again.
"""

from __future__ import annotations

import re
import sys
import time
from typing import Any, TextIO

REFRESH_S = 0.1  # shortest interval between two redraws of the terminal line [s]
GRACE_S = 1.0  # a pipe hears of no stage before the command has run this long [s]: a command
# that ends at once (a bad option, a quick table) prints its result or error alone
LONG_S = 5.0  # a stage that has run this long prints its tenths in a pipe [s]
_KEY = re.compile(r"^[^\d(:]*")
_OF = re.compile(r"(\d[\d,]*)\s*(?:of|/)\s*(\d[\d,]*)")


def stage_key(stage: str) -> str:
    """The stage a progress text belongs to: its words before the first digit, parenthesis or
    colon (``units 33-64 of 1000`` -> ``units``), the whole text if that leaves nothing."""
    key = _KEY.match(stage).group(0).strip(" ,;-=")  # type: ignore[union-attr]
    return key or stage


def stage_fraction(stage: str, done: int | None, total: int | None) -> float | None:
    """How far a stage is, from ``done``/``total`` or its text's ``k of n`` / ``k/n`` (the last
    number of a range: ``units 33-64 of 1000`` is 64/1000); None when neither says."""
    if done is not None and total:
        return done / total
    m = _OF.search(stage)
    if m:
        k, n = (int(g.replace(",", "")) for g in m.groups())
        return k / n if n else None
    return None


class StageReporter:
    """A :data:`ema_cli.progress.Reporter` for one command (see the module docstring)."""

    def __init__(self, command: str, stream: TextIO | None = None,
                 tty: bool | None = None) -> None:
        self.command = command
        self.stream = stream or sys.stderr
        self.tty = self.stream.isatty() if tty is None else tty
        self.t0 = time.perf_counter()
        self.last_stage: str | None = None
        self.seen: dict[str, tuple[float, int]] = {}  # stage key -> (its first line's time,
        # the tenths printed) in a pipe
        self.pending: tuple[str, int | None] | None = None  # reported within GRACE_S (pipe)
        self.last_draw = 0.0
        self.drawn = 0  # characters of the line on screen (terminal)

    def __call__(self, stage: str, done: int | None, total: int | None, bar: bool) -> None:
        new = stage != self.last_stage
        self.last_stage = stage
        if not self.tty:
            self._pipe(stage, done, total)
            return
        if bar:  # the caller draws its own bar
            self.clear()
            return
        now = time.perf_counter()
        if not new and now - self.last_draw < REFRESH_S and done != total:
            return
        self.last_draw = now
        count = f" {done:,}/{total:,}" if done is not None and total else (
            f" {done:,}" if done is not None else "")
        text = f"{self.command}: {stage}{count} · {now - self.t0:.1f} s"
        width = _width(self.stream)
        text = text[: max(width - 1, 10)]
        self.stream.write("\r" + text + " " * max(self.drawn - len(text), 0))
        self.stream.flush()
        self.drawn = len(text)

    def _pipe(self, stage: str, done: int | None, total: int | None) -> None:
        """A pipe: a stage's first line, then at most one per tenth once it has run LONG_S."""
        key = stage_key(stage)
        now = time.perf_counter()
        frac = stage_fraction(stage, done, total)
        tenth = int(min(max(frac, 0.0), 1.0) * 10 + 1e-9) if frac is not None else 0
        if key in self.seen:
            started, shown = self.seen[key]
            if frac is not None and tenth > shown and now - started >= LONG_S:
                self.seen[key] = (started, tenth)
                count = f" {done:,}/{total:,}" if done is not None and total else ""
                self.stream.write(f"{self.command}: {stage}{count} ({frac:.0%})\n".replace(
                    "%)", " %)"))
                self.stream.flush()
            return
        if now - self.t0 < GRACE_S:  # said later, if it lasts
            self.pending = (stage, total)
            return
        if self.pending is not None and stage_key(self.pending[0]) != key:
            self._line(*self.pending)
        self.pending = None
        self._line(stage, total, tenth)

    def _line(self, stage: str, total: int | None, tenth: int = 0) -> None:
        self.seen[stage_key(stage)] = (time.perf_counter(), tenth)
        count = f" ({total:,})" if total else ""
        self.stream.write(f"{self.command}: {stage}{count} ...\n")
        self.stream.flush()

    def clear(self) -> None:
        """Erase the terminal line (before the command prints its results)."""
        if self.tty and self.drawn:
            self.stream.write("\r" + " " * self.drawn + "\r")
            self.stream.flush()
            self.drawn = 0


def _width(stream: TextIO) -> int:
    import os
    import shutil

    cols = os.environ.get("COLUMNS", "")
    if cols.isdigit() and int(cols) > 0:
        return int(cols)
    try:
        return os.get_terminal_size(stream.fileno()).columns
    except (OSError, ValueError, AttributeError):
        return shutil.get_terminal_size().columns


class _ClearFirst:
    """A rich render hook: erase the progress line before the console prints anything."""

    def __init__(self, reporter: StageReporter) -> None:
        self.reporter = reporter

    def process_renderables(self, renderables: list) -> list:  # type: ignore[type-arg]
        self.reporter.clear()
        return renderables


def _took(reporter: StageReporter, err_console: Any) -> None:
    """The actual time at the end of a command that announced an estimate or ran long."""
    from ema_cli.progress import finished_line

    done = finished_line()
    if done:
        reporter.clear()
        err_console.print(done, highlight=False, markup=False)


def stages(command: str, console: Any, err_console: Any):  # type: ignore[no-untyped-def]
    """A context manager for one command: installs a :class:`StageReporter` as the progress
    reporter (announcements go to ``err_console``) and erases its line whenever the command's
    consoles print, and at the end."""
    import contextlib

    from rich.console import RenderHook

    from ema_cli.progress import reporting

    @contextlib.contextmanager
    def run():  # type: ignore[no-untyped-def]
        reporter = StageReporter(command)
        hook = type("ClearHook", (_ClearFirst, RenderHook), {})(reporter)
        for c in (console, err_console):
            c.push_render_hook(hook)
        try:
            with reporting(reporter, lambda text: err_console.print(text, highlight=False,
                                                                    markup=False)):
                try:
                    yield reporter
                except Exception as exc:  # a verdict's exit code (FAIL 1, INCONCLUSIVE 3)
                    if getattr(exc, "exit_code", None) in (1, 3):
                        _took(reporter, err_console)
                    raise
                _took(reporter, err_console)
        finally:
            reporter.clear()
            for c in (console, err_console):
                c.pop_render_hook()

    return run()
