"""Machine-checkable claims over reproduction results: value, compare, monotonic, scalar.

A claim turns one of the paper's statements into an assertion over our computed results: per
study a metrics table (one row per run, swept values and metrics in edge units), and a flat
dictionary of scalars (identification errors, thresholds). Each evaluates to PASS or FAIL with
the number it measured, so a reader sees what was computed, not only the verdict.
"""

from __future__ import annotations

import math
import operator
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
import pandas as pd

from ema_cli.config.claims import Claim, CompareCheck, MonotonicCheck, ScalarCheck, ValueCheck
from ema_cli.units import fmt_num

OPS = {"<": operator.lt, "<=": operator.le, ">": operator.gt, ">=": operator.ge}


@dataclass(frozen=True)
class Verdict:
    """The outcome of one claim."""

    claim: Claim
    passed: bool
    measured: str
    error: str | None = None


class ClaimError(Exception):
    """A claim that cannot be evaluated (missing study, row or column)."""


def _select(df: pd.DataFrame, where: Mapping[str, Any], study: str) -> pd.Series:
    mask = np.ones(len(df), dtype=bool)
    for col, want in where.items():
        if col not in df.columns:
            raise ClaimError(f"study '{study}' has no column '{col}' "
                             f"(columns: {', '.join(map(str, df.columns))})")
        col_values = df[col]
        if isinstance(want, str):
            mask &= col_values.astype(str).to_numpy() == want
        else:
            num = pd.to_numeric(col_values, errors="coerce").to_numpy(dtype=float)
            mask &= np.isclose(num, want, rtol=1e-9, atol=0)
    rows = df[mask]
    if len(rows) != 1:
        raise ClaimError(f"study '{study}': {dict(where)} selects {len(rows)} rows, expected 1")
    return rows.iloc[0]


def _metric(row: pd.Series, metric: str, study: str) -> float:
    if metric not in row.index:
        raise ClaimError(f"study '{study}' has no metric '{metric}'")
    return float(row[metric])


def evaluate_claim(claim: Claim, studies: Mapping[str, pd.DataFrame],
                   scalars: Mapping[str, float]) -> Verdict:
    """Evaluate one claim; a claim that cannot be evaluated FAILS with the reason."""
    c = claim.check
    try:
        if isinstance(c, ScalarCheck):
            if c.name not in scalars:
                raise ClaimError(f"no result named '{c.name}'")
            x = float(scalars[c.name])
            ok = math.isfinite(x) and OPS[c.op](x, c.value)
            return Verdict(claim, ok, f"{c.name} = {fmt_num(x)} ({c.op} {c.value:g} required)")
        if c.study not in studies:
            raise ClaimError(f"no study '{c.study}' in the results")
        df = studies[c.study]
        if isinstance(c, ValueCheck):
            x = _metric(_select(df, c.where, c.study), c.metric, c.study)
            ok = math.isfinite(x) and OPS[c.op](x, c.value)
            return Verdict(claim, ok, f"{c.metric} = {fmt_num(x)} ({c.op} {c.value:g} required)")
        if isinstance(c, CompareCheck):
            xa = _metric(_select(df, c.a, c.study), c.metric, c.study)
            xb = _metric(_select(df, c.b, c.study), c.metric, c.study)
            ok = math.isfinite(xa) and math.isfinite(xb) and OPS[c.op](xa, c.factor * xb)
            fac = "" if c.factor == 1 else f"{c.factor:g} x "
            return Verdict(claim, ok, f"{c.metric}: {fmt_num(xa)} {c.op} {fac}{fmt_num(xb)}")
        if isinstance(c, MonotonicCheck):
            if c.axis not in df.columns or c.metric not in df.columns:
                raise ClaimError(f"study '{c.study}' lacks column '{c.axis}' or '{c.metric}'")
            axis = pd.to_numeric(df[c.axis], errors="coerce")
            sub = df.assign(_x=axis).dropna(subset=["_x"]).sort_values("_x")
            y = sub[c.metric].to_numpy(dtype=float)
            if len(y) < 2:
                raise ClaimError(f"study '{c.study}': fewer than 2 numeric values of '{c.axis}'")
            d = np.diff(y)
            if c.direction == "increasing":
                ok = bool(np.all(d > 0) if c.strict else np.all(d >= 0))
            else:
                ok = bool(np.all(d < 0) if c.strict else np.all(d <= 0))
            ok = ok and bool(np.all(np.isfinite(y)))
            pairs = ", ".join(f"{fmt_num(a)}: {fmt_num(b)}"
                              for a, b in zip(sub["_x"], y, strict=True))
            return Verdict(claim, ok, f"{c.metric} along {c.axis} = {pairs}")
    except ClaimError as exc:
        return Verdict(claim, False, "not evaluable", str(exc))
    raise AssertionError(f"unhandled check kind {type(c).__name__}")


def evaluate_claims(claims: list[Claim], studies: Mapping[str, pd.DataFrame],
                    scalars: Mapping[str, float]) -> list[Verdict]:
    """Evaluate every claim (in order)."""
    return [evaluate_claim(c, studies, scalars) for c in claims]


def verdicts_frame(verdicts: list[Verdict]) -> pd.DataFrame:
    """claims.csv: one row per claim."""
    return pd.DataFrame([{
        "id": v.claim.id, "figure": v.claim.figure, "result": "PASS" if v.passed else "FAIL",
        "measured": v.measured, "statement": v.claim.statement, "paper": v.claim.paper,
        "error": v.error or "",
    } for v in verdicts])
