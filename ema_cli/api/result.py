"""The contract every API result honours (``typing.Protocol``): ``.metrics``, ``.to_pandas()``,
``.plot()``, ``.save()``.

    metrics          a DataFrame: the result's key numbers, units in the column names (or a
                     ``unit`` column)
    to_pandas(form)  a DataFrame of the result's data: ``form`` "wide" or "long" (one value a
                     row); another form is an EmaError naming ``form``
    plot(...)        a matplotlib Figure, or a list of them (every argument has a default)
    save(folder)     the command's output folder written -> its path (None: a new folder
                     under results/; a given folder must be new or empty)

``tests/unit/test_result_contract.py`` checks every result class of ``api.__all__`` and the
return type of every API function against it.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol, runtime_checkable

if TYPE_CHECKING:
    import pandas as pd
    from matplotlib.figure import Figure

FORMS = ("wide", "long")
"""The forms every ``to_pandas`` takes."""


@runtime_checkable
class Result(Protocol):
    """What every API function returns (see the module docstring)."""

    @property
    def metrics(self) -> pd.DataFrame: ...

    def to_pandas(self, form: str = ...) -> pd.DataFrame: ...

    def plot(self, *args: Any, **kwargs: Any) -> Figure | list[Figure]: ...

    def save(self, folder: str | Path | None = None) -> Path: ...


def long_form(wide: pd.DataFrame, form: str, id_vars: list[str], var_name: str = "column"
              ) -> pd.DataFrame:
    """``wide`` as it is (``form`` "wide") or melted on ``id_vars`` (``form`` "long": one value
    a row, the column name in ``var_name``); another form is an EmaError naming ``form``."""
    from ema_cli.errors import EmaError

    if form == "wide":
        return wide
    if form != "long":
        raise EmaError(f"form must be 'wide' or 'long', got {form!r}")
    return wide.melt(id_vars=id_vars, var_name=var_name, value_name="value")
