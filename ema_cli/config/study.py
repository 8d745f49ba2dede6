"""The schema of a sweep study (``ema sweep``): a run config plus the sweep, outputs and
parallel sections (``config.run`` holds the run part)."""

from __future__ import annotations

import math
from typing import Any, Literal

from pydantic import Field, field_validator, model_validator

from ema_cli.config.base import (
    FiniteFloat,
    Integer,
    PlainName,
    PositiveInt,
    Strict,
)
from ema_cli.config.run import RunConfig, Scalar, as_value_error, bools_to_words
from ema_cli.errors import EmaError
from ema_cli.model.nonlinearities import lookup, nonlinearity_updates
from ema_cli.model.params import INDEX, check_value, resolve
from ema_cli.sim.tables import METRIC_BY_EDGE

MAX_JOBS_DEFAULT = 100_000  # a sweep expanding past this many jobs is refused [jobs]
MAX_JOBS_CAP = 1_000_000  # the largest sweep.max_jobs accepted [jobs]
from ema_cli.limits import MAX_WORKERS  # noqa: E402 - the most parallel workers [workers]

MAX_CHUNK = 1_000_000  # the largest parallel.chunk_size [jobs]
MAX_AXIS_POINTS = 1_000_000  # the most points one linspace/logspace may ask for [points]
MAX_CURVES_DEFAULT = 8  # the most curves drawn in one overlay figure [curves]
RELATIVE_TYPES = ("deadzone",)
"""Nonlinearity types whose magnitude may be given relative to the baseline's peak signal."""
FIGURE_KINDS = ("errors", "response", "metrics")
"""Figures a sweep can draw: tracking-error overlays (paper Figs 2-5), position/velocity
response overlays (Figs 6-10), and metric-vs-magnitude plots."""
DEFAULT_SUMMARY_METRICS = (
    "iae_pos_deg_s", "rms_err_vel_deg_s", "overshoot_pct", "settling_time_s", "t50_s",
    "ss_err_pos_deg", "p2p_err_pos_deg", "peak_current_a",
)
"""Metrics shown in the summary table and the metric-vs-magnitude plots (metrics.csv has all)."""


class Span(Strict):
    """``num`` magnitudes from ``start`` to ``stop`` (both included), in the axis unit."""

    start: FiniteFloat = Field(description="first value, in the axis unit")
    stop: FiniteFloat = Field(description="last value, in the axis unit")
    num: PositiveInt = Field(le=MAX_AXIS_POINTS,
                             description=f"number of values (at most {MAX_AXIS_POINTS:,})")


class SweepAxis(Strict):
    """One sweep axis: a nonlinearity's magnitude, a type/location list, or a model parameter.

    * ``nonlinearity: deadzone2`` sweeps one placement's magnitude in the unit of
      ``ema locations`` (deadzone2: deg; saturation2: V or off; gap1: N*m/rad; ...).
    * ``nonlinearity: [deadzone1, deadzone@transmission, ...]`` sweeps over type and location:
      each listed placement takes each value (``values`` may map each name to its own list).
    * ``parameter: Kpp`` sweeps a model parameter in SI, as ``ema params`` lists it.

    Values come from exactly one of ``values``, ``linspace`` or ``logspace``. With
    ``relative: true`` (dead zones only) the values are percent of the peak of the signal the
    dead zone acts on, measured in the baseline run: the voltage demand (amplifier), the motor
    speed (speed sensor) and the input signal's amplitude (position sensor, transmission);
    see ``ema_cli.sweep.plan._relative_scales``.
    """

    name: PlainName | None = Field(
        None, description="axis name for columns, legends and files (default: the swept name, "
                          "or 'location'/'type'/'placement' for a list)")
    nonlinearity: str | list[str] | None = Field(
        None, description="paper name or type@location whose magnitude is swept; a list sweeps "
                          "type/location")
    parameter: str | None = Field(None, description="model parameter swept, SI (see `ema params`)")
    values: list[Scalar] | dict[str, list[Scalar]] | None = Field(
        None, description="magnitudes in the axis unit ('off' for saturations and friction); "
                          "for a list of nonlinearities optionally a mapping name -> values")
    linspace: Span | None = Field(None, description="evenly spaced values, axis unit")
    logspace: Span | None = Field(
        None, description="logarithmically spaced values from start to stop (not exponents), "
                          "axis unit; start, stop > 0")
    relative: bool = Field(
        False, description="dead zones: values are % of the baseline's peak signal at the "
                           "location")

    @field_validator("values", mode="before")
    @classmethod
    def _words(cls, v: Any) -> Any:
        return bools_to_words(v)

    @property
    def targets(self) -> tuple[str, ...]:
        """The swept nonlinearity names, or the parameter name."""
        if self.parameter is not None:
            return (self.parameter,)
        if isinstance(self.nonlinearity, str):
            return (self.nonlinearity,)
        return tuple(self.nonlinearity or ())

    @property
    def is_placement_axis(self) -> bool:
        """True when the axis sweeps over a list of nonlinearities (type/location)."""
        return isinstance(self.nonlinearity, list)

    @property
    def label(self) -> str:
        """The axis name (given, or derived from what is swept)."""
        if self.name:
            return self.name
        if not self.is_placement_axis:
            return self.targets[0]
        placements = [lookup(t) for t in self.targets]
        if len({pl.type for pl in placements}) == 1:
            return "location"
        if len({pl.location for pl in placements}) == 1:
            return "type"
        return "placement"

    def value_list(self, target: str | None = None) -> list[float | str]:
        """The axis values (for ``target`` when ``values`` maps names to lists), axis unit."""
        import numpy as np

        if self.linspace is not None:
            s = self.linspace
            return [float(x) for x in np.linspace(s.start, s.stop, s.num)]
        if self.logspace is not None:
            s = self.logspace
            return [float(x) for x in np.geomspace(s.start, s.stop, s.num)]
        if isinstance(self.values, dict):
            return list(self.values[target or self.targets[0]])
        return list(self.values or [])

    def n_points(self) -> int:
        """How many points the axis has (arithmetic only, nothing is expanded)."""
        if self.linspace is not None:
            return self.linspace.num
        if self.logspace is not None:
            return self.logspace.num
        if isinstance(self.values, dict):
            return sum(len(v) for v in self.values.values())
        return len(self.targets) * len(self.values or [])

    @model_validator(mode="after")
    def _check(self) -> SweepAxis:
        if (self.nonlinearity is None) == (self.parameter is None):
            raise ValueError("an axis sweeps exactly one of 'nonlinearity' or 'parameter'")
        given = [k for k in ("values", "linspace", "logspace") if getattr(self, k) is not None]
        if len(given) != 1:
            raise ValueError("give the axis values with exactly one of 'values', 'linspace' "
                             f"or 'logspace' (got {given or 'none'})")
        if self.logspace is not None and (self.logspace.start <= 0 or self.logspace.stop <= 0):
            raise as_value_error(EmaError("start and stop must be > 0 for a logarithmic axis, got "
                                    f"{self.logspace.start}, {self.logspace.stop}"), "logspace")
        if self.parameter is not None:
            self._check_parameter()
        else:
            self._check_nonlinearities()
        return self

    def _check_parameter(self) -> None:
        if self.parameter not in INDEX:
            raise as_value_error(EmaError(f"unknown model parameter '{self.parameter}'; "
                                          f"expected one of: {', '.join(INDEX)}"), "parameter")
        if isinstance(self.values, dict):
            raise as_value_error(EmaError("a parameter axis takes a list of values"), "values")
        if self.relative:
            raise as_value_error(EmaError("only dead-zone axes can be relative"), "relative")
        values = self.value_list()
        if not values:
            raise as_value_error(EmaError("empty sweep: the axis has no values"), "values")
        for k, v in enumerate(values):
            try:
                check_value(self.parameter, v)  # type: ignore[arg-type]
            except EmaError as exc:
                raise as_value_error(exc, f"values.{k}") from None

    def _check_nonlinearities(self) -> None:
        names = list(self.targets)
        if not names:
            raise as_value_error(EmaError("empty sweep: no nonlinearity listed"), "nonlinearity")
        for k, name in enumerate(names):
            try:
                lookup(name)
            except EmaError as exc:
                raise as_value_error(exc, "nonlinearity" if not self.is_placement_axis
                               else f"nonlinearity.{k}") from None
        keys = [f"{lookup(n).type}@{lookup(n).location}" for n in names]
        if len(set(keys)) != len(keys):
            raise as_value_error(EmaError(f"a placement is listed twice: {names}"), "nonlinearity")
        if isinstance(self.values, dict):
            if not self.is_placement_axis:
                raise as_value_error(EmaError("a mapping of values needs a list of nonlinearities"),
                               "values")
            if set(self.values) != set(names):
                raise as_value_error(EmaError(
                    f"the mapping must give values for exactly {names}, got {list(self.values)}"),
                    "values")
        base = resolve()
        for name in names:
            pl = lookup(name)
            if self.relative and pl.type not in RELATIVE_TYPES:
                raise as_value_error(EmaError(
                    f"only dead zones can be relative; '{name}' is a {pl.type}"), "relative")
            values = self.value_list(name)
            where = f"values.{name}" if isinstance(self.values, dict) else "values"
            if not values:
                raise as_value_error(EmaError("empty sweep: the axis has no values"), where)
            for k, v in enumerate(values):
                try:
                    if self.relative:
                        if isinstance(v, str) or not (math.isfinite(v) and v >= 0):
                            raise EmaError(f"a relative magnitude is a number >= 0 [%], got {v!r}")
                    else:
                        nonlinearity_updates(name, v, base)
                except EmaError as exc:
                    raise as_value_error(exc, f"{where}.{k}") from None


class SweepConfig(Strict):
    """What varies: the axes, how they combine, the baseline and the job cap."""

    mode: Literal["grid", "zip"] = Field(
        "grid", description="grid: cartesian product of the axes; zip: axes advance together")
    axes: list[SweepAxis] = Field(default_factory=list, description="the sweep axes")
    baseline: bool = Field(
        True, description="add a run with the swept nonlinearities off (dead zones 0, "
                          "saturations and friction off, compliance at the model default)")
    max_jobs: PositiveInt = Field(
        MAX_JOBS_DEFAULT, le=MAX_JOBS_CAP,
        description=f"refuse sweeps with more jobs (at most {MAX_JOBS_CAP:,})")

    @model_validator(mode="after")
    def _check(self) -> SweepConfig:
        seen: dict[str, int] = {}
        names: set[str] = set()
        for k, axis in enumerate(self.axes):
            for t in axis.targets:
                key = t if axis.parameter else f"{lookup(t).type}@{lookup(t).location}"
                if key in seen:
                    raise as_value_error(EmaError(f"'{t}' is swept by axes {seen[key]} and {k}"),
                                   f"axes.{k}")
                seen[key] = k
            if axis.label in names:
                raise as_value_error(EmaError(f"two axes are named '{axis.label}'; set 'name'"),
                               f"axes.{k}.name")
            names.add(axis.label)
        if self.mode == "zip" and len({a.n_points() for a in self.axes}) > 1:
            counts = [a.n_points() for a in self.axes]
            raise as_value_error(EmaError(f"zip needs axes of equal length, got {counts} points"),
                           "axes")
        return self

    def n_jobs(self) -> int:
        """Jobs the sweep expands to, without the baseline (arithmetic only)."""
        if not self.axes:
            return 0
        counts = [a.n_points() for a in self.axes]
        if self.mode == "zip":
            return counts[0]
        return math.prod(counts)


class OutputsConfig(Strict):
    """What a sweep writes besides metrics.csv, manifest.json and the resolved config."""

    timeseries: bool = Field(
        True, description="record every job's signals every simulation.output_interval_s into "
                          "signals.parquet (one file, one row per job and sample)")
    per_job_csv: bool = Field(
        False, description="also write timeseries/<job>.csv, one CSV per job (slow and large "
                           "for big sweeps: signals.parquet holds the same values)")
    figures: list[Literal["errors", "response", "metrics"]] = Field(
        default_factory=lambda: ["errors", "metrics"],
        description="figures to draw: errors (tracking-error overlays), response (position and "
                    "velocity overlays), metrics (metric vs magnitude)")
    metrics: list[str] = Field(
        default_factory=lambda: list(DEFAULT_SUMMARY_METRICS),
        description="metrics (metrics.csv column names) for the summary and the metric plots")
    max_curves: int = Field(
        MAX_CURVES_DEFAULT, ge=1, description="most curves per overlay figure (evenly sampled)")

    @field_validator("metrics")
    @classmethod
    def _metrics(cls, v: list[str]) -> list[str]:
        for k, name in enumerate(v):
            if name not in METRIC_BY_EDGE:
                raise as_value_error(EmaError(f"unknown metric '{name}'; expected one of "
                                        f"{', '.join(METRIC_BY_EDGE)}"), str(k))
        return v

    @property
    def needs_signals(self) -> bool:
        """True when the decimated time series must be recorded."""
        return (self.timeseries or self.per_job_csv or "errors" in self.figures
                or "response" in self.figures)


class ParallelConfig(Strict):
    """How the jobs are spread over cores or a cluster."""

    n_jobs: Integer | None = Field(
        None, ge=-1, le=MAX_WORKERS,
        description=f"workers (processes or threads, at most {MAX_WORKERS}); None or -1: all "
                    "cores")
    backend: Literal["auto", "loky", "threads", "dask"] = Field(
        "auto", description="auto (the faster local backend), loky (processes), threads "
                            "(threads in this process) or dask (needs scheduler)")
    scheduler: str | None = Field(None, description="dask scheduler address, e.g. tcp://host:8786")
    chunk_size: PositiveInt | None = Field(
        None, le=MAX_CHUNK,
        description=f"jobs per kernel batch (default: automatic; at most {MAX_CHUNK:,})")

    @field_validator("n_jobs")
    @classmethod
    def _n_jobs(cls, v: int | None) -> int | None:
        if v == 0:
            raise ValueError("n_jobs must be >= 1, or -1/null for all cores, got 0")
        return v


class StudyConfig(RunConfig):
    """A study: one run's settings (RunConfig) plus the sweep, outputs and parallel sections."""

    sweep: SweepConfig = Field(default_factory=SweepConfig)
    outputs: OutputsConfig = Field(default_factory=OutputsConfig)
    parallel: ParallelConfig = Field(default_factory=ParallelConfig)
