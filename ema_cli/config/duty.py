"""Schema of a mission (duty) profile (``ema duty PROFILE.yaml``, e.g. configs/duty/tvc.yaml).

A profile is a list of segments, each a one-key mapping, run in order (and the whole list
``repeat`` times)::

    name: tvc
    actuator: {config: null}          # a run config (relative to the profile) and overrides
    stroke: 30 deg                    # centre to either end: bare numbers are its fractions
    ambient: 40 degC                  # default: the actuator's (drive.thermal.ambient)
    load: {spring: 25 N*m/rad}        # every segment's load unless it gives its own
    segments:
      - sine: {amplitude: 0.95, frequency_hz: 0.3, cycles: 3700}
      - move: {to: 0.5, speed: 20 deg/s, accel: 200 deg/s^2}
      - dwell: {duration_s: 60, load: {force: 5 N*m}}
      - repeat: {count: 100, segments: [{move: ...}, {dwell: ...}]}
    limits:                           # PASS/FAIL/INCONCLUSIVE (default: winding <= insulation)
      winding_temperature: {max: 155, unit: degC}
    life: {dynamic_load_rating: 400 N*m}

Positions and amplitudes are a fraction of ``stroke`` (a bare number) or a value with a unit of
the axis (``'5 deg'``, ``'12 mm'``); speeds and accelerations likewise (per second, per second
squared). Temperatures are degC (a bare number) or K. Values are checked here as far as the
schema goes; what needs the actuator (its axis, its time step) is checked by ``duty.profile``
before anything runs, each error one line naming the key.
"""

from __future__ import annotations

import math
from typing import Any, ClassVar, Literal

from pydantic import Field, field_validator, model_validator

from ema_cli.config.base import (
    FiniteFloat,
    PlainName,
    PositiveFloat,
    Strict,
    tagged_union,
)
from ema_cli.config.limits import DUTY_METRICS, ActuatorSpec, Limit
from ema_cli.config.run import KEY_MARK
from ema_cli.units import units_of

Q = float | int | str
"""A value: a number (a fraction of the stroke, or SI where said) or ``"<number> <unit>"``."""
MAX_SEGMENTS = 1000  # segments in a profile, nested ones included [-]
MAX_REPEAT = 10**6  # repetitions of a block or of the profile [-]
MAX_CYCLES = 10**9  # cycles of one sine block [-]
KINDS = ("sine", "move", "dwell", "repeat")
"""The segment kinds."""
METRICS = DUTY_METRICS
"""A duty run's metrics and their dimensions (``config.acceptance.DUTY_METRICS``)."""


def _at(key: str, message: str) -> ValueError:
    return ValueError(f"{KEY_MARK}{key}{KEY_MARK}{message}")


class SegmentLoad(Strict):
    """The external load during a segment, along +x (load side)."""

    force: Q = Field(0.0, description="constant force (torque) [N | N*m]")
    spring: Q = Field(0.0, description="hinge gradient: force -spring*x [N*m/rad | N/m]")
    profile: list[tuple[FiniteFloat, FiniteFloat]] | None = Field(
        None, description="[[t_s, force (SI)], ...] over one cycle of the segment, added to "
                          "the force (linear between rows), repeated every cycle")

    @field_validator("profile")
    @classmethod
    def _rows(cls, v: list[tuple[float, float]] | None) -> list[tuple[float, float]] | None:
        if v is not None:
            if len(v) < 2:
                raise ValueError("a load profile needs at least 2 rows [t_s, force]")
            t = [r[0] for r in v]
            if any(b <= a for a, b in zip(t, t[1:], strict=False)) or t[0] < 0:
                raise ValueError("the profile's t_s must start at >= 0 and increase")
        return v


class _Segment(Strict):
    load: SegmentLoad | None = Field(None, description="the segment's load (default: the "
                                                        "profile's)")
    ambient: Q | None = Field(None, description="ambient temperature [degC or K] (default: "
                                                "the profile's)")
    label: str = Field("", max_length=64, description="a name for reports")


def _whole(v: Any, what: str, hi: int) -> int:
    if isinstance(v, bool) or not isinstance(v, int | float) or v != int(v):
        raise ValueError(f"{what} must be a whole number, got {v!r}")
    if v < 1:
        raise ValueError(f"{what} must be >= 1, got {v!r} (a negative or zero count runs "
                         "nothing)")
    if v > hi:
        raise ValueError(f"{what} must be <= {hi}, got {v!r}")
    return int(v)


class Sine(_Segment):
    """``centre + amplitude*sin(2*pi*f*t)`` for a whole number of cycles (from the centre,
    which defaults to where the previous segment ended)."""

    kind: Literal["sine"] = "sine"
    amplitude: Q = Field(description="fraction of the stroke, or a position with its unit")
    frequency_hz: PositiveFloat = Field(description="[Hz]")
    cycles: Any = Field(description=f"whole cycles, 1..{MAX_CYCLES}")
    centre: Q | None = Field(None, description="centre position (default: where the profile "
                                               "is)")

    @field_validator("cycles")
    @classmethod
    def _cycles(cls, v: Any) -> int:
        return _whole(v, "cycles", MAX_CYCLES)


class Move(_Segment):
    """A trapezoidal move (accelerate, cruise, decelerate; a triangle when too short to
    reach ``speed``) to ``to``."""

    kind: Literal["move"] = "move"
    to: Q = Field(description="target position: fraction of the stroke, or with its unit")
    speed: Q = Field(description="cruise speed: fraction of the stroke per s, or with a unit")
    accel: Q = Field(description="acceleration and deceleration: fraction of the stroke per "
                                 "s^2, or with a unit")


class Dwell(_Segment):
    """Hold the position for ``duration_s``."""

    kind: Literal["dwell"] = "dwell"
    duration_s: PositiveFloat = Field(description="[s]")


class Repeat(Strict):
    """A cycle of segments run ``count`` times (it must end where it starts)."""

    kind: Literal["repeat"] = "repeat"
    count: Any = Field(description=f"repetitions, 1..{MAX_REPEAT}")
    segments: list[Any] = Field(min_length=1, description="the cycle's segments (no repeat)")
    label: str = Field("", max_length=64)

    @field_validator("count")
    @classmethod
    def _count(cls, v: Any) -> int:
        return _whole(v, "count", MAX_REPEAT)

    @field_validator("segments", mode="before")
    @classmethod
    def _inner(cls, v: Any) -> Any:
        return [_parse(s, k, nested=True) for k, s in enumerate(_as_list(v))]


Leaf = tagged_union("kind", {"sine": Sine, "move": Move, "dwell": Dwell})


def _as_list(v: Any) -> list[Any]:
    if not isinstance(v, list):
        raise ValueError("expected a list of segments, each a one-key mapping "
                         f"({', '.join(KINDS)})")
    return v


def _parse(entry: Any, k: int, nested: bool = False) -> Any:
    """One ``{kind: {...}}`` entry -> the validated segment (a one-line error naming it)."""
    from pydantic import TypeAdapter, ValidationError

    if not isinstance(entry, dict) or len(entry) != 1:
        raise _at(str(k), f"expected a one-key mapping, the segment kind ({', '.join(KINDS)}) "
                          "with its settings")
    (kind, body), = entry.items()
    allowed = KINDS[:3] if nested else KINDS
    if kind not in allowed:
        why = " (a repeat block holds no repeat)" if kind == "repeat" else ""
        raise _at(f"{k}", f"unknown segment kind {kind!r}{why}; expected one of "
                          f"{', '.join(allowed)}")
    if not isinstance(body, dict):
        raise _at(f"{k}.{kind}", "expected a mapping of its settings")
    cls = {"sine": Sine, "move": Move, "dwell": Dwell, "repeat": Repeat}[kind]
    try:
        return TypeAdapter(cls).validate_python({**body, "kind": kind})
    except ValidationError as exc:
        err = exc.errors()[0]
        loc = ".".join(str(x) for x in err["loc"])
        msg = err["msg"].removeprefix("Value error, ")
        if msg.startswith(KEY_MARK):
            key, msg = msg[1:].split(KEY_MARK, 1)
            loc = f"{loc}.{key}" if loc else key
        if err["type"] == "extra_forbidden":
            msg = "unknown key"
        raise _at(f"{k}.{kind}" + (f".{loc}" if loc else ""), msg) from None


class Life(Strict):
    """The screw's or gear's rating (ISO 281 / ISO 3408-5) and the insulation's reference
    life (IEC 60085)."""

    dynamic_load_rating: Q | None = Field(
        None, description="basic dynamic load rating C: the load at which 90 % survive 1e6 "
                          "revolutions [N (a screw) | N*m (a rotary output)]; absent: no L10")
    exponent: PositiveFloat = Field(3.0, le=10.0, description="life exponent p "
                                                              "(3 balls, 10/3 rollers)")
    insulation_life_h: PositiveFloat = Field(
        20000.0, description="the insulation's life at its class temperature [h] (halved "
                             "every 10 K above it)")


class DutySimulation(Strict):
    """How the segments' mechanics are simulated."""

    dt_s: PositiveFloat | None = Field(None, description="integration step [s] (default: the "
                                                          "actuator's simulation.dt_s)")
    settle_s: PositiveFloat = Field(0.5, le=60.0, description="simulated before a cycle is "
                                                             "measured (whole cycles) [s]")


class DutyProfile(Strict):
    """A mission profile: the actuator, the segments, the limits (module docstring)."""

    METRICS: ClassVar[dict[str, str]] = METRICS
    name: PlainName
    description: str = ""
    actuator: ActuatorSpec = Field(default_factory=ActuatorSpec)
    stroke: Q | None = Field(None, description="centre to either end (a position with its "
                                               "unit); bare numbers elsewhere are fractions of it")
    start: Q = Field(0.0, description="where the profile starts (fraction of the stroke or "
                                      "with a unit)")
    ambient: Q | None = Field(None, description="ambient [degC or K] (default: the actuator's)")
    load: SegmentLoad = Field(default_factory=SegmentLoad)
    repeat: Any = Field(1, description=f"the whole list run this many times, 1..{MAX_REPEAT}")
    segments: list[Any] = Field(min_length=1, description="the segments, in order")
    limits: dict[str, Limit] = Field(
        default_factory=dict, description="metric -> limit (default: winding_temperature at "
                                          "most the insulation's limit)")
    life: Life = Field(default_factory=Life)
    simulation: DutySimulation = Field(default_factory=DutySimulation)

    @field_validator("repeat")
    @classmethod
    def _repeat(cls, v: Any) -> int:
        return _whole(v, "repeat", MAX_REPEAT)

    @field_validator("segments", mode="before")
    @classmethod
    def _segments(cls, v: Any) -> Any:
        return [_parse(s, k) for k, s in enumerate(_as_list(v))]

    @field_validator("limits")
    @classmethod
    def _limits(cls, v: dict[str, Limit]) -> dict[str, Limit]:
        return check_limits(v)

    def sim_seconds(self) -> float:
        """The simulated seconds of the segments' windows at two resistances, about (a move
        counts its distance at its speed; ``duty.mechanics.window`` gives the exact ones) [s]:
        what the step cap checks before anything runs."""
        settle = self.simulation.settle_s
        total = 0.0
        for seg in self.segments:
            subs = seg.segments if seg.kind == "repeat" else [seg]
            period = sum(_rough_seconds(x) for x in subs)
            count = seg.count if seg.kind == "repeat" else (
                seg.cycles if seg.kind == "sine" else 1)
            if seg.kind == "sine":
                period = 1.0 / seg.frequency_hz
            if seg.kind == "dwell":
                total += min(seg.duration_s, settle + 0.2)
                continue
            n_s = max(1, math.ceil(settle / period - 1e-9)) if period > 0 else 1
            total += period * min(count, n_s + 2)
        return 2.0 * total

    @model_validator(mode="after")
    def _size(self) -> DutyProfile:
        n = sum(len(s.segments) if s.kind == "repeat" else 1 for s in self.segments)
        if n > MAX_SEGMENTS:
            raise _at("segments", f"{n} segments, more than {MAX_SEGMENTS}")
        return self


def _rough_seconds(seg: Any) -> float:
    """A segment's duration, a move's estimated by its distance over its speed when both are
    fractions of the stroke (else 1 s) [s]."""
    if seg.kind == "sine":
        return seg.cycles / seg.frequency_hz
    if seg.kind == "dwell":
        return seg.duration_s
    if isinstance(seg.to, int | float) and isinstance(seg.speed, int | float) and seg.speed:
        return 2.0 * abs(seg.to) / abs(seg.speed) + 1.0
    return 1.0


def check_limits(v: dict[str, Limit]) -> dict[str, Limit]:
    """Each limit names a duty metric and has a unit of its dimension (ValueError naming it)."""
    for metric, lim in v.items():
        if metric not in METRICS:
            raise _at(metric, f"unknown metric; expected one of {', '.join(METRICS)}")
        dim = METRICS[metric]
        if lim.dimension != dim:
            raise _at(f"{metric}.unit", f"{lim.unit!r} is a unit of {lim.dimension}, {metric} "
                                        f"is a {dim}; expected one of {', '.join(units_of(dim))}")
    return v
