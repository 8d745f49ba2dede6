"""Measured records of one axis for inverse-model identification: position and actuation force
sampled uniformly, read from a MATLAB file such as the EMPS benchmark's or given as arrays, and
checked once, here.

A record holds the measured load position ``q_m`` [m], the actuation force ``force_n`` [N]
(for the EMPS, ``gtau*vir``: the amplifier's gain [N/V] times the controller's output [V]), the
sample interval ``h_s`` [s] and, when the file has them, the reference position and the
controller's constants. Every problem with the input is one :class:`EmaError` line naming the
source (``data file '...'`` or ``arrays``), the variable and the sample: the MATLAB index
(1-based) for files, the 0-based index for arrays.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ema_cli.errors import EmaError
from ema_cli.identify.logs.channels import LogTable, read_log_table

UNIFORM_TOL = 0.01  # a sample interval may differ from the mean by 1 % (EMPS: 2e-5) [-]
SATURATED_MAX_SHARE = 0.5  # most of the record at the actuation's limit is refused [-]
AT_LIMIT_TOL = 1e-6  # |u| within this fraction of the limit counts as saturated [-]
EMPS_VARIABLES = {"time": "t", "position": "qm", "actuation": "vir", "gain": "gtau",
                  "reference": "qg"}
"""Roles -> variable names of the EMPS benchmark's files (DATA_EMPS.mat)."""
EMPS_CONSTANTS = ("gtau", "kp", "kv")
"""The benchmark's scalars kept with a record when present: gtau [N/V], kp [1/s], kv [V*s/m]."""


@dataclass(frozen=True)
class PlantRecord:
    """A checked record, SI: ``t_s[n]`` [s], ``q_m[n]`` [m], ``force_n[n]`` [N], the nominal
    sample interval ``h_s`` [s]; ``source`` names it in messages (``data file 'x.mat'`` or
    ``arrays``), ``names`` maps roles (position, force, ...) to what the source calls them,
    ``one_based`` says how a sample is named. ``reference_m`` [m] and ``constants`` (gtau,
    kp, kv) come with EMPS files."""

    t_s: np.ndarray
    q_m: np.ndarray
    force_n: np.ndarray
    h_s: float
    source: str
    names: dict[str, str]
    one_based: bool = False
    reference_m: np.ndarray | None = None
    constants: dict[str, float] = field(default_factory=dict)

    @property
    def n(self) -> int:
        """Number of samples."""
        return int(self.q_m.shape[0])

    def where(self, i: int) -> str:
        """Sample ``i`` (0-based) as the source names it (:func:`sample_name`)."""
        return sample_name(i, self.one_based)

    def label(self, role: str) -> str:
        """How a message names a role's variable: ``variable 'qm'``."""
        return f"variable '{self.names.get(role, role)}'"


def sample_name(i: int, one_based: bool) -> str:
    """Sample ``i`` (0-based) as a message names it: ``index i+1`` for a MATLAB file,
    ``index i (0-based)`` for arrays."""
    return f"index {i + 1}" if one_based else f"index {i} (0-based)"


def _at_limit(u: np.ndarray, limit: float | None) -> np.ndarray:
    """Samples at the actuation's limit: ``|u| >= limit`` (within AT_LIMIT_TOL), the limit being
    the largest ``|u|`` of the record when not stated."""
    lim = float(np.max(np.abs(u))) if limit is None else float(limit)
    return np.abs(u) >= lim * (1.0 - AT_LIMIT_TOL)


def check_signals(source: str, names: dict[str, str], t_s: np.ndarray, q_m: np.ndarray,
                  actuation: np.ndarray, one_based: bool,
                  saturation: float | None = None) -> float:
    """The checks every record passes -> the nominal sample interval ``h_s`` [s]: finite values,
    one length, a time that increases uniformly (within UNIFORM_TOL), an actuation that varies
    and is not at its limit (``saturation``, or its largest magnitude) for most of the record.
    ``names`` maps time, position and actuation to their variable names."""
    def at(i: int) -> str:
        return sample_name(i, one_based)

    arrays = {"time": t_s, "position": q_m, "actuation": actuation}
    for role, v in arrays.items():
        if v.ndim != 1:
            raise EmaError(f"{source}: variable '{names[role]}' has shape {v.shape}; expected a "
                           "vector")
        bad = ~np.isfinite(v)
        if bad.any():
            raise EmaError(f"{source}: variable '{names[role]}' has {int(bad.sum())} NaN or inf "
                           f"value(s) (first at {at(int(np.flatnonzero(bad)[0]))})")
        if v.shape[0] != q_m.shape[0]:
            raise EmaError(f"{source}: variable '{names[role]}' has {v.shape[0]} samples but "
                           f"'{names['position']}' has {q_m.shape[0]}; expected one length")
    n = q_m.shape[0]
    if n < 3:
        raise EmaError(f"{source}: variable '{names['position']}' has {n} sample(s); expected "
                       "a record (hundreds of samples at least)")
    dt = np.diff(t_s)
    if np.any(dt <= 0):
        i = int(np.flatnonzero(dt <= 0)[0]) + 1
        raise EmaError(f"{source}: variable '{names['time']}' does not increase at {at(i)} "
                       f"({t_s[i - 1]:.9g} s then {t_s[i]:.9g} s); expected increasing times")
    h = float((t_s[-1] - t_s[0]) / (n - 1))
    off = np.abs(dt / h - 1.0)
    if np.any(off > UNIFORM_TOL):
        i = int(np.argmax(off)) + 1
        raise EmaError(f"{source}: variable '{names['time']}' steps by {dt[i - 1]:.6g} s at "
                       f"{at(i)}, the mean step being {h:.6g} s; expected uniform sampling "
                       f"(within {100 * UNIFORM_TOL:g} %)")
    u, un = actuation, names["actuation"]
    if np.ptp(u) == 0:
        raise EmaError(f"{source}: variable '{un}' is constant ({u[0]:.6g} at every sample, "
                       f"{at(0)} to {at(n - 1)}); expected the varying actuation")
    sat = _at_limit(u, saturation)
    if sat.mean() > SATURATED_MAX_SHARE:
        lim = float(np.max(np.abs(u))) if saturation is None else float(saturation)
        first = int(np.flatnonzero(sat)[0])
        raise EmaError(f"{source}: variable '{un}' is at its limit |{un}| = {lim:.6g} in "
                       f"{100 * sat.mean():.0f} % of the samples (first at {at(first)}); "
                       f"expected it below its limit in at least "
                       f"{100 * (1 - SATURATED_MAX_SHARE):g} % (a clipped actuation does not "
                       "measure the force)")
    return h


def record_from_arrays(q_m: np.ndarray, force_n: np.ndarray, h_s: float,
                       t_s: np.ndarray | None = None, source: str = "arrays",
                       saturation_n: float | None = None) -> PlantRecord:
    """A record from arrays: position ``q_m`` [m], actuation force ``force_n`` [N], sampled
    every ``h_s`` [s] (times ``t_s`` [s] default ``k*h_s``); ``saturation_n`` [N] the force's
    limit if known. Checked as :func:`check_signals` says; samples are named 0-based."""
    q = np.asarray(q_m, dtype=np.float64)
    f = np.asarray(force_n, dtype=np.float64)
    if not (np.isfinite(h_s) and h_s > 0):
        raise EmaError(f"{source}: sample interval h_s = {h_s!r}; expected a positive number "
                       "of seconds")
    t = np.arange(q.shape[0]) * float(h_s) if t_s is None else np.asarray(t_s, np.float64)
    names = {"time": "t_s", "position": "q_m", "actuation": "force_n", "force": "force_n"}
    h = check_signals(source, names, t, q, f, one_based=False, saturation=saturation_n)
    if abs(h / h_s - 1.0) > UNIFORM_TOL:
        raise EmaError(f"{source}: the times t_s step by {h:.6g} s on average but h_s = "
                       f"{h_s:.6g} s; expected them to agree (within {100 * UNIFORM_TOL:g} %)")
    return PlantRecord(t, q, f, float(h_s), source, names)


def _scalar(table: LogTable, name: str, what: str) -> float:
    """A 1x1 MATLAB variable as a float; else an EmaError naming the file and the variable."""
    v = table.column(name)
    if v.size != 1:
        raise EmaError(f"data file '{table.path}': variable '{name}' has {v.size} values; "
                       f"expected a scalar (1x1), {what}")
    return float(v[0])


def read_plant_mat(path: str | Path, variables: dict[str, str] | None = None,
                   saturation_v: float | None = None) -> PlantRecord:
    """Read a record from a MATLAB file (v5 or v7.3) laid out as the EMPS benchmark's:
    time [s], measured position [m], actuation [V] vectors and the actuation's gain [N/V] as
    a 1x1 scalar; ``force = gain*actuation`` [N]. ``variables`` maps roles to names (default
    :data:`EMPS_VARIABLES`: t, qm, vir, gtau, and the optional reference qg);
    ``saturation_v`` [V] the actuation's limit if known (default: its largest magnitude; pass
    ``inf`` for a record whose actuation really is at its extremes most of the time, such as
    a square wave). Every problem is one EmaError naming the file, the variable and the
    MATLAB index."""
    names = {**EMPS_VARIABLES, **(variables or {})}
    table = read_log_table(path)
    p = table.path
    source = f"data file '{p}'"
    what = {"time": "the time [s]", "position": "the measured position [m]",
            "actuation": "the actuation (controller output) [V]",
            "gain": "the actuation's force gain [N/V]"}
    for role, meaning in what.items():
        if names[role] not in table.raw:
            raise EmaError(f"{source} has no variable '{names[role]}' ({meaning}); it has "
                           f"{table.listing()}")
    t = table.column(names["time"])
    q = table.column(names["position"])
    u = table.column(names["actuation"])
    gain = _scalar(table, names["gain"], "the actuation's force gain [N/V]")
    if gain == 0:
        raise EmaError(f"{source}: variable '{names['gain']}' is 0; expected the actuation's "
                       "force gain [N/V], nonzero")
    h = check_signals(source, names, t, q, u, one_based=True, saturation=saturation_v)
    ref = None
    if names["reference"] in table.raw:
        ref = table.column(names["reference"])
        if ref.shape != q.shape:
            raise EmaError(f"{source}: variable '{names['reference']}' has {ref.size} samples "
                           f"but '{names['position']}' has {q.size}; expected one length")
    constants = {c: _scalar(table, c, "a controller constant") for c in EMPS_CONSTANTS
                 if c in table.raw}
    names = {**names, "force": f"{names['gain']}*{names['actuation']}"}
    return PlantRecord(t, q, gain * u, h, source, names, one_based=True, reference_m=ref,
                       constants=constants)
