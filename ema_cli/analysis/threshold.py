"""Threshold finder: the largest (or smallest) magnitude at which tracking metrics stay in limits.

The search is a batched bracketing: evaluate a grid of magnitudes in one kernel call, find the
first grid point that fails (scanning from the benign end), and refine the grid inside that
bracket until its width is below the tolerance. ``direction = "max"`` looks for the largest
passing value with benign values small (a dead band); ``"min"`` the smallest passing value with
benign values large (a stiffness). The answer is the edge of the *first* failure seen from the
benign end, so a metric that fails and later passes again does not move it past the failure.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np
import pandas as pd

from ema_cli.config.criteria import DEFAULT_RTOL, Criterion
from ema_cli.config.loader import resolve_params
from ema_cli.errors import EmaError
from ema_cli.model.params import to_row
from ema_cli.sim.runner import plan_steps, simulate_batch
from ema_cli.sim.signals import InputSignal, sampler

GRID_POINTS = 12  # magnitudes evaluated per refinement round (one kernel batch)
MAX_ROUNDS = 12  # refinement rounds at most


@dataclass
class ThresholdResult:
    """The outcome of a threshold search (magnitudes in the varied quantity's edge unit).

    status: "found" (bracketed), "all-pass" (no failure in range: threshold beyond the range),
    "none-pass" (the benign end already fails).
    threshold: the last passing value of the final bracket (conservative), or NaN.
    bracket: (pass side, fail side) of the final bracket.
    """

    status: str
    threshold: float
    bracket: tuple[float, float]
    rel_width: float
    n_sims: int
    rounds: int
    direction: str
    history: pd.DataFrame = field(repr=False)

    def summary(self) -> dict[str, Any]:
        return {"status": self.status, "threshold": self.threshold,
                "bracket": list(self.bracket), "relative_width": self.rel_width,
                "n_simulations": self.n_sims, "rounds": self.rounds, "direction": self.direction}


def _grid(lo: float, hi: float, n: int, log: bool) -> np.ndarray:
    return np.geomspace(lo, hi, n) if log else np.linspace(lo, hi, n)


def expected_rounds(lo: float, hi: float, log: bool = True, rtol: float = DEFAULT_RTOL,
                    grid_points: int = GRID_POINTS, max_rounds: int = MAX_ROUNDS) -> int:
    """The refinement rounds :func:`find_threshold` runs when the threshold lies inside
    [lo, hi] (one when every magnitude passes or none does): each round narrows the bracket to
    one of its ``grid_points - 1`` intervals until its relative width is at most ``rtol``
    (linear grids: taken relative to the middle of the range)."""
    if log:
        width = math.log(hi / lo)
        needed = -math.log1p(-rtol)  # log-width whose relative width is rtol
    else:
        width = (hi - lo) / max(abs(hi + lo) / 2, 1e-300)
        needed = rtol
    rounds = 1
    while width / (grid_points - 1) ** rounds > needed and rounds < max_rounds:
        rounds += 1
    return rounds


def find_threshold(
    evaluate: Callable[[np.ndarray], pd.DataFrame],
    criteria: Sequence[Criterion],
    lo: float,
    hi: float,
    direction: Literal["max", "min"] = "max",
    log: bool = True,
    rtol: float = DEFAULT_RTOL,
    grid_points: int = GRID_POINTS,
    max_rounds: int = MAX_ROUNDS,
) -> ThresholdResult:
    """Bracket and refine the threshold of ``criteria`` over magnitudes in [lo, hi].

    ``evaluate(values)`` returns one metrics row per value (edge-unit columns). With
    ``direction = "max"`` small values are benign; with ``"min"`` large values are.
    """
    if not criteria:
        raise EmaError("a threshold search needs at least one requirement (--metric/--limit)")
    if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi):
        raise EmaError(f"--range must be two finite numbers LO < HI, got {lo}, {hi}")
    if log and lo <= 0:
        raise EmaError(f"a logarithmic search needs LO > 0, got {lo}")
    if direction not in ("max", "min"):
        raise EmaError(f"--direction must be max or min, got {direction!r}")
    frames = []
    a, b = lo, hi
    n_sims = 0
    status = "found"
    rounds = 0
    last_pass, first_fail = math.nan, math.nan
    from ema_cli.progress import report

    for rounds in range(1, max_rounds + 1):  # noqa: B007 - rounds is reported
        report(f"bracketing round {rounds}", n_sims)
        grid = _grid(a, b, grid_points, log)
        if direction == "min":
            grid = grid[::-1]  # scan from the benign (large) end
        df = evaluate(grid).reset_index(drop=True)
        n_sims += len(grid)
        ok = np.ones(len(grid), dtype=bool)
        for c in criteria:
            ok &= c.passes(df[c.metric].to_numpy())
        frames.append(df.assign(value=grid, passes=ok, round=rounds))
        fails = np.flatnonzero(~ok)
        if rounds == 1 and len(fails) == 0:
            status, last_pass = "all-pass", grid[-1]
            break
        if rounds == 1 and fails[0] == 0:
            status, first_fail = "none-pass", grid[0]
            break
        k = fails[0] if len(fails) else len(grid)
        if k == len(grid):  # everything in the refined bracket passed: the fail edge holds
            last_pass = grid[-1]
            break
        last_pass, first_fail = grid[k - 1], grid[k]
        a, b = sorted((last_pass, first_fail))
        if (b - a) / abs(b) <= rtol:
            break
    width = abs(first_fail - last_pass) / abs(first_fail) if status == "found" else math.nan
    history = pd.concat(frames, ignore_index=True)
    return ThresholdResult(status, float(last_pass), (float(last_pass), float(first_fail)),
                           width, n_sims, rounds, direction, history)


def simulation_evaluator(
    vary: str,
    plant: Mapping[str, Any],
    nonlinearities: Mapping[str, Any],
    signal: InputSignal,
    duration: float,
    dt: float,
    friction_reading: str = "sigma2",
    parallel: bool = True,
) -> Callable[[np.ndarray], pd.DataFrame]:
    """An ``evaluate(values)`` that simulates one run per magnitude of nonlinearity ``vary``
    (edge units), all in one kernel batch, and returns their metrics in edge units."""
    n_steps, _ = plan_steps(duration, dt, None)
    ref = sampler(signal, dt, n_steps)  # sampled per time chunk by every evaluation

    def evaluate(values: np.ndarray) -> pd.DataFrame:
        rows = [to_row(resolve_params(plant, {**nonlinearities, vary: float(v)},
                                      friction_reading)) for v in values]
        res = simulate_batch(np.array(rows), [ref], None, dt, n_steps, 0, parallel=parallel)
        return res.metrics_frame()

    return evaluate
