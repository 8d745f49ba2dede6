"""Pieces an acceptance spec and a duty profile share (``config.acceptance``,
``config.duty``): a limit with its unit, the actuator under test, the duty metrics."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

from pydantic import Field, field_validator, model_validator

from ema_cli.config.base import FiniteFloat, Strict
from ema_cli.config.run import KEY_MARK, Scalar
from ema_cli.errors import EmaError
from ema_cli.units import UNITS, to_si


class Limit(Strict):
    """A limit on one metric: ``min`` and/or ``max`` in ``unit``."""

    min: FiniteFloat | None = Field(None, description="the value must be >= min")
    max: FiniteFloat | None = Field(None, description="the value must be <= max")
    unit: str | None = Field(None, description="unit of min and max, e.g. s, ms, deg, Hz, dB, "
                                                "%, deg/s, N*m/rad (required)")

    @field_validator("unit")
    @classmethod
    def _unit(cls, v: str | None) -> str:
        if v is None:
            raise ValueError(f"a limit needs its unit, one of {', '.join(UNITS)}")
        if v not in UNITS:
            raise ValueError(f"unknown unit {v!r}; expected one of {', '.join(UNITS)}")
        return v

    @model_validator(mode="after")
    def _bounds(self) -> Limit:
        if self.unit is None:
            raise _at("unit", f"missing: the unit of min/max, one of {', '.join(UNITS)}")
        if self.min is None and self.max is None:
            raise ValueError("a limit needs min or max (or both)")
        if self.min is not None and self.max is not None and self.min > self.max:
            raise ValueError(f"min ({self.min}) is above max ({self.max})")
        return self

    @property
    def dimension(self) -> str:
        return UNITS[self.unit][0]

    def si(self) -> tuple[float, float]:
        """(lower, upper) bounds in SI (-inf/inf where not given; degC -> K)."""
        return (-math.inf if self.min is None else to_si(self.min, self.unit),
                math.inf if self.max is None else to_si(self.max, self.unit))


def _at(key: str, message: str) -> ValueError:
    """A validation error at ``key`` below the failing model (named in the message)."""
    return ValueError(f"{KEY_MARK}{key}{KEY_MARK}{message}")


class ActuatorSpec(Strict):
    """The actuator under test: a run config and overrides on top of it."""

    config: str | None = Field(None, description="run config, relative to the spec (null: "
                                                 "the bundled defaults)")
    plant: dict[str, Scalar] = Field(default_factory=dict,
                                     description="SI parameter overrides (`ema params`; "
                                                 "off removes a saturation)")
    nonlinearities: dict[str, Any] = Field(
        default_factory=dict, description="name -> magnitude (`ema locations`)")

    def pairs(self) -> list[tuple[str, Any]]:
        """The overrides as dotted run-config paths (``plant.X``, ``nonlinearities.X``)."""
        return ([(f"plant.{k}", v) for k, v in self.plant.items()]
                + [(f"nonlinearities.{k}", v) for k, v in self.nonlinearities.items()])

    def label(self) -> str:
        """The actuator under test in a reader's words (figure titles): the run config's file
        stem, or the reference EMA, with the plant parameters set on it."""
        from ema_cli.config.run import actuator_label

        return actuator_label(None if self.config is None else Path(self.config).stem,
                              list(self.plant))

    def source(self, here: Path | None, owner: str) -> tuple[Path | None, Path | None]:
        """(the run config file or None for the defaults, the folder its relative paths are
        read from); ``here`` the folder of the ``owner`` file that names it. Raises EmaError
        when the file does not exist."""
        if self.config is None:
            return None, here
        src = (here / self.config) if here is not None else Path(self.config)
        if not src.is_file():
            raise EmaError(f"actuator.config: '{self.config}' is not a file (a run config, "
                           f"relative to the {owner})")
        return src, src.parent


DUTY_METRICS: dict[str, str] = {
    "winding_temperature": "temperature", "housing_temperature": "temperature",
    "time_above_limit": "time", "peak_current": "current", "rms_current": "current",
    "peak_torque": "torque", "rms_torque": "torque", "envelope_use": "percent",
    "l10_life": "time", "insulation_life_used": "percent", "energy": "energy"}
"""A duty run's metrics and their dimensions (``config.duty``, ``duty.summary``): peak winding
and housing temperature, time the winding spends above its limit, peak and RMS motor current
and torque, the largest share of the drive's torque-speed envelope used, the screw's or gear's
L10 life, the share of the insulation's life one pass consumes, the electrical energy drawn."""
