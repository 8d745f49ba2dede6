"""The drive's thermal element in an actuator description (``actuator.drive.thermal``).

Datasheet-style values with their units (docs/model.md §10, ``model/thermal.py``)::

    drive:
      thermal:
        rth_winding_housing: 1.2 K/W
        rth_housing_ambient: 2.93 K/W
        cth_winding: 25 J/K            # or tau_winding: 30 s   (= rth_winding_housing*cth)
        cth_housing: 400 J/K           # or tau_housing: 1172 s (= rth_housing_ambient*cth)
        alpha: 0.00393 1/K             # copper
        reference_temperature: 25 degC # the temperature the drive's resistance is given at
        ambient: 40 degC
        insulation: F                  # IEC 60085 class (A E B F H N R) or a limit '150 degC'
        friction_share: 1              # share of the motor's friction losses heating it
        iron_hysteresis: 0 N*m         # iron losses k_h*|w_m| + k_e*w_m^2 [W], heat only
        iron_eddy: 0 N*m*s/rad
        resistance: 0.5 ohm            # amplifier drives only: the winding's resistance

Temperatures are absolute, in degC (a bare number) or K. Every value left out keeps the
reference EMA's (``ema params``: its continuous current at 40 degC and class F is its rated
6.07 A). A described thermal element switches the kernel's thermal states on (winding and
housing temperature, R(T) in the armature).
"""

from __future__ import annotations

from typing import Any

from pydantic import Field, model_validator

from ema_cli.config.base import NonNegFloat, Strict
from ema_cli.model.params import BY_NAME
from ema_cli.model.thermal import INSULATION_CLASSES
from ema_cli.units import ZERO_CELSIUS, parse_quantity, parse_temperature

Q = float | int | str
KEY = "\x00"  # wraps a key path at the start of a message (config.run.KEY_MARK)
DEFAULT_CLASS = "F"
"""The insulation class assumed when a description gives none (the reference EMA's)."""


def _err(key: str, message: str) -> ValueError:
    return ValueError(f"{KEY}{key}{KEY}{message}")


class Thermal(Strict):
    """A two-node thermal network (winding, housing) with R(T) (module docstring)."""

    rth_winding_housing: Q | None = Field(None, description="winding-housing [K/W]")
    rth_housing_ambient: Q | None = Field(None, description="housing-ambient [K/W]")
    cth_winding: Q | None = Field(None, description="winding heat capacity [J/K]")
    cth_housing: Q | None = Field(None, description="housing heat capacity [J/K]")
    tau_winding: Q | None = Field(None, description="winding time constant rth_wh*cth_w [s]")
    tau_housing: Q | None = Field(None, description="housing time constant rth_ha*cth_h [s]")
    alpha: Q | None = Field(None, description="temperature coefficient of the resistance [1/K]")
    reference_temperature: Q | None = Field(
        None, description="temperature the drive's resistance is given at [degC or K]")
    ambient: Q | None = Field(None, description="ambient temperature [degC or K]")
    insulation: str | int | float = Field(
        DEFAULT_CLASS, description="insulation class (A E B F H N R) or its limit ('150 degC')")
    friction_share: NonNegFloat | None = Field(
        None, le=1.0, description="share of the motor's friction losses heating the housing")
    iron_hysteresis: Q | None = Field(None, description="iron loss per motor speed [N*m]")
    iron_eddy: Q | None = Field(None, description="iron loss per speed^2 [N*m*s/rad]")
    resistance: Q | None = Field(None, description="amplifier drives: winding resistance [ohm]")

    @model_validator(mode="after")
    def _check(self) -> Thermal:
        self.params("armature" if self.resistance is None else "amplifier")
        self.limit_k()
        return self

    def limit_k(self) -> float:
        """The insulation's temperature limit [K] (a class's hot-spot rating, or the value)."""
        v = self.insulation
        if isinstance(v, str) and v.strip().upper() in INSULATION_CLASSES:
            return INSULATION_CLASSES[v.strip().upper()] + ZERO_CELSIUS
        try:
            return parse_temperature(v)
        except ValueError as exc:
            raise _err("insulation", f"expected a class ({' '.join(INSULATION_CLASSES)}) or a "
                                     f"temperature such as '150 degC' ({exc})") from None

    def params(self, drive: str) -> dict[str, float]:
        """The SI parameters (``model.params``) this section sets, ``thermal`` switched on."""
        out: dict[str, float] = {"thermal": 1.0}

        def q(key: str, kind: str) -> float | None:
            v = getattr(self, key)
            if v is None:
                return None
            try:
                x = parse_quantity(v, kind, None)
            except ValueError as exc:
                raise _err(key, str(exc)) from None
            if not x > 0 and key not in ("iron_hysteresis", "iron_eddy", "alpha"):
                raise _err(key, f"must be > 0, got {v!r}")
            if x < 0:
                raise _err(key, f"must be >= 0, got {v!r}")
            return x

        def temp(key: str) -> float | None:
            v = getattr(self, key)
            if v is None:
                return None
            try:
                return parse_temperature(v)
            except ValueError as exc:
                raise _err(key, str(exc)) from None

        for key, name, kind in (("rth_winding_housing", "Rth_wh", "thermal_resistance"),
                                ("rth_housing_ambient", "Rth_ha", "thermal_resistance"),
                                ("alpha", "alpha_cu", "temperature_coefficient"),
                                ("iron_hysteresis", "fe_hyst", "loss_torque"),
                                ("iron_eddy", "fe_eddy", "loss_damping")):
            x = q(key, kind)
            if x is not None:
                out[name] = x
        for node, r_name, c_name in (("winding", "Rth_wh", "Cth_w"),
                                     ("housing", "Rth_ha", "Cth_h")):
            c, tau = q(f"cth_{node}", "heat_capacity"), q(f"tau_{node}", "time")
            if c is not None and tau is not None:
                raise _err(f"tau_{node}", f"give cth_{node} or tau_{node}, not both")
            if c is not None:
                out[c_name] = c
            elif tau is not None:  # with the section's resistance, or the reference EMA's
                out[c_name] = tau / out.get(r_name, BY_NAME[r_name].default)
        for key, name in (("reference_temperature", "T_ref"), ("ambient", "T_amb")):
            t = temp(key)
            if t is not None:
                out[name] = t
        if self.friction_share is not None:
            out["fric_heat"] = float(self.friction_share)
        r = q("resistance", "resistance")
        if r is not None:
            if drive != "amplifier":
                raise _err("resistance", "an armature's resistance is drive.resistance; "
                                         "thermal.resistance is an amplifier drive's winding")
            out["R"] = r
        return out


def thermal_of(cfg: Any) -> Thermal | None:
    """The thermal section of a run config's actuator description, or None (the reference
    EMA's network, ``ema params``)."""
    a = getattr(cfg, "actuator", None)
    return None if a is None else a.drive.thermal
