"""Markdown for every report: one cell formatter and one table helper (NaN reads ``n/a``)."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from ema_cli.units import fmt_num

DIGITS = 4  # significant digits of a number in a markdown table [-]


def md_cell(value: Any, digits: int = DIGITS) -> str:
    """One table cell: floats with ``digits`` significant digits (``units.fmt_num``: NaN and
    None read ``n/a``), booleans, integers and text as they are (``|`` escaped), a list as
    its cells joined by commas (``none`` if empty)."""
    if isinstance(value, bool | np.bool_):
        return str(bool(value))
    if isinstance(value, list | tuple):
        return ", ".join(md_cell(v, digits) for v in value) or "none"
    if isinstance(value, int | np.integer):
        return str(int(value))
    if value is None or isinstance(value, float | np.floating):
        return fmt_num(None if value is None else float(value), digits=digits)
    return str(value).replace("|", "\\|")


def md_table(rows: Any, columns: Sequence[str] | None = None,
             headers: Sequence[str] | None = None, digits: int = DIGITS) -> str:
    """A markdown table of ``rows``: a DataFrame (``columns`` default: all of them) or a
    sequence of row sequences (then ``columns`` names them). ``headers``: the header line
    (default: the column names)."""
    if hasattr(rows, "iterrows"):
        cols = list(rows.columns if columns is None else columns)
        body = [[r[c] for c in cols] for _, r in rows.iterrows()]
    else:
        if columns is None:
            raise ValueError("md_table: columns are required for rows that are not a DataFrame")
        cols, body = list(columns), [list(r) for r in rows]
    head = [str(h).replace("|", "\\|") for h in (cols if headers is None else headers)]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    lines += ["| " + " | ".join(md_cell(v, digits) for v in r) + " |" for r in body]
    return "\n".join(lines)
