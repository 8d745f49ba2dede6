"""The schema of one run (``ema simulate``; the part of every study config a simulation reads).

pydantic models, frozen, unknown keys are errors; units in the field names. A run config gives
the plant (SI overrides of the parameter table), the input signal and simulation grid (paper
units: degrees, seconds), the nonlinearities fixed for the run (paper names or
``type@location`` in the units of ``ema locations``) and the load, motor, controller and sensor
options. ``config.study`` extends it with what a sweep adds.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any, Literal

from pydantic import Field, field_validator, model_validator

from ema_cli.config.actuator import Actuator
from ema_cli.config.base import (
    FiniteFloat,
    NonNegFloat,
    PlainName,
    PositiveFloat,
    Seed,
    Strict,
)
from ema_cli.errors import EmaError
from ema_cli.model.nonlinearities import check_distinct, lookup, nonlinearity_updates
from ema_cli.model.params import check_value, resolve
from ema_cli.sim.grid import DEFAULT_DT, DEFAULT_OUTPUT_INTERVAL, off_grid, plan_steps
from ema_cli.units import RPM

Scalar = float | int | str


def as_value_error(exc: EmaError, key: str | None = None) -> ValueError:
    """An EmaError as a pydantic ValueError; ``key`` (a dict key) is folded into the key path."""
    return ValueError(f"{KEY_MARK}{key}{KEY_MARK}{exc.message}" if key else exc.message)


KEY_MARK = "\x00"
"""Wraps a dict key at the start of a validator message; ``loader.validate`` folds it into the
key path so errors read ``plant.kL: ...``."""


class InputSignalConfig(Strict):
    """One channel of a log as the run's input signal (held between its samples by default: a
    logged DAC output)."""

    path: str = Field(description="the log (CSV, Parquet, .mat)")
    column: str = Field(description="the channel's column or variable")
    unit: str | None = Field(None, description="its unit (V, A, N, N*m, ...; default SI)")
    time_column: str = Field("t_s", description="the log's time column [s]")
    hold: bool = Field(True, description="held between samples (true) or linear (false)")
    scale: FiniteFloat = Field(1.0, description="a factor applied to it (e.g. a gain)")


class InputConfig(Strict):
    """The position reference (load side), in degrees and seconds."""

    kind: Literal["step", "ramp", "sine", "chirp", "csv"] = Field(
        "step", description="signal shape")
    amplitude_deg: FiniteFloat = Field(
        20.0, description="step size, sine/chirp amplitude, or how far a ramp goes (it stops "
                          "|amplitude_deg| away, in the direction of rate_deg_s; 0: no end) [deg]")
    start_s: NonNegFloat = Field(
        0.0, description="time the signal starts [s], before simulation.duration_s")
    rate_deg_s: FiniteFloat = Field(0.0, description="ramp slope [deg/s]")
    freq_hz: PositiveFloat = Field(
        1.0, description="sine frequency / chirp start frequency [Hz]")
    freq_end_hz: PositiveFloat = Field(1.0, description="chirp end frequency [Hz]")
    sweep_time_s: NonNegFloat = Field(
        0.0, description="chirp sweep time [s] (0: whole run)")
    offset_deg: FiniteFloat = Field(0.0, description="constant added to sine/chirp [deg]")
    amplitude: float | int | str | None = Field(
        None, description="the amplitude with its unit, in the actuator's axis ('5 mm', "
                          "'2 deg'; a translational axis takes this, not amplitude_deg)")
    rate: float | int | str | None = Field(
        None, description="ramp slope with its unit ('10 mm/s'; instead of rate_deg_s)")
    offset: float | int | str | None = Field(
        None, description="sine/chirp offset with its unit (instead of offset_deg)")
    path: str | None = Field(None, description="profile file: a CSV with columns t_s, "
                                               "theta_ref_deg, or any log (CSV, Parquet, .mat) "
                                               "with column/unit")
    column: str | None = Field(None, description="the profile's column (variable) in the log")
    unit: str | None = Field(None, description="the profile column's unit (position: deg, "
                                               "rad, m, mm, ...)")
    time_column: str = Field("t_s", description="the log's time column [s] (a .mat: often 't')")
    signal: InputSignalConfig | None = Field(
        None, description="the input signal from a log: a disturbance added to the controller's "
                          "output (actuator.disturbance: output) or the actuation (actuator."
                          "controller.type: none)")

    @model_validator(mode="after")
    def _check(self) -> InputConfig:
        if self.kind == "csv" and not self.path:
            raise ValueError("input kind 'csv' needs 'path' (a CSV with t_s, theta_ref_deg)")
        if self.column is not None and self.kind != "csv":
            raise ValueError("input.column reads a profile: it needs kind 'csv'")
        if self.kind == "ramp" and self.rate_deg_s == 0:
            raise ValueError("input kind 'ramp' needs a non-zero 'rate_deg_s'")
        return self


class SimulationConfig(Strict):
    """The fixed-step time grid."""

    duration_s: PositiveFloat = Field(1.0, description="simulated time [s]")
    dt_s: PositiveFloat = Field(DEFAULT_DT, description="integration step [s]")
    output_interval_s: PositiveFloat | None = Field(
        DEFAULT_OUTPUT_INTERVAL, description="interval of the recorded time series [s]; null: "
                                             "record nothing (metrics only)")

    @model_validator(mode="after")
    def _grid(self) -> SimulationConfig:
        try:
            plan_steps(self.duration_s, self.dt_s, self.output_interval_s)
        except EmaError as exc:
            raise as_value_error(exc) from None
        return self


def _check_plant(values: dict[str, Any]) -> dict[str, Any]:
    for name, value in values.items():
        try:
            check_value(name, value)
        except EmaError as exc:
            raise as_value_error(exc, name) from None
    return values


def _check_nonlinearities(values: dict[str, Any]) -> dict[str, Any]:
    for name, value in values.items():
        try:
            lookup(name)
        except EmaError as exc:
            raise as_value_error(exc, name) from None
        if isinstance(value, str) and value.strip().lower() != "off":
            try:
                float(value)
            except ValueError:
                raise as_value_error(EmaError(f"expects a number or 'off', got {value!r}"),
                               name) from None
        if not isinstance(value, str) and (not math.isfinite(float(value)) or value < 0):
            raise as_value_error(EmaError(f"must be a finite number >= 0, got {value!r}"), name)
    try:
        check_distinct(values)  # one setting per placement (deadzone2 = deadzone@transmission)
    except EmaError as exc:
        raise as_value_error(exc) from None
    return values


class LoadConfig(Strict):
    """The external load on the output (aerodynamic hinge moment, disturbance), load side.

    T_load(t) = torque_nm + profile(t) - spring_nm_per_rad*theta_L, applied to the load inertia,
    positive along +theta_L.
    """

    torque_nm: FiniteFloat = Field(
        0.0, description="constant external torque on the load [N*m]")
    spring_nm_per_rad: FiniteFloat = Field(
        0.0, description="hinge-moment gradient k_h: external torque -k_h*theta_L [N*m/rad]")
    profile: str | None = Field(
        None, description="CSV with columns t_s, torque_nm added to the torque (interpolated "
                          "linearly, end values held)")


class MotorConfig(Strict):
    """Motor options."""

    locked: bool = Field(
        False, description="hold the motor shaft fixed (controller and armature off), for "
                           "load-deflection tests of the gear train")


class ControllerConfig(Strict):
    """Controller options: continuous (default) or digital with a sample time; the position
    fed back (load sensor, motor angle / ratio, or a blend)."""

    sample_time_s: PositiveFloat | None = Field(
        None, description="digital controller sample time [s], a whole multiple of "
                                "simulation.dt_s (absent: continuous)")
    position_feedback: Literal["load", "motor", "blend"] = Field(
        "load", description="position fed back: load (load-angle sensor), motor (motor angle "
                            "/ gear ratio: the transmission's free play is outside the loop), "
                            "blend ((1-b)*load + b*motor, b = feedback_blend)")
    feedback_blend: FiniteFloat | None = Field(
        None, ge=0.0, le=1.0, description="b of position_feedback: blend, in [0, 1]")
    deadzone_inverse_v: NonNegFloat | None = Field(
        None, description="dead-zone inverse: the amplifier dead zone it assumes [V]")
    deadzone_inverse_band_v: PositiveFloat | None = Field(
        None, description="dead-zone inverse smoothing band [V] (default 0.02)")
    friction_ff_fc_nm: NonNegFloat | None = Field(
        None, description="friction feed-forward: assumed Coulomb friction [N*m]")
    friction_ff_fs_nm: NonNegFloat | None = Field(
        None, description="friction feed-forward: assumed static friction [N*m]")
    friction_ff_vs_rad_s: PositiveFloat | None = Field(
        None, description="friction feed-forward: assumed Stribeck velocity [rad/s]")
    friction_ff_sigma2: NonNegFloat | None = Field(
        None, description="friction feed-forward: assumed viscous coefficient [N*m*s/rad]")
    friction_ff_sigma0: NonNegFloat | None = Field(
        None, description="friction compensation by a LuGre observer on the measured motor speed:"
                          " assumed bristle stiffness [N*m/rad] (absent or 0: static feed-forward"
                          " on the speed command)")
    friction_ff_sigma1: NonNegFloat | None = Field(
        None, description="LuGre observer: assumed bristle damping [N*m*s/rad]")
    friction_ff_band_rad_s: PositiveFloat | None = Field(
        None, description="friction feed-forward: sign smoothing band [rad/s] (default 0.5)")
    notch_hz: PositiveFloat | None = Field(
        None, description="speed-loop notch centre frequency [Hz] (absent: no notch)")
    notch_depth_db: FiniteFloat | None = Field(
        None, le=0.0, description="notch gain at its centre [dB] <= 0 (default -20)")
    notch_zeta: PositiveFloat | None = Field(
        None, description="notch width: damping of its poles (default 0.5)")

    @model_validator(mode="after")
    def _blend(self) -> ControllerConfig:
        if self.position_feedback == "blend" and self.feedback_blend is None:
            raise ValueError("position_feedback: blend needs feedback_blend (b in [0, 1])")
        if self.position_feedback != "blend" and self.feedback_blend is not None:
            raise ValueError(f"feedback_blend is used only with position_feedback: blend, not "
                             f"{self.position_feedback}")
        return self

    def compensator_params(self) -> dict[str, float]:
        """The model parameters (SI) of the compensators set here."""
        c = self
        pairs = {"dzi_v": c.deadzone_inverse_v, "dzi_band": c.deadzone_inverse_band_v,
                 "ff_fc": c.friction_ff_fc_nm, "ff_fs": c.friction_ff_fs_nm,
                 "ff_vs": c.friction_ff_vs_rad_s, "ff_sigma2": c.friction_ff_sigma2,
                 "ff_sigma0": c.friction_ff_sigma0, "ff_sigma1": c.friction_ff_sigma1,
                 "ff_band": c.friction_ff_band_rad_s, "notch_hz": c.notch_hz,
                 "notch_depth": (None if c.notch_depth_db is None
                                 else 10.0 ** (c.notch_depth_db / 20.0)),
                 "notch_zeta": c.notch_zeta}
        return {k: float(v) for k, v in pairs.items() if v is not None}

    def blend(self) -> float | None:
        """The blend b the kernel sees (None: the default, load feedback)."""
        return {"load": None, "motor": 1.0, "blend": self.feedback_blend}[self.position_feedback]


class SensorsConfig(Strict):
    """Sensor quantisation (absent: ideal sensors)."""

    position_counts_per_rev: PositiveFloat | None = Field(
        None, description="load-angle encoder resolution [counts/rev]")
    speed_resolution_rpm: PositiveFloat | None = Field(
        None, description="motor-speed measurement resolution [rpm]")


SECTION_PARAMS = {
    "load.torque_nm": "T_load", "load.spring_nm_per_rad": "k_h", "motor.locked": "locked",
    "controller.sample_time_s": "Ts", "controller.position_feedback": "fb_motor",
    "controller.deadzone_inverse_v": "dzi_v", "controller.deadzone_inverse_band_v": "dzi_band",
    "controller.friction_ff_fc_nm": "ff_fc", "controller.friction_ff_fs_nm": "ff_fs",
    "controller.friction_ff_vs_rad_s": "ff_vs", "controller.friction_ff_sigma2": "ff_sigma2",
    "controller.friction_ff_sigma0": "ff_sigma0", "controller.friction_ff_sigma1": "ff_sigma1",
    "controller.friction_ff_band_rad_s": "ff_band", "controller.notch_hz": "notch_hz",
    "controller.notch_depth_db": "notch_depth", "controller.notch_zeta": "notch_zeta",
    "sensors.position_counts_per_rev": "q_pos",
    "sensors.speed_resolution_rpm": "q_speed",
}
"""Config settings that set a model parameter (``config path -> parameter``)."""


class RunConfig(Strict):
    """Everything one simulation needs (the part of a study config ``ema simulate`` reads)."""

    name: PlainName = Field(
        "default", description="study name: letters, digits, _ . - (a folder name), <= 64 chars")
    description: str = Field("", description="what the study is for")
    plant: dict[str, Scalar] = Field(
        default_factory=dict, description="model parameter overrides, SI (see `ema params`)")
    input: InputConfig = Field(default_factory=InputConfig)
    simulation: SimulationConfig = Field(default_factory=SimulationConfig)
    nonlinearities: dict[str, Scalar] = Field(
        default_factory=dict,
        description="nonlinearities fixed for the study: paper name or type@location -> "
                    "magnitude in the units of `ema locations`, or off")
    friction_reading: Literal["sigma2", "scale"] = Field(
        "sigma2", description="friction1 magnitude: viscous sigma2 [N*m*s/rad] or Fc scale [N*m]")
    load: LoadConfig = Field(default_factory=LoadConfig)
    motor: MotorConfig = Field(default_factory=MotorConfig)
    controller: ControllerConfig = Field(default_factory=ControllerConfig)
    sensors: SensorsConfig = Field(default_factory=SensorsConfig)
    actuator: Actuator | None = Field(
        None, description="the actuator description (docs/model.md §3): inline, or the path of "
                          "a YAML file holding one (configs/actuators/); absent: the paper's "
                          "EMA")
    seed: Seed = Field(0, description="seed of everything random (0 .. 2**63-1)")

    @model_validator(mode="before")
    @classmethod
    def _off_words(cls, data: Any) -> Any:
        """YAML reads unquoted off/on as booleans: plant values and magnitudes get the words."""
        if isinstance(data, dict):
            data = dict(data)
            for key in ("plant", "nonlinearities"):
                if isinstance(data.get(key), dict):
                    data[key] = bools_to_words(data[key])
        return data

    def section_params(self) -> dict[str, float]:
        """The model parameters (SI) set by the load, motor, controller and sensors sections."""
        out: dict[str, float] = {}
        if self.load.torque_nm:
            out["T_load"] = self.load.torque_nm
        if self.load.spring_nm_per_rad:
            out["k_h"] = self.load.spring_nm_per_rad
        if self.motor.locked:
            out["locked"] = 1.0
        if self.controller.sample_time_s is not None:
            out["Ts"] = self.controller.sample_time_s
        if self.controller.blend() is not None:
            out["fb_motor"] = self.controller.blend()
        out.update(self.controller.compensator_params())
        if self.sensors.position_counts_per_rev is not None:
            out["q_pos"] = 2.0 * math.pi / self.sensors.position_counts_per_rev
        if self.sensors.speed_resolution_rpm is not None:
            out["q_speed"] = self.sensors.speed_resolution_rpm * RPM
        return out

    def actuator_label(self) -> str:
        """The actuator that runs, for figure titles (:func:`actuator_label`)."""
        desc = self.actuator
        return actuator_label(None if desc is None else (desc.name or f"{desc.axis} actuator"),
                              list(self.plant))

    def describe_options(self) -> str:
        """The option sections in use, for titles and reports ('' when none)."""
        parts = []
        if self.actuator is not None:
            parts.append(f"actuator {self.actuator.name or self.actuator.axis}")
        if self.load.torque_nm:
            parts.append(f"load torque {self.load.torque_nm:g} N*m")
        if self.load.spring_nm_per_rad:
            parts.append(f"hinge gradient {self.load.spring_nm_per_rad:g} N*m/rad")
        if self.load.profile:
            parts.append(f"load profile {Path(self.load.profile).name}")
        if self.motor.locked:
            parts.append("motor locked")
        if self.controller.sample_time_s is not None:
            parts.append(f"digital controller Ts {self.controller.sample_time_s * 1e3:g} ms")
        comp = self.controller.compensator_params()
        if comp.get("dzi_v"):
            parts.append(f"dead-zone inverse {comp['dzi_v']:g} V")
        if comp.get("ff_fc") or comp.get("ff_sigma2"):
            parts.append("friction observer" if comp.get("ff_sigma0") else "friction feed-forward")
        if comp.get("notch_hz"):
            parts.append(f"notch {comp['notch_hz']:g} Hz")
        if self.controller.position_feedback == "motor":
            parts.append("motor-angle position feedback")
        elif self.controller.position_feedback == "blend":
            parts.append(f"blended position feedback b = {self.controller.feedback_blend:g}")
        if self.sensors.position_counts_per_rev is not None:
            parts.append(f"encoder {self.sensors.position_counts_per_rev:g} counts/rev")
        if self.sensors.speed_resolution_rpm is not None:
            parts.append(f"speed resolution {self.sensors.speed_resolution_rpm:g} rpm")
        return ", ".join(parts)

    @property
    def axis(self) -> str:
        """The actuator's axis: rotary (the paper's EMA) or translational."""
        return self.actuator.axis if self.actuator is not None else "rotary"

    def plant_overrides(self) -> dict[str, Any]:
        """The actuator description's parameters, then ``plant`` (SI) and the parameters of the
        option sections on top."""
        base = self.actuator.params() if self.actuator is not None else {}
        return {**base, **self.plant, **self.section_params()}

    @model_validator(mode="after")
    def _sections(self) -> RunConfig:
        for path, param in SECTION_PARAMS.items():
            section, key = path.split(".")
            part = getattr(self, section)
            if param in self.plant and (key in part.model_fields_set
                                        or getattr(part, key) not in (None, 0.0, False, "load")):
                raise ValueError(f"{path} and plant.{param} set the same parameter; give one")
        for name, value in self.nonlinearities.items():  # a magnitude and plant.X of one param
            written = nonlinearity_updates(name, value, resolve(), self.friction_reading)
            both = sorted(set(written) & set(self.plant))
            if both:
                raise ValueError(f"nonlinearities.{name} and plant.{both[0]} set the same "
                                 "model parameter; give one")
        # plant.Ts has passed check_value already (field validators run first)
        key = "plant.Ts" if "Ts" in self.plant else "controller.sample_time_s"
        ts = float(check_value("Ts", self.plant_overrides().get("Ts", 0.0)))
        if off_grid(ts, self.simulation.dt_s):
            raise ValueError(f"{key} ({ts:g} s) must be a whole multiple of simulation.dt_s "
                             f"({self.simulation.dt_s:g} s)")
        return self

    @model_validator(mode="after")
    def _axis_units(self) -> RunConfig:
        if self.axis == "translational":
            for key in ("amplitude_deg", "rate_deg_s", "offset_deg"):
                if key in self.input.model_fields_set:
                    new = key.split("_")[0]
                    raise ValueError(f"{KEY_MARK}input.{key}{KEY_MARK}a translational axis "
                                     f"takes input.{new} with a length unit (e.g. '5 mm')")
            if self.input.kind == "csv" and self.input.column is None:
                raise ValueError(f"{KEY_MARK}input.column{KEY_MARK}a translational axis reads "
                                 "its profile from a column with a length unit (column, unit)")
        from ema_cli.units import parse_quantity

        for key, kind in (("amplitude", "position"), ("rate", "velocity"),
                          ("offset", "position")):
            v = getattr(self.input, key)
            if v is not None:
                try:
                    parse_quantity(v, kind, self.axis)
                except ValueError as exc:
                    raise ValueError(f"{KEY_MARK}input.{key}{KEY_MARK}{exc}") from None
        if self.actuator is not None:
            a = self.actuator
            c = a.controller
            if c.type == "discrete" and c.sample_time_s is not None \
                    and c.delay_samples * c.sample_time_s >= self.simulation.duration_s:
                raise ValueError(f"{KEY_MARK}actuator.controller.delay_samples{KEY_MARK}"
                                 f"{c.delay_samples} samples of {c.sample_time_s:g} s is not "
                                 f"shorter than the run (simulation.duration_s = "
                                 f"{self.simulation.duration_s:g} s)")
            ext = a.controller.type == "none" or a.disturbance == "output"
            if ext and self.input.signal is None:
                what = ("the actuation (controller none)" if a.controller.type == "none"
                        else "the disturbance on the controller's output")
                raise ValueError(f"{KEY_MARK}input.signal{KEY_MARK}this actuator reads {what} "
                                 "from an input signal: give input.signal (path, column, unit)")
        return self

    @model_validator(mode="after")
    def _start(self) -> RunConfig:
        if self.input.start_s >= self.simulation.duration_s:
            raise ValueError(f"input.start_s ({self.input.start_s:g} s) must be before the end "
                             f"of the run, simulation.duration_s ({self.simulation.duration_s:g}"
                             " s)")
        return self

    @field_validator("plant")
    @classmethod
    def _plant(cls, v: dict[str, Any]) -> dict[str, Any]:
        return _check_plant(v)

    @field_validator("nonlinearities")
    @classmethod
    def _nl(cls, v: dict[str, Any]) -> dict[str, Any]:
        return _check_nonlinearities(v)


def bools_to_words(value: Any) -> Any:
    """YAML 1.1 reads unquoted off/on as booleans: turn them back into the words."""
    if isinstance(value, bool):
        return "on" if value else "off"
    if isinstance(value, list):
        return [bools_to_words(v) for v in value]
    if isinstance(value, dict):
        return {k: bools_to_words(v) for k, v in value.items()}
    return value


def actuator_label(described: str | None, overrides: list[str]) -> str:
    """The actuator that runs, in a reader's words (figure titles): a description's name, or
    the reference EMA (the paper's) with the plant parameters set on it, e.g. ``reference EMA
    with kL, alpha, Fc +3 set``."""
    base = described or "reference EMA"
    if not overrides:
        return base
    names = ", ".join(overrides[:3]) + (f" +{len(overrides) - 3}" if len(overrides) > 3 else "")
    return f"{base} with {names} set"
