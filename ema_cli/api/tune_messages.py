"""The one-line refusal of a tuning whose candidates all violate a constraint, and the violation
    measure it ranks them by (``api.tune`` raises it)."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    import pandas as pd


def infeasible_message(res: Any) -> str:
    """One line (``res`` an ``api.tune.TuneResult``): no candidate met every constraint, and
    which the best one violates most (the
    largest violation relative to its limit, as the tuning scores it; NaN counts as the
    largest)."""
    ev = res.outcome.after
    worst = ""
    df = res.constraints_frame()
    bad = df[~df["met"]]
    if len(bad):
        r = bad.loc[relative_violation(bad).idxmax()]
        bound = f"<= {r['max']:g}" if r["max"] is not None and not math.isnan(
            r["max"]) else f">= {r['min']:g}"
        worst = (f"; the best violates scenarios.{r['scenario']} {r['constraint']} "
                 f"{r['after']:.4g} {r['unit']} (limit {bound} {r['unit']})")
    elif ev.diverged.any():
        worst = "; the best diverges"
    return (f"no candidate met every constraint in {int(res.outcome.timings['evaluations'])} "
            f"evaluations{worst}: relax the constraints, widen the bounds or raise budget "
            "(infeasible constraints)")


def relative_violation(df: pd.DataFrame) -> pd.Series:
    """Per row of :meth:`TuneResult.constraints_frame`: how far the tuned value lies outside
    its limit, relative to the limit (``(v - max)/|max|``, ``(min - v)/|min|``; inf for NaN)."""
    import numpy as np

    def one(r: Any) -> float:
        v = r["after"]
        if v != v:  # NaN: not measured, the worst
            return math.inf
        out = 0.0
        for bound, sign in ((r["max"], 1.0), (r["min"], -1.0)):
            if bound is not None and bound == bound:
                out += max(sign * (v - bound), 0.0) / (abs(bound) or 1.0)
        return out

    return df.apply(one, axis=1).astype(np.float64)
