"""Schema of an acceptance spec (``ema acceptance SPEC.yaml``, e.g. configs/acceptance.yaml).

A spec names the actuator under test (a run config and SI overrides) and a battery of tests,
each a mapping entry ``NAME: {test: KIND, ...settings, limits: {METRIC: {min|max, unit}}}``.
Every limit carries its unit, checked against the metric's dimension (a time limit in ``deg``
is an error) and converted to SI here, once (:data:`ema_cli.units.UNITS`).

Test kinds and their metrics (dimension):

=================== ===============================================================
step                rise_time (time), overshoot (percent), settling_time (time),
                    steady_state_error (angle), peak_current (current)
frequency_response  bandwidth (frequency), phase_lag (angle, at ``phase_at_hz``),
                    peak_gain (decibel); each at every amplitude of ``amplitudes_deg``
margins             gain_margin (decibel), phase_margin (angle); each loop of ``loops``
threshold           threshold (angle)
hysteresis          hysteresis (angle), free_play (angle)
load_deflection     stiffness (stiffness), free_play (angle)
dynamic_stiffness   dynamic_stiffness (stiffness)
no_load_rate        rate (rate)
=================== ===============================================================
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any, ClassVar, Literal

from pydantic import Field, PrivateAttr, field_validator, model_validator

from ema_cli.config.base import (
    FiniteFloat,
    PlainName,
    PositiveFloat,
    PositiveInt,
    Strict,
    tagged_union,
)
from ema_cli.config.limits import DUTY_METRICS, ActuatorSpec, Limit, _at
from ema_cli.errors import EmaError
from ema_cli.units import SI_UNIT, units_of

MAX_TESTS = 50  # tests in one spec, at most [-]
MAX_DURATION_S = 120.0  # simulated duration of one test run, at most [s]
MIN_STEPS = 10  # a duration, a quarter period or a branch spans this many time steps, at least [-]
SINE_PERIOD_STEPS = 88  # steps in one period of a sine test, at least (analysis.freqresp) [-]
MARGINS_F_MIN_HZ = 1e-3  # lowest frequency of the margins' search grid [Hz]


def _sine_seconds(f_hz: float) -> float:
    """Simulated seconds of one sinestream frequency at ``f_hz``, at most (analysis.freqresp:
    max(3 periods, 0.3 s) of settling and 4 measured periods)."""
    return max(3.0 / f_hz, 0.3 + 1.0 / f_hz) + 4.0 / f_hz


def _article(word: str) -> str:
    return "an" if word[0] in "aeiou" else "a"


class _Test(Strict):
    METRICS: ClassVar[dict[str, str]] = {}
    """The metrics of the kind and their dimensions (:data:`ema_cli.units.UNITS`)."""

    limits: dict[str, Limit] = Field(description="metric -> limit; at least one")
    overrides: dict[str, Any] = Field(
        default_factory=dict, alias="set",
        description="actuator settings for this test only, by dotted path of the run config "
                    "(e.g. controller.position_feedback: motor)")

    @model_validator(mode="after")
    def _limits(self) -> _Test:
        kind = self.test  # type: ignore[attr-defined]
        known = type(self).METRICS
        if not self.limits:
            raise _at("limits", f"a {kind} test needs at least one limit; its metrics: "
                                f"{', '.join(known)}")
        for metric, lim in self.limits.items():
            if metric not in known:
                raise _at(f"limits.{metric}", f"unknown metric for a {kind} test; expected "
                                              f"one of {', '.join(known)}")
            dim = known[metric]
            if lim.dimension != dim:
                raise _at(f"limits.{metric}.unit",
                          f"{lim.unit!r} is a unit of {lim.dimension}, {metric} is "
                          f"{_article(dim)} {dim}; expected one of {', '.join(units_of(dim))}")
        return self

    def spans(self) -> list[tuple[str, float, int]]:
        """(key, time span [s], time steps it must hold at least) of every setting that
        sets how finely the test samples time: a spec whose span holds fewer steps of the
        actuator's ``dt`` cannot measure and is refused (:func:`check_measurable`)."""
        return []

    def sim_seconds(self) -> float:
        """The simulated time of the test (cases x seconds, summed over its kernel calls) [s],
        at most: with ``dt`` it gives the test's integration steps before it runs."""
        return 0.0


class StepTest(_Test):
    """A step of the position reference; the kernel's step metrics."""

    METRICS: ClassVar[dict[str, str]] = {
        "rise_time": "time", "overshoot": "percent", "settling_time": "time",
        "steady_state_error": "angle", "peak_current": "current"}

    test: Literal["step"]
    amplitude_deg: FiniteFloat = Field(description="step size [deg], load side (not 0)")
    duration_s: PositiveFloat = Field(1.0, le=MAX_DURATION_S, description="[s]")

    @field_validator("amplitude_deg")
    @classmethod
    def _nonzero(cls, v: float) -> float:
        if v == 0:
            raise ValueError("a step needs a nonzero amplitude [deg]")
        return v

    def sim_seconds(self) -> float:
        return self.duration_s

    def spans(self) -> list[tuple[str, float, int]]:
        return [("duration_s", self.duration_s, MIN_STEPS)]


class FrequencyResponseTest(_Test):
    """A sinestream at each amplitude: -3 dB bandwidth, phase lag at a frequency, peak gain."""

    METRICS: ClassVar[dict[str, str]] = {"bandwidth": "frequency", "phase_lag": "angle",
                                         "peak_gain": "decibel"}

    test: Literal["frequency_response"]
    amplitudes_deg: list[PositiveFloat] = Field(min_length=1, max_length=10)
    f_min_hz: PositiveFloat = 0.5
    f_max_hz: PositiveFloat = 50.0
    n: PositiveInt = Field(20, ge=2, le=200, description="log-spaced frequencies")
    phase_at_hz: PositiveFloat | None = Field(None, description="frequency of phase_lag [Hz]")

    @model_validator(mode="after")
    def _range(self) -> FrequencyResponseTest:
        if not self.f_min_hz < self.f_max_hz:
            raise ValueError(f"f_min_hz ({self.f_min_hz}) must be below f_max_hz "
                             f"({self.f_max_hz})")
        if "phase_lag" in self.limits and self.phase_at_hz is None:
            raise ValueError("a phase_lag limit needs phase_at_hz (the frequency [Hz])")
        if self.phase_at_hz is not None and not (self.f_min_hz <= self.phase_at_hz
                                                 <= self.f_max_hz):
            raise ValueError(f"phase_at_hz ({self.phase_at_hz}) must lie within f_min_hz.."
                             f"f_max_hz ({self.f_min_hz}..{self.f_max_hz})")
        return self

    def sim_seconds(self) -> float:
        return len(self.amplitudes_deg) * (self.n + 1) * _sine_seconds(self.f_min_hz)

    def spans(self) -> list[tuple[str, float, int]]:
        return [("f_max_hz", 1.0 / self.f_max_hz, SINE_PERIOD_STEPS)]


class MarginsTest(_Test):
    """Gain and phase margins of the linear limit, each loop broken in turn."""

    METRICS: ClassVar[dict[str, str]] = {"gain_margin": "decibel", "phase_margin": "angle"}

    test: Literal["margins"]
    loops: list[Literal["position", "speed"]] = Field(["position", "speed"], min_length=1)
    f_max_hz: PositiveFloat = Field(
        1e5, gt=10 * MARGINS_F_MIN_HZ, le=1e7,
        description="highest frequency searched for crossovers [Hz] (from 1e-3 Hz)")


class ThresholdTest(_Test):
    """The smallest step the load follows to ``fraction`` of its size within ``within_s``."""

    METRICS: ClassVar[dict[str, str]] = {"threshold": "angle"}

    test: Literal["threshold"]
    fraction: PositiveFloat = Field(0.5, le=1.0, description="share of the step to reach")
    within_s: PositiveFloat = Field(0.5, le=MAX_DURATION_S, description="[s]")
    search_deg: tuple[PositiveFloat, PositiveFloat] = Field(
        (1e-4, 1.0), description="LO < HI: the bisection's bracket [deg]")
    rtol: PositiveFloat = Field(0.01, le=0.5, description="relative resolution of the result")

    @field_validator("search_deg")
    @classmethod
    def _bracket(cls, v: tuple[float, float]) -> tuple[float, float]:
        if not v[0] < v[1]:
            raise ValueError(f"search_deg needs LO < HI, got {list(v)}")
        return v

    @model_validator(mode="after")
    def _decidable(self) -> ThresholdTest:
        lim = self.limits.get("threshold")
        if lim is None or lim.dimension != "angle":
            return self
        lo, hi = lim.si()
        floor, ceiling = (math.radians(v) for v in self.search_deg)
        if floor > hi:
            raise _at("search_deg", f"the search floor {self.search_deg[0]:g} deg is above the "
                                    f"limit (max {lim.max:g} {lim.unit}): every outcome would "
                                    "be at or above the floor; lower search_deg")
        if ceiling < lo:
            raise _at("search_deg", f"the search ceiling {self.search_deg[1]:g} deg is below "
                                    f"the limit (min {lim.min:g} {lim.unit}): every outcome "
                                    "would be at or below the ceiling; raise search_deg")
        return self

    def sim_seconds(self) -> float:
        return 8 * 13 * self.within_s  # 8 steps a batch, the first batch and 12 rounds at most

    def spans(self) -> list[tuple[str, float, int]]:
        return [("within_s", self.within_s, MIN_STEPS)]


class HysteresisTest(_Test):
    """A slow triangle command (0 -> +A in a quarter period, then +A -> -A -> +A per period),
    measured on the last period."""

    METRICS: ClassVar[dict[str, str]] = {"hysteresis": "angle", "free_play": "angle"}

    test: Literal["hysteresis"]
    amplitude_deg: PositiveFloat = 2.0
    period_s: PositiveFloat = Field(8.0, le=MAX_DURATION_S)
    cycles: PositiveInt = Field(1, ge=1, le=10)

    @model_validator(mode="after")
    def _length(self) -> HysteresisTest:
        if self.sim_seconds() > MAX_DURATION_S:
            raise ValueError(f"period_s x (cycles + 1/4) = {self.sim_seconds():g} s is longer "
                             f"than {MAX_DURATION_S:g} s")
        return self

    def sim_seconds(self) -> float:
        return self.period_s * (self.cycles + 0.25)

    def spans(self) -> list[tuple[str, float, int]]:
        return [("period_s", self.period_s / 4, MIN_STEPS)]  # a quarter period: one ramp


class LoadDeflectionTest(_Test):
    """Motor locked; a slow load-torque triangle 0 -> +T -> -T -> 0 over ``period_s``."""

    METRICS: ClassVar[dict[str, str]] = {"stiffness": "stiffness", "free_play": "angle"}

    test: Literal["load_deflection"]
    torque_nm: PositiveFloat = Field(description="peak load torque [N*m]")
    period_s: PositiveFloat = Field(6.0, le=MAX_DURATION_S)
    fit_fraction: PositiveFloat = Field(
        0.25, lt=1.0, description="the lines are fitted where |T| >= this share of the peak")

    def sim_seconds(self) -> float:
        return self.period_s

    def spans(self) -> list[tuple[str, float, int]]:
        return [("period_s", self.period_s / 4, MIN_STEPS)]  # a quarter period: one ramp


class DynamicStiffnessTest(_Test):
    """A sine load torque, closed loop: min over frequency of |T / theta_L|."""

    METRICS: ClassVar[dict[str, str]] = {"dynamic_stiffness": "stiffness"}

    test: Literal["dynamic_stiffness"]
    amplitude_nm: PositiveFloat = 1.0
    f_min_hz: PositiveFloat = 0.5
    f_max_hz: PositiveFloat = 50.0
    n: PositiveInt = Field(20, ge=2, le=200)

    @model_validator(mode="after")
    def _range(self) -> DynamicStiffnessTest:
        if not self.f_min_hz < self.f_max_hz:
            raise ValueError(f"f_min_hz ({self.f_min_hz}) must be below f_max_hz "
                             f"({self.f_max_hz})")
        return self

    def sim_seconds(self) -> float:
        return (self.n + 16) * _sine_seconds(self.f_min_hz)  # the grid and 2 x 8 refinements

    def spans(self) -> list[tuple[str, float, int]]:
        return [("f_max_hz", 1.0 / self.f_max_hz, SINE_PERIOD_STEPS)]


class NoLoadRateTest(_Test):
    """The peak load rate on a large step, no load."""

    METRICS: ClassVar[dict[str, str]] = {"rate": "rate"}

    test: Literal["no_load_rate"]
    amplitude_deg: PositiveFloat = 40.0
    duration_s: PositiveFloat = Field(1.0, le=MAX_DURATION_S)

    def sim_seconds(self) -> float:
        return self.duration_s

    def spans(self) -> list[tuple[str, float, int]]:
        return [("duration_s", self.duration_s, MIN_STEPS)]


class DutyTest(_Test):
    """A mission profile (``ema duty``) on the actuator under test: its winding temperature
    and the other duty metrics against the test's limits (the profile's own actuator and
    limits are not used)."""

    METRICS: ClassVar[dict[str, str]] = DUTY_METRICS

    test: Literal["duty"]
    profile: str | dict[str, Any] = Field(
        description="the profile: a YAML file relative to the spec, or the profile inline")
    insulation: str = Field("F", description="insulation class (A E B F H N R) or its limit "
                                             "('150 degC'): the 10 K rule counts from it")
    _folder: Path | None = PrivateAttr(default=None)

    def bind(self, folder: Path | None) -> None:
        """The folder a relative ``profile`` is read from (the spec's)."""
        self._folder = folder

    def load_profile(self) -> Any:
        """The validated profile (``config.duty.DutyProfile``); EmaError naming the key."""
        from ema_cli.config.duty import DutyProfile
        from ema_cli.config.loader import load_config

        src: Any = self.profile
        if isinstance(src, str):
            path = (self._folder / src) if self._folder is not None else Path(src)
            if not path.is_file():
                raise EmaError(f"profile: '{src}' is not a file (a mission profile, relative "
                               "to the spec)")
            src = path
        return load_config(src, (), DutyProfile)

    def sim_seconds(self) -> float:
        return self.load_profile().sim_seconds()


_KINDS: dict[str, type[_Test]] = {
    "step": StepTest, "frequency_response": FrequencyResponseTest, "margins": MarginsTest,
          "threshold": ThresholdTest, "hysteresis": HysteresisTest,
          "load_deflection": LoadDeflectionTest, "dynamic_stiffness": DynamicStiffnessTest,
          "no_load_rate": NoLoadRateTest, "duty": DutyTest}


METRICS: dict[str, dict[str, str]] = {k: dict(cls.METRICS) for k, cls in _KINDS.items()}
"""The metrics of each test kind and their dimensions (from each schema's ``METRICS``)."""


TestSpec = tagged_union("test", _KINDS)


class AcceptanceSpec(Strict):
    """An acceptance battery: the actuator and its tests."""

    name: PlainName
    description: str = ""
    actuator: ActuatorSpec = Field(default_factory=ActuatorSpec)
    tests: dict[PlainName, TestSpec] = Field(min_length=1, max_length=MAX_TESTS)

    @field_validator("tests", mode="before")
    @classmethod
    def _kinds(cls, v: Any) -> Any:
        if isinstance(v, dict):
            for name, entry in v.items():
                if not isinstance(entry, dict):
                    raise _at(name, "expected a mapping with test: KIND, its settings and "
                                    "limits")
                if "test" not in entry:
                    raise _at(f"{name}.test", f"missing: the test kind, one of "
                                              f"{', '.join(METRICS)}")
                if not isinstance(entry["test"], str) or entry["test"] not in METRICS:
                    raise _at(f"{name}.test", f"unknown test {entry['test']!r}; expected one "
                                              f"of {', '.join(METRICS)}")
        return v

    def si_unit(self, test: str, metric: str) -> str:
        return SI_UNIT[METRICS[self.tests[test].test][metric]]


TEST_KINDS = tuple(METRICS)


def check_measurable(name: str, test: _Test, dt: float) -> None:
    """Refuse a test that cannot measure with the time step ``dt`` [s] of its actuator: a
    duration or period spanning fewer time steps than it needs (EmaError naming the key)."""
    from ema_cli.limits import check_steps

    check_steps(test.sim_seconds() / dt, f"tests.{name} ({test.test})",
                f"the actuator's dt_s = {dt:g} s is too fine for it: raise simulation.dt_s "
                "(of the actuator, or in the test's set:), or shorten the test")
    for key, span, steps in test.spans():
        if span < steps * dt * (1 - 1e-9):
            value = getattr(test, key)
            raise EmaError(f"tests.{name}.{key}: {value:g} gives {span / dt:.3g} time steps of "
                           f"the actuator's dt_s = {dt:g} s where the {test.test} test needs "
                           f"{steps} at least; {'lower' if key.startswith('f_') else 'lengthen'}"
                           f" {key} (or reduce simulation.dt_s)")
