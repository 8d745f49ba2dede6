"""``api.production_yield``: the share of built actuators that pass an acceptance battery,
under manufacturing tolerances and wear (``ema yield``)."""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ema_cli.api._inputs import ConfigSource, Overrides, base_dir, folder_arg, override_pairs
from ema_cli.errors import EmaError

if TYPE_CHECKING:
    import pandas as pd
    from matplotlib.figure import Figure

    from ema_cli.production.run import Rate, YieldPlan
    from ema_cli.production.worst import WorstCase

COMMAND = "yield"
METHODS = ("random", "sobol")
DEFAULT_BLOCK = 100  # units per block: one checkpoint, every test batched over them [-]
WORST_BUDGET = 48  # units differential evolution evaluates per test in the worst case [-]


@dataclass
class YieldResult:
    """A yield run: the plan (spec, tolerances, sampling), ``samples`` (one row per unit:
    values, measured values, verdicts, margins), the pass rates at confidence ``level``
    (``overall``, per test, per limit), the drivers of each limit, the worst case, the
    history of the estimate after each block, timings; ``folder``: where the run was
    checkpointed (None: nothing written yet)."""

    plan: YieldPlan
    samples: pd.DataFrame
    level: float
    settings: dict[str, Any]
    history: list[dict[str, Any]]
    timings: dict[str, float]
    stop_reason: str
    drivers: list[dict[str, Any]] = field(default_factory=list)
    worst: WorstCase | None = None
    folder: Path | None = None
    resumed_units: int = 0
    inputs: Any = None
    """What the folder's marker records (``report.run_inputs.RunInputs``)."""
    execution: dict[str, Any] = field(default_factory=dict)
    """Where the units ran (``sweep.executor.Executor.describe``: backend, workers, retries)."""

    @property
    def overall(self) -> Rate:
        from ema_cli.production.run import rate

        return rate(self.samples["result"], self.level)

    @property
    def tests(self) -> dict[str, Rate]:
        from ema_cli.production.run import rate

        return {n: rate(self.samples[f"{n} result"], self.level) for n in self.plan.names}

    @property
    def limits(self) -> dict[str, Rate]:
        from ema_cli.production.run import rate

        return {r.label: rate(self.samples[f"{r.label} result"], self.level)
                for r in self.plan.rows}

    @property
    def title(self) -> str:
        return f"{self.plan.spec.name}: production yield ({self.plan.spec.actuator.label()})"

    @property
    def metrics(self) -> pd.DataFrame:
        """One row per test and one for the whole battery: yield, interval, counts."""
        import pandas as pd

        rows = [{"test": "(battery)", **self.overall.to_dict()}]
        rows += [{"test": n, **r.to_dict()} for n, r in self.tests.items()]
        return pd.DataFrame(rows)

    def to_pandas(self, form: str = "wide") -> pd.DataFrame:
        """samples.parquet: one row per unit (``wide``), or ``long`` (unit, column, value)."""
        from ema_cli.api.result import long_form

        return long_form(self.samples, form, ["unit"])

    def to_json(self) -> dict[str, Any]:
        """yield.json: overall, tests, limits, drivers, worst case, settings, timings."""

        out: dict[str, Any] = {
            "overall": self.overall.to_dict(),
            "tests": {n: r.to_dict() for n, r in self.tests.items()},
            "limits": {lb: {**r.to_dict(), "limit": row.limit_text, "test": row.test,
                            "metric": row.metric, "condition": row.condition}
                       for (lb, r), row in zip(self.limits.items(), self.plan.rows,
                                               strict=True)},
            "level": self.level, "stop_reason": self.stop_reason,
            "drivers": self.drivers, "settings": self.settings, "timings_s": self.timings,
            "history": self.history, "tolerances": self.plan.tolerances.describe()}
        if self.worst is not None:
            out["worst_case"] = {"k": self.worst.k, "box": {
                p: [float(a), float(b)] for p, a, b in zip(
                    self.plan.tolerances.paths, self.worst.lower, self.worst.upper,
                    strict=True)}, "evaluated_per_test": self.worst.evaluated,
                "limits": self.worst.limits}
        return out

    def plot(self, which: str = "convergence") -> Figure | list[Figure]:
        """``convergence`` (the yield and its interval as N grows), ``distributions`` (per
        test, each limit's measured values against the limit: a list of figures)."""
        from ema_cli.report import yield_report

        if which == "convergence":
            return yield_report.convergence_figure(self)
        if which == "distributions":
            return [yield_report.distribution_figure(self, n) for n in self.plan.names]
        raise EmaError(f"plot: which must be 'convergence' or 'distributions', got {which!r}")

    def save(self, folder: str | Path | None = None) -> Path:
        """Write yield.json, samples.parquet, yield.md, the figures, the spec and tolerance
        snapshots and a manifest (into the checkpoint folder when there is one and ``folder``
        is None or the same)."""
        from ema_cli.report.rundir import FINISHED, finish_output, prepare_output, read_marker
        from ema_cli.report.yield_report import write_yield

        target = folder_arg(folder)
        if self.folder is not None and (target is None or Path(target) == self.folder):
            out = self.folder
            state = FINISHED if (read_marker(out) or {}).get("finished") is True else ""
        else:
            out, state = prepare_output(COMMAND, self.plan.spec.name,
                                        self.inputs or self.settings["fingerprint"], target)
        if state != FINISHED:  # the finished run of these inputs is kept as it is
            write_yield(out, self)
            finish_output(out)
        self.folder = out
        return out


def _plan(spec: ConfigSource, tolerances: ConfigSource, overrides: Overrides, seed: int,
          method: str, k: float | None) -> YieldPlan:
    from ema_cli.acceptance.setup import test_setups
    from ema_cli.config.acceptance import AcceptanceSpec
    from ema_cli.config.loader import load_config
    from ema_cli.production.run import YieldPlan
    from ema_cli.production.tolerances import load_tolerances

    if spec is None:
        raise EmaError("yield needs a spec (an acceptance spec such as configs/acceptance.yaml)")
    if tolerances is None:
        raise EmaError("yield needs a tolerance file (e.g. configs/tolerances.yaml)")
    if method not in METHODS:
        raise EmaError(f"method must be one of {', '.join(METHODS)}, got {method!r}")
    pairs = override_pairs(overrides)
    sp = load_config(spec, pairs, AcceptanceSpec)
    tol = load_tolerances(tolerances, k=k)
    writes = tol.model_parameters()  # model parameter -> the tolerance path setting it
    clash = [(f"plant.{k}", writes[k]) for k in sp.actuator.plant if k in writes] + [
        (f"nonlinearities.{k}", f"nonlinearities.{k}") for k in sp.actuator.nonlinearities
        if f"nonlinearities.{k}" in tol.paths]
    if clash:
        raise EmaError(f"tolerances: {clash[0][1]} sets what the spec's actuator sets "
                       f"(actuator.{clash[0][0]}); the tolerance would replace it in every "
                       "unit: remove one of the two")
    test_setups(sp, list(sp.tests), base_dir(spec))  # the nominal battery is measurable
    plan = YieldPlan(sp, spec if not isinstance(spec, Path) else str(spec), base_dir(spec),
                     pairs, list(sp.tests), tol, seed, method)
    plan.values(0, 0)  # the seed and the method checked before any folder is made
    return plan


def _check_size(plan: YieldPlan, n: int, block: int) -> None:
    """Refuse more units than the sampler numbers, or a block above the case-step cap of one
    kernel workload (``limits.MAX_CASE_STEPS``: a block is what one checkpoint holds); announce
    a large run's size and time."""
    from ema_cli.acceptance.setup import test_setups
    from ema_cli.limits import check_steps, cores
    from ema_cli.production.laws import MAX_UNITS
    from ema_cli.progress import announce_size

    if n > MAX_UNITS:
        raise EmaError(f"n must be at most {MAX_UNITS} (2**30) units, got {n}")
    _, setups = test_setups(plan.spec, plan.names, plan.folder)
    per_unit = sum(plan.spec.tests[t].sim_seconds() / setups[t][1] for t in plan.names)
    check_steps(min(block, n) * per_unit, f"block: {min(block, n)} units of this battery",
                "run fewer units per block")
    announce_size(n, int(per_unit), cores(), "--n")


def _fingerprint(plan: YieldPlan) -> str:
    from ema_cli.hashing import content_hash

    return content_hash({"spec": plan.spec.model_dump(mode="json", by_alias=True),
                         "tolerances": plan.tolerances.to_dict(), "seed": plan.seed,
                         "method": plan.method}, 16)


def production_yield(spec: ConfigSource, tolerances: ConfigSource, overrides: Overrides = None,
                     *, n: int = 200, seed: int = 0, level: float = 0.95,
                     target_halfwidth: float | None = None, method: str = "random",
                     k: float | None = None, block: int = DEFAULT_BLOCK,
                     worst_budget: int | None = WORST_BUDGET, drivers: bool = True,
                     out: str | Path | None = None, checkpoint: bool = False,
                     progress: Callable[[dict[str, Any]], None] | None = None,
                     backend: str | None = None, n_jobs: int | None = None,
                     scheduler: str | None = None) -> YieldResult:
    """The yield of the battery ``spec`` over units drawn from ``tolerances`` (a YAML file or a
    dict: ``production.tolerances``), ``overrides`` being dotted paths of the spec.

    ``n`` units (with ``target_halfwidth``: units in blocks until the overall interval's half
    width is at most that, ``n`` the cap), drawn by ``method`` (``random`` or scrambled
    ``sobol``) from ``seed``: unit i's values depend only on (seed, i, method, the file).
    ``level``: the intervals' confidence. ``k``: the worst-case box in sd (default the file's,
    3); ``worst_budget``: units differential evolution evaluates per test (None: no worst-case
    search). ``checkpoint``: each finished block is written into the output folder (``out``,
    or a new one under results/yield/) and an interrupted run of the same inputs resumes from
    it. ``progress(state)`` is called after each block with the counts and the interval.
    ``backend`` (threads, loky, dask; None: this process's threads), ``n_jobs`` (workers) and
    ``scheduler`` (dask) say where the units and the worst-case searches run
    (``sweep.executor``): the results are the same bits on every backend, and a run
    checkpointed on one resumes on any other."""
    from ema_cli.api._inputs import backend_args, callable_arg

    callable_arg(progress, "progress")
    n_jobs = backend_args(backend, n_jobs, scheduler)
    for name, v, lo in (("n", n, 1), ("block", block, 1)):
        if isinstance(v, bool) or not isinstance(v, int) or v < lo:
            raise EmaError(f"{name} must be an integer >= {lo}, got {v!r}")
    if not (isinstance(level, float | int) and 0.5 <= float(level) < 1.0):
        raise EmaError(f"level must be in [0.5, 1), got {level!r}")
    if target_halfwidth is not None and not (0.0 < float(target_halfwidth) < 0.5):
        raise EmaError(f"target_halfwidth must be in (0, 0.5), got {target_halfwidth!r}")
    if worst_budget is not None and (isinstance(worst_budget, bool)
                                     or not isinstance(worst_budget, int) or worst_budget < 0):
        raise EmaError(f"worst_budget must be an integer >= 0 or None, got {worst_budget!r}")
    plan = _plan(spec, tolerances, overrides, seed, method, k)
    _check_size(plan, n, block)
    fp = _fingerprint(plan)
    settings = {"n": n, "seed": seed, "method": method, "level": float(level),
                "target_halfwidth": target_halfwidth, "k": plan.tolerances.k, "block": block,
                "worst_budget": worst_budget, "fingerprint": fp,
                "overrides": [[a, b] for a, b in plan.overrides]}
    from ema_cli.report.run_inputs import run_inputs

    inputs = run_inputs(plan.spec, sets=plan.overrides,
                        parts={"tolerances": plan.tolerances.to_dict()},
                        options={"n": n, "seed": seed, "method": method, "ci": float(level),
                                 "target_halfwidth": target_halfwidth, "k": plan.tolerances.k,
                                 "block": block, "worst_budget": worst_budget,
                                 "drivers": drivers})
    from ema_cli.sweep.executor import executing

    with executing(backend, n_jobs, scheduler) as ex:  # a cluster out of reach: before any
        res = _checkpointed(plan, settings, inputs, out, checkpoint, n, level,  # folder
                            target_halfwidth, block, worst_budget, drivers, progress)
        res.execution = ex.describe()
    res.inputs = inputs
    return res


def _checkpointed(plan: YieldPlan, settings: dict[str, Any], inputs: Any, out: Any,
                  checkpoint: bool, n: int, level: float, target_halfwidth: float | None,
                  block: int, worst_budget: int | None, drivers: bool, progress: Any
                  ) -> YieldResult:
    """The run, checkpointed in its folder (``checkpoint``: an unfinished run of the same
    inputs there resumes from its finished blocks)."""
    folder, done = None, None
    if checkpoint:
        from ema_cli.report.rundir import FINISHED, NEW, prepare_output
        from ema_cli.report.yield_report import read_blocks, write_plan

        folder, state = prepare_output(COMMAND, plan.spec.name, inputs, folder_arg(out))
        done, rows = read_blocks(folder) if state != NEW else (None, None)
        if done is not None and len(done) > n:  # asked for fewer than were run: the first n
            done = done.iloc[:n].reset_index(drop=True)
        if done is not None:
            from ema_cli.progress import announce

            announce(f"resuming the run in {folder}: {len(done)} units already done")
        if rows:
            plan.rows = rows
        if state != FINISHED:
            write_plan(folder, plan, settings)
    return _run(plan, settings, folder, done, n, level, target_halfwidth, block, worst_budget,
                drivers, progress)


def _run(plan: YieldPlan, settings: dict[str, Any], folder: Path | None,
         done: pd.DataFrame | None, n: int, level: float, target: float | None, block: int,
         worst_budget: int | None, drivers: bool, progress: Any) -> YieldResult:
    import pandas as pd

    from ema_cli.production.run import rate, unit_blocks
    from ema_cli.progress import report

    t0 = time.perf_counter()
    frames = [] if done is None else [done]
    have = 0 if done is None else len(done)

    def estimate(r: Rate, elapsed: float | None) -> dict[str, Any]:
        lo, hi = r.interval
        return {"n": r.n, "n_pass": r.n_pass, "n_fail": r.n_fail,
                "n_inconclusive": r.n_inconclusive, "yield": r.value, "ci_low": lo,
                "ci_high": hi, "elapsed_s": elapsed}

    # the estimates after each block an earlier, interrupted run finished, as a whole run has
    # them (their times are that run's: not known)
    history = [estimate(rate(done["result"].iloc[:m], level), None)
               for m in range(block, have, block)] if done is not None else []
    walls: dict[str, float] = {}
    kernel_s, lane_steps = 0.0, 0
    stop = f"n = {n} units sampled"
    blocks = unit_blocks(plan, have, n, block)
    try:
        while True:
            current = pd.concat(frames, ignore_index=True) if frames else None
            if current is not None and len(current):
                r = rate(current["result"], level)
                state = estimate(r, time.perf_counter() - t0)
                if not history or history[-1]["n"] != r.n:
                    history.append(state)
                    if progress is not None:
                        progress(state)
                if target is not None and r.halfwidth <= target:
                    stop = (f"the interval's half width {r.halfwidth:.4f} reached the target "
                            f"{target:g} at n = {r.n}")
                    break
            if have >= n:
                if target is not None:
                    stop = (f"the cap n = {n} was reached before the half width reached "
                            f"{target:g}")
                break
            report(f"units {have + 1}-{min(have + block, n)} of {n}")
            run = next(blocks)
            for key, v in run.walls.items():
                walls[key] = walls.get(key, 0.0) + v
            kernel_s, lane_steps = kernel_s + run.kernel_s, lane_steps + run.lane_steps
            if folder is not None:
                from ema_cli.report.yield_report import write_block

                write_block(folder, have, run.frame, plan.rows)
            frames.append(run.frame)
            have += len(run.frame)
    finally:
        blocks.close()
    samples = pd.concat(frames, ignore_index=True)
    timings = {"yield_s": time.perf_counter() - t0,
               # the units' kernel work, wherever it ran: its throughput is lane_steps / kernel_s
               "kernel_s": kernel_s, "kernel_lane_steps": lane_steps,
               **{f"test {k}": v for k, v in walls.items()}}
    res = YieldResult(plan, samples, float(level), settings, history, timings, stop,
                      folder=folder, resumed_units=0 if done is None else len(done))
    if drivers:
        from ema_cli.production.drivers import rank_drivers

        res.drivers = rank_drivers(samples, list(plan.tolerances.paths), plan.rows)
    if worst_budget is not None:
        from ema_cli.production.worst import search

        report("worst case")
        t1 = time.perf_counter()
        res.worst = search(plan, samples, worst_budget, plan.seed, res.drivers)
        res.timings["worst_case_s"] = time.perf_counter() - t1
    return res
