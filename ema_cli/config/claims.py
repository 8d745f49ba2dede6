"""Schema of the claims of an experiment batch: value, compare, monotonic, scalar checks.

A claim turns one of the paper's statements into an assertion over computed results (see
``analysis.claims``, which evaluates them). Here only the shape the experiment file must have.
"""

from __future__ import annotations

from typing import Literal

from pydantic import BaseModel, ConfigDict, Field

Op = Literal["<", "<=", ">", ">="]


class _Strict(BaseModel):
    model_config = ConfigDict(frozen=True, extra="forbid")


class ValueCheck(_Strict):
    """metric(row selected by ``where``) op value."""

    kind: Literal["value"]
    study: str
    where: dict[str, float | str] = Field(default_factory=dict)
    metric: str
    op: Op
    value: float


class CompareCheck(_Strict):
    """metric(row a) op factor * metric(row b) (e.g. removing a saturation raises a peak)."""

    kind: Literal["compare"]
    study: str
    a: dict[str, float | str]
    b: dict[str, float | str]
    metric: str
    op: Op
    factor: float = 1.0


class MonotonicCheck(_Strict):
    """metric is monotonic along the numeric values of column ``axis`` (rows with a number)."""

    kind: Literal["monotonic"]
    study: str
    axis: str
    metric: str
    direction: Literal["increasing", "decreasing"]
    strict: bool = True


class ScalarCheck(_Strict):
    """A named scalar result (identification error, threshold) op value."""

    kind: Literal["scalar"]
    name: str
    op: Op
    value: float


Check = ValueCheck | CompareCheck | MonotonicCheck | ScalarCheck


class Claim(_Strict):
    """One of the paper's statements and the assertion that checks it on our results."""

    id: str
    figure: str = ""
    paper: str = Field(description="the paper's statement, quoted or paraphrased")
    statement: str = Field(description="what we assert, in words")
    check: Check = Field(discriminator="kind")
