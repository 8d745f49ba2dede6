"""Settings of a plant identification (``ema identify plant``), validated: unknown keys are
errors, every value is checked where it is read."""

from __future__ import annotations

from typing import Literal

from pydantic import Field, field_validator

from ema_cli.config.base import FiniteFloat, NonNegInt, PlainName, PositiveInt, Strict
from ema_cli.config.loader import parse_value


class PlantSettings(Strict):
    """Everything one ``ema identify plant`` run needs (SI; times in s)."""

    name: PlainName = Field("plant", description="study name (a folder name)")
    data: str = Field(..., description="the closed-loop record: .csv, .parquet or .mat "
                                       "(MATLAB v5 or v7.3)")
    actuator: str = Field(..., description="the actuator description (YAML): a rigid axis, an "
                                           "amplifier drive, load friction, a discrete controller")
    columns: dict[str, str] = Field(
        default_factory=dict,
        description="role -> 'NAME[:UNIT]' (roles time, position, reference, actuation, "
                    "disturbance, gain; default the EMPS names t, qm, qg, vir, gtau; units: time "
                    "s|ms|us, position m|mm|um|rad|deg|mrad, actuation V|mV|A|mA|N|kN|N*m)")
    set: list[str] = Field(default_factory=list,
                           description="overrides of the description, 'actuator.KEY=VALUE'")
    law: Literal["auto", "symmetric", "per-direction"] = Field(
        "auto", description="friction law fitted: symmetric (M, Fv, Fc, OF), per-direction (M, "
                            "Fv+, Fc+, Fv-, Fc-) or auto (per-direction when the symmetric fit "
                            "misses the viscous asymmetry)")
    delay: Literal["auto"] | NonNegInt = Field(
        "auto", description="the controller's computation delay [samples]; auto: the delay the "
                            "controller check finds in the log")
    window: tuple[FiniteFloat, FiniteFloat] | None = Field(
        None, description="[T0, T1]: fit only the samples with T0 <= t <= T1 [s, from the "
                          "record's start]; null: all")
    split: FiniteFloat = Field(0.7, ge=0.0, lt=1.0,
                               description="share of the samples a second fit uses, the rest "
                                           "scoring it (time-split validation); 0: none")
    free: dict[str, tuple[FiniteFloat, FiniteFloat]] = Field(
        default_factory=dict,
        description="further kernel parameters freed with bounds, NAME -> [LO, HI] in SI (names "
                    "of `ema params`: the load friction law's Fs_L, vs_L, sigma0_L, sigma1_L, "
                    "...), started from the description's values")
    max_iter: PositiveInt = Field(20, le=200, description="Levenberg-Marquardt iterations "
                                                          "(cap 200)")
    validate_data: str | None = Field(None, description="another record the fitted model is "
                                                        "simulated against (validation)")

    @field_validator("set")
    @classmethod
    def _pairs(cls, v: list[str]) -> list[str]:
        for item in v:
            key, sep, _ = item.partition("=")
            if not sep or not key.startswith("actuator."):
                raise ValueError(f"'{item}': expected actuator.KEY=VALUE")
        return v

    @field_validator("free")
    @classmethod
    def _free(cls, v: dict[str, tuple[float, float]]) -> dict[str, tuple[float, float]]:
        from ema_cli.identify.plant.output_error import TERM_PARAMS
        from ema_cli.model.params import INDEX

        for name, (lo, hi) in v.items():
            if name not in INDEX:
                raise ValueError(f"free.{name}: not a model parameter (`ema params` lists them)")
            if name in {p for ps in TERM_PARAMS.values() for p in ps}:
                raise ValueError(f"free.{name}: the law's terms free it already (--law)")
            if not lo < hi:
                raise ValueError(f"free.{name}: expected LO < HI, got [{lo}, {hi}]")
        return v

    def overrides(self) -> list[tuple[str, object]]:
        """The ``set`` items as (dotted path, value) pairs."""
        out = []
        for item in self.set:
            key, _, val = item.partition("=")
            out.append((key.strip(), parse_value(val.strip())))
        return out
