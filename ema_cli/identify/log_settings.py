"""Settings of the log identifications (pydantic, frozen, unknown keys are errors): the
closed-loop fit, the friction sweep and synthetic data (``ema identify --closed-loop``,
``--friction-sweep``, ``--make-data``). SI inside, units in the names or descriptions.
"""

from __future__ import annotations

from typing import Any, Literal

from pydantic import Field, field_validator, model_validator

from ema_cli.config.base import (
    FiniteFloat,
    NonNegFloat,
    NonNegInt,
    PlainName,
    PositiveFloat,
    PositiveInt,
    Seed,
    Strict,
)
from ema_cli.config.run import KEY_MARK
from ema_cli.errors import EmaError
from ema_cli.identify.closed_loop.problem import CHANNELS, DEFAULT_FREE
from ema_cli.model.params import check_value

Scalar = float | int | str
DEFAULT_DT_S = 1e-5  # fine step: polish, uncertainty, profile (docs/model.md §6) [s]
DEFAULT_GA_DT_S = 5e-5  # the GA's step (see docs/identification.md for the check) [s]
DEFAULT_CL_POP = 64  # closed-loop GA population: 4 chunks of 16 lanes, 2 per core [individuals]
DEFAULT_CL_GENERATIONS = 40  # closed-loop GA generations, the initial one included
DEFAULT_MAX_ITER = 30  # most Jacobian evaluations of the least-squares polish
DEFAULT_PROFILE_POINTS = 41  # alpha values of the cost profile [points]
DEFAULT_GA_HORIZON_S = 1.0  # the GA fits the log's first second (docs/identification.md) [s]
MAX_CL_POP = 4096  # the largest closed-loop population [individuals]
MAX_CL_GENERATIONS = 10_000  # the most closed-loop generations
MAX_NOISE_PCT = 100.0  # the largest noise of synthetic data [% of the RMS]
DEFAULT_STARTS = 8  # multiple shooting: Sobol starts over the bounds
DEFAULT_SEGMENT_S = 0.05  # multiple shooting: segment length [s] (docs/identification.md)
DEFAULT_MS_ITER = 60  # multiple shooting: most joint LM iterations of a start
DEFAULT_LENGTHEN_S = (0.1, 0.2, 0.4, 0.8, 1.6)  # multiple shooting: lengthened to these [s]
MAX_STARTS = 256  # the most multiple-shooting starts


def _check_plant(v: dict[str, Any]) -> dict[str, Any]:
    for name, value in v.items():
        try:
            check_value(name, value)
        except EmaError as exc:
            raise ValueError(f"{KEY_MARK}{name}{KEY_MARK}{exc.message}") from None
    return v


class ClosedLoopGA(Strict):
    """The GA of a closed-loop fit (the improved real-coded GA of ``optim.ga``)."""

    pop: PositiveInt = Field(DEFAULT_CL_POP, ge=2, le=MAX_CL_POP,
                             description=f"population size, 2 .. {MAX_CL_POP}")
    generations: PositiveInt = Field(
        DEFAULT_CL_GENERATIONS, le=MAX_CL_GENERATIONS,
        description="evaluated generations, the initial one included")
    patience: NonNegInt = Field(0, le=MAX_CL_GENERATIONS,
                                description="early stop after N stale generations (0: off)")


class ClosedLoopShooting(Strict):
    """The multiple-shooting search of a closed-loop fit (docs/identification.md)."""

    starts: PositiveInt = Field(DEFAULT_STARTS, ge=2, le=MAX_STARTS,
                                description=f"Sobol starts over the bounds, 2 .. {MAX_STARTS}")
    segment_s: PositiveFloat = Field(DEFAULT_SEGMENT_S, description="segment length [s]")
    max_iter: PositiveInt = Field(DEFAULT_MS_ITER, le=1000,
                                  description="most joint Levenberg-Marquardt iterations")
    lengthen_s: list[PositiveFloat] = Field(
        default_factory=lambda: list(DEFAULT_LENGTHEN_S),
        description="longer segment lengths [s] the best start continues on, in order "
                    "(fewer free states: less bias and variance; a length that leaves fewer "
                    "than 2 segments is skipped, as is one that costs the fit, and on fewer "
                    "than 10 the covariance is taken on the segments cut into parts); [] for "
                    "none")
    tie_motor_angle: bool = Field(
        True, description="tie each segment's motor angle to the integral of the logged motor "
                          "speed between segment starts (kinematics; needs omega_motor_rpm "
                          "fitted); false: each segment's motor angle is free")


class ClosedLoopSettings(Strict):
    """Everything one ``ema identify --closed-loop`` run needs."""

    name: PlainName = Field("closed-loop", description="study name (a folder name)")
    data: str | None = Field(None, description="the log: .csv/.txt, .parquet/.pq or .mat (MATLAB "
                                               "v5 or v7.3) with t_s, theta_ref_deg, "
                                               "theta_load_deg [, omega_motor_rpm, current_a, "
                                               "voltage_cmd_v] (or mapped by columns)")
    columns: dict[str, str] | None = Field(
        None, description="column map: channel -> 'COLUMN[:UNIT]' (e.g. theta_load_deg: pos:rad; "
                          "units: time s|ms|us, angle deg|rad|mrad, speed rpm|rad/s|deg/s, "
                          "current A|mA, voltage V|mV; default the channel's own); null: the "
                          "file's columns carry the channel names")
    command: Literal["linear", "cubic"] = Field(
        "cubic", description="the command between the log's samples: cubic (a spline through "
                             "them: a smooth command sampled) or linear (straight lines)")
    window: tuple[FiniteFloat, FiniteFloat] | None = Field(
        None, description="[T0, T1]: fit only the samples with T0 <= t <= T1 [s, the log's own "
                          "time]; null: the whole log")
    free: dict[str, tuple[float, float]] = Field(
        default_factory=lambda: dict(DEFAULT_FREE),
        description="free parameters -> [LO, HI] in SI (names of `ema params`)")
    plant: dict[str, Scalar] = Field(default_factory=dict,
                                     description="fixed model parameters, SI (`ema params`)")
    channels: dict[str, PositiveFloat | Literal["auto"]] | None = Field(
        None, description="channels fitted -> scale in the channel's edge unit, or auto (its "
                          "noise estimate); null: every channel in the log, auto")
    dt_s: PositiveFloat = Field(DEFAULT_DT_S, description="integration step of the polish and "
                                                          "the uncertainty [s]")
    ga_dt_s: PositiveFloat | None = Field(DEFAULT_GA_DT_S,
                                          description="integration step of the GA [s] (null: dt_s)")
    ga_horizon_s: PositiveFloat | None = Field(
        DEFAULT_GA_HORIZON_S, description="the GA fits the log's first ga_horizon_s [s]; the "
        "polish then doubles the horizon up to the whole log (null, or polish: false: the "
        "GA fits the whole log)")
    free_contact: bool = Field(
        True, description="multiple shooting: free the contact's damping ratio zeta_t "
        "[0.02, 1], damping ramp contact_tau [0, 1 ms] and Hunt-Crossley share contact_hc "
        "[0, 1] as nuisance parameters unless plant or free names them (naming "
        "contact_tau or contact_hc states the law's shape: both are then fixed, e.g. "
        "contact_tau: 0 is the jump law); a real contact follows none of the model's laws; "
        "false: the model's values")
    search: Literal["shooting", "ga"] = Field(
        "shooting", description="shooting: multiple shooting from many starts (default); ga: "
        "the GA over the first ga_horizon_s, then a polish over growing horizons")
    shooting: ClosedLoopShooting = Field(default_factory=ClosedLoopShooting)
    ga: ClosedLoopGA = Field(default_factory=ClosedLoopGA)
    polish: bool = Field(True, description="least-squares polish after the GA")
    max_iter: PositiveInt = Field(DEFAULT_MAX_ITER, le=1000,
                                  description="most Jacobians of the polish")
    profile_points: PositiveInt = Field(DEFAULT_PROFILE_POINTS, ge=3, le=1001,
                                        description="alpha values of the cost profile")
    seed: Seed = Field(0, description="seed of the GA")

    @field_validator("plant")
    @classmethod
    def _plant(cls, v: dict[str, Any]) -> dict[str, Any]:
        return _check_plant(v)

    @field_validator("channels")
    @classmethod
    def _channels(cls, v: dict[str, Any] | None) -> dict[str, Any] | None:
        if v is None:
            return v
        if not v:
            raise ValueError("name at least one channel (or null: every channel in the log)")
        for key in v:
            if key not in CHANNELS:
                raise ValueError(f"{KEY_MARK}{key}{KEY_MARK}unknown channel; expected one of "
                                 f"{', '.join(CHANNELS)}")
        return v

    @field_validator("columns")
    @classmethod
    def _columns(cls, v: dict[str, str] | None) -> dict[str, str] | None:
        from ema_cli.identify.logs.channels import parse_column_spec

        for key, spec in (v or {}).items():
            try:
                parse_column_spec(key, spec)
            except EmaError as exc:
                raise ValueError(f"{KEY_MARK}{key}{KEY_MARK}{exc.message}") from None
        return v

    @field_validator("window")
    @classmethod
    def _window(cls, v: tuple[float, float] | None) -> tuple[float, float] | None:
        if v is not None and not v[1] > v[0]:
            raise ValueError(f"needs T0 < T1, got [{v[0]:g}, {v[1]:g}]")
        return v

    @model_validator(mode="after")
    def _check(self) -> ClosedLoopSettings:
        from ema_cli.identify.closed_loop.problem import check_free

        try:
            check_free(self.free, self.plant)
        except EmaError as exc:
            raise ValueError(exc.message) from None
        if self.search == "shooting" and self.shooting.segment_s < 20 * (self.ga_dt_s
                                                                        or self.dt_s):
            raise ValueError(f"shooting.segment_s ({self.shooting.segment_s:g} s) must be at "
                             "least 20 steps of ga_dt_s")
        if self.ga_dt_s is not None and self.ga_dt_s < self.dt_s:
            raise ValueError(f"ga_dt_s ({self.ga_dt_s:g} s) must not be finer than dt_s "
                             f"({self.dt_s:g} s)")
        return self


class FrictionSweepSettings(Strict):
    """Everything one ``ema identify --friction-sweep`` run needs."""

    name: PlainName = Field("friction-sweep", description="study name (a folder name)")
    data: str | None = Field(None, description="CSV with omega_rpm, torque_nm")
    delta: PositiveFloat = Field(1.0, le=10, description="Stribeck exponent, fixed [-]")
    vs_range: tuple[PositiveFloat, PositiveFloat] | None = Field(
        None, description="vs search range [rad/s] (null: min|w|/10 .. max|w|*10)")

    @field_validator("vs_range")
    @classmethod
    def _vs(cls, v: tuple[float, float] | None) -> tuple[float, float] | None:
        if v is not None and not v[1] > v[0]:
            raise ValueError(f"needs LO < HI, got [{v[0]:g}, {v[1]:g}]")
        return v


class MakeDataSettings(Strict):
    """Synthetic data (``ema identify --make-data KIND``): truths are the model defaults, the
    make-data defaults (alpha 3 mrad, friction on, sigma2 1e-4) and ``plant``."""

    kind: Literal["closed-loop", "friction-sweep"] = Field("closed-loop",
                                                          description="what to make")
    noise_pct: NonNegFloat = Field(0.0, le=MAX_NOISE_PCT,
                                   description="Gaussian noise, % of each channel's RMS")
    seed: Seed = Field(0, description="seed of the noise")
    plant: dict[str, Scalar] = Field(default_factory=dict,
                                     description="true model parameters, SI (`ema params`)")
    amplitude_deg: PositiveFloat = Field(5.0, le=180, description="chirp amplitude [deg]")
    freq_hz: PositiveFloat = Field(0.5, description="chirp start frequency [Hz]")
    freq_end_hz: PositiveFloat = Field(8.0, description="chirp end frequency [Hz]")
    duration_s: PositiveFloat = Field(4.0, le=3600, description="log duration [s]")
    sample_interval_s: PositiveFloat = Field(1e-3, description="log sample interval [s]")
    dt_s: PositiveFloat = Field(DEFAULT_DT_S, description="integration step [s]")
    speeds_rpm: tuple[PositiveFloat, PositiveFloat, PositiveInt] = Field(
        (1.0, 1000.0, 20), description="friction sweep: lowest, highest |speed| [rpm] and "
                                       "speeds per direction (log-spaced)")

    @field_validator("plant")
    @classmethod
    def _plant(cls, v: dict[str, Any]) -> dict[str, Any]:
        return _check_plant(v)

    @model_validator(mode="after")
    def _check(self) -> MakeDataSettings:
        from ema_cli.sim.grid import off_grid, plan_steps

        try:
            plan_steps(self.duration_s, self.sample_interval_s, None)
            plan_steps(self.duration_s, self.dt_s, self.sample_interval_s)
        except EmaError as exc:
            raise ValueError(exc.message) from None
        if bool(off_grid(self.sample_interval_s, self.dt_s)):
            raise ValueError("sample_interval_s must be a whole multiple of dt_s")
        if self.duration_s / self.dt_s > 1e8:
            raise ValueError("duration_s / dt_s is more than 1e8 steps")
        lo, hi, n = self.speeds_rpm
        if not hi > lo or n < 2 or n > 10_000:
            raise ValueError(f"speeds_rpm: needs LO < HI and 2 .. 10000 speeds, got {lo:g}, "
                             f"{hi:g}, {n}")
        return self
