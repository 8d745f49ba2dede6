"""The run's time-varying inputs from its config: the position reference (a shape, or a profile
from a CSV or any log), the load-torque profile and the input signal (a logged disturbance or
the actuation), in SI of the actuator's axis."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from ema_cli.errors import EmaError
from ema_cli.sim.signals import InputSignal, load_profile
from ema_cli.units import DEG


def _local(path: str, base_dir: Path | None) -> Path:
    """A path from a config: relative paths are relative to the config's folder (``base_dir``),
    else to the working folder (a config given as a dict, or a file found only there)."""
    p = Path(path)
    if p.is_absolute() or base_dir is None:
        return p
    beside = base_dir / p
    if beside.exists() or not p.exists():
        return beside
    return p


def input_signal(cfg_input: Any, base_dir: Path | None = None,
                 cfg_load: Any = None, axis: str = "rotary") -> InputSignal:
    """InputConfig [+ LoadConfig] -> InputSignal (SI, the ``axis``'s units: rad or m); profiles
    (the reference's, the load torque's, the input signal) are read and validated here."""
    from ema_cli.units import parse_quantity

    table = None
    path = cfg_input.path
    if cfg_input.kind == "csv":
        p = _local(path, base_dir)
        if cfg_input.column is not None:
            t, th = log_channel(p, cfg_input.column, cfg_input.unit, "position", axis,
                                cfg_input.time_column, "input")
        else:
            t, th = load_profile(p)
        table = (tuple(t), tuple(th))
        path = str(p)
    load_table = load_path = None
    if cfg_load is not None and cfg_load.profile:
        p = _local(cfg_load.profile, base_dir)
        t, tq = load_profile(p, value="torque_nm", scale=1.0)
        load_table = (tuple(t), tuple(tq))
        load_path = str(p)
    ext_table = ext_name = None
    ext_hold = True
    sig_cfg = getattr(cfg_input, "signal", None)
    if sig_cfg is not None:
        p = _local(sig_cfg.path, base_dir)
        t, v = log_channel(p, sig_cfg.column, sig_cfg.unit, "command", None,
                           sig_cfg.time_column, "input.signal")
        ext_table = (tuple(t), tuple(v * sig_cfg.scale))
        ext_hold = sig_cfg.hold
        ext_name = f"{p.name}:{sig_cfg.column}"

    def q(value: Any, deg: float, kind: str) -> float:
        return parse_quantity(value, kind, axis) if value is not None else deg * DEG
    return InputSignal(
        kind=cfg_input.kind,
        amplitude=(q(cfg_input.amplitude, cfg_input.amplitude_deg, "position")
                   if cfg_input.amplitude is not None or axis == "rotary"
                   else TRANSLATIONAL_STEP_M),
        start=cfg_input.start_s,
        rate=q(cfg_input.rate, cfg_input.rate_deg_s, "velocity"),
        freq=cfg_input.freq_hz,
        freq_end=cfg_input.freq_end_hz,
        sweep_time=cfg_input.sweep_time_s,
        offset=q(cfg_input.offset, cfg_input.offset_deg, "position"),
        path=path,
        table=table,
        load_table=load_table,
        load_path=load_path,
        ext_table=ext_table,
        ext_hold=ext_hold,
        ext_name=ext_name,
    )


TRANSLATIONAL_STEP_M = 0.01  # a translational axis's default reference amplitude [m]
COMMAND_UNITS = {"V": 1.0, "mV": 1e-3, "A": 1.0, "mA": 1e-3, "N": 1.0, "kN": 1e3, "N*m": 1.0}
"""Units of an input signal's channel (a command, a current, a force): SI factor."""


def log_channel(path: Path, column: str, unit: str | None, kind: str, axis: str | None,
                time_column: str, key: str) -> tuple[np.ndarray, np.ndarray]:
    """One channel of a log file (CSV, Parquet, .mat) and its time -> (t [s], SI values); the
    unit is a position of the ``axis`` (``kind`` position) or a command, current or force.
    Errors name ``key``, the file and the column."""
    from ema_cli.logs import read_log_table
    from ema_cli.units import parse_quantity

    tab = read_log_table(path)
    for name in (column, time_column):
        if name not in tab.raw:
            raise EmaError(f"{key}: '{path}' has no {tab.noun} '{name}'; it holds "
                           f"{tab.listing()}")
    t = tab.column(time_column)
    v = tab.column(column)
    if t.shape != v.shape or t.shape[0] < 2:
        raise EmaError(f"{key}: '{path}': '{time_column}' and '{column}' must be vectors of one "
                       f"length >= 2, got {t.shape[0]} and {v.shape[0]} samples")
    bad = np.flatnonzero(np.diff(t) <= 0)
    if bad.size:
        raise EmaError(f"{key}: '{path}': time '{time_column}' must increase, it does not at "
                       f"{tab.where(int(bad[0]) + 1)}")
    if kind == "position":
        factor = parse_quantity(f"1 {unit}", "position", axis) if unit else 1.0
    else:
        if unit is not None and unit not in COMMAND_UNITS:
            raise EmaError(f"{key}.unit: {unit!r} is not a unit of a command, current or force;"
                           f" expected one of {', '.join(COMMAND_UNITS)}")
        factor = COMMAND_UNITS[unit] if unit else 1.0
    return t, v * factor if factor != 1.0 else v


