"""``api.tune``: tune the controller gains and compensators over scenarios (``ema tune``)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ema_cli.api._inputs import ConfigSource, Overrides, base_dir, folder_arg, override_pairs
from ema_cli.api.result import long_form
from ema_cli.errors import EmaError

if TYPE_CHECKING:
    import pandas as pd
    from matplotlib.figure import Figure

    from ema_cli.config.tune import TuneConfig
    from ema_cli.tune.run import TuneOutcome

RECORD_DT_S = 1.0e-4  # interval of the recorded before/after signals [s]
BOUND_SHARE = 0.01  # a tuned variable this close to a bound (share of its range) is flagged [-]
CONTROLLERS = ("reference", "before", "after")
"""The three controllers the report compares: the default controller (no scenario
compensators), the start (scenario compensators, variables at the actuator's values) and the
tuned one."""


@dataclass
class TuneResult:
    """A finished tuning (see :class:`ema_cli.tune.run.TuneOutcome`) and where it came from."""

    config: TuneConfig
    outcome: TuneOutcome
    source: str
    overrides: list[tuple[str, Any]] = field(default_factory=list)
    inputs: Any = None
    """What the folder's marker records (``report.run_inputs.RunInputs``; :func:`tune_inputs`)."""
    execution: dict[str, Any] = field(default_factory=dict)
    """Where the candidates ran (``sweep.executor.Executor.describe``)."""

    # ------------------------------------------------------------------ values
    @property
    def variables(self) -> list[str]:
        return list(self.outcome.problem.variables)

    @property
    def tuned(self) -> dict[str, float]:
        """The tuned values (SI, `ema params` names)."""
        return {v: float(x) for v, x in zip(self.variables, self.outcome.best.x, strict=True)}

    @property
    def initial(self) -> dict[str, float]:
        return {v: float(x) for v, x in zip(self.variables, self.outcome.initial, strict=True)}

    @property
    def cost(self) -> float:
        """The tuned cost (normalised: 1 is the default controller's)."""
        return float(self.outcome.after.cost[0])

    @property
    def title(self) -> str:
        return (f"{self.config.name}: tuning ({self.outcome.method_label}) on the "
                f"{self.config.actuator.label()}")

    @property
    def verdict(self) -> str | None:
        """With a spec: the battery's verdict on the tuned controller (PASS, FAIL,
        INCONCLUSIVE); None without one."""
        return self.outcome.verdict

    @property
    def exit_code(self) -> int:
        """``ema tune``'s exit code: 0, or with a spec 0 PASS, 1 FAIL, 3 INCONCLUSIVE."""
        from ema_cli.acceptance.verdict import EXIT_CODES

        return 0 if self.verdict is None else EXIT_CODES[self.verdict]

    def on_bounds(self, share: float = BOUND_SHARE) -> list[dict[str, Any]]:
        """The tuned variables within ``share`` of their range (on their scale) from a bound:
        ``variable``, ``side`` (lower/upper), ``value``, ``bound``, ``hard`` (the bound is the
        end of the parameter's own range, e.g. fb_motor's [0, 1]) and ``text``, one line."""
        from ema_cli.config.tune import FRACTIONS
        from ema_cli.model.params import BY_NAME
        from ema_cli.units import fmt_num

        out = []
        for v, x in self.tuned.items():
            spec = self.config.variables[v]
            u = spec.to_unit(x)
            side = "lower" if u <= share else "upper" if u >= 1.0 - share else None
            if side is None:
                continue
            bound = spec.bounds[0 if side == "lower" else 1]
            hard = v in FRACTIONS and bound in (0.0, 1.0)
            unit = BY_NAME[v].unit if v in BY_NAME else ""
            where = "on" if x == bound else f"within {100 * share:g} % of its range from"
            text = (f"{v} = {fmt_num(x, unit, 4)} is {where} its {side} bound "
                    f"{fmt_num(bound, unit, 4)}" + (
                        f", the end of {v}'s own range" if hard else
                        f": the best may lie beyond it (widen variables.{v}.bounds)"))
            out.append({"variable": v, "side": side, "value": x, "bound": bound,
                        "hard": hard, "text": text})
        return out

    def shortfalls(self, verdicts: Any = None) -> list[dict[str, str]]:
        """With a spec: the requirements the tuned controller misses by the battery's rows
        ``verdicts`` (default: the check's), each with the value, the best the search
        reached, why and the limit that would pass (``tune.shortfalls.shortfalls``); else []."""
        from ema_cli.tune.shortfalls import shortfalls

        o = self.outcome
        if o.spec is None:
            return []
        return shortfalls(o.spec, o.checked[o.chosen]["verdicts"] if verdicts is None
                          else verdicts)

    def unmeetable(self) -> str:
        """With a spec and a FAIL: the sentence naming the requirements no gains inside the
        bounds were found to meet (``tune.shortfalls.blocking_summary``); else ""."""
        from ema_cli.tune.shortfalls import blocking_summary

        return blocking_summary(self.shortfalls()) if self.outcome.verdict == "FAIL" else ""

    def requirements_frame(self) -> pd.DataFrame:
        """With a spec (else empty): one row per requirement (a test's metric): the limit, the
        search's tightened limit, the tier, the tuned controller's value and result by the
        battery, what the search saw (controllers measured, how many met the limit, the best
        value and the range) and why a requirement left the search."""
        import pandas as pd

        from ema_cli.acceptance.verdict import overall
        from ema_cli.tune.shortfalls import fmt_range, fmt_value
        from ema_cli.units import from_si

        o = self.outcome
        if o.spec is None:
            return pd.DataFrame()
        pick = o.checked[o.chosen]
        rows = []
        for r in o.spec.requirements:
            value, cond, _, _ = pick["readings"][r.key]
            res = overall([v.result for v in pick["verdicts"]
                           if v.test == r.test and v.metric == r.metric])
            t = o.spec.tallies[r.key]
            lo_t, hi_t = (from_si(b, r.unit) for b in (r.lo_t, r.hi_t))
            rows.append({
                "test": r.test, "metric": r.metric, "limit": r.limit_text,
                "search_min": lo_t, "search_max": hi_t, "unit": r.unit, "tier": r.tier,
                "measured_in_search": r.proxy or ("battery" if r.tier == "search" else ""),
                "tuned": from_si(value, r.unit), "tuned_condition": cond, "result": res,
                "seen": t.seen, "met": t.met,
                "best": fmt_value(r, t.best) if t.seen else "",
                "range": fmt_range(r, t.low, t.high) if t.seen and t.high >= t.low else "",
                "out_of_reach": o.spec.unreachable.get(r.key, "")})
        return pd.DataFrame(rows)

    def evaluation(self, which: str) -> Any:
        if which not in CONTROLLERS:
            raise EmaError(f"which must be one of {', '.join(CONTROLLERS)}, got {which!r}")
        return getattr(self.outcome, which)

    # ------------------------------------------------------------------ documents
    def scenario_document(self, name: str, which: str = "after") -> dict[str, Any]:
        """The run config of scenario ``name`` with controller ``which`` (``after``: the tuned
        values in ``plant``; ``before``: as configured; ``reference``: the default controller,
        the scenario's compensators removed), runnable with ``ema simulate``."""
        import copy

        sc = {s.name: s for s in self.outcome.problem.scenarios}
        if name not in sc:
            raise EmaError(f"no scenario {name!r}; scenarios: {', '.join(sc)}")
        if which not in CONTROLLERS:
            raise EmaError(f"which must be one of {', '.join(CONTROLLERS)}, got {which!r}")
        src = sc[name].reference_document if which == "reference" else sc[name].document
        doc = copy.deepcopy(src)
        if which == "after":
            doc["plant"] = {**(doc.get("plant") or {}), **self.tuned}
        doc["name"] = f"{sc[name].document['name']}-{which}"
        doc["description"] = (f"{self.config.name}: scenario {name} with the "
                              + {"after": "tuned controller", "before": "controller before "
                                 "tuning (the scenario's compensators, the variables at their "
                                 "start)", "reference": "default controller (no compensators)"
                                 }[which])
        return doc

    def tuned_document(self) -> dict[str, Any]:
        """tuned.yaml: the actuator's run config with the tuned values (in ``plant``), on the
        first scenario's input and the tuning grid, without any scenario's condition."""
        import copy

        first = self.outcome.problem.scenarios[0]
        act = copy.deepcopy(self.outcome.actuator_document)
        act["name"] = f"{self.config.name}-tuned"
        act["description"] = (f"{self.config.name}: the actuator with the tuned controller "
                              f"({', '.join(f'{k} = {v:.6g}' for k, v in self.tuned.items())})")
        act["plant"] = {**(act.get("plant") or {}), **self.tuned}
        act["input"] = copy.deepcopy(first.document["input"])
        act["simulation"] = copy.deepcopy(first.document["simulation"])
        return act

    # ------------------------------------------------------------------ tables
    @property
    def metrics(self) -> pd.DataFrame:
        """Per scenario: the cost metric (edge units) and its ratio to the default controller,
        for the default, the starting and the tuned controller (scenarios.csv)."""
        return self.scenarios_frame()

    def to_pandas(self, form: str = "wide") -> pd.DataFrame:
        """The search history (tuning.csv: per run and generation the scores and the best
        values so far); ``long``: one row per run, generation and quantity."""
        return long_form(self.history(), form, ["run", "seed", "generation", "evaluations"],
                         "quantity")

    def history(self) -> pd.DataFrame:
        """tuning.csv: per run and generation the evaluations so far, the generation's best
        and mean score, the best so far, its cost when feasible and its variable values."""
        import numpy as np
        import pandas as pd

        from ema_cli.tune.problem import INFEASIBLE

        frames = []
        prob = self.outcome.problem
        for k, r in enumerate(self.outcome.runs):
            h = r.result.history
            ever = np.asarray(h.best_ever)
            df = pd.DataFrame({
                "run": k, "seed": r.seed, "generation": np.arange(len(ever)),
                "evaluations": h.evaluations, "best_score": h.best, "mean_score": h.mean,
                "best_ever_score": ever,
                "best_ever_feasible": ever < INFEASIBLE,
                "best_ever_cost": np.where(ever < INFEASIBLE, ever, np.nan)})
            vals = prob.values(np.asarray(h.x_best_ever))
            for j, v in enumerate(self.variables):
                df[v] = vals[:, j]
            frames.append(df)
        return pd.concat(frames, ignore_index=True)

    def runs_frame(self) -> pd.DataFrame:
        """runs.csv: one row per run (seed): cost, feasibility, budget used, time, values."""
        import pandas as pd

        rows = []
        for r in self.outcome.runs:
            row = {"seed": r.seed, "method": self.outcome.method, "cost": r.cost,
                   "feasible": r.feasible, "evaluations": r.result.evaluations,
                   "generations": r.result.generations, "wall_s": r.result.wall_time_s}
            row.update({v: float(x) for v, x in zip(self.variables, r.x, strict=True)})
            rows.append(row)
        return pd.DataFrame(rows)

    def scenarios_frame(self) -> pd.DataFrame:
        """Per scenario: the cost metric (edge units) and its ratio to the default controller
        for the three controllers."""
        import pandas as pd

        from ema_cli.units import DEG

        metric = self.config.cost.metric
        unit = {"itae": "deg_s2", "iae": "deg_s", "ise": "deg2_s"}[metric]
        scale = 1.0 / DEG**2 if metric == "ise" else 1.0 / DEG
        rows = []
        for s, sc in enumerate(self.outcome.problem.scenarios):
            row: dict[str, Any] = {"scenario": sc.name, "weight": sc.weight}
            for w in CONTROLLERS:
                ev = self.evaluation(w)
                row[f"{metric}_{unit}_{w}"] = float(ev.metric[0, s]) * scale
                row[f"ratio_{w}"] = float(ev.ratio[0, s])
            rows.append(row)
        return pd.DataFrame(rows)

    def constraints_frame(self) -> pd.DataFrame:
        """Per scenario and constraint: the limit and the value (limit's unit) of the three
        controllers, and whether the tuned one meets it."""
        import pandas as pd

        from ema_cli.units import UNITS

        rows = []
        for s, sc in enumerate(self.outcome.problem.scenarios):
            for name, lim in self.config.constraints_of(sc.name).items():
                f = UNITS[lim.unit][1]
                row: dict[str, Any] = {"scenario": sc.name, "constraint": name,
                                       "min": lim.min, "max": lim.max, "unit": lim.unit}
                for w in CONTROLLERS:
                    row[w] = float(self.evaluation(w).constraint[name][0, s]) / f
                lo, hi = lim.si()
                v = float(self.evaluation("after").constraint[name][0, s])
                row["met"] = bool(lo <= v <= hi)
                rows.append(row)
        return pd.DataFrame(rows)

    # ------------------------------------------------------------------ figures and files
    def plot(self, kind: str = "convergence", scenario: str | None = None) -> Figure:
        """``convergence`` (best cost vs evaluations, every run) or ``scenario`` (load angle
        and error of the three controllers on ``scenario``)."""
        from ema_cli.report.tune_report import convergence_figure, scenario_figure

        if kind == "convergence":
            return convergence_figure(self)
        if kind == "scenario":
            names = [s.name for s in self.outcome.problem.scenarios]
            return scenario_figure(self, names.index(scenario) if scenario in names else 0)
        raise EmaError(f"kind must be 'convergence' or 'scenario', got {kind!r}")

    def save(self, folder: str | Path | None = None) -> Path:
        """Write tuned.yaml, scenarios/*.yaml, tuning.csv, runs.csv, scenarios.csv,
        constraints.csv, convergence.png, one before/after figure per scenario, tuning.md,
        the resolved config and a manifest."""
        import yaml

        from ema_cli.report.rundir import write_run
        from ema_cli.report.tune_report import write_tuning

        cfg_json = self.config.model_dump(mode="json", by_alias=True)
        inputs = self.inputs or _inputs(self.config, self.overrides, self.outcome.method,
                                        len(self.outcome.runs), None)
        return write_run("tune", self.config.name, inputs, folder_arg(folder),
                         lambda out: write_tuning(out, yaml.safe_dump(cfg_json,
                                                                      sort_keys=False), self))


def _inputs(cfg: TuneConfig, pairs: list[tuple[str, Any]], method: str | None,
            runs: int | None, budget: int | None, spec: ConfigSource = None) -> Any:
    """The marker's inputs of a tuning: the resolved config, the effective --method, --runs
    and --budget (the config's when not given), the --set paths, the spec (its SHA-256 when
    a file, its leaves when a document)."""
    from ema_cli.report.run_inputs import run_inputs

    o = cfg.optimiser
    spec_file = spec if isinstance(spec, str | Path) else None
    spec_doc = spec if spec is not None and spec_file is None else None
    return run_inputs(cfg, sets=pairs, options={"method": method or o.method,
                                                "runs": runs or o.runs,
                                                "budget": budget or o.budget},
                      files={"spec": spec_file} if spec_file is not None else None,
                      parts={"spec": spec_doc} if spec_doc is not None else None)


def tune_inputs(config: ConfigSource, overrides: Overrides = None, *,
                method: str | None = None, runs: int | None = None,
                budget: int | None = None, spec: ConfigSource = None) -> Any:
    """The inputs (``report.run_inputs.RunInputs``) a :func:`tune` with these arguments
    records in its folder's marker: what ``ema tune`` checks ``--out`` against before it
    tunes."""
    from ema_cli.config.loader import load_config
    from ema_cli.config.tune import TuneConfig

    pairs = override_pairs(overrides)
    return _inputs(load_config(config, pairs, TuneConfig), pairs, method, runs, budget, spec)


EVAL_OVERHEAD_S = 0.015
"""A candidate evaluation's time beyond its kernel time on 2 idle cores (scoring, the
optimiser's bookkeeping, the spec's measurements): 13.5 ms for `ema tune configs/tune.yaml`
(24 s for 1,428 evaluations, 4.7 s of it the kernel's estimate), 19 ms for the tuning of the
README's design line, 2026-11-27 [s]."""


def tuning_seconds(n_evals: int, steps_per_eval: float, workers: int) -> float:
    """The estimated time [s] of a tuning: ``n_evals`` evaluations of ``steps_per_eval``
    integration steps each (its scenarios, and the spec's tests it measures) on ``workers``
    cores at ``progress.CPU_S_PER_STEP``, plus :data:`EVAL_OVERHEAD_S` per evaluation: the
    cost model of ``ema tune``, ``ema design`` and ``ema reproduce``'s threshold tunings."""
    from ema_cli.progress import kernel_seconds

    return kernel_seconds(n_evals, steps_per_eval, workers) + n_evals * EVAL_OVERHEAD_S


def tune(config: ConfigSource, overrides: Overrides = None, *, method: str | None = None,
         runs: int | None = None, budget: int | None = None, spec: ConfigSource = None,
         progress: Callable[[int, int, int], None] | None = None,
         log: Callable[[str], None] | None = None, backend: str | None = None,
         n_jobs: int | None = None, scheduler: str | None = None) -> TuneResult:
    """Tune the controller of ``config`` (a tuning config: YAML file, dict or
    :class:`~ema_cli.config.tune.TuneConfig`); ``method`` (ga|de), ``runs`` (seeds) and
    ``budget`` (candidate evaluations per run) override the config's optimiser section.
    ``spec`` (an acceptance spec: YAML file, dict or ``AcceptanceSpec``): its tests run on
    the tuning's actuator and its limits become requirements of the search (``tune/spec.py``);
    the tuned controller is the one the whole battery ranks best among the search's best, and
    :attr:`TuneResult.verdict` is the battery's verdict on it.
    ``progress(run, done, total)`` is called after each generation with the evaluations done
    and planned in that run; ``log(text)`` once before the run with how the budget becomes
    whole generations (:func:`tune.run.explain_budget`). A budget that cannot pay for two
    generations is refused before anything is logged. ``backend`` (threads, loky, dask; None:
    this process's threads), ``n_jobs`` and ``scheduler`` say where each generation's
    candidates run (``sweep.executor``; the same bits on every backend). Raises EmaError when
    no candidate meets
    the tuning config's own constraints (nothing is written then); a spec's requirements
    that are not met are a result (the verdict FAIL), not an error."""
    from ema_cli.config.loader import load_config
    from ema_cli.config.tune import MAX_BUDGET, MAX_RUNS, TuneConfig
    from ema_cli.tune.problem import build_scenarios
    from ema_cli.tune.run import explain_budget, run_tuning

    if config is None:
        raise EmaError("tune needs a tuning config (a YAML file such as configs/tune.yaml)")
    if method is not None and method not in ("ga", "de"):
        raise EmaError(f"method must be ga or de, got {method!r}")
    for value, name, cap in ((runs, "runs", MAX_RUNS), (budget, "budget", MAX_BUDGET)):
        if value is not None and (isinstance(value, bool) or not isinstance(value, int)
                                  or not 1 <= value <= cap):
            raise EmaError(f"{name} must be an integer in [1, {cap}], got {value!r}")
    from ema_cli.api._inputs import callable_arg

    callable_arg(progress, "progress")
    callable_arg(log, "log")
    from ema_cli.api._inputs import backend_args

    n_jobs = backend_args(backend, n_jobs, scheduler)
    pairs = override_pairs(overrides)
    cfg = load_config(config, pairs, TuneConfig)
    from ema_cli.tune.run import check_budget

    o = cfg.optimiser
    check_budget(method or o.method, budget or o.budget, o.pop, len(cfg.variables), o.polish,
                 "--budget" if budget is not None else "optimiser.budget")
    scenarios, actuator_doc = build_scenarios(cfg, base_dir(config))
    requirements = spec_requirements(spec, cfg, base_dir(config))
    from ema_cli.limits import check_steps
    from ema_cli.tune.run import evaluations_for

    n_evals = (runs or o.runs) * evaluations_for(method or o.method, budget or o.budget, o.pop,
                                                 len(cfg.variables), o.polish, o.local)
    steps = cfg.simulation.duration_s / cfg.simulation.dt_s
    check_steps(n_evals * len(scenarios) * steps,
                f"tune: {n_evals:,} evaluations x {len(scenarios)} scenarios x {steps:.3g} steps",
                "lower budget or runs, shorten simulation.duration_s or raise simulation.dt_s")
    if log is not None:
        n_runs = runs or o.runs
        import os

        from ema_cli.progress import BIG_RUN, announce_estimate

        log(explain_budget(method or o.method, budget or o.budget, o.pop, len(cfg.variables),
                           o.polish, o.local) + (f"; x {n_runs} runs" if n_runs > 1 else ""))
        n_sims = n_evals * len(scenarios)
        n_steps, workers = round(steps), os.cpu_count() or 1
        announce_estimate(tuning_seconds(n_evals, n_steps * len(scenarios), workers),
                          f"{n_sims:,} simulations of {n_steps:,} steps on {workers} cores "
                          f"({n_evals:,} evaluations of {len(scenarios)} scenarios, "
                          f"{1e3 * EVAL_OVERHEAD_S:g} ms each beyond the kernel; --budget, "
                          "--runs set it)", force=n_sims > BIG_RUN)
    from ema_cli.sweep.executor import executing

    with executing(backend, n_jobs, scheduler) as ex:
        outcome = run_tuning(cfg, scenarios, method, runs, budget, progress, RECORD_DT_S,
                             requirements)
    outcome.actuator_document = actuator_doc
    res = TuneResult(cfg, outcome, str(config) if isinstance(config, str | Path) else "dict",
                     pairs, _inputs(cfg, pairs, method, runs, budget, spec), ex.describe())
    if not outcome.own_feasible:
        from ema_cli.api.tune_messages import infeasible_message

        raise EmaError(infeasible_message(res))
    return res


def spec_requirements(spec: ConfigSource, cfg: TuneConfig, folder: Path | None) -> Any:
    """The requirements (``tune.spec.SpecRequirements``) of acceptance spec ``spec`` on the
    tuning's actuator (None without a spec); bad specs raise EmaError naming ``spec``."""
    if spec is None:
        return None
    from ema_cli.config.acceptance import AcceptanceSpec
    from ema_cli.config.loader import load_config
    from ema_cli.tune.spec import SpecRequirements

    if isinstance(spec, str | Path) and not Path(spec).is_file():
        raise EmaError(f"spec '{spec}' is not a file (an acceptance spec, e.g. "
                       "configs/acceptance.yaml)")
    try:
        sp = load_config(spec, [], AcceptanceSpec)
        return SpecRequirements.build(sp, spec_label(spec), cfg.actuator, folder,
                                      list(cfg.variables), cfg.requirements.margin)
    except EmaError as exc:
        raise EmaError(f"spec: {exc.message}", exc.exit_code) from None


def spec_label(spec: ConfigSource) -> str:
    """How reports name a spec: a path as given, relative to the project when inside it (no
    machine path), or ``dict``."""
    if not isinstance(spec, str | Path):
        return "dict"
    p = Path(spec)
    root = Path(__file__).resolve().parents[2]
    try:
        return p.resolve().relative_to(root).as_posix() if p.is_absolute() else str(p)
    except ValueError:
        return p.name


