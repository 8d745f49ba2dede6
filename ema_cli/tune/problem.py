"""The tuning problem: scenarios resolved to kernel rows, candidates evaluated in one batch.

A candidate is a point of the unit cube ``u[n_var]`` (each variable mapped by its lin/log scale
to its value). :meth:`TuneProblem.evaluate` runs the whole population on every scenario in ONE
batched kernel call, then scores each candidate:

* cost: each scenario's error integral (ITAE by default), divided by its value with the
  default controller when ``cost.normalise`` (the actuator's controller without the scenario's
  compensators), then the weighted mean (or the worst weighted value) over the scenarios;
* constraints: each scenario's metrics against its limits, the margins of the linearised loops
  (position and speed, the closed linear loop must also be stable), and no divergence. A
  violation is measured relative to its limit (``(v - max)/|max|``, capped at
  :data:`VIOLATION_CAP`) and the violations are summed;
* feasibility first (Deb's rules, as a single number for both optimisers): a feasible
  candidate scores its cost, an infeasible one :data:`INFEASIBLE` + its total violation, so
  every feasible candidate beats every infeasible one and, among infeasible ones, the smaller
  violation wins. Tournament selection (GA) and greedy replacement (DE) only compare scores.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ema_cli.analysis.linear import LINEAR_PARAMS, closed_loop_stable, margins
from ema_cli.config.loader import dotted_pairs, load_config, read_yaml, resolve_run
from ema_cli.config.run import RunConfig
from ema_cli.config.support import check_command
from ema_cli.config.tune import TuneConfig
from ema_cli.errors import EmaError
from ema_cli.model.params import CONTROLLER_PARAMS, INDEX, PARAMS, resolve, to_row
from ema_cli.sim.runner import BatchResult, simulate_batch
from ema_cli.sim.signals import InputSignal
from ema_cli.sim.tables import MET

INFEASIBLE = 1.0e12  # score offset of an infeasible candidate (costs are far below) [-]
VIOLATION_CAP = 1.0e6  # largest counted violation of one constraint [-]
COST_METRIC = {"itae": "itae_pos", "iae": "iae_pos", "ise": "ise_pos"}
SIM_CONSTRAINTS = {"overshoot": "overshoot", "peak_current": "peak_current",
                   "peak_voltage": "peak_voltage", "settling_time": "settling_time",
                   "steady_state_error": "ss_err_pos", "residual_oscillation": "p2p_pos"}
"""Simulated constraint -> kernel metric (SI)."""
MARGIN_CONSTRAINTS = ("gain_margin", "phase_margin")
NAMES = tuple(p.name for p in PARAMS)
RUN_KEYS = tuple(RunConfig.model_fields)


@dataclass(frozen=True)
class Scenario:
    """One scenario resolved: its run config (a document ``ema simulate`` reads, without the
    free variables), SI parameters with and without its compensators, and its input."""

    name: str
    document: dict[str, Any]
    params: dict[str, float]
    reference: dict[str, float]
    signal: InputSignal
    weight: float
    reference_document: dict[str, Any]


@dataclass
class Evaluation:
    """Everything about some candidates (``n`` rows; SI): values ``x[n, n_var]``, per-scenario
    ``metric[n, n_scen]`` (cost metric) and ``ratio`` (normalised), ``constraint`` values
    ``{name: [n, n_scen]}`` (margins: the same for every scenario with the same linear model),
    ``violation[n]``, ``cost[n]``, ``score[n]``."""

    x: np.ndarray
    metric: np.ndarray
    ratio: np.ndarray
    constraint: dict[str, np.ndarray]
    limits: list[dict[str, tuple[float, float]]]
    diverged: np.ndarray
    violation: np.ndarray
    cost: np.ndarray
    score: np.ndarray
    batch: BatchResult | None = field(default=None, repr=False)

    @property
    def feasible(self) -> np.ndarray:
        return self.violation == 0.0


def scenario_document(cfg: TuneConfig, name: str, actuator: Mapping[str, Any],
                      compensators: bool = True) -> dict[str, Any]:
    """The run config (document) of scenario ``name``: the actuator's run config with the
    actuator overrides, the scenario's input, condition and settings, and the tuning grid.
    ``compensators`` False leaves out the scenario's controller settings (``set`` paths under
    ``controller.`` and controller parameters in its ``plant``): the default controller."""
    from ema_cli.config.loader import apply_overrides

    sc = cfg.scenarios[name]
    doc = {k: v for k, v in actuator.items() if k in RUN_KEYS}
    plant = {k: v for k, v in sc.plant.items() if compensators or k not in CONTROLLER_PARAMS}
    sets = [(k, v) for k, v in dotted_pairs(sc.overrides)
            if compensators or not k.startswith("controller.")]
    pairs: list[tuple[str, Any]] = (
        cfg.actuator.pairs()
        + [(f"nonlinearities.{k}", v) for k, v in sc.nonlinearities.items()]
        + [(f"plant.{k}", v) for k, v in plant.items()]
        + sets
        + [("simulation.duration_s", cfg.simulation.duration_s),
           ("simulation.dt_s", cfg.simulation.dt_s)])
    doc = apply_overrides(doc, pairs, RUN_KEYS)
    doc["input"] = sc.input.model_dump(mode="json", exclude_unset=True)
    doc["name"] = f"{cfg.name}-{name}" + ("" if compensators else "-default")
    doc["description"] = f"{cfg.name}: scenario {name}" + (
        "" if compensators else " with the default controller (no compensators)")
    sim = dict(doc.get("simulation") or {})
    out_iv = sim.get("output_interval_s")
    if out_iv is not None and out_iv < cfg.simulation.dt_s:
        sim["output_interval_s"] = None
    doc["simulation"] = sim
    return doc


def build_scenarios(cfg: TuneConfig, base_dir: Path | None
                    ) -> tuple[list[Scenario], dict[str, Any]]:
    """Resolve every scenario of ``cfg`` -> (scenarios, the actuator's run config document)."""
    from ema_cli.config.study import StudyConfig

    src, act_dir = cfg.actuator.source(base_dir, "tuning config")
    if src is not None:  # the schema of `ema simulate`: an unknown key is named, never dropped
        try:
            check_command(load_config(src, [], StudyConfig), "tune")
        except EmaError as exc:
            raise EmaError(f"actuator.config: {exc}") from None
    act_data: dict[str, Any] = read_yaml(src) if src is not None else {}
    if src is not None:  # an actuator description in a file of its own: read beside the config
        from ema_cli.config.loader import inline_actuator

        act_data = inline_actuator(act_data, Path(src).parent, str(src))
    try:
        from ema_cli.config.loader import apply_overrides

        act_doc = {k: v for k, v in act_data.items() if k in RUN_KEYS}
        act_full = apply_overrides(act_doc, cfg.actuator.pairs(), RUN_KEYS)
        resolve_run(load_config(act_full, [], RunConfig), act_dir)
    except EmaError as exc:
        raise EmaError(f"actuator: {exc}") from None
    out = []
    for name, sc in cfg.scenarios.items():
        where = f"scenarios.{name}"
        try:
            doc = scenario_document(cfg, name, act_data)
            run = resolve_run(load_config(doc, [], RunConfig), act_dir)
            ref_doc = scenario_document(cfg, name, act_data, compensators=False)
            ref = resolve_run(load_config(ref_doc, [], RunConfig), act_dir).params
        except EmaError as exc:
            raise EmaError(f"{where}: {exc}") from None
        params = run.params
        for var, spec in cfg.variables.items():
            try:  # the tuned value goes into plant: no section may set the same parameter
                load_config({**doc, "plant": {**(doc.get("plant") or {}),
                                              var: spec.bounds[0]}}, [], RunConfig)
            except EmaError as exc:
                raise EmaError(f"variables.{var}: scenario {name} (or the actuator) already "
                               f"sets it: {exc}") from None
            for bound in spec.bounds:
                try:
                    resolve({**{p: params[p] for p in CONTROLLER_PARAMS}, var: bound})
                except EmaError as exc:
                    raise EmaError(f"variables.{var}: at the bound {bound:g} in scenario "
                                   f"{name}: {exc}") from None
        out.append(Scenario(name, doc, params, ref, run.signal, sc.weight, ref_doc))
    for var in cfg.variables:  # the start ("before tuning") must be one controller
        vals = {s.name: s.params[var] for s in out}
        if len(set(vals.values())) > 1:
            raise EmaError(f"variables.{var}: the scenarios start it at different values "
                           f"({', '.join(f'{k}: {v:g}' for k, v in vals.items())}); a free "
                           "variable must not be set by a scenario")
    return out, act_full


def _violation(value: np.ndarray, lo: float, hi: float) -> np.ndarray:
    """Relative violation of ``lo <= value <= hi`` (0 when met; NaN counts as the cap)."""
    v = np.zeros_like(value, dtype=np.float64)
    if math.isfinite(hi):
        v += np.maximum(value - hi, 0.0) / (abs(hi) if hi != 0 else 1.0)
    if math.isfinite(lo):
        v += np.maximum(lo - value, 0.0) / (abs(lo) if lo != 0 else 1.0)
    return np.where(np.isnan(v), VIOLATION_CAP, np.minimum(v, VIOLATION_CAP))


class TuneProblem:
    """Bounds ``[0, 1]^n_var`` (the unit cube of the variables) and a batched ``evaluate``.

    ``progress(done, total)`` is called after each batch with the candidate evaluations done
    so far and ``budget`` (if given).
    """

    def __init__(self, cfg: TuneConfig, scenarios: Sequence[Scenario],
                 parallel: bool = True) -> None:
        self.cfg = cfg
        self.scenarios = list(scenarios)
        self.variables = list(cfg.variables)
        self.specs = [cfg.variables[v] for v in self.variables]
        self.cols = np.array([INDEX[v] for v in self.variables], dtype=np.int64)
        self.lower = np.zeros(len(self.variables))
        self.upper = np.ones(len(self.variables))
        self.parallel = parallel
        self.dt = cfg.simulation.dt_s
        self.n_steps = int(round(cfg.simulation.duration_s / self.dt))
        self.refs = [s.signal for s in self.scenarios]
        self.base = np.array([to_row(s.params) for s in self.scenarios])
        self.reference_base = np.array([to_row(s.reference) for s in self.scenarios])
        self.weights = np.array([s.weight for s in self.scenarios])
        self.limits = [{k: lim.si() for k, lim in cfg.constraints_of(s.name).items()}
                       for s in self.scenarios]
        self.metric_col = MET[COST_METRIC[cfg.cost.metric]]
        self.n_evaluations = 0
        self.kernel_s = 0.0
        self.margins_s = 0.0
        self.progress: Callable[[int], None] | None = None
        self._margin_cache: dict[tuple[float, ...], tuple[float, float, bool]] = {}
        self.reference_metric = np.ones(len(self.scenarios))
        if cfg.cost.normalise:
            ref = self.simulate(self.reference_base, np.arange(len(self.scenarios)))
            vals = ref.metrics[:, self.metric_col]
            for s, v in zip(self.scenarios, vals, strict=True):
                if not (math.isfinite(v) and v > 0):
                    raise EmaError(f"scenarios.{s.name}: its {cfg.cost.metric.upper()} with the "
                                   f"default controller is {v:g}, so it cannot normalise the "
                                   "cost (a reference that never moves, or a diverging run); "
                                   "use cost.normalise: false or change the scenario")
            self.reference_metric = vals

    # ------------------------------------------------------------------ mapping
    def values(self, U: np.ndarray) -> np.ndarray:
        """Unit-cube points ``U[n, n_var]`` -> variable values ``X[n, n_var]`` (SI)."""
        U = np.clip(np.atleast_2d(U), 0.0, 1.0)
        return np.column_stack([spec.to_value(U[:, k]) for k, spec in enumerate(self.specs)])

    def units(self, X: np.ndarray) -> np.ndarray:
        """Variable values -> unit-cube points (the inverse of :meth:`values`)."""
        X = np.atleast_2d(X)
        return np.column_stack([[spec.to_unit(float(x)) for x in X[:, k]]
                                for k, spec in enumerate(self.specs)])

    def rows(self, X: np.ndarray, base: np.ndarray | None = None) -> np.ndarray:
        """Kernel rows of candidates ``X[n, n_var]`` on every scenario: ``[n*n_scen, N]``,
        candidate-major (row ``c*n_scen + s``), on the scenario rows ``base`` (default: the
        scenarios as configured)."""
        n, n_s = X.shape[0], len(self.scenarios)
        P = np.repeat((self.base if base is None else base)[None], n, axis=0)  # [n, n_s, N]
        P[:, :, self.cols] = X[:, None, :]
        return P.reshape(n * n_s, -1)

    def simulate(self, P: np.ndarray, ref_index: np.ndarray, dec: int = 0) -> BatchResult:
        """Rows ``P`` (SI), row r on scenario ``ref_index[r]``, with signals every ``dec``
        steps (0: metrics only: then cut over the executor's workers, ``sweep.execute.
        spread_batch``, the same bits)."""
        t0 = time.perf_counter()
        if dec == 0 and self.parallel:
            from ema_cli.sweep.execute import spread_batch

            res = spread_batch(P, self.refs, ref_index, self.dt, self.n_steps,
                               "candidate rows")
        else:
            res = simulate_batch(P, self.refs, ref_index, self.dt, self.n_steps, dec,
                                 parallel=self.parallel)
        self.kernel_s += time.perf_counter() - t0
        return res

    # ------------------------------------------------------------------ scoring
    def _margins(self, row: np.ndarray) -> tuple[float, float, bool]:
        key = tuple(float(row[INDEX[n]]) for n in LINEAR_PARAMS)
        hit = self._margin_cache.get(key)
        if hit is not None:
            return hit
        p = dict(zip(NAMES, (float(v) for v in row), strict=True))
        stable = closed_loop_stable(p)
        gm = pm = -math.inf
        if stable:
            mp, ms = margins(p, "position"), margins(p, "speed")
            gm, pm = min(mp.gm_db, ms.gm_db), min(mp.pm_deg, ms.pm_deg)
            pm = math.radians(pm)
        out = (gm, pm, stable)
        if len(self._margin_cache) > 100_000:
            self._margin_cache.clear()
        self._margin_cache[key] = out
        return out

    def score(self, X: np.ndarray, dec: int = 0, base: np.ndarray | None = None) -> Evaluation:
        """Simulate and score candidates ``X[n, n_var]`` (values, SI) on the scenario rows
        ``base`` (default: the scenarios as configured)."""
        X = np.atleast_2d(np.asarray(X, dtype=np.float64))
        n, n_s = X.shape[0], len(self.scenarios)
        P = self.rows(X, base)
        res = self.simulate(P, np.tile(np.arange(n_s), n), dec)
        met = res.metrics.reshape(n, n_s, -1)
        metric = met[:, :, self.metric_col]
        diverged = met[:, :, MET["diverged"]] == 1.0
        ratio = metric / self.reference_metric[None, :]
        w = self.weights[None, :]
        if self.cfg.cost.aggregate == "mean":
            cost = (ratio * w).sum(axis=1) / w.sum()
        else:
            cost = (ratio * w).max(axis=1)
        cost = np.where(np.isfinite(cost) & ~diverged.any(axis=1), cost, np.inf)
        values: dict[str, np.ndarray] = {}
        for name, col in SIM_CONSTRAINTS.items():
            v = met[:, :, MET[col]].copy()
            if name == "settling_time":
                v = np.where(np.isnan(v), np.inf, v)  # never settled
            if name == "steady_state_error":
                v = np.abs(v)
            values[name] = v
        needs_margins = any(k in lim for lim in self.limits for k in MARGIN_CONSTRAINTS)
        unstable = np.zeros((n, n_s), dtype=bool)
        if needs_margins:
            t0 = time.perf_counter()
            gm = np.empty((n, n_s))
            pm = np.empty((n, n_s))
            for c in range(n):
                for s in range(n_s):
                    gm[c, s], pm[c, s], ok = self._margins(P[c * n_s + s])
                    unstable[c, s] = not ok
            values["gain_margin"], values["phase_margin"] = gm, pm
            self.margins_s += time.perf_counter() - t0
        violation = np.zeros(n)
        for s, lims in enumerate(self.limits):
            for name, (lo, hi) in lims.items():
                violation += _violation(values[name][:, s], lo, hi)
        violation += VIOLATION_CAP * (diverged.sum(axis=1) + unstable.sum(axis=1))
        score = np.where(violation > 0, INFEASIBLE + violation, cost)
        score = np.where(np.isfinite(score), score, INFEASIBLE + VIOLATION_CAP * 10)
        return Evaluation(X, metric, ratio, values, self.limits, diverged, violation, cost,
                          score, res if dec > 0 else None)

    def evaluate(self, U: np.ndarray) -> np.ndarray:
        """Scores of unit-cube candidates ``U[n, n_var]`` (the optimisers' interface)."""
        ev = self.score(self.values(U))
        self.n_evaluations += U.shape[0]
        if self.progress is not None:
            self.progress(self.n_evaluations)
        return ev.score

