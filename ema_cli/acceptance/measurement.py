"""What an acceptance test returns: its measurements (a value, or a bound with the reason it
is only a bound) and the data of its figure."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any


@dataclass(frozen=True)
class Measurement:
    """One value: the metric, a condition (``""``, ``"5 deg"``, ``"position loop"``), the value
    in SI (``si_unit``), and a note (e.g. "at 36.5 Hz").

    A value read inside the test's measurable range has ``reason == ""``. Otherwise the test
    only bounds it: the true value lies in ``[lower, upper]`` (SI, one side infinite), ``value``
    is the finite edge, and ``reason`` says why and which setting widens the range ("bandwidth
    above the highest frequency measured, 2 Hz: widen f_max_hz"). :func:`judge` decides such a
    bound only when the whole interval lies on one side of the limit."""

    metric: str
    condition: str
    value: float
    si_unit: str
    note: str = ""
    lower: float = -math.inf
    upper: float = math.inf
    reason: str = ""

    @property
    def measured(self) -> bool:
        """Whether ``value`` was measured inside the measurable range."""
        return not self.reason


@dataclass
class TestRun:
    """The outcome of one test: measurements, data for its figure, wall time [s]."""

    name: str
    kind: str
    measurements: list[Measurement]
    data: dict[str, Any] = field(default_factory=dict)
    wall_s: float = 0.0
    notes: list[str] = field(default_factory=list)

    def values(self, metric: str) -> list[Measurement]:
        return [m for m in self.measurements if m.metric == metric]
