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
from typing import Any

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


ROLE_KINDS: dict[str, tuple[str, ...]] = {
    "time": ("time",),
    "position": ("length", "angle"),
    "reference": ("length", "angle"),
    "actuation": ("voltage", "current", "force"),
    "disturbance": ("voltage", "current", "force"),
}
"""The roles of a record's channels -> the kinds of unit each takes (``ema_cli.units.LOG_UNITS``);
``gain`` (a variable or a number) converts the actuation into a force."""
ROLE_DEFAULTS = {"time": "t", "position": "qm", "actuation": "vir", "reference": "qg",
                 "gain": "gtau"}
"""Each role's variable when no column map names it (the EMPS benchmark's names)."""


def parse_role_spec(role: str, spec: str) -> tuple[str, str | None]:
    """``NAME[:UNIT]`` of a record role -> (name, unit or None: SI); errors name the role and
    the units it takes."""
    from ema_cli.units import LOG_UNITS

    if role not in (*ROLE_KINDS, "gain"):
        raise EmaError(f"--columns {role}=...: unknown role '{role}'; expected one of "
                       f"{', '.join([*ROLE_KINDS, 'gain'])}")
    name, sep, unit = str(spec).rpartition(":")
    if not sep or role == "gain":
        return str(spec).strip(), None
    name, unit = name.strip(), unit.strip()
    kinds = ROLE_KINDS[role]
    if not any(unit in LOG_UNITS[k] for k in kinds):
        allowed = ", ".join(u for k in kinds for u in LOG_UNITS[k])
        raise EmaError(f"--columns {role}={spec}: unknown unit '{unit}' for the {role}; "
                       f"expected one of {allowed}")
    return name, unit


def _to_si(v: np.ndarray, unit: str | None, role: str) -> np.ndarray:
    from ema_cli.units import LOG_UNITS, log_to_si

    if unit is None:
        return v
    kind = next(k for k in ROLE_KINDS[role] if unit in LOG_UNITS[k])
    return np.asarray(log_to_si(v, unit, kind), dtype=np.float64)


def read_plant_record(path: str | Path, columns: dict[str, str] | None = None,
                      gain: float | None = None, saturation: float | None = None,
                      need_reference: bool = True, limit_force: float | None = None
                      ) -> tuple[PlantRecord, dict[str, Any]]:
    """A closed-loop record in any log format (CSV, Parquet, MATLAB v5/v7.3) -> (record,
    extras). ``columns`` maps roles (:data:`ROLE_KINDS` and ``gain``) to ``NAME[:UNIT]`` (default
    :data:`ROLE_DEFAULTS`, the EMPS names; no unit: SI). The force is ``gain * actuation``
    with the gain from the record's variable (``gain=NAME``, EMPS ``gtau``) when it has one,
    else ``gain`` [N per unit of actuation] (the description's amplifier), else 1 for an
    actuation in N. ``extras``: ``actuation`` (the command as logged, its unit), ``gain``,
    ``disturbance`` (a logged input added to the controller's output, or None). ``saturation``
    the command's limit (its units), ``limit_force`` the same as a force [N] for an actuation
    logged as a force. Every problem is one EmaError naming the file, the variable and the
    sample."""
    from ema_cli.identify.logs.channels import read_log_table

    spec = {**ROLE_DEFAULTS, **(columns or {})}
    roles = {r: parse_role_spec(r, s) for r, s in spec.items()}
    table = read_log_table(path)
    source = f"data file '{table.path}'"
    one_based = table.path.suffix.lower() == ".mat"
    names = {r: n for r, (n, _) in roles.items()}
    needed = {"time": "the time", "position": "the measured position",
              "actuation": "the actuation (controller output or force)"}
    if need_reference:
        needed["reference"] = "the reference position (the closed loop's input)"
    for role, meaning in needed.items():
        if names[role] not in table.raw:
            given = " (--columns " + role + "=" + spec[role] + ")" if columns and role in columns \
                else f"; name it with --columns {role}=NAME[:UNIT]"
            raise EmaError(f"{source} has no variable '{names[role]}' ({meaning}){given}; it "
                           f"has {table.listing()}")
    vals = {r: _to_si(table.column(names[r]), roles[r][1], r) for r in
            ("time", "position", "actuation", "reference", "disturbance")
            if r in names and names[r] in table.raw}
    unit_a = roles["actuation"][1] or "V"
    g_name = names.get("gain")
    if g_name and g_name in table.raw:
        g = _scalar(table, g_name, "the actuation's force gain")
        g_from = f"variable '{g_name}'"
    elif unit_a in ("N", "kN", "N*m"):
        g, g_from = 1.0, "the actuation is a force"
    elif gain is not None:
        g, g_from = float(gain), "the description's drive gain"
    else:
        raise EmaError(f"{source}: no gain converts the actuation '{names['actuation']}' "
                       f"[{unit_a}] into a force: the record has no variable '{g_name}' and the "
                       "description's drive has none; give --columns gain=NAME or an amplifier "
                       "drive with a gain")
    if g == 0:
        raise EmaError(f"{source}: the actuation's gain ({g_from}) is 0; expected nonzero")
    t, q, u = vals["time"], vals["position"], vals["actuation"]
    if unit_a in ("N", "kN", "N*m"):  # a force: its limit is the command's times the gain
        saturation = limit_force
    h = check_signals(source, names, t, q, u, one_based, saturation)
    ref = vals.get("reference")
    for role in ("reference", "disturbance"):
        v = vals.get(role)
        if v is not None and v.shape != q.shape:
            raise EmaError(f"{source}: variable '{names[role]}' has {v.size} samples but "
                           f"'{names['position']}' has {q.size}; expected one length")
        if v is not None and not np.all(np.isfinite(v)):
            i = int(np.flatnonzero(~np.isfinite(v))[0])
            raise EmaError(f"{source}: variable '{names[role]}' is NaN or inf at "
                           f"{sample_name(i, one_based)}; expected finite values")
    constants = {c: _scalar(table, c, "a controller constant") for c in EMPS_CONSTANTS
                 if c in table.raw and table.column(c).size == 1}
    rec = PlantRecord(t - t[0], q, g * u, h, source,
                      {**names, "force": f"gain*{names['actuation']}"},
                      one_based=one_based, reference_m=ref, constants=constants)
    mapped = {n for r, n in names.items() if r in vals or r == "gain"}
    unused = sorted(k for k in table.raw if k not in mapped and k not in EMPS_CONSTANTS
                    and not k.startswith("__"))
    extras = {"actuation": u, "unit": unit_a, "gain": g, "gain_from": g_from,
              "disturbance": vals.get("disturbance"), "unused": unused}
    return rec, extras
