"""Schema of an experiment batch (e.g. experiments/paper2020.yaml): studies, thresholds, claims.

Paths to study configs are relative to the experiment file. Units: threshold ranges are in the
unit of the varied nonlinearity (`ema locations`); requirements use metric columns in edge units.
"""

from __future__ import annotations

from typing import Any, Literal

from pydantic import Field, field_validator

from ema_cli.config.claims import Claim
from ema_cli.config.criteria import DEFAULT_RTOL, Criterion
from ema_cli.config.schema import Strict
from ema_cli.errors import EmaError
from ema_cli.model.nonlinearities import lookup


class StudySpec(Strict):
    """One sweep of the batch, shown as one of the paper's figures."""

    id: str = Field(description="study id, used by claims (e.g. fig03)")
    config: str = Field(description="study config (path relative to the experiment file)")
    figure: str = Field(description="file name of our figure, e.g. fig03_deadzone2.png")
    caption: str = Field(description="the paper's caption")
    shows: str = Field("", description="what the paper says the figure shows")
    plot: Literal["errors", "response"] = Field(
        "errors", description="errors: tracking-error overlay; response: position/velocity")


class RelativeRequirement(Strict):
    """metric <= factor * metric of the reference run (plus an absolute margin)."""

    metric: str
    factor: float = Field(gt=0)
    margin: float = Field(0.0, ge=0, description="added to the limit, metric unit")


class ThresholdSpec(Strict):
    """A threshold to compute (and compare with the paper's value)."""

    id: str
    config: str
    vary: str
    range: tuple[float, float]
    direction: Literal["max", "min"] = "max"
    require: list[str] = Field(default_factory=list, description="METRIC<=VALUE requirements")
    reference_value: float | None = Field(
        None, description="magnitude of the varied nonlinearity for the reference run of the "
                          "relative requirements (e.g. a near-rigid stiffness)")
    require_relative: list[RelativeRequirement] = Field(default_factory=list)
    rtol: float = DEFAULT_RTOL
    percent_of_input: bool = Field(False, description="also report the value as % of the input")
    unit: str = Field("", description="unit of the reported value")
    paper: str = Field("", description="the paper's statement")
    paper_value: float | None = Field(None, description="the paper's threshold, same unit")

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


class IdentificationSpec(Strict):
    """The paper's §3.1 identification, run through `ema identify`'s library entry point."""

    settings: dict[str, Any] = Field(default_factory=dict,
                                     description="settings passed to the identification")
    paper_errors_pct: tuple[float, float] = Field(
        (0.85, 3.7), description="the paper's kL and alpha errors [%]")


class RankingSpec(Strict):
    """Rank nonlinearities by the worst ratio of a metric to its baseline within each study."""

    metric: str = "iae_pos_deg_s"
    studies: list[str]
    paper: str = ""
    paper_first: str = Field("", description="the study the paper names the worst")


class ExperimentConfig(Strict):
    """An experiment batch: what to run together and what it must show."""

    name: str
    description: str = ""
    paper: str = ""
    studies: list[StudySpec]
    thresholds: list[ThresholdSpec] = Field(default_factory=list)
    identification: IdentificationSpec | None = None
    ranking: RankingSpec | None = None
    claims: list[Claim] = Field(default_factory=list)
