"""Settings of an identification (pydantic, frozen, unknown keys are errors); units in the names.

The YAML file ``configs/identify.yaml`` and the ``ema identify`` options both fill an
:class:`IdentifySettings`; the library entry point ``run_identification`` takes one.
"""

from __future__ import annotations

import math
from typing import Any, Literal

from pydantic import Field, ValidationInfo, field_validator, model_validator

from ema_cli.config.base import (
    Integer,
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
from ema_cli.identify.torque.data import CSV_COLUMNS
from ema_cli.model.params import check_value
from ema_cli.optim import ga as ga_mod

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

MAX_POP = 100_000  # the largest GA population [individuals]
MAX_GENERATIONS = 1_000_000  # the most GA generations [generations]
MAX_RUNS = 10_000  # the most GA runs of one identification [runs]
MAX_WORKERS = 4096  # the most parallel processes (n_jobs) [processes]
MAX_EVALUATIONS = 10**9  # the most cost evaluations, pop * generations * runs [evaluations]
MAX_NOISE_PCT = 1000.0  # the largest noise level of synthetic data [% of the torque RMS]
MAX_ETA = 1000.0  # the largest SBX / polynomial-mutation distribution index [-]

Method = Literal["ga", "ga-paper", "exact"]
Form = Literal["contact", "paper"]


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

    pop: PositiveInt = Field(ga_mod.DEFAULT_POP, ge=2, le=MAX_POP,
                             description=f"population size, 2 .. {MAX_POP:,}")
    generations: PositiveInt = Field(
        ga_mod.DEFAULT_GENERATIONS, le=MAX_GENERATIONS,
        description=f"evaluated generations, including the initial one, 1 .. "
                    f"{MAX_GENERATIONS:,}")
    pc: NonNegFloat = Field(ga_mod.DEFAULT_PC, le=1,
                            description="crossover probability per pair of parents, 0 .. 1")
    pm: NonNegFloat = Field(
        ga_mod.DEFAULT_PM, le=1,
        description="mutation probability: per bit (ga-paper) or per gene (ga), 0 .. 1")
    bits: PositiveInt = Field(ga_mod.DEFAULT_BITS, ge=2, le=52,
                              description="bits per parameter (binary coding, ga-paper), 2 .. 52")
    selection: Literal["roulette", "tournament"] | None = Field(
        None, description="selection (null: roulette for ga-paper, tournament for ga)")
    elitism: NonNegInt | None = Field(
        None, le=MAX_POP, description="elites kept, fewer than pop (null: 0 / 2)")
    crossover: Literal["line-sbx", "sbx"] | None = Field(
        None, description="real-coded crossover of ga (null: line-sbx)")
    tournament: PositiveInt = Field(ga_mod.DEFAULT_TOURNAMENT, le=MAX_POP,
                                    description="tournament size, at most pop")
    eta_c: NonNegFloat | None = Field(
        None, le=MAX_ETA, description=f"SBX distribution index, 0 .. {MAX_ETA:g} (null: preset)")
    eta_m: NonNegFloat = Field(
        ga_mod.DEFAULT_ETA_M, le=MAX_ETA,
        description=f"polynomial-mutation distribution index, 0 .. {MAX_ETA:g}")
    mutation_unit: Literal["bit", "chromosome"] = Field(
        "bit", description="ga-paper: pm per bit, or per chromosome (one random bit flips)")
    patience: NonNegInt = Field(
        0, le=MAX_GENERATIONS, description="early stop after N stale generations (0: off)")

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

    kL: PositiveFloat = Field(TRUE_KL, description="true stiffness [N*m/rad]")
    alpha: NonNegFloat = Field(TRUE_ALPHA, description="true half backlash [rad]")
    damping: Form = Field("contact", description="damping form of the simulator")
    noise_pct: NonNegFloat = Field(
        0.0, le=MAX_NOISE_PCT, description=f"Gaussian noise, % of the torque RMS (at most "
                                           f"{MAX_NOISE_PCT:g})")
    amplitude_deg: PositiveFloat = Field(CHIRP_AMPLITUDE_DEG, description="chirp amplitude [deg]")
    freq_hz: PositiveFloat = Field(CHIRP_F0_HZ, description="chirp start frequency [Hz]")
    freq_end_hz: PositiveFloat = Field(CHIRP_F1_HZ, description="chirp end frequency [Hz]")
    sweep_time_s: PositiveFloat = Field(CHIRP_SWEEP_S, description="chirp sweep time [s]")
    duration_s: PositiveFloat = Field(DATA_DURATION_S, description="simulated time [s]")
    dt_s: PositiveFloat = Field(DATA_DT_S, description="integration step [s], <= duration_s")
    sample_interval_s: PositiveFloat = Field(
        SAMPLE_INTERVAL_S, description="sample interval of the data [s], dt_s .. duration_s")
    plant: dict[str, float | int | str] = Field(
        default_factory=dict, description="other model parameter overrides, SI")

    @field_validator("plant")
    @classmethod
    def _plant(cls, v: dict[str, Any]) -> dict[str, Any]:
        for name, value in v.items():
            if name in ("kL", "alpha", "damping"):
                raise ValueError(f"{KEY_MARK}{name}{KEY_MARK}set synthetic.{name} instead (the "
                                 "data's true value)")
            try:
                check_value(name, value)
            except EmaError as exc:
                raise ValueError(f"{KEY_MARK}{name}{KEY_MARK}{exc.message}") from None
        return v

    @model_validator(mode="after")
    def _grid(self) -> SyntheticSettings:
        if self.dt_s > self.duration_s:
            raise ValueError(f"dt_s ({self.dt_s:g} s) must not exceed duration_s "
                             f"({self.duration_s:g} s)")
        if not self.dt_s <= self.sample_interval_s <= self.duration_s:
            raise ValueError(f"sample_interval_s ({self.sample_interval_s:g} s) must lie "
                             f"between dt_s ({self.dt_s:g} s) and duration_s "
                             f"({self.duration_s:g} s)")
        steps = self.duration_s / self.dt_s
        if steps > MAX_SYNTHETIC_STEPS:
            raise ValueError(f"duration_s / dt_s = {steps:.3g} steps; synthetic data is "
                             f"limited to {MAX_SYNTHETIC_STEPS:,} steps")
        from ema_cli.sim.grid import off_grid

        if off_grid(self.sample_interval_s, self.dt_s):
            raise ValueError(f"sample_interval_s ({self.sample_interval_s:g} s) must be a whole "
                             f"multiple of dt_s ({self.dt_s:g} s)")
        return self


MAX_SYNTHETIC_STEPS = 100_000_000  # integration steps of synthetic data at most [steps]


class IdentifySettings(Strict):
    """Everything one ``ema identify`` run needs (see configs/identify.yaml)."""

    name: PlainName = Field("identify", description="study name (a folder name)")
    method: Method = Field("ga", description="ga (improved GA), ga-paper, or exact")
    model: Form = Field("contact", description="torque form fitted: contact or paper (Eq. 2)")
    k_range: tuple[float, float] = Field(DEFAULT_K_RANGE, description="kL range [N*m/rad]")
    alpha_range: tuple[float, float] = Field(DEFAULT_ALPHA_RANGE, description="alpha range [rad]")
    c_range: tuple[float, float] = Field(DEFAULT_C_RANGE,
                                         description="c range when fitted [N*m*s/rad]")
    fit_c: bool | None = Field(
        None, description="fit c too (null: yes for --data, no for synthetic data)")
    c: NonNegFloat | None = Field(
        None, description="fixed c [N*m*s/rad], finite >= 0 (null: simulator's)")
    contact_tau: NonNegFloat | None = Field(
        None, description="contact form: damping ramp-in time of the model fitted [s] "
                          "(null: the synthetic data's, else the model default of `ema params`)")
    data: str | None = Field(None, description="CSV with t_s, dtheta_rad, domega_rad_s, torque_nm")
    columns: dict[str, str] = Field(default_factory=dict,
                                    description="column mapping, canonical name -> file column")
    runs: PositiveInt = Field(
        1, le=MAX_RUNS,
        description=f"GA runs (seeds SeedSequence(seed).spawn(runs)), 1 .. {MAX_RUNS:,}")
    n_jobs: Integer = Field(1, ge=-1, le=MAX_WORKERS,
                        description=f"parallel processes for the runs, 1 .. {MAX_WORKERS} "
                                    "(-1: all cores)")
    seed: Seed = Field(0, description="seed of the GA runs and of the noise (0 .. 2**63-1)")
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
            work = self.ga.pop * self.ga.generations * self.runs
            if work > MAX_EVALUATIONS:
                raise ValueError(
                    f"ga.pop * ga.generations * runs = {work:,} cost evaluations; at most "
                    f"{MAX_EVALUATIONS:,}: lower ga.pop, ga.generations or runs")
        return self

    @property
    def fits_c(self) -> bool:
        """Whether c is identified: explicit ``fit_c``, else yes for file data without c."""
        if self.fit_c is not None:
            return self.fit_c
        return self.data is not None and self.c is None
