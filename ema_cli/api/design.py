"""``api.design``: from a closed-loop log to a signed-off controller (``ema design LOG``).

Three steps, each the library call of its own command:

1. identify the actuator from the log (``api.identify_closed_loop``, multiple shooting);
2. tune the controller on the FITTED actuator against the acceptance spec it is signed off
   with (``api.tune`` with ``spec``): the tuning config's ``actuator:`` becomes the fitted
   plant (every identified parameter, backlash and friction included); a scenario condition
   that would set an identified parameter (``deadzone2`` sets alpha, ``friction1`` sigma2) is
   dropped, because the fitted value holds in every scenario, and a scenario's
   friction-observer settings (``controller.friction_ff_*``) take the fitted friction, as a
   user sets them after ``ema identify``. The spec's tests run on the fitted actuator inside
   the search, its limits (tightened by ``requirements.margin``) its constraints
   (``tune/spec.py``); the tuning config's scenarios give the cost;
3. run the acceptance spec (``api.acceptance``) with the tuned gains on the fitted actuator
   (``nominal``), then on the corners of the identified 95 % intervals of the free parameters
   (2^p cases, one after the other: the battery takes one actuator at a time) while they can
   change the verdict (``corners="auto"``): not when the fit cannot carry a sign-off, and no
   more once a case FAILs; ``corners="all"`` runs every corner.

The verdict: INCONCLUSIVE whenever the identification's optimum is not confirmed or a free
parameter is not determined, whatever the batteries say: no PASS is built on an unconfirmed
fit. Otherwise FAIL when any case's battery fails, else INCONCLUSIVE when any case's battery
is INCONCLUSIVE (a value not measured inside its test's range), else PASS (every corner run).
A FAIL names each requirement the tuned controller misses on the fitted actuator
(:attr:`DesignResult.shortfalls`): the value, the best the search reached, why no gains inside
the bounds were found to meet it, and the limit that would pass.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ema_cli.api._inputs import ConfigSource, Overrides, folder_arg, override_pairs
from ema_cli.api.design_steps import (  # noqa: F401 - re-exported: the steps' documents
    FEEDBACK,
    FRICTION_OBSERVER,
    SECTIONS,
    DesignCase,  # noqa: F401 (a result part, re-exported)
    actuator_name,
    corners,
    fitted_tune_document,
    spec_document,
    split_overrides,
)
from ema_cli.config.design import EXIT_CODES, MAX_FREE_CORNERS, DesignConfig
from ema_cli.errors import EmaError

if TYPE_CHECKING:
    from ema_cli.api.identify_logs import ClosedLoopIdentification
    from ema_cli.api.tune import TuneResult

ROOT = Path(__file__).resolve().parents[2]
DEFAULT_TUNE_CONFIG = ROOT / "configs" / "tune.yaml"
DEFAULT_SPEC = ROOT / "configs" / "acceptance.yaml"
CORNER_POLICIES = ("auto", "all")
"""``auto``: corners only while they can change the verdict; ``all``: every corner."""


@dataclass
class DesignResult:
    """A finished design loop: the three steps' results and the verdict."""

    config: DesignConfig
    log: str
    tune_source: str
    spec_source: str
    identification: ClosedLoopIdentification
    tuning: TuneResult
    cases: list[DesignCase]
    fitted_plant: dict[str, Any]
    inconclusive: list[str]
    notes: list[str] = field(default_factory=list)
    timings: dict[str, float] = field(default_factory=dict)
    overrides: list[tuple[str, Any]] = field(default_factory=list)
    inputs: Any = None
    """What the folder's marker records (``report.run_inputs.RunInputs``;
    :func:`design_inputs`)."""
    corner_policy: str = "auto"
    corners_planned: int = 0
    """Interval corners of the identified intervals (run or not)."""
    corners_skipped: str = ""
    """Why some corners were not run ("" when every planned corner ran)."""
    shortfalls: list[dict[str, str]] = field(default_factory=list)
    """The requirements the tuned controller misses on the fitted actuator
    (``tune.shortfalls.shortfalls``)."""
    execution: dict[str, Any] = field(default_factory=dict)
    """Where the work ran (``sweep.executor.Executor.describe``)."""

    @property
    def verdict(self) -> str:
        """PASS, FAIL or INCONCLUSIVE (see the module's docstring)."""
        return design_verdict(self.inconclusive, [c.verdict for c in self.cases])

    @property
    def exit_code(self) -> int:
        return EXIT_CODES[self.verdict]

    @property
    def unmeetable(self) -> str:
        """On a FAIL: one sentence naming the requirements no gains inside the bounds were
        found to meet, with the best value reached ("" otherwise; ``tune.spec.
        blocking_summary``)."""
        from ema_cli.tune.shortfalls import blocking_summary

        return blocking_summary(self.shortfalls) if self.verdict == "FAIL" else ""

    @property
    def tests(self) -> list[str]:
        return list(self.cases[0].result.spec.tests) if self.cases else []

    def to_json(self) -> dict[str, Any]:
        """The content of design.json (SI)."""
        fit = self.identification.result
        js = fit.to_json()
        u = fit.uncertainty
        ident = {n: {"value": float(fit.x[j]), "unit": js["parameters"][n]["unit"],
                     "ci95": [float(u.ci_low[j]), float(u.ci_high[j])],
                     "determined": bool(u.determined[j])}
                 for j, n in enumerate(fit.names)}
        tr = self.tuning
        return {
            "verdict": self.verdict,
            "exit_code": self.exit_code,
            "inconclusive_because": self.inconclusive + self.repeated_reasons(),
            "log": self.log,
            "identification": {
                "parameters": ident, "optimum": js["optimum"],
                "not_determined": js["not_determined"], "fit_quality": js["fit_quality"],
                "truth": js.get("truth"), "error_pct_vs_truth": js.get("error_pct_vs_truth"),
                "truth_in_ci95": js.get("truth_in_ci95"),
                "fitted_plant": self.fitted_plant, "folder": "identification"},
            "tuning": {
                "config": self.tune_source, "method": tr.outcome.method_label,
                "evaluations": int(tr.outcome.timings.get("evaluations", 0)),
                "gains_before": tr.initial, "gains_after": tr.tuned,
                "cost_before": float(tr.outcome.before.cost[0]), "cost_after": tr.cost,
                "cost_default_controller": float(tr.outcome.reference.cost[0]),
                "cost_meaning": "mean over the scenarios of each ITAE / its ITAE with the "
                                "default controller (1: the default controller)",
                "on_bounds": [f["text"] for f in tr.on_bounds()],
                "folder": "tune"},
            "requirements": {
                "margin": tr.config.requirements.margin,
                "unmet": self.shortfalls,
                "unmeetable": self.unmeetable,
                "out_of_reach": dict(tr.outcome.spec.unreachable),
                "table": tr.requirements_frame().to_dict(orient="records")},
            "acceptance": {
                "spec": self.spec_source, "tests": self.tests,
                "corners": {"policy": self.corner_policy, "planned": self.corners_planned,
                            "run": max(len(self.cases) - 1, 0),
                            "not_run_because": self.corners_skipped},
                "cases": [{"case": c.name, "parameters": c.values, "sides": c.sides,
                           "passed": c.passed, "verdict": c.verdict,
                           "tests": c.test_verdicts(), "test_results": c.test_results(),
                           "failed_limits": c.result.failed_limits(),
                           "folder": f"acceptance/{c.name}"} for c in self.cases]},
            "notes": self.notes,
            "overrides": [[k, v] for k, v in self.overrides],
            "timings_s": self.timings,
            "execution": self.execution,
        }

    def repeated_reasons(self) -> list[str]:
        """Why acceptance rows are INCONCLUSIVE, each reason once with the cases it occurs
        in (``in nominal and 16 corners``)."""
        groups: dict[str, list[str]] = {}
        for c in self.cases:
            for v in c.result.inconclusive:
                groups.setdefault(f"{v.test}: {v.metric} ({v.condition}): {v.reason}",
                                  []).append(c.name)
        return [f"acceptance {why} (in {case_list(names, len(self.cases))})"
                for why, names in groups.items()]

    def save(self, folder: str | Path | None = None) -> Path:
        """Write the run folder: design.json, design.md, manifest.json and the three steps'
        folders (identification/, tune/, acceptance/<case>/) -> the folder."""
        from ema_cli.report.design_report import write_design
        from ema_cli.report.run_inputs import run_inputs
        from ema_cli.report.rundir import write_run

        def write(out: Path) -> None:  # each step's folder is completed or kept like this one
            self.identification.save(out / "identification")
            self.tuning.save(out / "tune")
            for c in self.cases:
                c.result.save(out / "acceptance" / c.name)
            write_design(out, self)

        inputs = self.inputs or run_inputs(self.config, sets=self.overrides,
                                           files={"log": self.log})
        return write_run("design", self.config.name, inputs, folder_arg(folder), write)


def case_list(names: list[str], total: int) -> str:
    """The cases of a repeated outcome in a few words: ``nominal``, ``all 17 cases``,
    ``nominal and 3 corners``, ``corner-02, corner-05``."""
    if len(names) == total and total > 2:
        return f"all {total} cases"
    corners_ = [n for n in names if n != "nominal"]
    if len(corners_) > 3:
        head = "nominal and " if "nominal" in names else ""
        return f"{head}{len(corners_)} corners"
    return ", ".join(names)


def design_verdict(inconclusive: list[str], cases: list[bool | str]) -> str:
    """INCONCLUSIVE when the fit gives a reason (or there is no case); else FAIL if any case
    fails, INCONCLUSIVE if any case is inconclusive, else PASS. ``cases``: each case's
    acceptance verdict (PASS, FAIL, INCONCLUSIVE; a bool reads as PASS or FAIL)."""
    if inconclusive or not cases:
        return "INCONCLUSIVE"
    words = [("PASS" if c else "FAIL") if isinstance(c, bool) else c for c in cases]
    if "FAIL" in words:
        return "FAIL"
    return "INCONCLUSIVE" if "INCONCLUSIVE" in words else "PASS"


def primary_names(fit: Any) -> tuple[str, ...]:
    """The free parameters a sign-off rests on: all but the contact's nuisance parameters
    (``identify.closed_loop.NUISANCE``, freed by the fit unless stated), which stay at their
    estimates in every case (their intervals, often unbounded, are not corners)."""
    from ema_cli.identify.closed_loop.problem import NUISANCE

    skip = set(NUISANCE) if fit.shooting is not None and fit.settings.free_contact else set()
    return tuple(n for n in fit.names if n not in skip)


def fit_doubts(fit: Any) -> list[str]:
    """Why the identification cannot carry a sign-off (empty: it can): the optimum not
    confirmed (or, with the GA search, not checked), a free parameter not determined."""
    out: list[str] = []
    ms = fit.shooting
    if ms is None:
        out.append("the optimum is not checked (search: ga has no confirmation; the default "
                   "search: shooting confirms it)")
    elif not ms.confirmed:
        out.append("the identification's optimum is not confirmed: " + "; ".join(ms.reasons))
    bad = [n for n, d in zip(fit.names, fit.uncertainty.determined, strict=True)
           if not d and n in primary_names(fit)]
    if bad:
        out.append("not determined by the log: " + ", ".join(bad))
    return out


def design(log: str | Path, config: ConfigSource = None, overrides: Overrides = None, *,
           tune_config: str | Path | None = None, spec: str | Path | None = None,
           budget: int | None = None, corners: str = "auto",
           stage: Callable[[str], None] | None = None,
           tune_log: Callable[[str], None] | None = None, backend: str | None = None,
           n_jobs: int | None = None, scheduler: str | None = None) -> DesignResult:
    """Identify the actuator from ``log``, tune its controller against ``spec``, sign it off
    (module docstring).

    ``config``: a design config (``config.design.DesignConfig``: ``identify:`` settings,
    ``tune:`` overrides); ``overrides``: ``identify.KEY`` / ``tune.KEY`` dotted paths;
    ``tune_config`` (default configs/tune.yaml) and ``spec`` (default configs/acceptance.yaml);
    ``budget``: the tuning's candidate evaluations per run; ``corners``: ``auto`` (only while
    they can change the verdict) or ``all``; ``stage(text)`` is called at the start of each
    step. ``backend`` (threads, loky, dask; None: this process's threads), ``n_jobs`` and
    ``scheduler`` say where the identification's starts and the tuning's candidates run
    (``sweep.executor``; the same bits on every backend; the sign-off's cases run in turn, each
    deciding whether the next can change the verdict). Bad inputs raise EmaError before the
    identification starts."""
    from ema_cli.api._inputs import backend_args
    from ema_cli.sweep.executor import executing

    n_jobs = backend_args(backend, n_jobs, scheduler)
    with executing(backend, n_jobs, scheduler) as ex:
        res = _design(log, config, overrides, tune_config, spec, budget, corners, stage,
                      tune_log)
        res.execution = ex.describe()
    return res


def _design(log: str | Path, config: ConfigSource, overrides: Overrides,
            tune_config: str | Path | None, spec: str | Path | None, budget: int | None,
            corners: str, stage: Callable[[str], None] | None,
            tune_log: Callable[[str], None] | None) -> DesignResult:
    """:func:`design` on the current executor."""
    from ema_cli.api.design_steps import design_estimate
    from ema_cli.progress import whole_estimate

    say = stage or (lambda _text: None)
    t_all = time.perf_counter()
    log = Path(log)
    plan = _checked_inputs(log, config, overrides, tune_config, spec, budget, corners)
    with whole_estimate(*design_estimate(plan, budget)):  # the steps' estimates inside
        return _steps(log, plan, budget, corners, say, tune_log, t_all)


def _steps(log: Path, plan: dict[str, Any], budget: int | None, corners: str,
           say: Callable[[str], None], tune_log: Callable[[str], None] | None,
           t_all: float) -> DesignResult:
    """The three steps of :func:`design` (identification, tuning, sign-off) -> the result."""
    from ema_cli.api.identify_logs import identify_closed_loop
    from ema_cli.api.tune import tune
    from ema_cli.report.log_identify_report import fitted_config

    cfg, tune_path, spec_path, pairs = plan["cfg"], plan["tune_path"], plan["spec_path"], \
        plan["pairs"]
    timings: dict[str, float] = {}

    say(f"1/3 identification of {log}")
    t0 = time.perf_counter()
    ident = identify_closed_loop(plan["id_doc"], plan["id_pairs"])
    fit = ident.result
    timings["identification"] = time.perf_counter() - t0
    doubts = fit_doubts(fit)
    plant = fitted_config(fit, "reference.csv")["plant"]
    n_prim = len(primary_names(fit))
    if n_prim > MAX_FREE_CORNERS:
        raise EmaError(f"identify.free: {n_prim} free parameters make {2 ** n_prim} interval "
                       f"corners; at most {MAX_FREE_CORNERS}")

    say("2/3 tuning on the fitted actuator, against the spec")
    t0 = time.perf_counter()
    name = actuator_name(str(log))
    doc, notes = fitted_tune_document(plan["tune_doc"], plant, fit.params, name)
    try:
        tuned = tune(doc, plan["tune_pairs"], budget=budget, spec=spec_path, log=tune_log)
    except EmaError as exc:
        raise EmaError(f"tune (on the fitted actuator): {exc.message}",
                       exc.exit_code) from None
    timings["tuning"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    cases_in, cnotes = design_cases(fit)
    notes += cnotes
    cases, skipped = _sign_off(cases_in, plan["spec_doc"], plant, tuned.tuned, str(log),
                               doubts, corners, notes, say)
    timings["acceptance"] = time.perf_counter() - t0
    timings["total"] = time.perf_counter() - t_all
    # the bundled tuning config by its place in the project, not this machine's path
    tune_shown = ("the bundled configs/tune.yaml" if tune_path == DEFAULT_TUNE_CONFIG
                  else str(tune_path))
    from ema_cli.api.tune import spec_label

    res = DesignResult(cfg, str(log), tune_shown, spec_label(spec_path), ident, tuned, cases,
                       plant, doubts, notes, timings, pairs,
                       _inputs(cfg, pairs, log, tune_path, spec_path, budget, corners))
    res.corner_policy, res.corners_planned, res.corners_skipped = (corners, len(cases_in) - 1,
                                                                   skipped)
    res.shortfalls = tuned.shortfalls(cases[0].result.verdicts)
    return res


def _checked_inputs(log: Path, config: ConfigSource, overrides: Overrides,
                    tune_config: str | Path | None, spec: str | Path | None,
                    budget: int | None, corner_policy: str) -> dict[str, Any]:
    """Every input of :func:`design` checked before the identification, the long step ->
    the documents and pairs of each step."""
    from ema_cli.config.acceptance import AcceptanceSpec
    from ema_cli.config.loader import dotted_pairs, load_config, read_yaml
    from ema_cli.config.tune import TuneConfig
    from ema_cli.identify.log_settings import ClosedLoopSettings
    from ema_cli.tune.run import check_budget

    if not log.is_file():
        raise EmaError(f"log '{log}' is not a file (a closed-loop log: CSV, Parquet or .mat)")
    if corner_policy not in CORNER_POLICIES:
        raise EmaError(f"corners must be one of {', '.join(CORNER_POLICIES)}, got "
                       f"{corner_policy!r}")
    tune_path = Path(tune_config) if tune_config is not None else DEFAULT_TUNE_CONFIG
    spec_path = Path(spec) if spec is not None else DEFAULT_SPEC
    for p, what, arg in ((tune_path, "a tuning config", "tune_config"),
                         (spec_path, "an acceptance spec", "spec")):
        if not p.is_file():
            raise EmaError(f"{arg} '{p}' is not a file ({what}, e.g. configs/"
                           f"{'tune' if arg == 'tune_config' else 'acceptance'}.yaml)")
    pairs = override_pairs(overrides)
    by = split_overrides(pairs)
    cfg = load_config(config, [], DesignConfig)
    id_doc = {**cfg.identify, "name": cfg.identify.get("name", cfg.name)}
    id_pairs = by["identify"] + [("data", str(log))]
    try:
        id_cfg = load_config(id_doc, id_pairs, ClosedLoopSettings)
    except EmaError as exc:
        raise EmaError(f"identify: {exc.message}") from None
    tune_pairs = dotted_pairs(cfg.tune) + by["tune"]
    tune_doc = read_yaml(tune_path)
    try:
        tcfg = load_config(tune_doc, tune_pairs, TuneConfig)
    except EmaError as exc:
        raise EmaError(f"tune: {exc.message}") from None
    if budget is not None and (isinstance(budget, bool) or not isinstance(budget, int)
                               or budget < 1):
        raise EmaError(f"budget must be a positive integer, got {budget!r}")
    o = tcfg.optimiser
    check_budget(o.method, budget or o.budget, o.pop, len(tcfg.variables), o.polish,
                 "budget" if budget is not None else "tune.optimiser.budget",
                 "--set tune.optimiser.pop")
    spec_doc = read_yaml(spec_path)
    try:  # the spec's tests measurable on the tuning's actuator (the fitted one comes later)
        from ema_cli.acceptance.setup import test_setups

        sp = load_config(spec_doc, [], AcceptanceSpec)
        test_setups(sp.model_copy(update={"actuator": tcfg.actuator}), list(sp.tests), None)
    except EmaError as exc:
        raise EmaError(f"spec: {exc.message}") from None
    return {"cfg": cfg, "pairs": pairs, "tune_path": tune_path, "spec_path": spec_path,
            "id_doc": id_doc, "id_pairs": id_pairs, "tune_doc": tune_doc,
            "tune_pairs": tune_pairs, "spec_doc": spec_doc,
            "id_cfg": id_cfg, "tune_cfg": tcfg, "spec": sp}  # the three steps' configs, parsed


def design_cases(fit: Any) -> tuple[list[tuple[str, dict[str, float], dict[str, str]]],
                                    list[str]]:
    """The cases of the sign-off: ``nominal`` (the estimate) and the 2^p corners of the 95 %
    intervals of the primary free parameters, clipped to the identification bounds (the
    nuisance parameters at their estimates) -> ([(name, values, sides)], notes)."""
    import numpy as np

    from ema_cli.identify.closed_loop.problem import MIN_POSITIVE

    names = primary_names(fit)
    idx = [fit.names.index(n) for n in names]
    u = fit.uncertainty
    ci_low, ci_high = u.ci_low[idx], u.ci_high[idx]
    low = np.maximum(ci_low, [max(fit.problem.lower[j], MIN_POSITIVE.get(fit.names[j], -np.inf))
                              for j in idx])
    high = np.minimum(ci_high, fit.problem.upper[idx])
    cases = [("nominal", {n: float(fit.x[j]) for j, n in enumerate(fit.names)}, {})]
    notes = []
    if np.all(np.isfinite(low)) and np.all(np.isfinite(high)):
        for k, (vals, sides) in enumerate(corners(names, low, high)):
            cases.append((f"corner-{k + 1:02d}", {**cases[0][1], **vals}, sides))
        clipped = [n for j, n in enumerate(names)
                   if low[j] != ci_low[j] or high[j] != ci_high[j]]
        if clipped:
            notes.append("interval corners clipped to the identification bounds: "
                         + ", ".join(clipped))
    else:
        notes.append("interval corners not run: an interval is not finite")
    return cases, notes


def _sign_off(cases_in: list[tuple[str, dict[str, float], dict[str, str]]],
              spec_doc: dict[str, Any], plant: dict[str, Any], gains: dict[str, float],
              log: str, doubts: list[str], policy: str, notes: list[str],
              say: Callable[[str], None]) -> tuple[list[DesignCase], str]:
    """The battery on the nominal case, then on each corner while it can change the verdict
    (``policy`` auto) or on every corner (all) -> (the cases run, why corners were left out
    or "")."""
    from ema_cli.api.acceptance import acceptance

    cases: list[DesignCase] = []
    skipped = ""
    for k, (case, vals, sides) in enumerate(cases_in):
        if k and policy == "auto":
            left = len(cases_in) - k
            if doubts:
                skipped = (f"{left} interval corners not run: the fit cannot carry a sign-off "
                           "(INCONCLUSIVE whatever they say)")
            elif any(c.verdict == "FAIL" for c in cases):
                first = next(c.name for c in cases if c.verdict == "FAIL")
                skipped = (f"{left} interval corner{'s' if left > 1 else ''} not run: "
                           f"{first} FAILs, which no corner can turn back")
            if skipped:
                break
        say(f"3/3 acceptance {k + 1}/{len(cases_in)}: {case}")
        sdoc, snotes = spec_document(spec_doc, {**plant, **vals}, gains,
                                     actuator_name(log, case))
        if k == 0:
            notes += snotes
        cases.append(DesignCase(case, vals, sides, acceptance(sdoc)))
    return cases, skipped


def _inputs(cfg: DesignConfig, pairs: list[tuple[str, Any]], log: Path, tune_path: Path,
            spec_path: Path, budget: int | None, corner_policy: str = "auto") -> Any:
    from ema_cli.report.run_inputs import run_inputs

    # the --set pairs go to the steps, not into the design config: their values are inputs
    return run_inputs(cfg, sets=pairs, options={"budget": budget, "corners": corner_policy},
                      files={"log": log, "tune config": tune_path, "spec": spec_path}
                      ).with_components(**{k: v for k, v in pairs})


def design_inputs(log: str | Path, config: ConfigSource = None, overrides: Overrides = None, *,
                  tune_config: str | Path | None = None, spec: str | Path | None = None,
                  budget: int | None = None, corners: str = "auto") -> Any:
    """The inputs (``report.run_inputs.RunInputs``) a :func:`design` with these arguments
    records in its folder's marker: the design config, the --set paths, --budget and the
    SHA-256 of the log, the tuning config and the spec (what ``ema design`` checks ``--out``
    against first)."""
    from ema_cli.config.loader import load_config

    tune_path = Path(tune_config) if tune_config is not None else DEFAULT_TUNE_CONFIG
    spec_path = Path(spec) if spec is not None else DEFAULT_SPEC
    return _inputs(load_config(config, [], DesignConfig), override_pairs(overrides), Path(log),
                   tune_path, spec_path, budget, corners)
