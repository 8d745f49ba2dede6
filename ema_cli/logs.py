"""Log files as tables of named columns: CSV, Parquet and MATLAB .mat (v4/v5 via scipy, v7.3
via h5py), chosen by the file's extension (below every layer: the run configs read input signals
from logs, the identification its measured channels).

MATLAB files: the columns are the top-level variables that are numeric vectors (N, Nx1 or
1xN), or the fields of the file's one struct. In a v7.3 file (HDF5) they are the datasets at
the root, or in the root's one group (a struct); MATLAB writes column-major, so an Nx1 vector
is an HDF5 dataset of shape (1, N): both orientations are vectors.

A MATLAB column may also be a selector (:func:`parse_selector`): ``VAR.FIELD...`` walks into
structs (nested ones too), and an index picks one channel of a matrix: ``[k]`` (0-based) the
k-th channel along the matrix's shorter axis (a 3xN or Nx3 matrix holds 3 channels), ``[:, k]`` /
``[k, :]`` column / row k (0-based), or MATLAB's own ``(:, k)`` / ``(k)`` 1-based. E.g.
``rec.pos_link[0]``, ``rec.data[:, 2]``, ``data(:, 3)``. The single struct of a file whose
fields became the columns may be named or not: ``rec.t`` and ``t`` are the same column.

Every problem is one :class:`EmaError` line naming the file, the column or variable and the
place: the CSV line (1 = the header), the Parquet data row or the MATLAB index (1-based).
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ema_cli.errors import EmaError

FORMATS: dict[str, str] = {".csv": "CSV", ".txt": "CSV", ".parquet": "Parquet",
                           ".pq": "Parquet", ".mat": "MATLAB"}
"""File extension (lower case) -> format."""
MAX_LISTED = 12  # names listed in an error about what a file holds [names]
MAT_SKIP_PREFIX = "#"  # HDF5 members MATLAB keeps for itself (#refs#, #subsystem#)
_SELECTOR = re.compile(r"^\s*([A-Za-z_]\w*(?:\s*\.\s*[A-Za-z_]\w*)*)\s*"
                       r"(?:\[([^\]]*)\]|\(([^)]*)\))?\s*$")


@dataclass(frozen=True)
class Selector:
    """A parsed MATLAB column selector: ``path`` (variable, fields...), ``index`` per axis
    (None: ``:``; at most 2 entries, 0-based) or None for no index, and its text."""

    path: tuple[str, ...]
    index: tuple[int | None, ...] | None
    text: str


def parse_selector(text: str) -> Selector | None:
    """``VAR(.FIELD)*`` with an optional ``[i]``, ``[i, j]`` (0-based) or ``(i)``, ``(i, j)``
    (1-based, MATLAB) index, one of ``i, j`` may be ``:`` -> a :class:`Selector`, or None
    when ``text`` is not of that form (a plain column name with other characters)."""
    m = _SELECTOR.match(str(text))
    if m is None:
        return None
    path = tuple(p.strip() for p in m.group(1).split("."))
    raw, base = (m.group(2), 0) if m.group(2) is not None else (m.group(3), 1)
    if raw is None:
        return Selector(path, None, text)
    parts = [p.strip() for p in raw.split(",")]
    if not 1 <= len(parts) <= 2 or (len(parts) == 2 and parts.count(":") != 1):
        raise EmaError(f"column selector '{text}': expected one index [k] or a row/column "
                       "[k, :] / [:, k] (0-based; MATLAB's (k) / (:, k) are 1-based)")
    index: list[int | None] = []
    for p in parts:
        if p == ":":
            index.append(None)
            continue
        try:
            k = int(p)
        except ValueError:
            raise EmaError(f"column selector '{text}': index '{p}' is not a whole number or "
                           "':'") from None
        if k < base:
            raise EmaError(f"column selector '{text}': index {k} is below {base} "
                           f"({'0' if base == 0 else '1'}-based {'[ ]' if base == 0 else '( )'})")
        index.append(k - base)
    if index == [None]:
        raise EmaError(f"column selector '{text}': ':' alone selects nothing; give [k]")
    return Selector(path, tuple(index), text)


@dataclass(frozen=True)
class LogTable:
    """The columns of one log file as read, unchecked: ``raw[name]`` is a pandas Series (CSV,
    Parquet) or an array of any shape (MATLAB); :meth:`column` checks one and returns floats."""

    path: Path
    fmt: str  # CSV, Parquet, MATLAB v5, MATLAB v7.3
    raw: dict[str, Any]
    struct: str | None = None  # the file's one struct whose fields are ``raw`` (MATLAB)

    @property
    def noun(self) -> str:
        """What the format calls a column: ``variable`` (MATLAB) or ``column``."""
        return "variable" if self.fmt.startswith("MATLAB") else "column"

    def where(self, i: int) -> str:
        """The place of sample ``i`` (0-based) as the user finds it in the file: the CSV line
        (the header is line 1), the Parquet data row or the MATLAB index (1-based)."""
        if self.fmt == "CSV":
            return f"line {i + 2}"
        if self.fmt == "Parquet":
            return f"row {i + 1}"
        return f"index {i + 1}"

    def listing(self) -> str:
        """The names the file holds (vectors with their length), at most MAX_LISTED."""
        items = []
        for name, value in self.raw.items():
            if self.fmt.startswith("MATLAB"):
                vec = _mat_vector(value)
                items.append(f"{name} [{vec.size}]" if isinstance(vec, np.ndarray)
                             else f"{name} ({vec})")
            else:
                items.append(str(name))
        more = len(items) - MAX_LISTED
        return (", ".join(items[:MAX_LISTED]) + (f" and {more} more" if more > 0 else "")
                or "none")

    def has(self, name: str) -> bool:
        """Whether ``name`` is a column, or (MATLAB) a selector whose variable exists."""
        if name in self.raw:
            return True
        if not self.fmt.startswith("MATLAB"):
            return False
        try:
            sel = parse_selector(name)
        except EmaError:
            return True  # a malformed selector: column() says what is wrong
        return sel is not None and (sel.path[0] in self.raw or sel.path[0] == self.struct)

    def _select(self, sel: Selector) -> Any:
        """The value a selector points at (its index applied) or an EmaError naming the file,
        the selector, the variable or field and what exists."""
        p = self.path
        head, *fields = sel.path
        if head in self.raw:
            value: Any = self.raw[head]
            where = head
        elif head == self.struct:
            value, where = dict(self.raw), head
        else:
            raise EmaError(f"data file '{p}': column selector '{sel.text}': no variable "
                           f"'{head}'; it has {self.listing()}")
        for f in fields:
            names = _struct_fields(value)
            if names is None:
                raise EmaError(f"data file '{p}': column selector '{sel.text}': '{where}' is "
                               f"{_describe(value)}, not a struct; it has no field '{f}'")
            if f not in names:
                raise EmaError(f"data file '{p}': column selector '{sel.text}': struct "
                               f"'{where}' has no field '{f}'; its fields: "
                               f"{', '.join(names[:MAX_LISTED]) or 'none'}")
            value = _struct_field(value, f)
            where = f"{where}.{f}"
        if sel.index is None:
            return value
        a = value if isinstance(value, np.ndarray) else None
        if a is None or a.dtype.names is not None or a.dtype.kind not in "biuf" or a.ndim > 2:
            raise EmaError(f"data file '{p}': column selector '{sel.text}': '{where}' is "
                           f"{_describe(value)}; an index needs a numeric matrix")
        a = a.reshape(a.shape[0], -1) if a.ndim == 2 else a.reshape(1, -1)
        rows, cols = a.shape
        if len(sel.index) == 1:
            if min(rows, cols) == 1:
                raise EmaError(f"data file '{p}': column selector '{sel.text}': '{where}' is "
                               f"a vector of {a.size} values; use it without an index")
            axis = 1 if rows >= cols else 0  # the channels run along the shorter axis
            k = sel.index[0]
        else:
            axis = 1 if sel.index[0] is None else 0
            k = sel.index[1] if axis == 1 else sel.index[0]
        n_ch = a.shape[axis]
        assert k is not None
        if k >= n_ch:
            noun = "column" if axis == 1 else "row"
            raise EmaError(f"data file '{p}': column selector '{sel.text}': '{where}' is a "
                           f"{rows}x{cols} matrix; {noun} {k} (0-based) does not exist "
                           f"(0 .. {n_ch - 1})")
        return a[:, k] if axis == 1 else a[k, :]

    def column(self, name: str) -> np.ndarray:
        """The column or variable ``name`` as a 1-D float64 array, every value finite; else
        an EmaError naming the file, the name and the first bad place. A MATLAB name that is
        not a variable is read as a selector (module docstring)."""
        p = self.path
        if name not in self.raw and self.fmt.startswith("MATLAB"):
            try:
                sel = parse_selector(name)
            except EmaError as exc:
                raise EmaError(f"data file '{p}': {exc.message}") from None
            if sel is None:
                raise EmaError(f"data file '{p}': no variable '{name}'; it has "
                               f"{self.listing()}")
            value = self._select(sel)
        else:
            value = self.raw[name]
        if self.fmt.startswith("MATLAB"):
            vec = _mat_vector(value)
            if not isinstance(vec, np.ndarray):
                raise EmaError(f"data file '{p}': variable '{name}' is {vec}; expected a "
                               "numeric vector (N, Nx1 or 1xN)")
            what = "NaN or inf"
        else:
            import pandas as pd

            try:
                vec = pd.to_numeric(value, errors="coerce").to_numpy(np.float64)
            except (TypeError, ValueError):
                raise EmaError(f"data file '{p}': column '{name}' is not numeric (dtype "
                               f"{value.dtype}); expected numbers") from None
            what = "empty, non-numeric, NaN or inf"
        bad = ~np.isfinite(vec)
        if bad.any():
            raise EmaError(f"data file '{p}': {self.noun} '{name}' has {int(bad.sum())} {what} "
                           f"value(s) (first at {self.where(int(np.flatnonzero(bad)[0]))})")
        return vec


def _struct_fields(value: Any) -> list[str] | None:
    """The field names of a struct value (a dict from v7.3, a 1x1 record array from v5)."""
    if isinstance(value, dict):
        return list(value)
    if isinstance(value, np.ndarray) and value.dtype.names is not None and value.size == 1:
        return list(value.dtype.names)
    return None


def _struct_field(value: Any, name: str) -> Any:
    if isinstance(value, dict):
        return value[name]
    return value.reshape(-1)[0][name]


def _describe(value: Any) -> str:
    """A few words on a MATLAB value (for errors)."""
    if isinstance(value, dict):
        return "a struct"
    if isinstance(value, np.ndarray) and value.dtype.kind in "biuf" and value.ndim == 2 \
            and min(value.shape) > 1:
        return f"a {value.shape[0]}x{value.shape[1]} matrix"
    vec = _mat_vector(value)
    return f"a vector of {vec.size} values" if isinstance(vec, np.ndarray) else vec


def _mat_vector(value: Any) -> np.ndarray | str:
    """A MATLAB value as a float64 vector, or a few words on what it is instead."""
    if isinstance(value, dict):
        return "a struct"
    if isinstance(value, str):
        return value  # a description made by the reader (h5py groups, references)
    a = np.asarray(value)
    if a.dtype.names is not None:
        return "a struct"
    kind = a.dtype.kind
    if kind == "O":
        return "a cell array"
    if kind in "US":
        return "text"
    if kind == "c":
        return "complex"
    if kind not in "biuf":
        return f"not numeric (dtype {a.dtype})"
    if a.size == 0:
        return "empty"
    if sum(d > 1 for d in a.shape) > 1:
        return f"a {'x'.join(map(str, a.shape))} matrix, not a vector"
    return a.reshape(-1).astype(np.float64)


def _first_line(exc: BaseException) -> str:
    text = str(exc).strip().splitlines()
    return text[0] if text else type(exc).__name__


def read_log_table(path: str | Path) -> LogTable:
    """Read the columns of a log file, the format chosen by its extension (:data:`FORMATS`);
    a missing, empty, unreadable or corrupt file is an EmaError naming it."""
    p = Path(path)
    if not p.exists():
        raise EmaError(f"data file '{p}' does not exist")
    if not p.is_file():
        raise EmaError(f"data file '{p}' is not a file")
    fmt = FORMATS.get(p.suffix.lower())
    if fmt is None:
        raise EmaError(f"data file '{p}': unknown format '{p.suffix}'; expected .csv or .txt "
                       "(CSV), .parquet or .pq (Parquet), .mat (MATLAB v5 or v7.3)")
    if p.stat().st_size == 0:
        raise EmaError(f"data file '{p}' is empty")
    if fmt == "CSV":
        return _read_csv(p)
    if fmt == "Parquet":
        return _read_parquet(p)
    return _read_mat(p)


def _read_csv(p: Path) -> LogTable:
    import pandas as pd

    try:
        df = pd.read_csv(p)
    except Exception as exc:  # pandas raises many types for malformed files
        raise EmaError(f"data file '{p}' is not a readable CSV: {_first_line(exc)}") from None
    return LogTable(p, "CSV", {str(c): df[c] for c in df.columns})


def _read_parquet(p: Path) -> LogTable:
    import pandas as pd

    try:
        df = pd.read_parquet(p, engine="pyarrow")
    except Exception as exc:  # pyarrow: ArrowInvalid, OSError, ... for a corrupt file
        raise EmaError(f"data file '{p}' is not a readable Parquet file: "
                       f"{_first_line(exc)}") from None
    return LogTable(p, "Parquet", {str(c): df[c] for c in df.columns})


def _read_mat(p: Path) -> LogTable:
    import h5py
    from scipy.io import loadmat
    from scipy.io.matlab import matfile_version

    try:
        major = matfile_version(str(p))[0]
    except Exception:  # text or garbage: scipy raises ValueError, IndexError, MatReadError
        major = -1
    if major == 2 or (major == -1 and h5py.is_hdf5(str(p))):
        return _read_mat73(p)
    if major == -1:
        raise EmaError(f"data file '{p}' is not a readable MATLAB file (.mat v5 or v7.3): "
                       "no MATLAB header")
    try:
        data = loadmat(str(p), squeeze_me=False, chars_as_strings=True)
    except Exception as exc:  # truncated or corrupt v5 data
        raise EmaError(f"data file '{p}' is not a readable MATLAB file (.mat v5): "
                       f"{_first_line(exc)}") from None
    raw = {k: v for k, v in data.items() if not k.startswith("__")}
    struct = None
    if len(raw) == 1:
        (name, value), = raw.items()
        if isinstance(value, np.ndarray) and value.dtype.names is not None:
            if value.size != 1:
                raise EmaError(f"data file '{p}': struct '{name}' is a "
                               f"{'x'.join(map(str, value.shape))} struct array; expected one "
                               "struct whose fields are vectors")
            rec = value.reshape(-1)[0]
            raw = {f: rec[f] for f in value.dtype.names}
            struct = name
    if not raw:
        raise EmaError(f"data file '{p}' holds no MATLAB variables")
    return LogTable(p, "MATLAB v5", raw, struct)


def _read_mat73(p: Path) -> LogTable:
    import h5py

    try:
        with h5py.File(p, "r") as f:
            members = {k: v for k, v in f.items() if not k.startswith(MAT_SKIP_PREFIX)}
            datasets = {k: v for k, v in members.items() if isinstance(v, h5py.Dataset)}
            groups = {k: v for k, v in members.items() if isinstance(v, h5py.Group)}
            struct = None
            if not datasets and len(groups) == 1:
                struct = next(iter(groups))
                members = dict(groups[struct].items())
            raw = {k: _h5_value(v) for k, v in members.items()}
    except EmaError:
        raise
    except Exception as exc:  # truncated or corrupt HDF5: OSError, KeyError, ...
        raise EmaError(f"data file '{p}' is not a readable MATLAB file (.mat v7.3, HDF5): "
                       f"{_first_line(exc)}") from None
    if not raw:
        raise EmaError(f"data file '{p}' holds no MATLAB variables")
    return LogTable(p, "MATLAB v7.3", raw, struct)


def _h5_value(obj: Any) -> np.ndarray | str | dict[str, Any]:
    """One HDF5 member of a v7.3 file as an array (shape as stored) or what it is instead."""
    import h5py

    if isinstance(obj, h5py.Group):  # a struct: its fields, nested structs too
        return {k: _h5_value(v) for k, v in obj.items() if not k.startswith(MAT_SKIP_PREFIX)}
    cls = obj.attrs.get("MATLAB_class", b"")
    cls = cls.decode() if isinstance(cls, bytes) else str(cls)
    if cls == "char":
        return "text"
    if cls == "cell" or obj.dtype.kind == "O":
        return "a cell array"
    if int(obj.attrs.get("MATLAB_empty", 0)):
        return "empty"
    if obj.dtype.names is not None:
        return "complex" if set(obj.dtype.names) == {"real", "imag"} else "a compound value"
    return np.asarray(obj[()]).T  # column-major on disk: back to MATLAB's N x M
