"""The production yield (``ema yield``): sampled units through the acceptance battery.

Every sampled unit is the spec's actuator with its sampled values set on top, exactly as
``ema acceptance SPEC --set actuator.PATH=VALUE`` would build it (the spec's per-test ``set:``
still applies on top), and runs every test of the spec. Units run in blocks; inside a block,
each test runs all of the block's units in the same kernel batches
(:func:`ema_cli.acceptance.kinds.run_units`), and a unit's result is bit for bit its result
alone. A block is one row per unit: the sampled values, every measured value (in its limit's
unit), every verdict, the normalised margin to each limit, each test's verdict and the unit's.

The normalised margin of a value ``v`` to a limit is ``(v - min) / |min|`` or
``(max - v) / |max|`` (the smaller of the two when both are set; a limit of 0 divides by 1):
positive inside the limit, negative outside, in shares of the limit. A bound decides a verdict
only when wholly on one side (``acceptance.verdict.judge``); its margin is then the one of its
edge nearest the limit. INCONCLUSIVE values have no margin (NaN).
"""

from __future__ import annotations

import math
import time
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ema_cli.errors import EmaError

if TYPE_CHECKING:
    import pandas as pd

    from ema_cli.acceptance.verdict import Verdict
    from ema_cli.config.acceptance import AcceptanceSpec
    from ema_cli.production.tolerances import Tolerances

PASS, FAIL, INCONCLUSIVE = "PASS", "FAIL", "INCONCLUSIVE"
TASK_UNITS = 16
"""Fewest units one task holds on the remote backends (loky, dask): each test batches a task's
units in the kernel's SIMD lanes (16), and a smaller batch pays the test's fixed work for
fewer units. Measured (reference battery, one numba thread, 2 shared cores under load): 6.8 s
for 1 unit, 2.07 s per unit in 8, 1.56 in 16, 1.36 in 32."""
TASKS_PER_WORKER = 2  # tasks per worker a run is cut into at least, when units allow [-]


@dataclass(frozen=True)
class Row:
    """One limit of the battery: a test's metric at one condition, its limit (``lo``..``hi``
    in ``unit``; None: not set) and the column label (``test/metric``, with ``@ condition``
    when the metric is measured at several)."""

    test: str
    metric: str
    condition: str
    unit: str
    lo: float | None
    hi: float | None
    label: str

    @property
    def limit_text(self) -> str:
        """``>= 5 Hz``, ``<= 80 ms`` or ``5..10 Hz``."""
        if self.lo is not None and self.hi is not None:
            return f"{self.lo:g}..{self.hi:g} {self.unit}"
        return (f">= {self.lo:g} {self.unit}" if self.lo is not None
                else f"<= {self.hi:g} {self.unit}")


@dataclass
class YieldPlan:
    """What a yield run is: the spec (with ``--set`` overrides applied), where its relative
    paths start, the tests, the tolerances, the sampling (seed, method)."""

    spec: AcceptanceSpec
    spec_source: Any
    folder: Path | None
    overrides: list[tuple[str, Any]]
    names: list[str]
    tolerances: Tolerances
    seed: int
    method: str
    rows: list[Row] = field(default_factory=list)

    def values(self, start: int, stop: int) -> np.ndarray:
        """The sampled values of units ``start..stop-1`` [n, d], in each path's unit."""
        return self.tolerances.sample(start, stop, self.seed, self.method)


def unit_pairs(plan: YieldPlan, row: np.ndarray) -> list[tuple[str, Any]]:
    """One unit's overrides of the spec (``actuator.plant.kL``, ...)."""
    return [(f"actuator.{path}", float(v)) for path, v in plan.tolerances.pairs(row)]


def unit_setups(plan: YieldPlan, values: np.ndarray) -> list[dict[str, Any]]:
    """Each unit's setups: test -> (SI parameters, dt), as ``ema acceptance`` resolves them
    with the unit's values as ``--set actuator.PATH=VALUE``."""
    from ema_cli.acceptance.setup import test_setups
    from ema_cli.config.acceptance import AcceptanceSpec
    from ema_cli.config.loader import load_config

    out = []
    for k, row in enumerate(values):
        try:
            sp = load_config(plan.spec_source, plan.overrides + unit_pairs(plan, row),
                             AcceptanceSpec)
            out.append(test_setups(sp, plan.names, plan.folder)[1])
        except EmaError as exc:
            vals = ", ".join(f"{p}={v:.6g}" for p, v in plan.tolerances.pairs(row))
            raise EmaError(f"a sampled unit ({vals}) is not a valid actuator: {exc} (narrow "
                           f"the tolerance, e.g. a truncnormal law, row {k})") from None
    return out


def margin(v: Verdict, lo: float | None, hi: float | None) -> float:
    """The normalised margin of a verdict row to its limit (module docstring) [-]."""
    if v.result == INCONCLUSIVE:
        return math.nan

    def at(x: float) -> float:
        m = math.inf
        if lo is not None:
            m = min(m, (x - lo) / (abs(lo) or 1.0))
        if hi is not None:
            m = min(m, (hi - x) / (abs(hi) or 1.0))
        return m

    if v.measured:
        return at(v.value)
    ends = [at(x) for x in (v.lower, v.upper) if math.isfinite(x)]
    if not ends:
        return math.nan
    return min(ends) if v.result == PASS else max(ends)


def _rows_of(rows: list[Verdict]) -> list[Row]:
    """The limit rows of one unit's verdicts, labelled."""
    per = {}
    for v in rows:
        per.setdefault((v.test, v.metric), []).append(v.condition)
    return [Row(v.test, v.metric, v.condition, v.unit, v.min, v.max,
                f"{v.test}/{v.metric}" + (f" @ {v.condition}"
                                          if len(per[(v.test, v.metric)]) > 1 else ""))
            for v in rows]


def run_block(plan: YieldPlan, start: int, values: np.ndarray,
              only: Sequence[str] | None = None,
              what: str | None = None) -> tuple[pd.DataFrame, dict[str, float]]:
    """Units ``start..start+len(values)-1`` with the sampled ``values`` through every test
    (``only``: those tests; ``what``: the progress label) -> (one row per unit: ``unit``, the
    values by path, per limit ``LABEL [UNIT]``, ``LABEL result``, ``LABEL margin``, per test
    ``TEST result``, ``result``; wall time per test [s])."""
    import pandas as pd

    from ema_cli.acceptance.kinds import run_units
    from ema_cli.acceptance.verdict import overall, verdicts
    from ema_cli.progress import report

    names = [n for n in plan.names if only is None or n in only]
    setups = unit_setups(plan, values)
    per_unit: list[list[Verdict]] = [[] for _ in range(len(values))]
    walls = {}
    for j, name in enumerate(names):
        report(f"{what or f'units {start + 1}-{start + len(values)}'} ({len(values)} "
               f"units): test {j + 1}/{len(names)} {name}")
        test = plan.spec.tests[name]
        dts = {s[name][1] for s in setups}
        if len(dts) != 1:
            raise EmaError(f"tests.{name}: the sampled units have different time steps "
                           f"{sorted(dts)}; a tolerance may not change simulation.dt_s")
        t0 = time.perf_counter()
        runs = run_units(name, test, [s[name][0] for s in setups], dts.pop())
        walls[name] = time.perf_counter() - t0
        for k, run in enumerate(runs):
            per_unit[k] += verdicts(run, test.limits)
    rows = _rows_of(per_unit[0])
    if only is None and plan.rows and [(r.test, r.metric, r.condition) for r in rows] != \
            [(r.test, r.metric, r.condition) for r in plan.rows]:
        raise EmaError(f"units {start}..{start + len(values) - 1}: the battery measured other "
                       "conditions than the earlier blocks' (a resumed run of another spec?)")
    for k, vs in enumerate(per_unit):
        if [(v.test, v.metric, v.condition) for v in vs] != \
                [(r.test, r.metric, r.condition) for r in rows]:
            raise EmaError(f"unit {start + k}: its battery measured other conditions than "
                           "the first unit's (a tolerance changed a test's conditions)")
    data: dict[str, Any] = {"unit": np.arange(start, start + len(values))}
    for j, path in enumerate(plan.tolerances.paths):
        data[path] = values[:, j]
    for i, r in enumerate(rows):
        data[f"{r.label} [{r.unit}]"] = [vs[i].value for vs in per_unit]
        data[f"{r.label} result"] = [vs[i].result for vs in per_unit]
        data[f"{r.label} margin"] = [margin(vs[i], r.lo, r.hi) for vs in per_unit]
        # a value outside the test's range is only a bound: which, and its lower end
        data[f"{r.label} measured"] = [bool(vs[i].measured) for vs in per_unit]
        data[f"{r.label} lower"] = [float(vs[i].lower) for vs in per_unit]
    for name in names:
        data[f"{name} result"] = [overall([v.result for v in vs if v.test == name])
                                  for vs in per_unit]
    data["result"] = [overall([v.result for v in vs]) for vs in per_unit]
    if only is None and not plan.rows:
        plan.rows = rows
    return pd.DataFrame(data), walls


@dataclass(frozen=True)
class Rate:
    """A pass rate: ``n_pass`` of ``n`` units, ``n_fail``, ``n_inconclusive`` (never counted as
    passes), the point estimate and its exact (Clopper-Pearson) interval at ``level``."""

    n: int
    n_pass: int
    n_fail: int
    n_inconclusive: int
    level: float

    @property
    def value(self) -> float:
        return self.n_pass / self.n if self.n else math.nan

    @property
    def interval(self) -> tuple[float, float]:
        from ema_cli.production.stats import clopper_pearson

        return clopper_pearson(self.n_pass, self.n, self.level)

    @property
    def halfwidth(self) -> float:
        lo, hi = self.interval
        return (hi - lo) / 2

    def to_dict(self) -> dict[str, Any]:
        lo, hi = self.interval
        return {"yield": self.value, "ci_low": lo, "ci_high": hi, "n_pass": self.n_pass,
                "n": self.n, "n_fail": self.n_fail, "n_inconclusive": self.n_inconclusive}


def rate(results: Sequence[str], level: float) -> Rate:
    """The pass rate of a column of verdicts."""
    r = list(results)
    return Rate(len(r), r.count(PASS), r.count(FAIL), r.count(INCONCLUSIVE), level)


@dataclass
class BlockRun:
    """Units ``start..start+len(frame)-1`` run (one task, or a whole checkpoint block):
    their rows (:func:`run_block`), the limit rows measured, the wall time per test [s] and
    the kernel's work (time [s], lane-steps) where they ran."""

    start: int
    frame: pd.DataFrame
    rows: list[Row]
    walls: dict[str, float]
    kernel_s: float
    lane_steps: int


def run_task(plan: YieldPlan, start: int, values: np.ndarray, what: str | None = None
             ) -> BlockRun:
    """Worker side of :func:`unit_blocks`: :func:`run_block` (``what``: its progress label)
    and the kernel's work."""
    from ema_cli.sim.runner import TALLY

    k0, s0 = TALLY["kernel_s"], TALLY["lane_steps"]
    df, walls = run_block(plan, start, values, what=what)
    return BlockRun(start, df, list(plan.rows), walls, TALLY["kernel_s"] - k0,
                    TALLY["lane_steps"] - s0)


def task_units(units: int, block: int, workers: int, remote: bool) -> int:
    """Units per task: the whole checkpoint ``block`` in this process (the kernel's threads
    share it); on ``workers`` remote workers, ``units`` to run cut into at least
    :data:`TASKS_PER_WORKER` tasks per worker, each of :data:`TASK_UNITS` or more."""
    if not remote:
        return block
    return max(1, min(block, max(TASK_UNITS, math.ceil(units / (TASKS_PER_WORKER
                                                                 * workers)))))


def unit_blocks(plan: YieldPlan, have: int, n: int, block: int) -> Iterator[BlockRun]:
    """Units ``have..n-1`` in checkpoint blocks of ``block`` units, each cut into tasks for the
    current executor (``sweep.executor.current``; :func:`task_units`) -> each whole block in
    order, as soon as its tasks are done (tasks of later blocks run meanwhile: a caller that
    stops, a target reached, cancels them). A unit's values depend only on its index, its
    results only on its values: every backend and task size gives the same blocks."""
    import pandas as pd

    from ema_cli.sweep.executor import Task, current

    ex = current()
    per = task_units(n - have, block, ex.workers, ex.remote)

    def tasks() -> Iterator[Task]:
        for b0 in range(have, n, block):
            b1 = min(b0 + block, n)
            parts = math.ceil((b1 - b0) / per)
            cuts = [b0 + (b1 - b0) * k // parts for k in range(parts + 1)]
            for a, b in zip(cuts[:-1], cuts[1:], strict=True):
                yield Task(run_task, (plan, a, plan.values(a, b)), f"units {a}-{b - 1}")

    results = ex.map(tasks())
    try:
        for b0 in range(have, n, block):
            b1 = min(b0 + block, n)
            parts: list[BlockRun] = []
            while sum(len(p.frame) for p in parts) < b1 - b0:
                part = next(results)[1]
                if not plan.rows:
                    plan.rows = part.rows
                elif [(r.test, r.metric, r.condition) for r in part.rows] != [
                        (r.test, r.metric, r.condition) for r in plan.rows]:
                    raise EmaError(f"units {part.start}..{part.start + len(part.frame) - 1}: "
                                   "the battery measured other conditions than the earlier "
                                   "blocks' (a resumed run of another spec?)")
                parts.append(part)
            walls: dict[str, float] = {}
            for p in parts:
                for key, v in p.walls.items():
                    walls[key] = walls.get(key, 0.0) + v
            yield BlockRun(b0, pd.concat([p.frame for p in parts], ignore_index=True),
                           plan.rows, walls, sum(p.kernel_s for p in parts),
                           sum(p.lane_steps for p in parts))
    finally:
        results.close()
