"""Schema of an experiment batch (e.g. experiments/paper2020.yaml): studies, thresholds, claims.

Paths to study configs are relative to the experiment file. Units: threshold ranges are in the
unit of the varied nonlinearity (`ema locations`); requirements use metric columns in edge units.

Study ids, threshold ids, figure names and the experiment's name become file and folder names
of the report, so they are plain names (``config.base.PlainName``) and unique. Claims and the
ranking may only name studies and results the experiment computes.
"""

from __future__ import annotations

from typing import Any, Literal

from pydantic import Field, field_validator, model_validator

from ema_cli.config.base import (
    FiniteFloat,
    NonNegFloat,
    PlainName,
    PositiveFloat,
    PositiveInt,
    Strict,
)
from ema_cli.config.claims import Claim, ScalarCheck
from ema_cli.config.criteria import DEFAULT_RTOL, MAX_RTOL, Criterion
from ema_cli.errors import EmaError
from ema_cli.model.nonlinearities import lookup, nonlinearity_updates
from ema_cli.model.params import resolve
from ema_cli.sim.tables import METRIC_BY_EDGE

FIGURE_SUFFIXES = (".png", ".svg", ".pdf")
"""File types a study figure may be written as."""
RANKING_SCALARS = ("ranking.paper_first_rank", "ranking.first_is_paper_first")
"""The scalar results a ranking adds (for scalar claims)."""
SENSITIVITY_SCALARS = ("sensitivity.paper_first_rank", "sensitivity.first_is_paper_first",
                       "sensitivity.paper_first_st", "sensitivity.first_st")
"""The scalar results the global sensitivity ranking adds (for scalar claims): the Sobol ST rank
of the paper's first, whether it is first, its ST, and the ST of the factor ranked first; also
``sensitivity.rank.<factor>`` for every factor."""


def _known_metric(name: str) -> str:
    if name not in METRIC_BY_EDGE:
        raise ValueError(f"unknown metric '{name}'; expected one of {', '.join(METRIC_BY_EDGE)}")
    return name


class StudySpec(Strict):
    """One sweep of the batch, shown as one of the paper's figures."""

    id: PlainName = Field(description="study id, used by claims and as a folder name (fig03)")
    config: str = Field(description="study config (path relative to the experiment file)")
    figure: PlainName = Field(
        description="file name of our figure, e.g. fig03_deadzone2.png (.png, .svg or .pdf)")
    caption: str = Field(description="the paper's caption")
    shows: str = Field("", description="what the paper says the figure shows")
    plot: Literal["errors", "response"] = Field(
        "errors", description="errors: tracking-error overlay; response: position/velocity")

    @field_validator("figure")
    @classmethod
    def _figure(cls, v: str) -> str:
        if not v.lower().endswith(FIGURE_SUFFIXES):
            raise ValueError(f"a figure file name ends in {', '.join(FIGURE_SUFFIXES)}, got "
                             f"{v!r}")
        return v


class RelativeRequirement(Strict):
    """metric <= factor * metric of the reference run (plus an absolute margin)."""

    metric: str
    factor: PositiveFloat
    margin: NonNegFloat = Field(0.0, description="added to the limit, metric unit")

    _metric = field_validator("metric")(_known_metric)


class ThresholdSpec(Strict):
    """A threshold to compute (and compare with the paper's value)."""

    id: PlainName = Field(description="threshold id: the scalar result claims name, and "
                                      "threshold_<id>.png")
    config: str
    vary: str
    range: tuple[PositiveFloat, PositiveFloat] = Field(
        description="LO < HI, both > 0 (the search is logarithmic), unit of the varied "
                    "nonlinearity")
    direction: Literal["max", "min"] = "max"
    require: list[str] = Field(default_factory=list, description="METRIC<=VALUE requirements")
    reference_value: NonNegFloat | None = Field(
        None, description="magnitude of the varied nonlinearity for the reference run of the "
                          "relative requirements (e.g. a near-rigid stiffness)")
    require_relative: list[RelativeRequirement] = Field(default_factory=list)
    rtol: PositiveFloat = Field(
        DEFAULT_RTOL, le=MAX_RTOL,
        description=f"relative width of the final bracket, > 0 and <= {MAX_RTOL}")
    percent_of_input: bool = Field(False, description="also report the value as % of the input")
    unit: str = Field("", description="unit of the reported value")
    paper: str = Field("", description="the paper's statement")
    paper_value: FiniteFloat | None = Field(None, description="the paper's threshold, same unit")
    tuning: str | None = Field(
        None, description="a tuning config (`ema tune`, relative to the experiment file): the "
                          "search runs with the controller it tunes (its tuned values as plant "
                          "overrides)")
    compare_to: PlainName | None = Field(
        None, description="an earlier threshold id: adds the scalar <id>_ratio = this "
                          "threshold / that one")

    @field_validator("vary")
    @classmethod
    def _vary(cls, v: str) -> str:
        try:
            lookup(v)
        except EmaError as exc:
            raise ValueError(exc.message) from None
        return v

    @field_validator("require")
    @classmethod
    def _require(cls, v: list[str]) -> list[str]:
        for r in v:
            try:
                Criterion.parse(r)
            except EmaError as exc:
                raise ValueError(exc.message) from None
        return v

    @model_validator(mode="after")
    def _check(self) -> ThresholdSpec:
        lo, hi = self.range
        if not lo < hi:
            raise ValueError(f"range needs LO < HI, got [{lo:g}, {hi:g}]")
        if not self.require and not self.require_relative:
            raise ValueError("a threshold needs at least one requirement (require or "
                             "require_relative)")
        if self.require_relative and self.reference_value is None:
            raise ValueError("require_relative needs reference_value (the magnitude of the "
                             "reference run)")
        base = resolve()
        for key, value in (("range", lo), ("range", hi), ("reference_value",
                                                          self.reference_value)):
            if value is None:
                continue
            try:
                nonlinearity_updates(self.vary, value, base)
            except EmaError as exc:
                raise ValueError(f"{key}: {exc.message}") from None
        return self


class IdentificationSpec(Strict):
    """The paper's §3.1 identification, run through `ema identify`'s library entry point."""

    settings: dict[str, Any] = Field(
        default_factory=dict, description="settings passed to the identification (the keys of "
                                          "configs/identify.yaml, checked when the experiment "
                                          "is loaded)")
    paper_errors_pct: tuple[NonNegFloat, NonNegFloat] = Field(
        (0.85, 3.7), description="the paper's kL and alpha errors [%]")


class RankingSpec(Strict):
    """Rank nonlinearities by the worst ratio of a metric to its baseline within each study."""

    metric: str = "iae_pos_deg_s"
    studies: list[PlainName] = Field(min_length=1, description="ids of studies of the batch")
    paper: str = ""
    paper_first: str = Field("", description="the study the paper names the worst")

    _metric = field_validator("metric")(_known_metric)


class SensitivitySpec(Strict):
    """A global sensitivity study (`ema sensitivity`) ranking the nonlinearities, beside the
    paper's ranking and the one-at-a-time ranking of the studies."""

    config: str = Field(description="sensitivity config (path relative to the experiment file)")
    method: Literal["sobol", "morris"] = "sobol"
    n: PositiveInt = Field(description="Sobol base samples (a power of two) or Morris "
                                       "trajectories; sized for CI")
    input: PlainName = Field(description="the input of the config whose ranking the claims read")
    metric: str = "iae_pos_deg_s"
    paper: str = ""
    paper_first: str = Field(description="the factor the paper names the worst")
    studies: dict[PlainName, str] = Field(
        default_factory=dict, description="study id of the one-at-a-time ranking -> the factor "
                                          "it varies (for the side-by-side table)")

    _metric = field_validator("metric")(_known_metric)

    @model_validator(mode="after")
    def _check(self) -> SensitivitySpec:
        if self.method == "sobol" and self.n & (self.n - 1):
            raise ValueError(f"n must be a power of two for Sobol sampling, got {self.n}")
        return self


def _unique(ids: list[str], what: str) -> None:
    seen: set[str] = set()
    for k, i in enumerate(ids):
        if i in seen:
            raise ValueError(f"{what} '{i}' is given twice (the second at index {k}); "
                             f"{what}s must be unique")
        seen.add(i)


class ExperimentConfig(Strict):
    """An experiment batch: what to run together and what it must show."""

    name: PlainName = Field(description="experiment name (a folder name)")
    description: str = ""
    paper: str = ""
    studies: list[StudySpec] = Field(default_factory=list)
    thresholds: list[ThresholdSpec] = Field(default_factory=list)
    identification: IdentificationSpec | None = None
    ranking: RankingSpec | None = None
    sensitivity: SensitivitySpec | None = None
    claims: list[Claim] = Field(default_factory=list)

    @model_validator(mode="after")
    def _check(self) -> ExperimentConfig:
        if not self.studies and not self.claims:
            raise ValueError("an experiment needs at least one study or claim; this one has "
                             "neither")
        if not (self.studies or self.thresholds or self.identification is not None
                or self.sensitivity is not None):
            raise ValueError("an experiment needs something to run: studies, thresholds or an "
                             "identification")
        _unique([s.id for s in self.studies], "study id")
        _unique([s.figure.lower() for s in self.studies], "figure file name")
        _unique([t.id for t in self.thresholds], "threshold id")
        for k, t in enumerate(self.thresholds):
            earlier = [u.id for u in self.thresholds[:k]]
            if t.compare_to is not None and t.compare_to not in earlier:
                raise ValueError(f"thresholds.{k} ({t.id}): compare_to '{t.compare_to}' is not "
                                 "an earlier threshold id; earlier: "
                                 f"{', '.join(earlier) or 'none'}")
        _unique([c.id for c in self.claims], "claim id")
        studies = {s.id for s in self.studies}
        known = ", ".join(sorted(studies)) or "none"
        if self.ranking is not None:
            for sid in self.ranking.studies:
                if sid not in studies:
                    raise ValueError(f"ranking.studies: unknown study '{sid}'; studies: {known}")
            if self.ranking.paper_first and self.ranking.paper_first not in studies:
                raise ValueError(f"ranking.paper_first: unknown study "
                                 f"'{self.ranking.paper_first}'; studies: {known}")
        if self.sensitivity is not None:
            for sid in self.sensitivity.studies:
                if sid not in studies:
                    raise ValueError(f"sensitivity.studies: unknown study '{sid}'; studies: "
                                     f"{known}")
        for k, c in enumerate(self.claims):
            if c.figure and c.figure not in studies:
                raise ValueError(f"claims.{k} ({c.id}): figure '{c.figure}' is not a study id; "
                                 f"studies: {known}")
            if isinstance(c.check, ScalarCheck):
                self._check_scalar(k, c.id, c.check.name)
            elif c.check.study not in studies:
                raise ValueError(f"claims.{k} ({c.id}): unknown study '{c.check.study}'; "
                                 f"studies: {known}")
        return self

    def _check_scalar(self, k: int, cid: str, name: str) -> None:
        thresholds = ([t.id for t in self.thresholds]
                      + [f"{t.id}_ratio" for t in self.thresholds if t.compare_to]
                      + [f"{t.id}.tuning_cost" for t in self.thresholds if t.tuning])
        if name in thresholds:
            return
        if name.startswith("identification.") and self.identification is not None:
            return
        if name in RANKING_SCALARS and self.ranking is not None:
            return
        if self.sensitivity is not None and (name in SENSITIVITY_SCALARS
                                             or name.startswith("sensitivity.rank.")):
            return
        results = thresholds + (["identification.<key>"] if self.identification else []) + (
            list(RANKING_SCALARS) if self.ranking else []) + (
            [*SENSITIVITY_SCALARS, "sensitivity.rank.<factor>"] if self.sensitivity else [])
        raise ValueError(f"claims.{k} ({cid}): no result named '{name}'; the experiment "
                         f"computes: {', '.join(results) or 'no scalar results'}")
