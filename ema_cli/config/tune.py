"""Schema of a tuning config (``ema tune CONFIG.yaml``, e.g. configs/tune.yaml).

A tuning config names the actuator (a run config and overrides, as an acceptance spec does),
the scenarios the controller must cope with (an input and a condition each: nonlinearities,
plant values and the compensators set for that condition), the free variables (controller and
compensator parameters of `ema params`, SI, with bounds on a linear or logarithmic scale), the
cost, the constraints and the optimiser. Every candidate runs every scenario for the same
``simulation.duration_s`` on the same step ``simulation.dt_s``, so that a whole generation is
one batched kernel call.

Constraints and their dimensions (units as in acceptance specs, see ``ema_cli.units.UNITS``):

===================== =========== ==================================================
overshoot             percent     step overshoot of each scenario
peak_current          current     largest |i| of each scenario
peak_voltage          voltage     largest |voltage command| of each scenario
settling_time         time        2 % settling time (a run that never settles: inf)
steady_state_error    angle       |mean error| over the last 10 % of each scenario
residual_oscillation  angle       peak-to-peak error over the last 20 % of each scenario
gain_margin           decibel     the linearised loops (position and speed; the smaller)
phase_margin          angle       the same
===================== =========== ==================================================

By default gain_margin >= 6 dB and phase_margin >= 45 deg (MIL-F-9490D); ``off`` removes a
constraint. No scenario may diverge, always.
"""

from __future__ import annotations

import math
from typing import Any, Literal

from pydantic import Field, field_validator, model_validator

from ema_cli.config.acceptance import ActuatorSpec, Limit
from ema_cli.config.base import (
    FiniteFloat,
    NonNegInt,
    PlainName,
    PositiveFloat,
    PositiveInt,
    Seed,
    Strict,
)
from ema_cli.config.run import KEY_MARK, InputConfig, Scalar
from ema_cli.model.params import BY_NAME, CONTROLLER_PARAMS, check_value
from ema_cli.sim.grid import DEFAULT_DT
from ema_cli.units import units_of

CONSTRAINTS: dict[str, str] = {
    "overshoot": "percent", "peak_current": "current", "peak_voltage": "voltage",
    "settling_time": "time", "steady_state_error": "angle", "residual_oscillation": "angle",
    "gain_margin": "decibel", "phase_margin": "angle",
}
"""Constraint name -> dimension."""
NON_NEGATIVE = ("overshoot", "peak_current", "peak_voltage", "settling_time",
                "steady_state_error", "residual_oscillation")
"""Constraints whose value is never negative (a max below 0 can never be met)."""
DEFAULT_CONSTRAINTS: dict[str, dict[str, Any]] = {
    "gain_margin": {"min": 6.0, "unit": "dB"},
    "phase_margin": {"min": 45.0, "unit": "deg"},
}
COSTS = ("itae", "iae", "ise")
FRACTIONS = ("fb_motor", "notch_depth")  # controller parameters that lie in [0, 1]
MAX_SCENARIOS = 20  # scenarios in one config, at most [-]
MAX_VARIABLES = 16  # free variables, at most (every controller parameter) [-]
MAX_DURATION_S = 30.0  # simulated time of one scenario run, at most [s]
MAX_BUDGET = 1_000_000  # candidate evaluations of one optimiser run, at most [-]
MAX_RUNS = 100  # seeds of one tuning, at most [-]
MAX_POP = 10_000  # population, at most [-]
DEFAULT_BUDGET = 960  # candidate evaluations per run (pop 24 x 40 generations + elites) [-]
DEFAULT_POP = 24  # population [-]
DEFAULT_POLISH = 0.33  # share of the budget for the local search after the global one [-]
DEFAULT_SPEC_MARGIN = 0.05  # share of each acceptance limit held back in the search [-]
DEFAULT_SPEC_CHECK = 8  # best distinct controllers of the search run through the battery [-]
DEFAULT_SPEC_SCREEN = 32  # Sobol controllers measured before the search [-]


def _at(key: str, message: str) -> ValueError:
    return ValueError(f"{KEY_MARK}{key}{KEY_MARK}{message}")


class Variable(Strict):
    """A free variable: bounds [lower, upper] in the parameter's SI unit and a scale."""

    bounds: tuple[FiniteFloat, FiniteFloat] = Field(
        description="[lower, upper] in the parameter's unit (`ema params`), lower < upper")
    scale: Literal["lin", "log"] = Field(
        "lin", description="lin: uniform in the value; log: uniform in its logarithm (bounds "
                           "> 0)")

    @model_validator(mode="after")
    def _bounds(self) -> Variable:
        lo, hi = self.bounds
        if lo == hi:
            raise ValueError(f"empty bounds [{lo:g}, {hi:g}]: lower must be below upper (fix "
                             "the value in the actuator or a scenario instead)")
        if lo > hi:
            raise ValueError(f"lower bound {lo:g} is above the upper bound {hi:g}")
        if self.scale == "log" and lo <= 0:
            raise ValueError(f"a log scale needs bounds > 0, got lower {lo:g}")
        return self

    def to_value(self, u: Any) -> Any:
        """Unit-cube coordinate(s) ``u`` in [0, 1] -> value(s)."""
        lo, hi = self.bounds
        if self.scale == "log":
            return lo * (hi / lo) ** u
        return lo + (hi - lo) * u

    def to_unit(self, x: float) -> float:
        """Value -> its unit-cube coordinate (outside [0, 1] when outside the bounds)."""
        lo, hi = self.bounds
        if self.scale == "log":
            return math.log(x / lo) / math.log(hi / lo)
        return (x - lo) / (hi - lo)


Constraint = Limit | Literal["off"]


class Scenario(Strict):
    """One condition the controller must cope with."""

    input: InputConfig = Field(description="the reference, as in a run config (degrees)")
    nonlinearities: dict[str, Scalar] = Field(
        default_factory=dict, description="name -> magnitude (`ema locations`) of this scenario")
    plant: dict[str, Scalar] = Field(
        default_factory=dict, description="SI parameter overrides of this scenario, e.g. the "
                                          "compensators set for it ({dzi_v: 1.0})")
    overrides: dict[str, Any] = Field(
        default_factory=dict, alias="set",
        description="run-config settings by dotted path (e.g. controller.deadzone_inverse_v)")
    weight: PositiveFloat = Field(1.0, description="weight in the cost [-]")
    constraints: dict[str, Constraint] = Field(
        default_factory=dict, description="constraints of this scenario only (replacing the "
                                          "global ones of the same name; off removes one)")

    @field_validator("constraints", mode="before")
    @classmethod
    def _off(cls, v: Any) -> Any:
        return _off_words(v)

    @field_validator("constraints")
    @classmethod
    def _known(cls, v: dict[str, Any]) -> dict[str, Any]:
        return _check_constraints(v)


def _off_words(v: Any) -> Any:
    """YAML reads an unquoted ``off`` as false: a constraint given as false is ``off``."""
    if isinstance(v, dict):
        return {k: ("off" if x is False else x) for k, x in v.items()}
    return v


def _check_constraints(v: dict[str, Any]) -> dict[str, Any]:
    for name, lim in v.items():
        if name not in CONSTRAINTS:
            raise _at(name, f"unknown constraint; expected one of {', '.join(CONSTRAINTS)}")
        if lim == "off":
            continue
        dim = CONSTRAINTS[name]
        if lim.dimension != dim:
            raise _at(f"{name}.unit", f"{lim.unit!r} is a unit of {lim.dimension}, {name} is "
                                      f"a {dim}; expected one of {', '.join(units_of(dim))}")
        lo, hi = lim.si()
        if name in NON_NEGATIVE and hi < 0:
            raise _at(f"{name}.max", f"{lim.max:g} {lim.unit} can never be met: {name} is "
                                     "never negative (infeasible constraint)")
        if name == "phase_margin" and (lo >= math.pi or hi <= -math.pi):
            raise _at(name, "a phase margin lies in (-180, 180] deg: this limit can never be "
                            "met (infeasible constraint)")
    return v


class CostConfig(Strict):
    """What is minimised."""

    metric: Literal["itae", "iae", "ise"] = Field(
        "itae", description="the position error integral of each scenario")
    normalise: bool = Field(
        True, description="divide each scenario's metric by its value with the default "
                          "controller (the actuator's, without the scenario's compensators), "
                          "so that a 0.1 deg and a 20 deg step weigh alike")
    aggregate: Literal["mean", "worst"] = Field(
        "mean", description="weighted mean over the scenarios, or the worst weighted value")


class SimulationSpec(Strict):
    """The time grid every scenario runs on."""

    duration_s: PositiveFloat = Field(2.0, le=MAX_DURATION_S, description="[s]")
    dt_s: PositiveFloat = Field(DEFAULT_DT, le=1e-3, description="integration step [s]")


class OptimiserConfig(Strict):
    """The optimiser and its budget."""

    method: Literal["ga", "de"] = Field(
        "ga", description="ga: the project's real-coded elitist GA; de: scipy's differential "
                          "evolution (a cross-check at the same budget)")
    budget: PositiveInt = Field(DEFAULT_BUDGET, le=MAX_BUDGET,
                                description="candidate evaluations per run (each runs every "
                                            "scenario); its global share must pay for two "
                                            "generations (checked before the run: "
                                            "tune.run.check_budget)")
    pop: PositiveInt = Field(DEFAULT_POP, ge=6, le=MAX_POP, description="population")
    runs: PositiveInt = Field(1, le=MAX_RUNS, description="independent runs (seeds seed, "
                                                          "seed+1, ...); the best is kept")
    seed: Seed = Field(0, description="seed of the first run")
    polish: float = Field(
        DEFAULT_POLISH, ge=0.0, le=0.9,
        description="fraction of the budget for a local search from the best point after the "
                    "global optimiser (0: none)")
    local: Literal["cma", "compass"] = Field(
        "cma", description="the local search of the polish: cma (CMA-ES: learns a valley "
                           "across the variables) or compass (pattern search along each "
                           "variable)")
    patience: NonNegInt = Field(
        0, description="GA: stop after this many generations without improvement (0: never)")


class RequirementsConfig(Strict):
    """How an acceptance spec given to the tuning (``ema tune --spec``, ``ema design``) becomes
    its requirements (``tune/spec.py``, docs/tuning.md)."""

    margin: float = Field(
        DEFAULT_SPEC_MARGIN, ge=0.0, le=0.5,
        description="share of each limit held back in the search (a maximum M becomes "
                    "M - margin*|M|, a minimum m becomes m + margin*|m|); the sign-off uses the "
                    "spec's own limits [-]")
    check: PositiveInt = Field(
        DEFAULT_SPEC_CHECK, le=64,
        description="the best distinct controllers of the search that run the whole battery "
                    "after it; the tuned controller is the best of them by the battery")
    screen: PositiveInt = Field(
        DEFAULT_SPEC_SCREEN, le=4096,
        description="controllers sampled across the bounds (Sobol) before the search: a "
                    "requirement none of them meets and that barely moves is out of the "
                    "controller's reach")


class TuneConfig(Strict):
    """A tuning problem: actuator, scenarios, free variables, cost, constraints, optimiser."""

    name: PlainName
    description: str = ""
    actuator: ActuatorSpec = Field(default_factory=ActuatorSpec)
    simulation: SimulationSpec = Field(default_factory=SimulationSpec)
    scenarios: dict[PlainName, Scenario] = Field(min_length=1, max_length=MAX_SCENARIOS)
    variables: dict[str, Variable] = Field(min_length=1, max_length=MAX_VARIABLES)
    cost: CostConfig = Field(default_factory=CostConfig)
    constraints: dict[str, Constraint] = Field(
        default_factory=dict, validate_default=True,  # the defaults are validated as well
        description="name -> limit (min/max with unit) or off; defaults: gain_margin >= 6 dB, "
                    "phase_margin >= 45 deg")
    optimiser: OptimiserConfig = Field(default_factory=OptimiserConfig)
    requirements: RequirementsConfig = Field(
        default_factory=RequirementsConfig,
        description="with an acceptance spec (--spec): its limits as requirements")

    @field_validator("variables")
    @classmethod
    def _variables(cls, v: dict[str, Variable]) -> dict[str, Variable]:
        for name, var in v.items():
            if name not in CONTROLLER_PARAMS:
                hint = (" (a plant parameter: tuning changes the controller, not the actuator)"
                        if name in BY_NAME else "")
                raise _at(name, f"unknown variable{hint}; expected one of "
                                f"{', '.join(CONTROLLER_PARAMS)}")
            for k, bound in zip(("lower", "upper"), var.bounds, strict=True):
                try:
                    check_value(name, bound)
                except Exception as exc:  # noqa: BLE001 - check_value raises EmaError
                    raise _at(f"{name}.bounds", f"{k} bound: {exc}") from None
                if name in FRACTIONS and not 0.0 <= bound <= 1.0:
                    raise _at(f"{name}.bounds", f"{k} bound {bound:g}: {name} lies in [0, 1]")
        return v

    @field_validator("constraints", mode="before")
    @classmethod
    def _with_defaults(cls, v: Any) -> Any:
        if isinstance(v, dict):  # the defaults stay unless named (off removes one)
            return {**DEFAULT_CONSTRAINTS, **_off_words(v)}
        return v

    @field_validator("constraints")
    @classmethod
    def _known(cls, v: dict[str, Any]) -> dict[str, Any]:
        return _check_constraints(v)

    @model_validator(mode="after")
    def _grid(self) -> TuneConfig:
        sim = self.simulation
        if sim.duration_s / sim.dt_s > 1e8:
            raise _at("simulation", "more than 1e8 steps per run; use a larger dt_s or a "
                                    "shorter duration_s")
        for name, sc in self.scenarios.items():
            if sc.input.start_s >= sim.duration_s:
                raise _at(f"scenarios.{name}.input.start_s",
                          f"{sc.input.start_s:g} s is not before the end of the run "
                          f"(simulation.duration_s {sim.duration_s:g} s)")
            for var in self.variables:
                if var in sc.plant:
                    raise _at(f"scenarios.{name}.plant.{var}",
                              f"{var} is a free variable; a scenario cannot fix it")
        return self

    def constraints_of(self, scenario: str) -> dict[str, Limit]:
        """The constraints of ``scenario``: the global ones, replaced by its own (off: none)."""
        merged = {**self.constraints, **self.scenarios[scenario].constraints}
        return {k: v for k, v in merged.items() if v != "off"}
