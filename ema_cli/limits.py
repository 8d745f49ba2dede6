"""Work limits checked before a command starts: integration steps per command and workers.

One estimate of the total work of a command (cases x integration steps, summed over its
simulations) is compared with :data:`MAX_CASE_STEPS` before anything runs; above it the command
is refused with the option or key that reduces it. Worker counts are capped at the cores this
process may use (:func:`cap_workers`), with a note, unless a cluster scheduler is given.
"""

from __future__ import annotations

import os

from ema_cli.errors import EmaError

MAX_CASE_STEPS = 100_000_000_000  # cases x integration steps one command may start [-]
"""1e11 case-steps: about half an hour of kernel time on two cores at the measured ~5.5e7
case-steps/s (README: 22 ns per step and job over the workers; docs/sensitivity.md: the bundled
Sobol study, 9.8e9 case-steps, in ~3 min). Every bundled config is far below it (the acceptance
battery ~2e8 by the same estimate, ``ema freqresp`` defaults ~3e7); a frequency response down to
1e-6 Hz (4.6e12, a day) is not."""
MAX_RUN_STEPS = 100_000_000  # integration steps of one simulated run (a pass over a log) [-]
MAX_WORKERS = 4096  # workers (--n-jobs, parallel.n_jobs) accepted at most; capped at the cores
BACKENDS = ("auto", "loky", "threads", "dask")  # the parallel backends (sweep/execute.py too)


def check_steps(total: float, what: str, reduce: str) -> None:
    """Refuse ``total`` case-steps above :data:`MAX_CASE_STEPS`: ``what`` names the work (the
    file, test or command), ``reduce`` the option or key that makes it smaller."""
    if not total <= MAX_CASE_STEPS:  # NaN and inf refused too
        raise EmaError(f"{what}: about {total:.3g} integration steps (cases x steps), more than "
                       f"the cap of {MAX_CASE_STEPS:.0e}; {reduce}")


def estimate(total: float, what: str, workers: int | None = None) -> float:
    """Announce (and record for the manifest) the estimated time of ``total`` case-steps on
    ``workers`` cores (default: all this process may use) from the cost model the cap uses
    (``progress.CPU_S_PER_STEP``): ``estimated time ~3 min: what``, when above
    ``progress.ESTIMATE_MIN_S`` -> the estimate [s]."""
    from ema_cli.progress import announce_estimate, kernel_seconds

    seconds = kernel_seconds(total, 1, cores() if workers is None else workers)
    announce_estimate(seconds, what)
    return seconds


def cores() -> int:
    """Cores this process may use."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


def cap_workers(n_jobs: int | None, what: str = "n_jobs",
                cluster: bool = False) -> tuple[int | None, str]:
    """``n_jobs`` capped at the cores available -> (the count to use, a note or ""). None and
    -1 (all cores) pass unchanged; with a cluster scheduler the count is the cluster's."""
    if n_jobs is None or n_jobs == -1 or cluster:
        return n_jobs, ""
    have = cores()
    if n_jobs > have:
        return have, (f"{what} {n_jobs} is more than the {have} cores available: using {have} "
                      "(a cluster scheduler takes more)")
    return n_jobs, ""
