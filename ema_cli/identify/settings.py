"""Settings of an identification (pydantic, frozen, unknown keys are errors); units in the names.

The YAML file ``configs/identify.yaml`` and the ``ema identify`` options both fill an
:class:`IdentifySettings`; the library entry point ``run_identification`` takes one.
"""

from __future__ import annotations

import math
from typing import Any, Literal

from pydantic import (
    BaseModel,
    ConfigDict,
    Field,
    ValidationInfo,
    field_validator,
    model_validator,
)

from ema_cli.identify import ga as ga_mod
from ema_cli.identify.data import CSV_COLUMNS

DEFAULT_K_RANGE = (500.0, 700.0)  # kL search range, paper §3.1 [N*m/rad]
DEFAULT_ALPHA_RANGE = (0.002, 0.004)  # alpha search range, paper §3.1 [rad]
DEFAULT_C_RANGE = (0.0, 5.0)  # c search range when fitted (truth ~0.773) [N*m*s/rad]
TRUE_KL = 590.0  # synthetic data: stiffness, docs/model.md §8 [N*m/rad]
TRUE_ALPHA = 0.003  # synthetic data: half backlash, docs/model.md §8 [rad]
CHIRP_AMPLITUDE_DEG = 5.0  # synthetic chirp amplitude [deg]
CHIRP_F0_HZ = 0.5  # chirp start frequency [Hz]
CHIRP_F1_HZ = 8.0  # chirp end frequency [Hz]
CHIRP_SWEEP_S = 4.0  # chirp sweep time [s]
DATA_DURATION_S = 4.0  # simulated time [s]
DATA_DT_S = 1e-5  # integration step of the data simulation [s] (docs/model.md §6)
SAMPLE_INTERVAL_S = 1e-3  # sample interval of the identification data: 4,001 samples [s]

Method = Literal["ga", "ga-paper", "exact"]
Form = Literal["contact", "paper"]


class Strict(BaseModel):
    """Base: frozen, closed (unknown keys are errors)."""

    model_config = ConfigDict(frozen=True, extra="forbid")


def _check_range(v: tuple[float, float], name: str, lo_min: float = 0.0) -> tuple[float, float]:
    lo, hi = float(v[0]), float(v[1])
    if not (math.isfinite(lo) and math.isfinite(hi)):
        raise ValueError(f"{name} must be finite, got [{lo}, {hi}]")
    if lo < lo_min:
        raise ValueError(f"{name} lower bound must be >= {lo_min}, got {lo}")
    if not hi > lo:
        raise ValueError(f"{name} needs LO < HI, got [{lo}, {hi}]")
    return lo, hi


class GASettings(Strict):
    """GA options; ``None`` takes the method's preset (ga-paper or ga)."""

    pop: int = Field(ga_mod.DEFAULT_POP, ge=2, description="population size")
    generations: int = Field(ga_mod.DEFAULT_GENERATIONS, ge=1,
                             description="evaluated generations, including the initial one")
    pc: float = Field(ga_mod.DEFAULT_PC, ge=0, le=1,
                      description="crossover probability per pair of parents")
    pm: float = Field(ga_mod.DEFAULT_PM, ge=0, le=1,
                      description="mutation probability: per bit (ga-paper) or per gene (ga)")
    bits: int = Field(ga_mod.DEFAULT_BITS, ge=2, le=52,
                      description="bits per parameter (binary coding, ga-paper)")
    selection: Literal["roulette", "tournament"] | None = Field(
        None, description="selection (null: roulette for ga-paper, tournament for ga)")
    elitism: int | None = Field(None, ge=0, description="elites kept (null: 0 / 2)")
    crossover: Literal["line-sbx", "sbx"] | None = Field(
        None, description="real-coded crossover of ga (null: line-sbx)")
    tournament: int = Field(ga_mod.DEFAULT_TOURNAMENT, ge=1, description="tournament size")
    eta_c: float | None = Field(None, ge=0, description="SBX distribution index (null: preset)")
    eta_m: float = Field(ga_mod.DEFAULT_ETA_M, ge=0,
                         description="polynomial-mutation distribution index")
    mutation_unit: Literal["bit", "chromosome"] = Field(
        "bit", description="ga-paper: pm per bit, or per chromosome (one random bit flips)")
    patience: int = Field(0, ge=0, description="early stop after N stale generations (0: off)")

    def options(self, method: str) -> ga_mod.GAOptions:
        """The GAOptions of ``method`` ("ga" or "ga-paper") with these settings applied."""
        mode = "paper" if method == "ga-paper" else "improved"
        over: dict[str, Any] = {
            "pop": self.pop, "generations": self.generations, "pc": self.pc, "pm": self.pm,
            "bits": self.bits, "tournament": self.tournament, "eta_m": self.eta_m,
            "mutation_unit": self.mutation_unit, "patience": self.patience,
        }
        for key in ("selection", "elitism", "eta_c", "crossover"):
            value = getattr(self, key)
            if value is not None:
                over[key] = value
        try:
            return ga_mod.preset(mode, **over)
        except ValueError as exc:
            raise ValueError(f"ga: {exc}") from None


class SyntheticSettings(Strict):
    """How synthetic data are generated (docs/model.md §8), edge units in the names."""

    kL: float = Field(TRUE_KL, gt=0, description="true stiffness [N*m/rad]")
    alpha: float = Field(TRUE_ALPHA, ge=0, description="true half backlash [rad]")
    damping: Form = Field("contact", description="damping form of the simulator")
    noise_pct: float = Field(0.0, ge=0, description="Gaussian noise, % of the torque RMS")
    amplitude_deg: float = Field(CHIRP_AMPLITUDE_DEG, gt=0, description="chirp amplitude [deg]")
    freq_hz: float = Field(CHIRP_F0_HZ, gt=0, description="chirp start frequency [Hz]")
    freq_end_hz: float = Field(CHIRP_F1_HZ, gt=0, description="chirp end frequency [Hz]")
    sweep_time_s: float = Field(CHIRP_SWEEP_S, gt=0, description="chirp sweep time [s]")
    duration_s: float = Field(DATA_DURATION_S, gt=0, description="simulated time [s]")
    dt_s: float = Field(DATA_DT_S, gt=0, description="integration step [s]")
    sample_interval_s: float = Field(SAMPLE_INTERVAL_S, gt=0,
                                     description="sample interval of the data [s]")
    plant: dict[str, float | int | str] = Field(
        default_factory=dict, description="other model parameter overrides, SI")


class IdentifySettings(Strict):
    """Everything one ``ema identify`` run needs (see configs/identify.yaml)."""

    name: str = Field("identify", description="study name")
    method: Method = Field("ga", description="ga (improved GA), ga-paper, or exact")
    model: Form = Field("contact", description="torque form fitted: contact or paper (Eq. 2)")
    k_range: tuple[float, float] = Field(DEFAULT_K_RANGE, description="kL range [N*m/rad]")
    alpha_range: tuple[float, float] = Field(DEFAULT_ALPHA_RANGE, description="alpha range [rad]")
    c_range: tuple[float, float] = Field(DEFAULT_C_RANGE,
                                         description="c range when fitted [N*m*s/rad]")
    fit_c: bool | None = Field(
        None, description="fit c too (null: yes for --data, no for synthetic data)")
    c: float | None = Field(None, ge=0, description="fixed c [N*m*s/rad] (null: simulator's)")
    data: str | None = Field(None, description="CSV with t_s, dtheta_rad, domega_rad_s, torque_nm")
    columns: dict[str, str] = Field(default_factory=dict,
                                    description="column mapping, canonical name -> file column")
    runs: int = Field(1, ge=1, description="GA runs (seeds SeedSequence(seed).spawn(runs))")
    n_jobs: int = Field(1, description="parallel processes for the runs (-1: all cores)")
    seed: int = Field(0, ge=0, description="seed of the GA runs and of the noise")
    ga: GASettings = Field(default_factory=GASettings)
    synthetic: SyntheticSettings = Field(default_factory=SyntheticSettings)

    @field_validator("k_range", "alpha_range", "c_range")
    @classmethod
    def _ranges(cls, v: tuple[float, float], info: ValidationInfo) -> tuple[float, float]:
        return _check_range(v, info.field_name or "range")

    @field_validator("columns")
    @classmethod
    def _cols(cls, v: dict[str, str]) -> dict[str, str]:
        for key in v:
            if key not in CSV_COLUMNS:
                raise ValueError(f"unknown column '{key}'; expected one of {list(CSV_COLUMNS)}")
        return v

    @model_validator(mode="after")
    def _check(self) -> IdentifySettings:
        if self.n_jobs == 0:
            raise ValueError("n_jobs must be a positive number of processes or -1 (all cores)")
        if self.fit_c is True and self.c is not None:
            raise ValueError("give either a fixed c or fit_c: true, not both")
        if self.data is not None and self.fit_c is False and self.c is None:
            raise ValueError("with data from a file and fit_c false, give the fixed c")
        if self.method != "exact":
            self.ga.options(self.method)  # raises on inconsistent GA options
        return self

    @property
    def fits_c(self) -> bool:
        """Whether c is identified: explicit ``fit_c``, else yes for file data without c."""
        if self.fit_c is not None:
            return self.fit_c
        return self.data is not None and self.c is None
