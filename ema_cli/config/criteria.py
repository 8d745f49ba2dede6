"""Requirements on metrics (``METRIC<=VALUE``) and the threshold search's default tolerance.

Parsed where configs are validated (``config.experiment``) and used by the threshold search
(``analysis.threshold``); metric names are the edge-unit columns of ``sim.tables``.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Literal

import numpy as np

from ema_cli.errors import EmaError
from ema_cli.sim.tables import METRIC_BY_EDGE

DEFAULT_RTOL = 1e-3  # stop when the bracket is narrower than this, relative to its upper end

_REQ = re.compile(r"^\s*([A-Za-z0-9_]+)\s*(<=|>=|<|>)\s*([-+0-9.eE]+|inf)\s*$")


@dataclass(frozen=True)
class Criterion:
    """``metric op limit`` on one metric column in edge units; NaN or diverged fails."""

    metric: str
    op: Literal["<=", ">=", "<", ">"]
    limit: float

    @classmethod
    def parse(cls, text: str) -> Criterion:
        """Parse ``METRIC<=VALUE`` (or >=, <, >)."""
        m = _REQ.match(text)
        if not m:
            raise EmaError(f"requirement {text!r} must look like METRIC<=VALUE (or >=, <, >)")
        crit = cls(m.group(1), m.group(2), float(m.group(3)))  # type: ignore[arg-type]
        crit.check()
        return crit

    def check(self) -> None:
        if self.metric not in METRIC_BY_EDGE:
            raise EmaError(f"unknown metric '{self.metric}'; expected one of "
                           f"{', '.join(METRIC_BY_EDGE)}")

    def passes(self, values: np.ndarray) -> np.ndarray:
        v = np.asarray(values, dtype=float)
        with np.errstate(invalid="ignore"):
            ok = {"<=": v <= self.limit, ">=": v >= self.limit,
                  "<": v < self.limit, ">": v > self.limit}[self.op]
        return ok & np.isfinite(v)

    def __str__(self) -> str:
        return f"{self.metric} {self.op} {self.limit:g}"
