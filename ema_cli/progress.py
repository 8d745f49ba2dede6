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
_announcer: Callable[[str], None] | None = None

BIG_RUN = 10_000
"""Simulations above which a command says how many it will run and how long that may take."""
CPU_S_PER_STEP = 22e-9
"""Kernel time per simulation and integration step on one core (``sweep.cache`` measures the
same constant: 1,000 jobs x 1e5 steps in 1.1 s on 2 threads) [s]."""


def estimate(n_sims: int, n_steps: int, workers: int) -> str:
    """``98,304 simulations of 100,000 steps, ~3 min on 2 cores``: the size of a run and its
    kernel time at :data:`CPU_S_PER_STEP` (an estimate: nonlinearities, writing and figures
    add to it)."""
    seconds = n_sims * n_steps * CPU_S_PER_STEP / max(workers, 1)
    if seconds < 90:
        t = f"~{max(seconds, 1):.0f} s"
    elif seconds < 5400:
        t = f"~{seconds / 60:.0f} min"
    else:
        t = f"~{seconds / 3600:.1f} h"
    cores = f"{workers} core{'s' if workers != 1 else ''}"
    return f"{n_sims:,} simulations of {n_steps:,} steps, {t} on {cores}"


def announce(text: str) -> None:
    """Tell the user something before a long computation starts (stderr, when a command runs;
    nothing otherwise)."""
    if _announcer is not None:
        _announcer(text)


def announce_size(n_sims: int, n_steps: int, workers: int, what: str = "") -> None:
    """:func:`announce` the size and estimated time of a run above :data:`BIG_RUN` simulations
    (``what``: e.g. ``--n 256`` to say which option sets it)."""
    if n_sims > BIG_RUN:
        announce(estimate(n_sims, n_steps, workers) + (f" ({what})" if what else ""))


def report(stage: str, done: int | None = None, total: int | None = None, *,
           bar: bool = False) -> None:
    """Say that ``stage`` is running, ``done`` of ``total`` steps finished when known;
    ``bar``: the caller draws its own progress bar on a terminal (only the stage line is
    printed in a pipe)."""
    if _reporter is not None:
        _reporter(stage, done, total, bar)


@contextlib.contextmanager
def reporting(reporter: Reporter | None,
              announcer: Callable[[str], None] | None = None) -> Iterator[None]:
    """Install ``reporter`` (and ``announcer``) for the duration of a block (the previous ones
    are restored)."""
    global _reporter, _announcer
    previous, _reporter = (_reporter, _announcer), reporter
    _announcer = announcer
    try:
        yield
    finally:
        _reporter, _announcer = previous
