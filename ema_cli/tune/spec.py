"""An acceptance spec as the tuning's requirements (``ema tune --spec``, ``ema design``).

The spec's tests run on the tuning's actuator (its ``actuator:`` replaces the spec's) with each
candidate's variables, except a variable that a test's ``set:`` fixes (the free-play test closes
the loop on the motor angle: the tuned feedback blend does not apply there). Each limit of a
test (one requirement per test and metric; of several conditions, amplitudes or loops, the
worst counts) falls in one of three tiers:

* ``fixed``: the test runs with the controller off (motor locked): measured once, no candidate
  changes it;
* ``search``: a cheap test, measured for every candidate: step, no-load rate and margins by the
  battery's own code (the same numbers as ``ema acceptance``), the threshold by a proxy (the
  step of the limit's size must be followed: one short step instead of a k-section search).
  Its violation, relative to the limit tightened by the margin (``requirements.margin``: a
  maximum M becomes M - margin*|M|), joins the tuning's constraints, feasibility first;
* ``check``: an expensive test (frequency response, hysteresis, dynamic stiffness): measured by
  :meth:`SpecRequirements.check`, the whole battery on the best distinct candidates of the
  search (``requirements.check`` of them) after it; the tuned controller is the best of those
  by the battery's own numbers.

Before the search (:meth:`SpecRequirements.screen`), the search tier is measured on a Sobol
sample of the variables' box (``requirements.screen`` controllers and the start): a
requirement that no sampled controller meets and that moves by less than :data:`INSENSITIVE`
of its limit over the whole box is beyond the controller's reach. It leaves the constraints
(it would only make every candidate infeasible, so that the cost would never be minimised) and
the report names it with the range measured.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ema_cli.acceptance.measurement import Measurement, TestRun
from ema_cli.config.acceptance import AcceptanceSpec, Limit
from ema_cli.tune.problem import VIOLATION_CAP, _violation

SEARCH_KINDS = ("step", "no_load_rate", "margins", "threshold")
"""Test kinds measured for every candidate (``threshold`` by its proxy, for a ``max`` limit)."""
SEARCH_SAMPLES = 500  # recorded samples of a step run in the search (its metrics: every step) [-]
UNMEASURED = 1.0  # violation of a value its test could not measure against the limit [-]
INSENSITIVE = 0.01  # a requirement moving less than this share of its limit: out of reach [-]
CHECK_SPACING = 0.02  # checked candidates lie this far apart in the unit cube, at least [-]
TIERS = ("fixed", "search", "check")
LOCKED_KINDS = ("load_deflection",)
"""Test kinds that lock the motor themselves (the controller is off)."""


@dataclass(frozen=True)
class Requirement:
    """One limit of the spec: ``test`` and ``metric``, the spec's bounds ``lo``..``hi`` and
    the search's ``lo_t``..``hi_t`` (tightened by the margin), SI; ``unit`` the limit's;
    ``tier`` (module docstring); ``proxy``: what the search measures instead of the battery's
    value ("" when the battery's own code)."""

    test: str
    kind: str
    metric: str
    limit: Limit
    lo: float
    hi: float
    lo_t: float
    hi_t: float
    tier: str
    proxy: str = ""

    @property
    def key(self) -> str:
        """``test: metric``."""
        return f"{self.test}: {self.metric}"

    @property
    def unit(self) -> str:
        return str(self.limit.unit)

    @property
    def limit_text(self) -> str:
        """``>= 5 Hz``, ``<= 80 ms`` or ``5..10 Hz`` (the spec's limit, its unit)."""
        lim = self.limit
        if lim.min is not None and lim.max is not None:
            return f"{lim.min:g}..{lim.max:g} {lim.unit}"
        return f">= {lim.min:g} {lim.unit}" if lim.min is not None else \
            f"<= {lim.max:g} {lim.unit}"


def tightened(lo: float, hi: float, margin: float) -> tuple[float, float]:
    """``lo``..``hi`` (SI) narrowed by ``margin`` of each bound's magnitude (a bound of 0
    stays); bounds that would cross meet at their middle."""
    lo_t = lo + margin * abs(lo) if math.isfinite(lo) else lo
    hi_t = hi - margin * abs(hi) if math.isfinite(hi) else hi
    if lo_t > hi_t:
        lo_t = hi_t = 0.5 * (lo + hi)
    return lo_t, hi_t


def relative_violation(value: float, lo: float, hi: float) -> float:
    """How far ``value`` lies outside ``lo``..``hi``, relative to the bound (as the tuning
    scores its constraints; NaN counts as :data:`VIOLATION_CAP`)."""
    return float(_violation(np.array([value], dtype=np.float64), lo, hi)[0])


def measurement_violation(m: Measurement, lo: float, hi: float) -> float:
    """The violation of one measurement of the battery against ``lo``..``hi`` (SI): a
    measured value's relative distance; a bound (``m.measured`` false) decided by the battery's
    rule (``acceptance.verdict.judge``) counts its nearest edge when wholly outside, 0 when
    wholly inside, and at least :data:`UNMEASURED` when it straddles the limit."""
    from ema_cli.acceptance.verdict import FAIL, PASS, judge

    if m.measured:
        return relative_violation(m.value, lo, hi)
    result, _ = judge(m, lo, hi)
    if result == PASS:
        return 0.0
    if result == FAIL:
        return min(relative_violation(m.lower, lo, hi), relative_violation(m.upper, lo, hi))
    return max(UNMEASURED, relative_violation(m.value, lo, hi))


@dataclass
class Reading:
    """One requirement over ``n`` candidates: the worst condition's ``value`` (SI; for a
    proxy, the proxy's quantity), its ``condition``, the violation against the search's
    tightened limits (``v_search``) and against the spec's (``v_spec``)."""

    value: np.ndarray
    condition: list[str]
    v_search: np.ndarray
    v_spec: np.ndarray
    measured: np.ndarray | None = None
    """Whether each value was measured inside its test's range (None: all were)."""


@dataclass
class Tally:
    """What the search saw of one requirement: candidates measured, how many met the spec's
    limit, the value of the one nearest to it (``best``) and the range of values."""

    seen: int = 0
    met: int = 0
    best: float = math.nan
    best_violation: float = math.inf
    best_condition: str = ""
    low: float = math.inf
    high: float = -math.inf

    def add(self, r: Reading) -> None:
        if not len(r.value):
            return
        self.seen += len(r.value)
        self.met += int(np.sum(r.v_spec == 0.0))
        k = int(np.argmin(r.v_spec))
        if r.v_spec[k] < self.best_violation:
            self.best_violation = float(r.v_spec[k])
            self.best, self.best_condition = float(r.value[k]), r.condition[k]
        finite = r.value[np.isfinite(r.value)]
        if finite.size:
            self.low = min(self.low, float(finite.min()))
            self.high = max(self.high, float(finite.max()))


def _params_of(path: str) -> set[str]:
    """The model parameters a run-config path of a test's ``set:`` fixes."""
    from ema_cli.config.run import SECTION_PARAMS

    if path.startswith("plant."):
        return {path.split(".", 1)[1]}
    if path == "controller.feedback_blend":
        return {"fb_motor"}
    return {SECTION_PARAMS[path]} if path in SECTION_PARAMS else set()


@dataclass
class SpecRequirements:
    """The requirements of an acceptance spec on the tuning's actuator (module docstring).

    ``setups``: test -> (SI parameters, dt) of the actuator the test runs on; ``fixed_vars``:
    test -> the variables its ``set:`` fixes; ``requirements`` in the spec's order."""

    spec: AcceptanceSpec
    source: str
    variables: list[str]
    margin: float
    setups: dict[str, tuple[dict[str, float], float]]
    fixed_vars: dict[str, set[str]]
    requirements: list[Requirement]
    unreachable: dict[str, str] = field(default_factory=dict)
    """requirement key -> why it is beyond the controller's reach (it left the search)."""
    no_margin: set[str] = field(default_factory=set)
    """Requirements every screened controller met: the search holds the spec's own limit
    (the margin guards what the controller can break, e.g. not a peak current the current
    limit caps below the requirement)."""
    tallies: dict[str, Tally] = field(default_factory=dict)
    fixed_readings: dict[str, tuple[float, str, float, float]] = field(default_factory=dict)
    screened: int = 0
    timings: dict[str, float] = field(default_factory=dict)

    # ------------------------------------------------------------------ building
    @classmethod
    def build(cls, spec: AcceptanceSpec, source: str, actuator: Any, folder: Path | None,
              variables: Sequence[str], margin: float) -> SpecRequirements:
        """The spec's tests on ``actuator`` (the tuning's ``ActuatorSpec``; ``folder``: where
        its relative paths start), every test checked measurable before any simulation."""
        from ema_cli.acceptance.setup import test_setups
        from ema_cli.config.loader import dotted_pairs

        sp = spec.model_copy(update={"actuator": actuator})
        names = list(sp.tests)
        _, setups = test_setups(sp, names, folder)
        fixed_vars = {}
        reqs = []
        for name in names:
            test = sp.tests[name]
            touched: set[str] = set()
            for path, _ in dotted_pairs(test.overrides or {}):
                touched |= _params_of(path)
            fixed_vars[name] = touched & set(variables)
            locked = (test.test in LOCKED_KINDS
                      or setups[name][0].get("locked", 0.0) == 1.0)
            for metric, lim in test.limits.items():
                lo, hi = lim.si()
                lo_t, hi_t = tightened(lo, hi, margin)
                proxy = ""
                if locked:
                    tier = "fixed"
                elif test.test == "threshold" and lim.min is None:
                    tier = "search"
                    proxy = (f"the step of the limit's size followed to "
                             f"{100 * test.fraction:g} % within {test.within_s:g} s")
                elif test.test in SEARCH_KINDS and test.test != "threshold":
                    tier = "search"
                else:
                    tier = "check"
                reqs.append(Requirement(name, test.test, metric, lim, lo, hi, lo_t, hi_t,
                                        tier, proxy))
        out = cls(sp, source, list(variables), margin, setups, fixed_vars, reqs)
        out.tallies = {r.key: Tally() for r in reqs}
        return out

    def by_tier(self, tier: str) -> list[Requirement]:
        return [r for r in self.requirements if r.tier == tier]

    @property
    def active(self) -> list[Requirement]:
        """The requirements the search's constraints hold: the search tier, reachable."""
        return [r for r in self.by_tier("search") if r.key not in self.unreachable]

    def units(self, test: str, X: np.ndarray) -> list[dict[str, float]]:
        """The SI parameters of each candidate ``X[n, n_var]`` (values) for ``test``."""
        base, _ = self.setups[test]
        keep = self.fixed_vars[test]
        cols = [(j, v) for j, v in enumerate(self.variables) if v not in keep]
        return [{**base, **{v: float(x[j]) for j, v in cols}} for x in np.atleast_2d(X)]

    # ------------------------------------------------------------------ measuring
    def _read(self, req: Requirement, runs: Sequence[TestRun]) -> Reading:
        n = len(runs)
        value, cond = np.full(n, math.nan), [""] * n
        vt, vs = np.full(n, VIOLATION_CAP), np.full(n, VIOLATION_CAP)
        measured = np.zeros(n, dtype=bool)
        for c, run in enumerate(runs):
            best = None
            for m in run.values(req.metric):
                key = (measurement_violation(m, req.lo, req.hi),
                       measurement_violation(m, req.lo_t, req.hi_t))
                if best is None or key > best[0]:
                    best = (key, m)
            if best is not None:
                (vs[c], vt[c]), m = best
                value[c], cond[c], measured[c] = m.value, m.condition, m.measured
        return Reading(value, cond, vt, vs, measured)

    def _threshold(self, req: Requirement, X: np.ndarray) -> Reading:
        """The proxy: the shares of the steps of the tightened and of the spec's limit the load
        reaches within ``within_s`` (value: the spec's), against the test's fraction."""
        from ema_cli.acceptance.battery import step_fractions

        test = self.spec.tests[req.test]
        _, dt = self.setups[req.test]
        units = self.units(req.test, X)
        n = len(units)
        share = step_fractions(units + units, np.r_[np.full(n, req.hi_t), np.full(n, req.hi)],
                               test.within_s, dt)
        short = np.maximum(test.fraction - share, 0.0) / test.fraction
        short = np.where(np.isfinite(short), np.minimum(short, VIOLATION_CAP), VIOLATION_CAP)
        cond = f"{req.hi / math.radians(1):g} deg step, {100 * test.fraction:g} % within " \
               f"{test.within_s:g} s"
        return Reading(share[n:], [cond] * n, short[:n], short[n:])

    def _search_runs(self, test: str, X: np.ndarray) -> list[TestRun]:
        from ema_cli.acceptance import battery as b

        t = self.spec.tests[test]
        units = self.units(test, X)
        dt = self.setups[test][1]
        if t.test == "step":
            return b.run_step(test, t, units, dt, samples=SEARCH_SAMPLES)
        if t.test == "no_load_rate":
            return b.run_no_load_rate(test, t, units, dt, samples=SEARCH_SAMPLES)
        return b.run_margins(test, t, units, dt, figure=False)

    def measure(self, X: np.ndarray) -> dict[str, Reading]:
        """The search tier (and the fixed tier's constants) for candidates ``X[n, n_var]``
        (values, SI) -> requirement key -> reading; the check tier is not measured here."""
        import time

        t0 = time.perf_counter()
        X = np.atleast_2d(X)
        n = X.shape[0]
        out: dict[str, Reading] = {}
        search = self.by_tier("search")
        tests = sorted({r.test for r in search if not r.proxy},
                       key=list(self.spec.tests).index)
        runs = {t: self._search_runs(t, X) for t in tests}
        for r in search:
            out[r.key] = self._threshold(r, X) if r.proxy else self._read(r, runs[r.test])
            if r.key in self.no_margin:
                out[r.key].v_search = out[r.key].v_spec
        self._measure_fixed()
        for r in self.by_tier("fixed"):
            v, cond, vt, vs = self.fixed_readings[r.key]
            out[r.key] = Reading(np.full(n, v), [cond] * n, np.full(n, vt), np.full(n, vs),
                                 np.ones(n, dtype=bool))
        self.timings["search_s"] = self.timings.get("search_s", 0.0) + time.perf_counter() - t0
        return out

    def _measure_fixed(self) -> None:
        """Run each fixed-tier test once (the battery's runner) and keep its readings."""
        from ema_cli.acceptance.kinds import run_units

        for name in dict.fromkeys(r.test for r in self.by_tier("fixed")):
            if any(r.test == name and r.key in self.fixed_readings
                   for r in self.requirements):
                continue
            p, dt = self.setups[name]
            run = run_units(name, self.spec.tests[name], [p], dt)[0]
            for r in self.by_tier("fixed"):
                if r.test == name:
                    rd = self._read(r, [run])
                    self.fixed_readings[r.key] = (float(rd.value[0]), rd.condition[0],
                                                  float(rd.v_search[0]), float(rd.v_spec[0]))
                    self.tallies[r.key].add(rd)

    def violation(self, readings: Mapping[str, Reading], n: int) -> np.ndarray:
        """The search's violation of each of ``n`` candidates: the sum over the active
        requirements (:attr:`active`) of their tightened violations."""
        v = np.zeros(n)
        for r in self.active:
            v += readings[r.key].v_search
        return v

    def record(self, readings: Mapping[str, Reading]) -> None:
        """Add the readings of candidates the search evaluated to each requirement's tally
        (the fixed tier's single measurement is counted once, when made)."""
        for r in self.by_tier("search"):
            self.tallies[r.key].add(readings[r.key])

    # ------------------------------------------------------------------ before and after
    def screen(self, start: np.ndarray, specs: Sequence[Any], n: int, seed: int) -> None:
        """Measure the search tier on ``start`` (values) and ``n`` scrambled Sobol points of
        the variables' box (``specs``: the variables, mapping the unit cube to values); a
        requirement no controller there meets, moving by less than :data:`INSENSITIVE` of its
        limit, becomes unreachable (module docstring)."""
        from scipy.stats import qmc

        from ema_cli.tune.shortfalls import fmt_range

        U = qmc.Sobol(len(specs), scramble=True, seed=seed).random(n)
        X = np.column_stack([spec.to_value(U[:, k]) for k, spec in enumerate(specs)])
        X = np.vstack([np.atleast_2d(start), X])
        readings = self.measure(X)
        self.record(readings)
        self.screened = X.shape[0]
        for r in self.by_tier("search"):
            rd = readings[r.key]
            if np.all(rd.v_spec == 0.0):
                self.no_margin.add(r.key)
            finite = rd.value[np.isfinite(rd.value)]
            if (np.any(rd.v_spec == 0.0) or finite.size < len(rd.value)
                    or (rd.measured is not None and not rd.measured.all())):
                continue  # met somewhere, or a value not measured: no sign of insensitivity
            if r.proxy:
                scale = float(self.spec.tests[r.test].fraction)
            else:
                scale = abs(r.lo if math.isfinite(r.lo) and (finite < r.lo).all() else r.hi)
            spread = float(finite.max() - finite.min())
            if math.isfinite(scale) and scale > 0 and spread < INSENSITIVE * scale:
                self.unreachable[r.key] = (
                    f"within {fmt_range(r, finite.min(), finite.max())} over "
                    f"{X.shape[0]} controllers across the bounds (the start and {n} Sobol "
                    "points)")

    def check(self, X: np.ndarray) -> list[dict[str, Any]]:
        """The whole battery (every test, ``ema acceptance``'s runners) on candidates
        ``X[n, n_var]`` (values), batched over them -> per candidate: ``runs`` (test ->
        TestRun), ``readings`` (requirement key -> (value, condition, violation tightened,
        violation spec)), ``verdicts`` (the battery's rows) and ``verdict``."""
        import time

        from ema_cli.acceptance.kinds import run_units
        from ema_cli.acceptance.verdict import overall, verdicts

        t0 = time.perf_counter()
        X = np.atleast_2d(X)
        per_test = {}
        for name, test in self.spec.tests.items():
            per_test[name] = run_units(name, test, self.units(name, X), self.setups[name][1])
        out = []
        for c in range(X.shape[0]):
            runs = {name: per_test[name][c] for name in self.spec.tests}
            rows = [v for name, test in self.spec.tests.items()
                    for v in verdicts(runs[name], test.limits)]
            readings = {}
            for r in self.requirements:
                rd = self._read(r, [runs[r.test]])
                v_search = rd.v_spec if r.key in self.no_margin else rd.v_search
                readings[r.key] = (float(rd.value[0]), rd.condition[0], float(v_search[0]),
                                   float(rd.v_spec[0]))
            out.append({"runs": runs, "readings": readings, "verdicts": rows,
                        "verdict": overall([v.result for v in rows])})
        self.timings["check_s"] = time.perf_counter() - t0
        for r in self.by_tier("check"):
            self.tallies[r.key].add(Reading(
                np.array([o["readings"][r.key][0] for o in out]),
                [o["readings"][r.key][1] for o in out],
                np.array([o["readings"][r.key][2] for o in out]),
                np.array([o["readings"][r.key][3] for o in out])))
        return out


def pick_distinct(U: np.ndarray, scores: np.ndarray, k: int,
                  spacing: float = CHECK_SPACING) -> list[int]:
    """Indices of up to ``k`` of the candidates ``U[n, n_var]`` (unit cube), best ``scores``
    first, each at least ``spacing`` (largest coordinate difference) from those picked."""
    picked: list[int] = []
    for i in np.argsort(scores, kind="stable"):
        if not np.isfinite(scores[i]):
            break
        if all(np.max(np.abs(U[i] - U[j])) >= spacing for j in picked):
            picked.append(int(i))
            if len(picked) == k:
                break
    return picked
