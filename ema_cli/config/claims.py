"""Schema of the claims of an experiment batch: value, compare, monotonic, scalar checks.

A claim turns one of the paper's statements into an assertion over computed results (see
``analysis.claims``, which evaluates them). Here only the shape the experiment file must have;
``config.experiment`` checks that the studies and results a claim names exist.
"""

from __future__ import annotations

from typing import Literal

from pydantic import Field

from ema_cli.config.base import FiniteFloat, PlainName, PositiveFloat, Strict

Op = Literal["<", "<=", ">", ">="]
Where = dict[str, FiniteFloat | str]
"""Selects one row of a study's metrics table: column -> value (a number or the text)."""


class ValueCheck(Strict):
    """metric(row selected by ``where``) op value."""

    kind: Literal["value"]
    study: PlainName = Field(description="id of a study of the experiment")
    where: Where = Field(default_factory=dict)
    metric: str
    op: Op
    value: FiniteFloat


class CompareCheck(Strict):
    """metric(row a) op factor * metric(row b) (e.g. removing a saturation raises a peak)."""

    kind: Literal["compare"]
    study: PlainName = Field(description="id of a study of the experiment")
    a: Where
    b: Where
    metric: str
    op: Op
    factor: PositiveFloat = 1.0


class MonotonicCheck(Strict):
    """metric is monotonic along the numeric values of column ``axis`` (rows with a number)."""

    kind: Literal["monotonic"]
    study: PlainName = Field(description="id of a study of the experiment")
    axis: str
    metric: str
    direction: Literal["increasing", "decreasing"]
    strict: bool = True


class ScalarCheck(Strict):
    """A named scalar result (identification error, threshold) op value."""

    kind: Literal["scalar"]
    name: str = Field(description="a threshold id, identification.<key> or ranking.<key>")
    op: Op
    value: FiniteFloat


Check = ValueCheck | CompareCheck | MonotonicCheck | ScalarCheck


class Claim(Strict):
    """One of the paper's statements and the assertion that checks it on our results."""

    id: PlainName
    figure: str = Field("", description="the study id whose figure the claim is about, or ''")
    paper: str = Field(description="the paper's statement, quoted or paraphrased")
    statement: str = Field(description="what we assert, in words")
    check: Check = Field(discriminator="kind")

    @property
    def study(self) -> str | None:
        """The study the check reads, None for a scalar check."""
        return None if isinstance(self.check, ScalarCheck) else self.check.study
