"""The schema of a global sensitivity study (``ema sensitivity``): a run config plus the factors
(nonlinearity magnitudes or model parameters, each over a linear or logarithmic range), the
metrics, one or more inputs, and the sampling settings (Morris or Sobol, with SALib).

Every sample is one simulation, run through the sweep machinery (``sensitivity.run``), so the
parallel section is the sweep's.
"""

from __future__ import annotations

from typing import Literal

from pydantic import Field, field_validator, model_validator

from ema_cli.config.base import FiniteFloat, PlainName, PositiveInt, Strict
from ema_cli.config.run import InputConfig, RunConfig, as_value_error
from ema_cli.config.study import ParallelConfig
from ema_cli.errors import EmaError
from ema_cli.model.nonlinearities import lookup, nonlinearity_updates
from ema_cli.model.params import BY_NAME, INDEX, check_value, resolve
from ema_cli.sim.tables import METRIC_BY_EDGE

METHODS = ("sobol", "morris")
DEFAULT_SOBOL_N = 1024  # Saltelli base samples: n*(D+2) runs per input [-]
DEFAULT_MORRIS_N = 64  # Morris trajectories: n*(D+1) runs per input [-]
MAX_N = 2**20  # the largest n of either method [-]
MAX_RUNS_DEFAULT = 500_000  # a study needing more simulations is refused [runs]
MAX_RUNS_CAP = 1_000_000  # the largest sensitivity.max_runs accepted [runs]
DEFAULT_RESAMPLES = 200  # bootstrap resamples of the confidence intervals [-]
MAX_RESAMPLES = 10_000  # the most bootstrap resamples accepted [-]
DEFAULT_METRICS = ("iae_pos_deg_s", "p2p_err_pos_deg")
"""IAE of the position error and the residual oscillation (peak-to-peak position error over the
last 20 % of the run)."""


def is_power_of_two(n: int) -> bool:
    """True for 1, 2, 4, 8, ..."""
    return n >= 1 and n & (n - 1) == 0


def check_sobol_n(n: int, where: str) -> None:
    """Refuse a Sobol base sample size that is not a power of two (Saltelli's scheme on a
    Sobol' sequence keeps its balance properties only then), naming ``where``."""
    if not is_power_of_two(n):
        lo = 1 << (n.bit_length() - 1)
        raise EmaError(f"{where} must be a power of two for Sobol sampling (Saltelli's scheme "
                       f"on a Sobol' sequence), got {n}; e.g. {lo} or {2 * lo}")


class Factor(Strict):
    """One uncertain factor: a nonlinearity magnitude (unit of ``ema locations``) or a model
    parameter (SI, ``ema params``), uniform over ``range`` on a linear or logarithmic scale."""

    name: PlainName | None = Field(
        None, description="factor name for tables and figures (default: the nonlinearity or "
                          "parameter name)")
    nonlinearity: str | None = Field(
        None, description="paper name or type@location whose magnitude varies")
    parameter: str | None = Field(None, description="model parameter that varies, SI")
    range: tuple[FiniteFloat, FiniteFloat] = Field(
        description="[low, high], low < high, in the unit of the nonlinearity or parameter")
    scale: Literal["linear", "log"] = Field(
        "linear", description="linear: uniform in the value; log: uniform in its logarithm "
                              "(low > 0)")

    @property
    def target(self) -> str:
        """The nonlinearity or parameter name."""
        return self.nonlinearity if self.nonlinearity is not None else str(self.parameter)

    @property
    def label(self) -> str:
        """The factor name (given, or the target)."""
        return self.name or self.target

    @property
    def unit(self) -> str:
        """The unit of the factor's values."""
        if self.parameter is not None:
            return BY_NAME[self.parameter].unit
        return lookup(self.target).unit

    @property
    def key(self) -> str:
        """What the factor sets: ``type@location`` or the parameter name (duplicates check)."""
        if self.parameter is not None:
            return self.parameter
        pl = lookup(self.target)
        return f"{pl.type}@{pl.location}"

    @model_validator(mode="after")
    def _check(self) -> Factor:
        if (self.nonlinearity is None) == (self.parameter is None):
            raise ValueError("a factor varies exactly one of 'nonlinearity' or 'parameter'")
        key = "parameter" if self.parameter is not None else "nonlinearity"
        try:
            if self.parameter is not None and self.parameter not in INDEX:
                raise EmaError(f"unknown model parameter '{self.parameter}'; expected one of: "
                               f"{', '.join(INDEX)}")
            if self.nonlinearity is not None:
                lookup(self.nonlinearity)
        except EmaError as exc:
            raise as_value_error(exc, key) from None
        lo, hi = self.range
        if not lo < hi:
            what = "empty" if lo == hi else "inverted"
            raise as_value_error(EmaError(
                f"{what} range [{lo:g}, {hi:g}]: expected [low, high] with low < high"), "range")
        if self.scale == "log" and lo <= 0:
            raise as_value_error(EmaError(
                f"a log range needs low > 0, got [{lo:g}, {hi:g}]"), "range")
        base = resolve()
        for v in (lo, hi):
            try:
                if self.parameter is not None:
                    if BY_NAME[self.parameter].choices is not None:
                        raise EmaError(f"parameter '{self.parameter}' is a choice, not a number")
                    check_value(self.parameter, v)
                else:
                    nonlinearity_updates(self.target, v, base)
            except EmaError as exc:
                raise as_value_error(exc, "range") from None
        return self


class NamedInput(InputConfig):
    """One input signal of the study, with a name for tables, figures and files."""

    name: PlainName = Field(description="input name, e.g. step0.1 (a plain file name)")


class SensitivitySettings(Strict):
    """How the factor space is sampled and the indices estimated (SALib)."""

    method: Literal["sobol", "morris"] = Field(
        "sobol", description="sobol: Saltelli sampling, first-order and total indices (S1, ST) "
                             "with bootstrap confidence intervals; morris: elementary effects "
                             "(mu*, sigma)")
    n_sobol: PositiveInt = Field(
        DEFAULT_SOBOL_N, le=MAX_N,
        description="Sobol base samples N, a power of two: N*(D+2) runs per input (no second "
                    "order)")
    n_morris: PositiveInt = Field(
        DEFAULT_MORRIS_N, le=MAX_N, description="Morris trajectories r: r*(D+1) runs per input")
    morris_levels: PositiveInt = Field(
        4, le=64, description="Morris grid levels p (even, >= 2); step = p/(2(p-1))")
    conf_level: FiniteFloat = Field(
        0.95, gt=0.0, lt=1.0, description="confidence level of the intervals (0..1)")
    num_resamples: PositiveInt = Field(
        DEFAULT_RESAMPLES, ge=10, le=MAX_RESAMPLES,
        description="bootstrap resamples for the confidence intervals")
    transform: Literal["none", "log10"] = Field(
        "none", description="none: the indices apportion the variance of each metric; log10: "
                            "of its decimal logarithm (for positive metrics spanning decades, "
                            "whose variance a few extreme runs would otherwise dominate)")
    max_runs: PositiveInt = Field(
        MAX_RUNS_DEFAULT, le=MAX_RUNS_CAP,
        description=f"refuse studies needing more simulations (at most {MAX_RUNS_CAP:,})")

    @field_validator("n_sobol")
    @classmethod
    def _n_sobol(cls, v: int) -> int:
        try:
            check_sobol_n(v, "n_sobol")
        except EmaError as exc:
            raise ValueError(exc.message) from None
        return v

    @field_validator("morris_levels")
    @classmethod
    def _levels(cls, v: int) -> int:
        if v < 2 or v % 2:
            raise ValueError(f"morris_levels must be even and >= 2, got {v}")
        return v

    def n(self, method: str) -> int:
        """The configured sample size of ``method``."""
        return self.n_sobol if method == "sobol" else self.n_morris


class SensitivityConfig(RunConfig):
    """A sensitivity study: one run's settings (RunConfig: plant, simulation, fixed
    nonlinearities, ...), the inputs, the factors, the metrics and the sampling settings."""

    inputs: list[NamedInput] | None = Field(
        None, description="input signals, each studied on its own (default: the run's 'input', "
                          "named 'input'; with 'inputs', 'input' must be absent or default)")
    factors: list[Factor] = Field(description="the factors that vary (at least one)")
    metrics: list[str] = Field(
        default_factory=lambda: list(DEFAULT_METRICS),
        description="metrics (metrics.csv column names) whose sensitivity is analysed")
    sensitivity: SensitivitySettings = Field(default_factory=SensitivitySettings)
    parallel: ParallelConfig = Field(default_factory=ParallelConfig)

    @field_validator("metrics")
    @classmethod
    def _metrics(cls, v: list[str]) -> list[str]:
        if not v:
            raise ValueError("give at least one metric")
        seen: set[str] = set()
        for k, name in enumerate(v):
            if name not in METRIC_BY_EDGE:
                raise as_value_error(EmaError(f"unknown metric '{name}'; expected one of "
                                              f"{', '.join(METRIC_BY_EDGE)}"), str(k))
            if name in seen:
                raise as_value_error(EmaError(f"metric '{name}' is listed twice"), str(k))
            seen.add(name)
        return v

    @model_validator(mode="after")
    def _check(self) -> SensitivityConfig:
        if not self.factors:
            raise as_value_error(EmaError("give at least one factor"), "factors")
        seen: dict[str, int] = {}
        names: dict[str, int] = {}
        writes: dict[str, int] = {}
        base = resolve()
        for k, f in enumerate(self.factors):
            if f.key in seen:
                raise as_value_error(EmaError(
                    f"'{f.target}' varies in factors {seen[f.key]} and {k}; give it once"),
                    f"factors.{k}")
            seen[f.key] = k
            if f.label in names:
                raise as_value_error(EmaError(
                    f"two factors are named '{f.label}' (factors {names[f.label]} and {k}); set "
                    "'name'"), f"factors.{k}.name")
            names[f.label] = k
            params = ({f.target} if f.parameter is not None else
                      set(nonlinearity_updates(f.target, f.range[1], base,
                                               self.friction_reading)))
            for p in sorted(params):
                if p in writes:
                    raise as_value_error(EmaError(
                        f"factors {writes[p]} and {k} both set the model parameter '{p}'; "
                        "vary it in one factor"), f"factors.{k}")
                writes[p] = k
        if self.inputs is not None:
            if not self.inputs:
                raise as_value_error(EmaError("give at least one input (or leave 'inputs' out "
                                              "to use 'input')"), "inputs")
            if "input" in self.model_fields_set and self.input != InputConfig():
                raise as_value_error(EmaError("give either 'input' or 'inputs', not both"),
                                     "inputs")
            seen_in: set[str] = set()
            for k, inp in enumerate(self.inputs):
                if inp.name in seen_in:
                    raise as_value_error(EmaError(f"input name '{inp.name}' is given twice"),
                                         f"inputs.{k}.name")
                seen_in.add(inp.name)
                if inp.start_s >= self.simulation.duration_s:
                    raise as_value_error(EmaError(
                        f"start_s ({inp.start_s:g} s) must be before the end of the run, "
                        f"simulation.duration_s ({self.simulation.duration_s:g} s)"),
                        f"inputs.{k}.start_s")
        return self

    def input_list(self) -> list[tuple[str, InputConfig]]:
        """(name, input) of every input studied."""
        if self.inputs is None:
            return [("input", self.input)]
        return [(i.name, InputConfig(**i.model_dump(exclude={"name"}))) for i in self.inputs]

    def runs(self, method: str, n: int) -> int:
        """Simulations the study needs with ``method`` at sample size ``n`` (all inputs)."""
        d = len(self.factors)
        per_input = n * (d + 2) if method == "sobol" else n * (d + 1)
        return per_input * len(self.input_list())
