"""Log files as tables of named columns: CSV, Parquet and MATLAB .mat (v4/v5 via scipy, v7.3
via h5py), chosen by the file's extension, with a column map and units at the edge.

A log names its columns after ema's channels (:data:`LOG_CHANNELS`: ``t_s, theta_ref_deg,
theta_load_deg, omega_motor_rpm, current_a, voltage_cmd_v``), or a column map says where each
channel is and in which unit: ``{"theta_load_deg": "pos:rad", "t_s": "time:ms"}``
(``ema identify --columns CHANNEL=COLUMN[:UNIT]``). The units of each kind and their SI
factors are one table, :data:`ema_cli.units.LOG_UNITS`.

MATLAB files: the columns are the top-level variables that are numeric vectors (N, Nx1 or
1xN), or the fields of the file's one struct. In a v7.3 file (HDF5) they are the datasets at
the root, or in the root's one group (a struct); MATLAB writes column-major, so an Nx1 vector
is an HDF5 dataset of shape (1, N): both orientations are vectors.

Every problem is one :class:`EmaError` line naming the file, the column or variable and the
place: the CSV line (1 = the header), the Parquet data row or the MATLAB index (1-based).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ema_cli.errors import EmaError
from ema_cli.logs import (  # noqa: F401 (the readers live below every layer)
    FORMATS,
    MAX_LISTED,
    LogTable,
    read_log_table,
)
from ema_cli.units import LOG_UNITS, log_to_si

LOG_CHANNELS: dict[str, tuple[str, str]] = {
    "t_s": ("time", "s"),
    "theta_ref_deg": ("angle", "deg"),
    "theta_load_deg": ("angle", "deg"),
    "omega_motor_rpm": ("speed", "rpm"),
    "current_a": ("current", "A"),
    "voltage_cmd_v": ("voltage", "V"),
}
"""ema's log channels -> (kind of unit, the channel's own unit): the keys of a column map."""
COLUMNS_OPTION = "--columns"  # the CLI option of the column map (settings key: columns)


def parse_column_spec(channel: str, spec: str) -> tuple[str, str]:
    """``COLUMN[:UNIT]`` of ``channel`` -> (column, unit); the unit defaults to the channel's
    own. The last ``:`` separates the unit (a column named ``a:b`` is written ``a:b:UNIT``).
    Errors name the channel and what is allowed."""
    if channel not in LOG_CHANNELS:
        raise EmaError(f"unknown channel '{channel}'; expected one of {', '.join(LOG_CHANNELS)}")
    kind, own = LOG_CHANNELS[channel]
    column, sep, unit = str(spec).rpartition(":")
    if not sep:
        column, unit = str(spec), own
    column, unit = column.strip(), unit.strip()
    allowed = ", ".join(LOG_UNITS[kind])
    if not column:
        raise EmaError(f"expected COLUMN[:UNIT], got {spec!r}")
    if unit not in LOG_UNITS[kind]:
        other = next((k for k, units in LOG_UNITS.items() if unit in units), None)
        why = f"'{unit}' is a unit of {other}" if other else f"unknown unit '{unit}'"
        raise EmaError(f"{why}; {channel} takes {kind} units: {allowed}")
    return column, unit


@dataclass(frozen=True)
class LogColumns:
    """The channels of a log read through a column map, in SI: ``values[channel]`` [s, rad,
    rad/s, A, V], ``names[channel]`` the file's column or variable, ``present`` the optional
    channels found, ``table`` the file (for :meth:`label` and ``table.where``)."""

    values: dict[str, np.ndarray]
    names: dict[str, str]
    units: dict[str, str]
    present: list[str]
    table: LogTable

    def label(self, channel: str) -> str:
        """How an error names a channel: ``column 't_s'`` or ``variable 'time' (t_s)``."""
        name = self.names[channel]
        return (f"{self.table.noun} '{name}'" + (f" ({channel})" if name != channel else ""))


def read_log(path: str | Path, required: Sequence[str], optional: Sequence[str] = (),
             columns: Mapping[str, str] | None = None) -> LogColumns:
    """Read the ``required`` and ``optional`` channels of a log file through the column map
    ``columns`` (channel -> ``COLUMN[:UNIT]``), checked and converted to SI. Errors name the
    file, the column (and the ``--columns`` entry that chose it) and the place."""
    spec = {ch: parse_column_spec_option(ch, s, path) for ch, s in (columns or {}).items()}
    table = read_log_table(path)
    p = table.path
    names, units = {}, {}
    for ch in (*required, *optional):
        col, unit = spec.get(ch, (ch, LOG_CHANNELS[ch][1]))
        if ch in spec and col not in table.raw:
            raise EmaError(f"{COLUMNS_OPTION} {ch}={columns[ch]}: data file '{p}' has no "
                           f"{table.noun} '{col}'; it has {table.listing()}")
        names[ch], units[ch] = col, unit
    missing = [ch for ch in required if names[ch] not in table.raw]
    if missing:
        opt = f" (optional: {', '.join(optional)})" if optional else ""
        raise EmaError(f"data file '{p}' lacks {table.noun}(s) {', '.join(missing)}; expected "
                       f"{', '.join(required)}{opt}; map other names with {COLUMNS_OPTION} "
                       f"CHANNEL=COLUMN[:UNIT]; found {table.listing()}")
    present = [ch for ch in optional if names[ch] in table.raw]
    used = [*required, *present]
    values = {}
    for ch in used:
        try:
            raw = table.column(names[ch])
        except EmaError as exc:
            if names[ch] == ch:
                raise
            raise EmaError(f"{exc.message} ({COLUMNS_OPTION} {ch}={columns[ch]})") from None
        values[ch] = log_to_si(raw, units[ch], LOG_CHANNELS[ch][0])
    lengths = {ch: v.shape[0] for ch, v in values.items()}
    first = used[0]
    for ch in used[1:]:
        if lengths[ch] != lengths[first]:
            raise EmaError(f"data file '{p}': {table.noun} '{names[ch]}' has {lengths[ch]} "
                           f"values but '{names[first]}' has {lengths[first]}; the log's "
                           f"{table.noun}s must have one length")
    return LogColumns(values, {ch: names[ch] for ch in used}, {ch: units[ch] for ch in used},
                      present, table)


def parse_column_spec_option(channel: str, spec: str, path: str | Path) -> tuple[str, str]:
    """:func:`parse_column_spec` with the option and the file named in the error."""
    try:
        return parse_column_spec(channel, spec)
    except EmaError as exc:
        raise EmaError(f"{COLUMNS_OPTION} {channel}={spec} (data file '{path}'): "
                       f"{exc.message}") from None
