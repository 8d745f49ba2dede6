"""Requirements on metrics (``METRIC<=VALUE``) and the threshold search's default tolerance.

Parsed where configs are validated (``config.experiment``) and used by the threshold search
(``analysis.threshold``); metric names are the edge-unit columns of ``sim.tables``.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from typing import Literal

import numpy as np

from ema_cli.errors import EmaError
from ema_cli.sim.tables import METRIC_BY_EDGE

DEFAULT_RTOL = 1e-3  # stop when the bracket is narrower than this, relative to its upper end
MAX_RTOL = 0.5  # the loosest relative tolerance accepted: wider is no threshold at all [-]

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
        m = _REQ.match(text) if isinstance(text, str) else None
        if not m:
            raise EmaError(f"requirement {text!r} must look like METRIC<=VALUE (or >=, <, >)")
        try:
            limit = float(m.group(3))
        except ValueError:  # the pattern admits e.g. '1e' or '1.2.3'
            raise EmaError(f"requirement {text!r}: '{m.group(3)}' is not a number") from None
        crit = cls(m.group(1), m.group(2), limit)  # type: ignore[arg-type]
        crit.check()
        return crit

    def check(self) -> None:
        """Refuse an unknown metric or a limit that is not a finite number."""
        if self.metric not in METRIC_BY_EDGE:
            raise EmaError(f"unknown metric '{self.metric}'; expected one of "
                           f"{', '.join(METRIC_BY_EDGE)}")
        if not math.isfinite(self.limit):
            raise EmaError(f"requirement on '{self.metric}': the limit must be a finite number, "
                           f"got {self.limit}")

    def passes(self, values: np.ndarray) -> np.ndarray:
        v = np.asarray(values, dtype=float)
        with np.errstate(invalid="ignore"):
            ok = {"<=": v <= self.limit, ">=": v >= self.limit,
                  "<": v < self.limit, ">": v > self.limit}[self.op]
        return ok & np.isfinite(v)

    def __str__(self) -> str:
        return f"{self.metric} {self.op} {self.limit:g}"
