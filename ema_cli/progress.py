"""Progress hooks: compute code says which stage it is in; the command line shows it.

Below every layer (imports nothing of the package): the GA says ``report("GA generation", k,
n)``, the sinestream ``report("frequencies", j, n)``, the acceptance battery the test it runs.
Nothing is shown unless a reporter is installed (:func:`reporting`; the CLI installs one that
draws a line on a terminal's stderr, or prints one line per stage in a pipe). A report costs a
function call when none is installed, and never changes a result.
"""

from __future__ import annotations

import contextlib
import time
from collections.abc import Callable, Iterator
from typing import Any

Reporter = Callable[[str, "int | None", "int | None", bool], None]

_reporter: Reporter | None = None
_announcer: Callable[[str], None] | None = None
_timing: dict[str, Any] = {}  # this command's estimate and start (see :func:`timing`)

BIG_RUN = 10_000
"""Simulations above which a command says how many it will run and how long that may take."""
CPU_S_PER_STEP = 22e-9
"""Kernel time per simulation and integration step on one core (``sweep.cache`` measures the
same constant: 1,000 jobs x 1e5 steps in 1.1 s on 2 threads) [s]. ``limits.MAX_CASE_STEPS`` is
set from the same figure: one cost model for the limits and the estimates."""
ESTIMATE_MIN_S = 10.0
"""A command whose estimated time is above this prints the estimate before it starts, and the
time it took at the end [s]."""


def kernel_seconds(n_sims: float, n_steps: float, workers: int) -> float:
    """The kernel time of ``n_sims`` simulations of ``n_steps`` steps on ``workers`` cores at
    :data:`CPU_S_PER_STEP` [s]."""
    return n_sims * n_steps * CPU_S_PER_STEP / max(workers, 1)


def duration(seconds: float) -> str:
    """``~40 s``, ``~3 min``, ``~1.5 h``: an estimated duration in a reader's unit."""
    if seconds < 90:
        return f"~{max(seconds, 1):.0f} s"
    if seconds < 5400:
        return f"~{seconds / 60:.0f} min"
    return f"~{seconds / 3600:.1f} h"


def elapsed(seconds: float) -> str:
    """``8.2 s``, ``3 min 12 s``, ``1 h 05 min``: a measured duration."""
    if seconds < 60:
        return f"{seconds:.1f} s"
    if seconds < 3600:
        return f"{int(seconds // 60)} min {int(seconds % 60):02d} s"
    return f"{int(seconds // 3600)} h {int(seconds % 3600 // 60):02d} min"


def announce_estimate(seconds: float, what: str, force: bool = False) -> None:
    """Record this command's estimated time [s] (added up over its parts: the manifest's
    ``timing``) and, when the total is above :data:`ESTIMATE_MIN_S`, :func:`announce` it:
    ``estimated time ~3 min: 98,304 simulations of 100,000 steps on 2 cores`` (``force``:
    whatever the time)."""
    if _timing.get("whole"):  # the command announced its whole estimate: parts say nothing
        return
    total = _timing.get("estimated_s", 0.0) + float(seconds)
    _timing["estimated_s"] = total
    _timing.setdefault("estimate_of", []).append(what)
    if total > ESTIMATE_MIN_S or force:
        _timing["announced"] = True
        announce(f"estimated time {duration(total)}: {what}")


def announce_whole_estimate(seconds: float, what: str) -> None:
    """:func:`announce_estimate` of a command that runs other commands' computations (``ema
    design``: an identification, a tuning, a battery): its estimate counts them all, so their
    own estimates are not added or announced again."""
    announce_estimate(seconds, what)
    _timing["whole"] = True


def timing() -> dict[str, Any]:
    """This command's estimate and elapsed time so far, for its manifest: ``estimated_s`` (None
    if it made none), ``elapsed_s`` since the command started, ``estimate_of`` what the estimate
    counts."""
    start = _timing.get("start")
    return {"estimated_s": _timing.get("estimated_s"),
            "elapsed_s": None if start is None else round(time.perf_counter() - start, 3),
            "estimate_of": list(_timing.get("estimate_of", []))}


def finished_line() -> str | None:
    """``took 3 min 12 s (estimated ~3 min)`` at the end of a command that announced an
    estimate; None otherwise (whether a line is printed depends on the size of the work, never
    on how loaded the machine is)."""
    t = timing()
    if t["elapsed_s"] is None or not _timing.get("announced"):
        return None
    est = t["estimated_s"]
    return f"took {elapsed(t['elapsed_s'])} (estimated {duration(est or 0.0)})"


def estimate(n_sims: int, n_steps: int, workers: int) -> str:
    """``98,304 simulations of 100,000 steps, ~3 min on 2 cores``: the size of a run and its
    kernel time at :data:`CPU_S_PER_STEP` (an estimate: nonlinearities, writing and figures
    add to it)."""
    t = duration(kernel_seconds(n_sims, n_steps, workers))
    cores = f"{workers} core{'s' if workers != 1 else ''}"
    return f"{n_sims:,} simulations of {n_steps:,} steps, {t} on {cores}"


def announce(text: str) -> None:
    """Tell the user something before a long computation starts (stderr, when a command runs;
    nothing otherwise)."""
    if _announcer is not None:
        _announcer(text)


def announce_size(n_sims: int, n_steps: int, workers: int, what: str = "") -> None:
    """Record the estimated time of a run of ``n_sims`` simulations and :func:`announce` its
    size and time when either is large: above :data:`BIG_RUN` simulations or
    :data:`ESTIMATE_MIN_S` seconds (``what``: e.g. ``--n sets it``)."""
    cores = f"{workers} core{'s' if workers != 1 else ''}"
    text = f"{n_sims:,} simulations of {n_steps:,} steps on {cores}" + (
        f" ({what})" if what else "")
    announce_estimate(kernel_seconds(n_sims, n_steps, workers), text, force=n_sims > BIG_RUN)


def report(stage: str, done: int | None = None, total: int | None = None, *,
           bar: bool = False) -> None:
    """Say that ``stage`` is running, ``done`` of ``total`` steps finished when known;
    ``bar``: the caller draws its own progress bar on a terminal (only the stage line is
    printed in a pipe)."""
    if _reporter is not None:
        _reporter(stage, done, total, bar)


StageHook = Callable[[str, "int | None", "int | None"], None]
"""The Python API's progress callback: ``on_progress(stage, done, total)`` (done and total None
when the stage does not count steps): what the command line draws, as it happens."""


@contextlib.contextmanager
def hooked(on_progress: StageHook | None, log: Callable[[str], None] | None = None
           ) -> Iterator[None]:
    """For an API call: install ``on_progress`` (and ``log`` for the announcements: the
    estimate) as the reporter for the call, unless a reporter runs already (the command line's)
    or neither is given."""
    if _reporter is not None or (on_progress is None and log is None):
        yield
        return
    hook = on_progress
    with reporting(None if hook is None else (lambda s, d, t, bar: hook(s, d, t)), log):
        yield


@contextlib.contextmanager
def reporting(reporter: Reporter | None,
              announcer: Callable[[str], None] | None = None) -> Iterator[None]:
    """Install ``reporter`` (and ``announcer``) for the duration of a block (the previous ones
    are restored)."""
    global _reporter, _announcer, _timing
    previous, _reporter = (_reporter, _announcer, _timing), reporter
    _announcer = announcer
    _timing = {"start": time.perf_counter()}
    try:
        yield
    finally:
        _reporter, _announcer, _timing = previous
