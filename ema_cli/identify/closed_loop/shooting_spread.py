"""The multiple-shooting search's starts on the executor (``sweep.executor``).

Each start's segment states and Levenberg-Marquardt path depend on that start alone (every
kernel row, every damping and every re-seat is the start's own; a batch only shares kernel
calls), so the starts can run in groups on other workers and give the same bits: the search
(:func:`ema_cli.identify.closed_loop.shooting_search.search`) runs its rounds through
:func:`start_states_spread` and :func:`lm_spread`, which cut the active starts into one group
per worker on a remote backend (loky, dask) and merge the groups back in start order; in this
process they are the batched calls themselves.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import fields
from typing import Any

import numpy as np

from ema_cli.identify.closed_loop.shooting import ShootingProblem
from ema_cli.identify.closed_loop.shooting_seat import start_states

LM = Callable[..., Any]
"""``shooting_search.lm_many`` (passed in: the search imports this module)."""

Counters = tuple[int, int, float]
"""What a worker's runs add to the problem's counters: (evaluations, kernel steps, kernel s)."""


def _counters(sp: ShootingProblem) -> Counters:
    w = sp.work  # on a worker: its copy's, so before and after differ by the worker's runs
    return w.evaluations, w.kernel_steps, w.kernel_s


def _add(sp: ShootingProblem, before: Counters, after: Counters) -> None:
    sp.work.add(after[0] - before[0], after[1] - before[1], after[2] - before[2])


def _groups(idx: np.ndarray) -> list[np.ndarray]:
    """``idx`` (start indices) in one group per worker of the current executor."""
    from ema_cli.sweep.executor import split

    return [idx[a:b] for a, b in split(idx.size)]


def _label(starts: np.ndarray, what: str) -> str:
    return f"starts {', '.join(str(int(i)) for i in starts)} ({what})"


def states_task(sp: ShootingProblem, X: np.ndarray, dt: float
                ) -> tuple[np.ndarray, Counters, Counters]:
    """Worker side: :func:`start_states` of the starts ``X`` -> V and the counters."""
    before = _counters(sp)
    return start_states(sp, X, dt), before, _counters(sp)


def start_states_spread(sp: ShootingProblem, X: np.ndarray, dt: float) -> np.ndarray:
    """:func:`start_states` of every start ``X[m, p]``, in groups on the current executor."""
    from ema_cli.sweep.executor import Task, current

    ex = current()
    groups = _groups(np.arange(X.shape[0]))
    if not ex.remote or len(groups) < 2:
        return start_states(sp, X, dt)
    out = ex.run(Task(states_task, (sp, X[g], dt), _label(g, "segment states"))
                 for g in groups)
    for _, before, after in out:
        _add(sp, before, after)
    return np.concatenate([v for v, _, _ in out])


def _part(st: Any, rows: np.ndarray) -> Any:
    """The starts ``rows`` of the ``LMState`` ``st`` as a state of their own (no history)."""
    return type(st)(**{f.name: ([] if f.name == "history" else getattr(st, f.name)[rows].copy())
                       for f in fields(st)})


def lm_task(lm_many: LM, sp: ShootingProblem, st: Any, dt: float, iters: int
            ) -> tuple[Any, Counters, Counters]:
    """Worker side: ``lm_many`` on the starts of ``st`` -> the state and the counters."""
    before = _counters(sp)
    return lm_many(sp, st, dt, iters), before, _counters(sp)


def lm_spread(lm_many: LM, sp: ShootingProblem, st: Any, dt: float, iters: int,
              progress: Callable[[int, int, float], None] | None = None) -> Any:
    """``lm_many`` (``shooting_search.lm_many``) on the active starts of the ``LMState``
    ``st``, in groups on the current executor, merged back into ``st``; ``progress(it, iters,
    best)`` and ``st.history`` after each iteration as the batched call gives them (the best
    cost over every start, a group that stopped early at its last cost)."""
    from ema_cli.sweep.executor import Task, current

    ex = current()
    act = np.flatnonzero(st.active)
    groups = _groups(act)
    if not ex.remote or len(groups) < 2:
        return lm_many(sp, st, dt, iters, progress=progress)
    out = ex.run(Task(lm_task, (lm_many, sp, _part(st, g), dt, iters),
                      _label(g, "joint fit")) for g in groups)
    for g, (part, before, after) in zip(groups, out, strict=True):
        _add(sp, before, after)
        for f in fields(st):
            if f.name != "history":
                getattr(st, f.name)[g] = getattr(part, f.name)
    n_it = max(len(part.history) for part, _, _ in out)
    for it in range(n_it):
        cost = st.cost.copy()  # the starts not in a group: as they were
        for g, (part, _, _) in zip(groups, out, strict=True):
            if part.history:
                cost[g] = part.history[min(it, len(part.history) - 1)]
        st.history.append(cost)
        if progress is not None:
            progress(it + 1, iters, float(np.min(cost)))
    return st
