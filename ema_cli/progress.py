"""Progress hooks: compute code says which stage it is in; the command line shows it.

Below every layer (imports nothing of the package): the GA says ``report("GA generation", k,
n)``, the sinestream ``report("frequencies", j, n)``, the acceptance battery the test it runs.
Nothing is shown unless a reporter is installed (:func:`reporting`; the CLI installs one that
draws a line on a terminal's stderr, or prints one line per stage in a pipe). A report costs a
function call when none is installed, and never changes a result.
"""

from __future__ import annotations

import contextlib
from collections.abc import Callable, Iterator

Reporter = Callable[[str, "int | None", "int | None", bool], None]

_reporter: Reporter | None = None


def report(stage: str, done: int | None = None, total: int | None = None, *,
           bar: bool = False) -> None:
    """Say that ``stage`` is running, ``done`` of ``total`` steps finished when known;
    ``bar``: the caller draws its own progress bar on a terminal (only the stage line is
    printed in a pipe)."""
    if _reporter is not None:
        _reporter(stage, done, total, bar)


@contextlib.contextmanager
def reporting(reporter: Reporter | None) -> Iterator[None]:
    """Install ``reporter`` for the duration of a block (the previous one is restored)."""
    global _reporter
    previous, _reporter = _reporter, reporter
    try:
        yield
    finally:
        _reporter = previous
