"""Sweep expansion: axes -> points -> job specifications (grid or zip, plus the baseline).

Nothing here resolves parameters or runs anything: a job specification only says which value
each axis takes, in the axis unit (the paper's units for nonlinearities, SI for parameters).
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

from ema_cli.config.study import StudyConfig, SweepAxis, SweepConfig
from ema_cli.errors import EmaError
from ema_cli.model.nonlinearities import OFF, lookup


@dataclass(frozen=True)
class AxisPoint:
    """One value of one axis.

    ``target`` is the nonlinearity name as written (paper name or type@location) or the model
    parameter; ``value`` is in the axis unit (or 'off'); ``relative`` means percent of the
    baseline's peak signal at the location.
    """

    axis: int
    index: int
    target: str
    value: float | str
    is_parameter: bool
    relative: bool


@dataclass(frozen=True)
class JobSpec:
    """One job before resolution: its axis points (none for the baseline)."""

    points: tuple[AxisPoint, ...]
    baseline: bool = False


def axis_points(axis: SweepAxis, k: int) -> list[AxisPoint]:
    """The points of axis number ``k``, in order (for a list of nonlinearities: name-major)."""
    out: list[AxisPoint] = []
    for target in axis.targets:
        for value in axis.value_list(target):
            out.append(AxisPoint(k, len(out), target, value, axis.parameter is not None,
                                 axis.relative))
    return out


def count_jobs(sweep: SweepConfig) -> int:
    """Jobs the sweep expands to, baseline included (arithmetic only, nothing materialised)."""
    return sweep.n_jobs() + (1 if sweep.baseline else 0)


def check_size(sweep: SweepConfig, source: str = "config") -> int:
    """Refuse an empty sweep or one past ``sweep.max_jobs``; return the job count."""
    if not sweep.axes:
        raise EmaError(f"{source}: sweep.axes: empty sweep: give at least one axis "
                       "(nonlinearity or parameter with values, linspace or logspace)")
    n = count_jobs(sweep)
    if n > sweep.max_jobs:
        raise EmaError(f"{source}: sweep: expands to {n:,} jobs, more than sweep.max_jobs = "
                       f"{sweep.max_jobs:,}; shrink the axes or raise sweep.max_jobs")
    return n


def expand(cfg: StudyConfig, source: str = "config") -> list[JobSpec]:
    """All job specifications: the baseline first (if asked), then the grid or zip points."""
    check_size(cfg.sweep, source)
    per_axis = [axis_points(a, k) for k, a in enumerate(cfg.sweep.axes)]
    combos = zip(*per_axis, strict=True) if cfg.sweep.mode == "zip" else itertools.product(
        *per_axis)
    jobs = [JobSpec(tuple(c)) for c in combos]
    if cfg.sweep.baseline:
        jobs.insert(0, JobSpec((), baseline=True))
    return jobs


def neutral_value(target: str) -> float | str | None:
    """The 'off' value of a swept nonlinearity for the baseline; None: leave it at the default.

    Dead zones -> 0, saturations and friction -> off, compliance -> the model's stiffness.
    """
    pl = lookup(target)
    if pl.type == "deadzone":
        return 0.0
    if pl.type in ("saturation", "friction"):
        return OFF
    return None
