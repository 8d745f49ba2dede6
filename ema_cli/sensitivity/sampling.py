"""Sampling designs of the factor space (SALib): Saltelli/Sobol for Sobol indices, Morris
trajectories for elementary effects.

Every design is drawn in the unit hypercube ``U[n_rows, D]`` (each factor uniform on [0, 1])
and mapped to the factor values ``X[n_rows, D]`` per factor: ``low + u*(high - low)`` on a
linear scale, ``low*(high/low)**u`` on a logarithmic one. The analysis reads ``U``, so the
indices of a log factor are those of its logarithm, as sampled.

Nesting: SALib's Saltelli rows come in blocks of D+2 per point of one scrambled Sobol'
sequence (A, the D cross-samples AB_j, B), and the first k points of that sequence are the
k-point sequence of the same seed; so the first k*(D+2) rows of an N-sample are the k-sample
(checked in the tests). Morris trajectories are independent blocks of D+1 rows, so the first r
trajectories are an r-trajectory design. :meth:`Design.prefix` relies on both to show the
convergence of the indices without new simulations.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass

import numpy as np

from ema_cli.errors import EmaError

METHODS = ("sobol", "morris")


@dataclass(frozen=True)
class FactorRange:
    """One factor: a name, ``[low, high]`` in ``unit``, linear or logarithmic (low > 0)."""

    name: str
    low: float
    high: float
    log: bool = False
    unit: str = ""

    def __post_init__(self) -> None:
        if not (math.isfinite(self.low) and math.isfinite(self.high) and self.low < self.high):
            raise EmaError(f"factor '{self.name}': expected a range low < high, got "
                           f"[{self.low:g}, {self.high:g}]")
        if self.log and self.low <= 0:
            raise EmaError(f"factor '{self.name}': a log range needs low > 0, got "
                           f"[{self.low:g}, {self.high:g}]")

    def values(self, u: np.ndarray) -> np.ndarray:
        """Unit-interval samples ``u`` -> factor values (unit ``unit``); u = 0 and 1 give
        ``low`` and ``high`` exactly."""
        u = np.asarray(u, dtype=np.float64)
        if self.log:
            out = self.low * (self.high / self.low) ** u
        else:
            out = self.low + u * (self.high - self.low)
        return np.where(u <= 0.0, self.low, np.where(u >= 1.0, self.high, out))


def problem(factors: tuple[FactorRange, ...] | list[FactorRange]) -> dict[str, object]:
    """SALib's problem definition in the unit hypercube (the design's ``U``)."""
    return {"num_vars": len(factors), "names": [f.name for f in factors],
            "bounds": [[0.0, 1.0]] * len(factors)}


def rows_per_sample(method: str, d: int) -> int:
    """Rows of the design per base sample: D+2 (Saltelli, no second order) or D+1 (a Morris
    trajectory)."""
    return d + 2 if method == "sobol" else d + 1


@dataclass(frozen=True)
class Design:
    """A sampling design: ``unit[n_rows, D]`` in [0, 1] and ``n`` base samples (Sobol) or
    trajectories (Morris); ``seed`` drew it; ``num_levels`` is the Morris grid."""

    method: str
    factors: tuple[FactorRange, ...]
    n: int
    unit: np.ndarray
    seed: int
    num_levels: int = 4

    @property
    def d(self) -> int:
        """Number of factors."""
        return len(self.factors)

    @property
    def n_rows(self) -> int:
        """Simulations the design needs."""
        return self.unit.shape[0]

    @property
    def values(self) -> np.ndarray:
        """X[n_rows, D]: every row's factor values, each in its factor's unit."""
        return np.column_stack([f.values(self.unit[:, k]) for k, f in enumerate(self.factors)])

    def prefix(self, k: int) -> Design:
        """The design of the first ``k`` base samples (Sobol) or trajectories (Morris): the
        first k*(D+2) or k*(D+1) rows (see the module docstring)."""
        if not 1 <= k <= self.n:
            raise ValueError(f"prefix size {k} outside 1..{self.n}")
        rows = k * rows_per_sample(self.method, self.d)
        return Design(self.method, self.factors, k, self.unit[:rows], self.seed,
                      self.num_levels)


def sample(factors: list[FactorRange] | tuple[FactorRange, ...], method: str, n: int,
           seed: int, num_levels: int = 4) -> Design:
    """Draw a design with SALib.

    sobol   Saltelli's scheme on a scrambled Sobol' sequence (``SALib.sample.sobol``), no
            second order: n*(D+2) rows; ``n`` must be a power of two
    morris  ``n`` Morris trajectories on a ``num_levels`` grid (``SALib.sample.morris``):
            n*(D+1) rows

    ``seed`` makes the design reproducible (the Sobol' scrambling, the Morris trajectories).
    """
    factors = tuple(factors)
    if method not in METHODS:
        raise EmaError(f"unknown method '{method}'; expected one of {', '.join(METHODS)}")
    if not factors:
        raise EmaError("a design needs at least one factor")
    if len({f.name for f in factors}) != len(factors):
        raise EmaError("factor names must be unique")
    if isinstance(n, bool) or not isinstance(n, int | np.integer) or n < 1:
        raise EmaError(f"--n must be an integer >= 1, got {n!r}")
    prob = problem(factors)
    if method == "sobol":
        if n & (n - 1):
            raise EmaError(f"--n must be a power of two for Sobol sampling, got {n}")
        from SALib.sample import sobol

        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # SALib/scipy balance warnings: n is checked above
            unit = sobol.sample(prob, int(n), calc_second_order=False, scramble=True,
                                seed=int(seed))
    else:
        if num_levels < 2 or num_levels % 2:
            raise EmaError(f"the Morris grid needs an even number of levels >= 2, got "
                           f"{num_levels}")
        from SALib.sample import morris

        unit = morris.sample(prob, int(n), num_levels=int(num_levels), seed=int(seed))
    return Design(method, factors, int(n), np.ascontiguousarray(unit, dtype=np.float64),
                  int(seed), int(num_levels))
