"""The worst case: for each limit, the unit inside the tolerance box with the smallest
normalised margin (``production.run``, module docstring).

The box: each tolerance's range (normal laws +-k sd, truncated and bounded laws their support,
``Tolerances.box``). The search, per test (only that test runs), every stage one batched call:

1. the box's corners (all of them up to :data:`MAX_CORNERS`, else that many drawn at random
   with a fixed seed), its centre, and per limit the corner its drivers point to (each
   tolerance at the edge where the sign of its SRRC, ``production.drivers``, says the margin
   is smaller: the exact worst case when the margin is monotonic in every tolerance);
2. differential evolution (``optim.de``, the project's optimiser, one kernel batch per
   generation) minimising the test's smallest margin, started from a Latin hypercube;
3. every sampled unit of the yield run that lies inside the box (free: already measured).

Per limit, the unit with the smallest margin among all of them is the worst case found; the
distinct worst units then run the whole battery, so each comes with its battery result. The
search is a global heuristic with a stated budget, not a proof: the report says how many units
each test evaluated. Margins that are monotonic in every tolerance (the common case) put the
worst case at a corner, which stage 1 covers exactly.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    import pandas as pd

    from ema_cli.production.run import YieldPlan

MAX_CORNERS = 16  # corners of the box evaluated at most per test, besides the predicted [-]


@dataclass
class WorstCase:
    """Per limit label: the worst unit's values (by path), its margin [-], the value measured
    (in the limit's unit), its verdict, and which stage found it; ``evaluated``: units run per
    test; ``battery``: the whole battery's verdict of each distinct worst unit."""

    k: float
    lower: np.ndarray
    upper: np.ndarray
    limits: dict[str, dict[str, Any]] = field(default_factory=dict)
    evaluated: dict[str, int] = field(default_factory=dict)
    battery: pd.DataFrame | None = None


def corners(lower: np.ndarray, upper: np.ndarray, seed: int,
            predicted: list[np.ndarray] | None = None) -> np.ndarray:
    """The predicted corners (``predicted``: 0/1 per tolerance, 1 the upper edge), the box's
    corners (at most :data:`MAX_CORNERS`: then a seeded random subset) and its centre last,
    without repeats [n, d]."""
    d = len(lower)
    if 2 ** d <= MAX_CORNERS:
        bits = np.array(list(itertools.product((0, 1), repeat=d)), dtype=float)
    else:
        bits = np.random.default_rng([seed, 7]).integers(0, 2, (MAX_CORNERS, d)).astype(float)
    if predicted:
        bits = np.vstack([np.array(predicted, dtype=float), bits])
    _, first = np.unique(bits, axis=0, return_index=True)
    pts = lower + bits[np.sort(first)] * (upper - lower)
    return np.vstack([pts, (lower + upper) / 2])


def predicted_corners(drivers: list[dict[str, Any]], paths: list[str],
                      labels: list[str]) -> list[np.ndarray]:
    """Per limit of ``labels`` with drivers: each tolerance at the edge its SRRC's sign points
    to (negative SRRC: a larger value eats the margin -> the upper edge)."""
    out = []
    for d in drivers:
        if d["label"] in labels:
            sign = dict(d["drivers"])
            out.append(np.array([1.0 if sign.get(p, 0.0) < 0 else 0.0 for p in paths]))
    return out


class _TestProblem:
    """DE's view of one test: the box, and the test's smallest margin of a batch of units;
    every evaluated unit's block rows kept."""

    def __init__(self, plan: YieldPlan, test: str, lower: np.ndarray, upper: np.ndarray,
                 labels: list[str]) -> None:
        self.plan, self.test, self.lower, self.upper = plan, test, lower, upper
        self.labels = labels
        self.frames: list[pd.DataFrame] = []

    def run(self, X: np.ndarray, stage: str) -> pd.DataFrame:
        from ema_cli.production.run import run_block

        df, _ = run_block(self.plan, 0, X, only=[self.test], what=f"worst case, {stage}")
        df["stage"] = stage
        self.frames.append(df)
        return df

    def evaluate(self, X: np.ndarray) -> np.ndarray:
        df = self.run(X, "search")
        m = df[[f"{lb} margin" for lb in self.labels]].to_numpy(dtype=float)
        m = np.where(np.isnan(m), np.inf, m)  # an INCONCLUSIVE value says nothing
        return m.min(axis=1)


def search_test(plan: YieldPlan, name: str, lower: np.ndarray, upper: np.ndarray,
                labels: list[str], seed: int, budget: int,
                predicted: list[np.ndarray]) -> list[pd.DataFrame]:
    """One test's search (stages 1 and 2 of the module docstring; a task of its own on the
    executor) -> the rows of every unit it evaluated (``stage``: corner or search)."""
    from ema_cli.optim.de import DEOptions, run_de

    prob = _TestProblem(plan, name, lower, upper, labels)
    prob.run(corners(lower, upper, seed, predicted), "corner")
    if budget > 0:
        pop = max(5, min(budget, 2 * len(lower)))
        run_de(prob, DEOptions(pop=pop, budget=max(budget, pop)),
               np.random.default_rng([seed, 11]))
    return prob.frames


def search(plan: YieldPlan, samples: pd.DataFrame | None, budget: int, seed: int,
           drivers: list[dict[str, Any]] | None = None) -> WorstCase:
    """The worst case of every limit of ``plan`` (module docstring); ``budget``: the units
    differential evolution may evaluate per test (0: corners and centre only). The tests'
    searches are independent: each is a task on the current executor
    (``sweep.executor.current``), results in the tests' order."""
    import pandas as pd

    from ema_cli.production.run import run_task
    from ema_cli.sweep.executor import Task, current

    tol = plan.tolerances
    lower, upper = tol.box()
    out = WorstCase(tol.k, lower, upper)
    paths = list(tol.paths)
    inside = None
    if samples is not None and len(samples):
        X = samples[paths].to_numpy(dtype=float)
        inside = samples[np.all((lower <= X) & (upper >= X), axis=1)].copy()
        inside["stage"] = "sampled"
    tests = {name: [r.label for r in plan.rows if r.test == name] for name in plan.names}
    tests = {name: labels for name, labels in tests.items() if labels}  # a test without
    ex = current()                                               # limits has no margin
    found = ex.run(Task(search_test, (plan, name, lower, upper, labels, seed, budget,
                                      predicted_corners(drivers or [], paths, labels)),
                        f"worst case of test {name}") for name, labels in tests.items())
    for name, frames in zip(tests, found, strict=True):
        seen = pd.concat(frames + ([inside] if inside is not None else []), ignore_index=True)
        out.evaluated[name] = sum(len(f) for f in frames)
        for r in (r for r in plan.rows if r.test == name):
            m = seen[f"{r.label} margin"].to_numpy(dtype=float)
            if not np.isfinite(m).any():
                out.limits[r.label] = {"found": False, "reason": "every evaluated unit was "
                                       "INCONCLUSIVE on this limit"}
                continue
            i = int(np.nanargmin(m))
            out.limits[r.label] = {
                "found": True, "test": name, "limit": r.limit_text,
                "margin": float(m[i]), "value": float(seen[f"{r.label} [{r.unit}]"].iloc[i]),
                "unit": r.unit, "result": str(seen[f"{r.label} result"].iloc[i]),
                "stage": str(seen["stage"].iloc[i]),
                "values": {p: float(seen[p].iloc[i]) for p in paths}}
    worst = [v for v in out.limits.values() if v["found"]]
    if worst:
        U = np.unique(np.array([[v["values"][p] for p in paths] for v in worst]), axis=0)
        bat = ex.run([Task(run_task, (plan, 0, U, "worst units, whole battery"),
                             "worst units, whole battery")])[0].frame
        keys = [tuple(row) for row in U]
        for v in worst:
            v["battery"] = str(bat["result"].iloc[keys.index(
                tuple(v["values"][p] for p in paths))])
        out.battery = bat
    return out
