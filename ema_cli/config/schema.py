"""The YAML config schema (pydantic, frozen, unknown keys are errors); units in the field names.

A config describes one study: the plant (SI overrides of the parameter table), the input signal
and simulation grid (paper units: degrees, seconds), the nonlinearities fixed for the study
(paper names or ``type@location`` in the units of ``ema locations``), and, for ``ema sweep``,
the sweep, outputs and parallel settings.
"""

from __future__ import annotations

import math
import re
from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field, field_validator, model_validator

from ema_cli.errors import EmaError
from ema_cli.model.nonlinearities import lookup
from ema_cli.model.params import check_value
from ema_cli.sim.runner import DEFAULT_DT, DEFAULT_OUTPUT_INTERVAL, plan_steps

Scalar = float | int | str

NAME_RE = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.-]*$")


class Strict(BaseModel):
    """Base: frozen, closed (unknown keys are errors)."""

    model_config = ConfigDict(frozen=True, extra="forbid")


def _reraise(exc: EmaError, key: str | None = None) -> ValueError:
    """An EmaError as a pydantic ValueError; ``key`` (a dict key) is folded into the key path."""
    return ValueError(f"{KEY_MARK}{key}{KEY_MARK}{exc.message}" if key else exc.message)


KEY_MARK = "\x00"
"""Wraps a dict key at the start of a validator message; ``loader.validate`` folds it into the
key path so errors read ``plant.kL: ...``."""


class InputConfig(Strict):
    """The position reference (load side), in degrees and seconds."""

    kind: Literal["step", "ramp", "sine", "chirp", "csv"] = Field(
        "step", description="signal shape")
    amplitude_deg: float = Field(
        20.0, description="step size, sine/chirp amplitude, or ramp end value (0: none) [deg]")
    start_s: float = Field(0.0, ge=0, description="time the signal starts [s]")
    rate_deg_s: float = Field(0.0, description="ramp slope [deg/s]")
    freq_hz: float = Field(1.0, gt=0, description="sine frequency / chirp start frequency [Hz]")
    freq_end_hz: float = Field(1.0, gt=0, description="chirp end frequency [Hz]")
    sweep_time_s: float = Field(0.0, ge=0, description="chirp sweep time [s] (0: whole run)")
    offset_deg: float = Field(0.0, description="constant added to sine/chirp [deg]")
    path: str | None = Field(None, description="CSV profile with columns t_s, theta_ref_deg")

    @model_validator(mode="after")
    def _check(self) -> InputConfig:
        if self.kind == "csv" and not self.path:
            raise ValueError("input kind 'csv' needs 'path' (a CSV with t_s, theta_ref_deg)")
        if self.kind == "ramp" and self.rate_deg_s == 0:
            raise ValueError("input kind 'ramp' needs a non-zero 'rate_deg_s'")
        return self


class SimulationConfig(Strict):
    """The fixed-step time grid."""

    duration_s: float = Field(1.0, gt=0, description="simulated time [s]")
    dt_s: float = Field(DEFAULT_DT, gt=0, description="integration step [s]")
    output_interval_s: float = Field(
        DEFAULT_OUTPUT_INTERVAL, gt=0, description="interval of the recorded time series [s]")

    @model_validator(mode="after")
    def _grid(self) -> SimulationConfig:
        try:
            plan_steps(self.duration_s, self.dt_s, self.output_interval_s)
        except EmaError as exc:
            raise _reraise(exc) from None
        return self


def _check_plant(values: dict[str, Any]) -> dict[str, Any]:
    for name, value in values.items():
        try:
            check_value(name, value)
        except EmaError as exc:
            raise _reraise(exc, name) from None
    return values


def _check_nonlinearities(values: dict[str, Any]) -> dict[str, Any]:
    for name, value in values.items():
        try:
            lookup(name)
        except EmaError as exc:
            raise _reraise(exc, name) from None
        if isinstance(value, str) and value.strip().lower() != "off":
            try:
                float(value)
            except ValueError:
                raise _reraise(EmaError(f"expects a number or 'off', got {value!r}"),
                               name) from None
        if not isinstance(value, str) and (not math.isfinite(float(value)) or value < 0):
            raise _reraise(EmaError(f"must be a finite number >= 0, got {value!r}"), name)
    return values


class RunConfig(Strict):
    """Everything one simulation needs (the part of a study config ``ema simulate`` reads)."""

    name: str = Field("default", description="study name: letters, digits, _ . - (a folder name)")
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
    seed: int = Field(0, ge=0, description="seed of everything random")

    @field_validator("name")
    @classmethod
    def _name(cls, v: str) -> str:
        if not NAME_RE.match(v) or ".." in v:
            raise ValueError(
                "name must be letters, digits, '_', '.', '-' (no path separators, no '..'), "
                f"got {v!r}")
        return v

    @field_validator("plant")
    @classmethod
    def _plant(cls, v: dict[str, Any]) -> dict[str, Any]:
        return _check_plant(v)

    @field_validator("nonlinearities")
    @classmethod
    def _nl(cls, v: dict[str, Any]) -> dict[str, Any]:
        return _check_nonlinearities(v)

