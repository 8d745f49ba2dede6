"""``api.design``: from a closed-loop log to a signed-off controller (``ema design LOG``).

Three steps, each the library call of its own command:

1. identify the actuator from the log (``api.identify_closed_loop``, multiple shooting);
2. tune the controller on the FITTED actuator (``api.tune``): the tuning config's ``actuator:``
   becomes the fitted plant (every identified parameter, backlash and friction included); a
   scenario condition that would set an identified parameter (``deadzone2`` sets alpha,
   ``friction1`` sigma2) is dropped, because the fitted value holds in every scenario, and a
   scenario's friction-observer settings (``controller.friction_ff_*``) take the fitted
   friction, as a user sets them after ``ema identify``;
3. run the acceptance spec (``api.acceptance``) with the tuned gains on the fitted actuator
   (``nominal``) and on every corner of the identified 95 % intervals of the free parameters
   (2^p cases, one after the other: the battery takes one actuator at a time).

The verdict: INCONCLUSIVE whenever the identification's optimum is not confirmed or a free
parameter is not determined, whatever the batteries say: no PASS is built on an unconfirmed
fit. Otherwise FAIL when any case's battery fails, else INCONCLUSIVE when any case's battery
is INCONCLUSIVE (a value not measured inside its test's range), else PASS.
"""

from __future__ import annotations

import copy
import itertools
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ema_cli.api._inputs import ConfigSource, Overrides, folder_arg, override_pairs
from ema_cli.config.design import EXIT_CODES, MAX_FREE_CORNERS, DesignConfig
from ema_cli.errors import EmaError

if TYPE_CHECKING:
    from ema_cli.api.acceptance import AcceptanceResult
    from ema_cli.api.identify_logs import ClosedLoopIdentification
    from ema_cli.api.tune import TuneResult

ROOT = Path(__file__).resolve().parents[2]
DEFAULT_TUNE_CONFIG = ROOT / "configs" / "tune.yaml"
DEFAULT_SPEC = ROOT / "configs" / "acceptance.yaml"
FRICTION_OBSERVER = {"friction_ff_fc_nm": "Fc", "friction_ff_fs_nm": "Fs",
                     "friction_ff_vs_rad_s": "vs", "friction_ff_sigma2": "sigma2",
                     "friction_ff_sigma0": "sigma0", "friction_ff_sigma1": "sigma1"}
"""Run-config controller key of the friction observer -> the model parameter it estimates."""
SECTIONS = ("identify", "tune")


@dataclass
class DesignCase:
    """One acceptance run: ``nominal`` (the estimate) or a corner of the 95 % intervals;
    ``values`` the free parameters (SI), ``sides`` low/high per parameter (corners)."""

    name: str
    values: dict[str, float]
    sides: dict[str, str]
    result: AcceptanceResult

    @property
    def passed(self) -> bool:
        return self.result.passed

    @property
    def verdict(self) -> str:
        """The battery's overall verdict: PASS, FAIL or INCONCLUSIVE."""
        return self.result.verdict

    def test_verdicts(self) -> dict[str, bool]:
        """Per test of the spec: whether every limit of it was met."""
        out: dict[str, bool] = {}
        for v in self.result.verdicts:
            out[v.test] = out.get(v.test, True) and bool(v.passed)
        return out

    def test_results(self) -> dict[str, str]:
        """Per test of the spec: PASS, FAIL or INCONCLUSIVE (its rows, as the overall)."""
        from ema_cli.acceptance.verdict import overall

        rows: dict[str, list[str]] = {}
        for v in self.result.verdicts:
            rows.setdefault(v.test, []).append(v.result)
        return {t: overall(r) for t, r in rows.items()}


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
            "inconclusive_because": self.inconclusive + [
                f"acceptance {c.name}: {v.test}: {v.metric} ({v.condition}): {v.reason}"
                for c in self.cases for v in c.result.inconclusive],
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
                "folder": "tune"},
            "acceptance": {
                "spec": self.spec_source, "tests": self.tests,
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


def split_overrides(pairs: list[tuple[str, Any]]) -> dict[str, list[tuple[str, Any]]]:
    """``identify.KEY=V`` / ``tune.KEY=V`` pairs -> {section: [(KEY, V)]}; anything else is
    an error naming the key."""
    out: dict[str, list[tuple[str, Any]]] = {s: [] for s in SECTIONS}
    for k, v in pairs:
        head, _, rest = str(k).partition(".")
        if head == "name" and not rest:
            continue
        if head not in SECTIONS or not rest:
            raise EmaError(f"--set {k}: expected identify.KEY=VALUE (a setting of `ema identify "
                           "--closed-loop`) or tune.KEY=VALUE (a key of the tuning config)")
        out[head].append((rest, v))
    return out


def fitted_tune_document(tune_doc: dict[str, Any], plant: dict[str, Any],
                         full: dict[str, float]) -> tuple[dict[str, Any], list[str]]:
    """The tuning config on the fitted actuator -> (document, notes on what changed).

    ``plant``: the fitted run config's plant (identified and fixed values); ``full``: every
    SI parameter of the fitted actuator (for the friction observer's estimates)."""
    from ema_cli.config.loader import dotted_pairs
    from ema_cli.model.nonlinearities import nonlinearity_updates
    from ema_cli.model.params import resolve

    doc = copy.deepcopy(tune_doc)
    notes = []
    act = doc.get("actuator") or {}
    if act.get("config") or act.get("plant") or act.get("nonlinearities"):
        notes.append("tuning config: its actuator section is replaced by the fitted actuator")
    doc["actuator"] = {"config": None, "plant": dict(plant), "nonlinearities": {}}
    for name, sc in (doc.get("scenarios") or {}).items():
        if not isinstance(sc, dict):
            continue
        nls = dict(sc.get("nonlinearities") or {})
        for nl, value in list(nls.items()):
            try:
                touched = set(nonlinearity_updates(nl, value, resolve())) - {"friction"}
            except EmaError:
                continue  # the tuning config's own validation names it
            hit = sorted(touched & set(plant))
            if hit:
                del nls[nl]
                notes.append(f"scenario {name}: condition {nl}={value} dropped (it sets "
                             f"{', '.join(hit)}: the fitted value holds)")
        sc["nonlinearities"] = nls
        sets = sc.get("set")
        if sets:
            flat = dict(dotted_pairs(sets))
            changed = []
            for key, par in FRICTION_OBSERVER.items():
                path = f"controller.{key}"
                if path in flat and par in full:
                    flat[path] = float(full[par])
                    changed.append(f"{key} = {full[par]:.4g}")
            if changed:
                sc["set"] = flat
                notes.append(f"scenario {name}: friction observer set to the fitted friction "
                             f"({', '.join(changed)})")
    return doc, notes


def corners(names: tuple[str, ...], low: Any, high: Any) -> list[tuple[dict[str, float],
                                                                       dict[str, str]]]:
    """The 2^p corners of the box [low, high] -> (values, sides) each, in binary order (the
    first parameter varies slowest)."""
    out = []
    for sides in itertools.product((0, 1), repeat=len(names)):
        vals = {n: float((low, high)[s][j]) for j, (n, s) in enumerate(zip(names, sides,
                                                                            strict=True))}
        out.append((vals, {n: ("low", "high")[s] for n, s in zip(names, sides, strict=True)}))
    return out


FEEDBACK = ("controller.position_feedback", "controller.feedback_blend")
"""Run-config paths that choose the position feedback: a test setting one keeps its own."""


def spec_document(spec_doc: dict[str, Any], plant: dict[str, Any], gains: dict[str, float]
                  ) -> tuple[dict[str, Any], list[str]]:
    """The spec on the fitted actuator with the tuned gains -> (document, notes).

    The spec's ``actuator:`` becomes ``plant`` + ``gains``. The tuned position-feedback blend
    ``fb_motor`` goes into each test's ``set`` instead, except in a test that chooses its own
    feedback (``controller.position_feedback``, e.g. the free-play test closes the loop on the
    motor angle): there the test's choice holds."""
    from ema_cli.config.loader import dotted_pairs

    doc = copy.deepcopy(spec_doc)
    gains = dict(gains)
    fb = gains.pop("fb_motor", None)
    doc["actuator"] = {"config": None, "plant": {**plant, **gains}, "nonlinearities": {}}
    notes = []
    if fb is not None:
        for name, test in (doc.get("tests") or {}).items():
            flat = dict(dotted_pairs(test.get("set") or {}))
            if any(k in flat for k in FEEDBACK):
                notes.append(f"acceptance test {name}: its own position feedback holds, not "
                             f"the tuned fb_motor = {fb:.4g}")
                continue
            flat["plant.fb_motor"] = fb
            test["set"] = flat
    return doc, notes


def design(log: str | Path, config: ConfigSource = None, overrides: Overrides = None, *,
           tune_config: str | Path | None = None, spec: str | Path | None = None,
           budget: int | None = None, stage: Callable[[str], None] | None = None,
           tune_log: Callable[[str], None] | None = None, backend: str | None = None,
           n_jobs: int | None = None, scheduler: str | None = None) -> DesignResult:
    """Identify the actuator from ``log``, tune its controller, sign it off (module docstring).

    ``config``: a design config (``config.design.DesignConfig``: ``identify:`` settings,
    ``tune:`` overrides); ``overrides``: ``identify.KEY`` / ``tune.KEY`` dotted paths;
    ``tune_config`` (default configs/tune.yaml) and ``spec`` (default configs/acceptance.yaml);
    ``budget``: the tuning's candidate evaluations per run; ``stage(text)`` is called at the
    start of each step. ``backend`` (threads, loky, dask; None: this process's threads),
    ``n_jobs`` and ``scheduler`` say where the identification's starts, the tuning's
    candidates and the acceptance cases run (``sweep.executor``; the same bits on every
    backend). Bad inputs raise EmaError before the identification starts."""
    from ema_cli.api._inputs import backend_args
    from ema_cli.sweep.executor import executing

    n_jobs = backend_args(backend, n_jobs, scheduler)
    with executing(backend, n_jobs, scheduler) as ex:
        res = _design(log, config, overrides, tune_config, spec, budget, stage, tune_log)
        res.execution = ex.describe()
    return res


def _design(log: str | Path, config: ConfigSource, overrides: Overrides,
            tune_config: str | Path | None, spec: str | Path | None, budget: int | None,
            stage: Callable[[str], None] | None, tune_log: Callable[[str], None] | None
            ) -> DesignResult:
    """:func:`design` on the current executor."""
    from ema_cli.api.acceptance import acceptance
    from ema_cli.api.identify_logs import identify_closed_loop
    from ema_cli.api.tune import tune
    from ema_cli.config.acceptance import AcceptanceSpec
    from ema_cli.config.loader import dotted_pairs, load_config, read_yaml
    from ema_cli.config.tune import TuneConfig
    from ema_cli.identify.closed_loop.problem import MIN_POSITIVE
    from ema_cli.identify.log_settings import ClosedLoopSettings
    from ema_cli.report.log_identify_report import fitted_config

    say = stage or (lambda _text: None)
    t_all = time.perf_counter()
    log = Path(log)
    if not log.is_file():
        raise EmaError(f"log '{log}' is not a file (a closed-loop log: CSV, Parquet or .mat)")
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
    # everything is checked before the identification, the long step
    id_doc = {**cfg.identify, "name": cfg.identify.get("name", cfg.name)}
    id_pairs = by["identify"] + [("data", str(log))]
    try:
        load_config(id_doc, id_pairs, ClosedLoopSettings)
    except EmaError as exc:
        raise EmaError(f"identify: {exc.message}") from None
    tune_pairs = dotted_pairs(cfg.tune) + by["tune"]
    tune_doc = read_yaml(tune_path)
    try:
        load_config(tune_doc, tune_pairs, TuneConfig)
    except EmaError as exc:
        raise EmaError(f"tune: {exc.message}") from None
    spec_doc = read_yaml(spec_path)
    load_config(spec_doc, [], AcceptanceSpec)
    if budget is not None and (isinstance(budget, bool) or not isinstance(budget, int)
                               or budget < 1):
        raise EmaError(f"budget must be a positive integer, got {budget!r}")
    timings: dict[str, float] = {}

    say(f"1/3 identification of {log}")
    t0 = time.perf_counter()
    ident = identify_closed_loop(id_doc, id_pairs)
    fit = ident.result
    timings["identification"] = time.perf_counter() - t0
    doubts = fit_doubts(fit)
    plant = fitted_config(fit, "reference.csv")["plant"]
    n_prim = len(primary_names(fit))
    if n_prim > MAX_FREE_CORNERS:
        raise EmaError(f"identify.free: {n_prim} free parameters make {2 ** n_prim} interval "
                       f"corners; at most {MAX_FREE_CORNERS}")

    say("2/3 tuning on the fitted actuator")
    t0 = time.perf_counter()
    doc, notes = fitted_tune_document(tune_doc, plant, fit.params)
    try:
        tuned = tune(doc, tune_pairs, budget=budget, log=tune_log)
    except EmaError as exc:
        raise EmaError(f"tune (on the fitted actuator): {exc.message}",
                       exc.exit_code) from None
    timings["tuning"] = time.perf_counter() - t0

    gains = tuned.tuned
    names = primary_names(fit)
    idx = [fit.names.index(n) for n in names]
    u = fit.uncertainty
    import numpy as np

    ci_low, ci_high = u.ci_low[idx], u.ci_high[idx]
    low = np.maximum(ci_low, [max(fit.problem.lower[j], MIN_POSITIVE.get(fit.names[j], -np.inf))
                              for j in idx])
    high = np.minimum(ci_high, fit.problem.upper[idx])
    cases_in = [("nominal", {n: float(fit.x[j]) for j, n in enumerate(fit.names)}, {})]
    if np.all(np.isfinite(low)) and np.all(np.isfinite(high)):
        for k, (vals, sides) in enumerate(corners(names, low, high)):
            # the nuisance parameters (not corners) at their estimates
            cases_in.append((f"corner-{k + 1:02d}", {**cases_in[0][1], **vals}, sides))
        clipped = [n for j, n in enumerate(names)
                   if low[j] != ci_low[j] or high[j] != ci_high[j]]
        if clipped:
            notes.append("interval corners clipped to the identification bounds: "
                         + ", ".join(clipped))
    else:
        notes.append("interval corners not run: an interval is not finite")
    from ema_cli.sweep.executor import Task, current

    t0 = time.perf_counter()
    docs = [spec_document(spec_doc, {**plant, **vals}, gains) for _, vals, _ in cases_in]
    notes += docs[0][1]
    ex = current()

    def tasks() -> Any:  # each case a task: on the workers of a remote backend
        for k, ((case, _, _), (sdoc, _)) in enumerate(zip(cases_in, docs, strict=True)):
            if not ex.remote:  # run here, now
                say(f"3/3 acceptance {k + 1}/{len(cases_in)}: {case}")
            yield Task(acceptance, (sdoc,), f"acceptance case {case}")

    cases = []
    for (k, res), (case, vals, sides) in zip(ex.map(tasks()), cases_in, strict=True):
        if ex.remote:
            say(f"3/3 acceptance {k + 1}/{len(cases_in)} done: {case}")
        cases.append(DesignCase(case, vals, sides, res))
    timings["acceptance"] = time.perf_counter() - t0
    timings["total"] = time.perf_counter() - t_all
    # the bundled tuning config by its place in the project, not this machine's path
    tune_shown = ("the bundled configs/tune.yaml" if tune_path == DEFAULT_TUNE_CONFIG
                  else str(tune_path))
    return DesignResult(cfg, str(log), tune_shown, str(spec_path), ident, tuned, cases,
                        plant, doubts, notes, timings, pairs,
                        _inputs(cfg, pairs, log, tune_path, spec_path, budget))


def _inputs(cfg: DesignConfig, pairs: list[tuple[str, Any]], log: Path, tune_path: Path,
            spec_path: Path, budget: int | None) -> Any:
    from ema_cli.report.run_inputs import run_inputs

    # the --set pairs go to the steps, not into the design config: their values are inputs
    return run_inputs(cfg, sets=pairs, options={"budget": budget},
                      files={"log": log, "tune config": tune_path, "spec": spec_path}
                      ).with_components(**{k: v for k, v in pairs})


def design_inputs(log: str | Path, config: ConfigSource = None, overrides: Overrides = None, *,
                  tune_config: str | Path | None = None, spec: str | Path | None = None,
                  budget: int | None = None) -> Any:
    """The inputs (``report.run_inputs.RunInputs``) a :func:`design` with these arguments
    records in its folder's marker: the design config, the --set paths, --budget and the
    SHA-256 of the log, the tuning config and the spec (what ``ema design`` checks ``--out``
    against first)."""
    from ema_cli.config.loader import load_config

    tune_path = Path(tune_config) if tune_config is not None else DEFAULT_TUNE_CONFIG
    spec_path = Path(spec) if spec is not None else DEFAULT_SPEC
    return _inputs(load_config(config, [], DesignConfig), override_pairs(overrides), Path(log),
                   tune_path, spec_path, budget)
