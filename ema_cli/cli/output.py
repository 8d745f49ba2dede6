"""Console output for a terminal of any width: tables that fall back to key/value blocks.

Every command prints its tables through :func:`print_table`. A table that fits the console
(``COLUMNS``, or 80 columns in a pipe or a CI log) prints as a table with every cell on one line
(no value is folded or cut); one that does not first drops its ``optional`` columns (a caption
says which, and where they are), then, if still too wide, prints one key/value block per row,
its values wrapped at word boundaries, never cut.
"""

from __future__ import annotations

import textwrap
from collections.abc import Sequence
from typing import Any

from rich.markup import escape

from ema_cli.cli.common import console


def width() -> int:
    """The console width [characters]."""
    return console.width


WRAP_WIDTH = 20  # narrowest a word-wrapped column may become [characters]


def _table(title: str | None, columns: Sequence[str], rows: Sequence[Sequence[str]],
           justify: Sequence[str], caption: str | None, styles: Sequence[str | None],
           wrap: Sequence[str] = (), measure: bool = False) -> Any:
    """The rich table; ``wrap`` columns wrap at words (``measure``: capped at WRAP_WIDTH, the
    width the fit is judged with), every other cell stays on one line."""
    from rich.table import Table

    table = Table(title=escape(title) if title else None, header_style="bold",
                  caption=escape(caption) if caption else None, title_justify="left",
                  caption_justify="left")
    for c, j in zip(columns, justify, strict=True):
        if c in wrap:
            table.add_column(escape(c), justify=j, overflow="fold",  # type: ignore[arg-type]
                             max_width=WRAP_WIDTH if measure else None)
        else:
            table.add_column(escape(c), justify=j, no_wrap=True)  # type: ignore[arg-type]
    for r, s in zip(rows, styles, strict=True):
        table.add_row(*(escape(x) for x in r), style=s)
    return table


def _fits(table: Any, limit: int) -> bool:
    from rich.measure import Measurement

    return Measurement.get(console, console.options.update(width=10_000), table).maximum <= limit


def print_table(title: str | None, columns: Sequence[str], rows: Sequence[Sequence[str]], *,
                justify: Sequence[str] | None = None, optional: Sequence[str] = (),
                caption: str | None = None, where: str = "the output files",
                styles: Sequence[str | None] | None = None, wrap: Sequence[str] = ()) -> str:
    """Print a table that stays readable at the console's width -> the layout used
    (``table``, ``narrow`` with optional columns dropped, or ``blocks``).

    ``rows`` are already formatted (units in the cells or the headers); ``optional``: columns
    (by header) that may be dropped, last first, when the table is too wide (the caption says
    they are in ``where``); ``wrap``: columns of prose that may wrap at words (judged at
    WRAP_WIDTH characters)."""
    justify = list(justify or ["left"] + ["right"] * (len(columns) - 1))
    styles = list(styles or [None] * len(rows))
    limit = width()
    cols = list(columns)
    if _fits(_table(title, cols, rows, justify, caption, styles, wrap, True), limit):
        console.print(_table(title, cols, rows, justify, caption, styles, wrap))
        return "table"
    keep = list(range(len(cols)))
    dropped: list[str] = []
    for name in reversed(list(optional)):
        if name not in cols:
            continue
        keep.remove(cols.index(name))
        dropped.insert(0, name)
        note = f"not shown at {limit} columns: {', '.join(dropped)} (in {where})"
        cap = f"{caption}; {note}" if caption else note
        args = (title, [cols[k] for k in keep], [[r[k] for k in keep] for r in rows],
                [justify[k] for k in keep], cap, styles, wrap)
        if _fits(_table(*args, measure=True), limit):
            console.print(_table(*args))
            return "narrow"
    print_blocks(title, cols, rows, caption=caption, styles=styles)
    return "blocks"


def print_blocks(title: str | None, columns: Sequence[str], rows: Sequence[Sequence[str]], *,
                 caption: str | None = None, styles: Sequence[str | None] | None = None) -> None:
    """One block per row: the first cell as a heading, then ``column  value`` lines, values
    wrapped at word boundaries within the console's width (never cut)."""
    limit = max(width(), 40)
    styles = list(styles or [None] * len(rows))
    if title:
        for line in textwrap.wrap(title, limit) or [""]:
            console.print(f"[bold]{escape(line)}[/]", highlight=False)
    key_w = min(max((len(c) for c in columns[1:]), default=0), limit // 2)
    for r, style in zip(rows, styles, strict=True):
        head = f"{columns[0]} {r[0]}" if columns[0] else r[0]
        for line in textwrap.wrap(head, limit) or [""]:
            console.print(f"[{style or 'bold'}]{escape(line)}[/]", highlight=False)
        for c, v in zip(columns[1:], r[1:], strict=True):
            if len(c) > key_w:  # a long key on its own line, the value below
                for line in textwrap.wrap(c, limit - 2):
                    console.print(escape("  " + line), highlight=False)
                pad, first = " " * (key_w + 4), ""
            else:
                pad, first = " " * (key_w + 4), f"  {c:<{key_w}}  "
            lines = textwrap.wrap(v, limit - len(pad), break_on_hyphens=False) or [""]
            console.print(escape((first or pad) + lines[0]), highlight=False, overflow="ignore",
                          crop=False)
            for line in lines[1:]:
                console.print(escape(pad + line), highlight=False, overflow="ignore", crop=False)
    if caption:
        for line in textwrap.wrap(caption, limit):
            console.print(escape(line), highlight=False)
