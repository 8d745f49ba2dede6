"""Names, SI units and edge (CSV/report) units of the simulator's recorded signals and metrics.

The kernel writes SI values in the column order of these tables; :func:`to_edge` converts a
column to its edge unit once, when a table is written or plotted.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

from ema_cli.units import DEG, RPM


@dataclass(frozen=True)
class Column:
    """A recorded quantity: kernel name, SI unit, edge column name and SI->edge factor."""

    name: str
    si_unit: str
    edge: str
    factor: float
    description: str
    value: str = ""
    """A signal's value in the kernel: an expression of the state at the step's instant, the
    inputs, what the step computed (``sim.layout.OUT``) and the parameters, by name
    (``sim.layout`` generates the recording from it)."""


def _col(name: str, si: str, edge: str, factor: float, desc: str, value: str = "") -> Column:
    return Column(name, si, edge, factor, desc, value)


SIGNALS: tuple[Column, ...] = (
    _col("theta_ref", "rad", "theta_ref_deg", 1 / DEG, "position reference (load)", "r0"),
    _col("theta_load", "rad", "theta_load_deg", 1 / DEG, "load angle", "theta_L"),
    _col("theta_motor", "rad", "theta_motor_deg", 1 / DEG, "motor angle / gear ratio",
         "theta_m / m"),
    _col("omega_ref", "rad/s", "omega_ref_deg_s", 1 / DEG, "velocity reference (load)", "rv"),
    _col("omega_load", "rad/s", "omega_load_deg_s", 1 / DEG, "load speed", "w_L"),
    _col("omega_motor", "rad/s", "omega_motor_rpm", 1 / RPM, "motor speed", "w_m"),
    _col("current", "A", "current_a", 1.0, "armature current", "cur"),
    _col("voltage_cmd", "V", "voltage_cmd_v", 1.0, "speed-regulator voltage demand (after SAT2)",
         "u_out"),
    _col("voltage_amp", "V", "voltage_amp_v", 1.0, "amplifier output (after DZ1)", "u_amp"),
    _col("torque_shaft", "N*m", "torque_shaft_nm", 1.0, "transmission torque T (load side)",
         "t_shaft"),
    _col("torque_friction", "N*m", "torque_friction_nm", 1.0, "LuGre friction torque (motor)",
         "t_fric"),
    _col("err_pos", "rad", "err_pos_deg", 1 / DEG, "position error theta_ref - theta_load",
         "r0 - theta_L"),
    _col("err_vel", "rad/s", "err_vel_deg_s", 1 / DEG, "velocity error omega_ref - omega_load",
         "rv - w_L"),
    _col("dtheta", "rad", "dtheta_rad", 1.0, "transmission deflection theta_m/m - theta_L",
         "theta_m / m - theta_L"),
    _col("domega", "rad/s", "domega_rad_s", 1.0, "transmission deflection rate w_m/m - w_L",
         "w_m / m - w_L"),
    _col("bristle_z", "rad", "bristle_z_rad", 1.0, "LuGre bristle deflection z", "z"),
    _col("torque_load", "N*m", "torque_load_nm", 1.0,
         "external torque on the load, + along +theta_L (config section load)", "t_load"),
    _col("drive_force", "N*m", "drive_force_nm", 1.0,
         "the drive's force (torque) on the axis, load side", "f_drive"),
    _col("friction_load", "N*m", "friction_load_nm", 1.0, "friction at the load, load side",
         "f_fric_L"),
    _col("winding_rise", "K", "winding_rise_k", 1.0,
         "winding temperature rise above ambient (thermal element)", "th_w"),
    _col("housing_rise", "K", "housing_rise_k", 1.0,
         "housing temperature rise above ambient (thermal element)", "th_h"),
)
THERMAL_SIGNALS = ("winding_rise", "housing_rise")
"""The thermal element's signals (shown only for an actuator that has it)."""
PAPER_SIGNALS = 17
"""The first signals are the paper's EMA's (its tables and files show exactly these)."""

METRICS: tuple[Column, ...] = (
    _col("iae_pos", "rad*s", "iae_pos_deg_s", 1 / DEG, "integral |position error| dt"),
    _col("ise_pos", "rad^2*s", "ise_pos_deg2_s", 1 / DEG**2, "integral position error^2 dt"),
    _col("itae_pos", "rad*s^2", "itae_pos_deg_s2", 1 / DEG, "integral t*|position error| dt"),
    _col("rms_pos", "rad", "rms_err_pos_deg", 1 / DEG, "RMS position error"),
    _col("max_pos", "rad", "max_abs_err_pos_deg", 1 / DEG, "max |position error|"),
    _col("iae_vel", "rad", "iae_vel_deg", 1 / DEG, "integral |velocity error| dt"),
    _col("ise_vel", "rad^2/s", "ise_vel_deg2_s", 1 / DEG**2, "integral velocity error^2 dt"),
    _col("itae_vel", "rad*s", "itae_vel_deg_s", 1 / DEG, "integral t*|velocity error| dt"),
    _col("rms_vel", "rad/s", "rms_err_vel_deg_s", 1 / DEG, "RMS velocity error"),
    _col("max_vel", "rad/s", "max_abs_err_vel_deg_s", 1 / DEG, "max |velocity error|"),
    _col("ss_err_pos", "rad", "ss_err_pos_deg", 1 / DEG,
         "steady-state position error: mean over the last 10 % of the run"),
    _col("overshoot", "%", "overshoot_pct", 1.0, "step overshoot, % of the step"),
    _col("rise_time", "s", "rise_time_s", 1.0, "step rise time 10-90 %"),
    _col("settling_time", "s", "settling_time_s", 1.0,
         "2 % settling time after the step (NaN: not settled by the end)"),
    _col("t50", "s", "t50_s", 1.0, "time to 50 % of the step (lag)"),
    _col("step_peak", "-", "step_peak", 1.0,
         "largest share of the step the load reached after it (1 + overshoot, not clipped)"),
    _col("p2p_pos", "rad", "p2p_err_pos_deg", 1 / DEG,
         "peak-to-peak position error over the last 20 % (residual oscillation)"),
    _col("p2p_vel", "rad/s", "p2p_err_vel_deg_s", 1 / DEG,
         "peak-to-peak velocity error over the last 20 %"),
    _col("peak_current", "A", "peak_current_a", 1.0, "max |armature current|"),
    _col("peak_voltage", "V", "peak_voltage_cmd_v", 1.0, "max |voltage demand|"),
    _col("peak_load_rate", "rad/s", "peak_load_rate_deg_s", 1 / DEG, "max |load speed|"),
    _col("peak_torque", "N*m", "peak_torque_shaft_nm", 1.0, "max |transmission torque|"),
    _col("diverged", "-", "diverged", 1.0, "1 if the run went non-finite or ran away"),
    _col("t_end", "s", "t_end_s", 1.0, "time reached (the duration unless diverged)"),
)

TRANSLATIONAL_NAMES: dict[str, tuple[str, float, str]] = {
    # signals: kernel name -> (edge column, SI -> edge factor, SI unit) on a translational axis
    "theta_ref": ("x_ref_mm", 1e3, "m"), "theta_load": ("x_load_mm", 1e3, "m"),
    "theta_motor": ("x_motor_mm", 1e3, "m"), "omega_ref": ("v_ref_mm_s", 1e3, "m/s"),
    "omega_load": ("v_load_mm_s", 1e3, "m/s"), "torque_shaft": ("force_shaft_n", 1.0, "N"),
    "err_pos": ("err_pos_mm", 1e3, "m"), "err_vel": ("err_vel_mm_s", 1e3, "m/s"),
    "dtheta": ("dx_mm", 1e3, "m"), "domega": ("dv_mm_s", 1e3, "m/s"),
    "torque_load": ("force_load_n", 1.0, "N"), "drive_force": ("drive_force_n", 1.0, "N"),
    "friction_load": ("friction_load_n", 1.0, "N"),
    # metrics
    "iae_pos": ("iae_pos_mm_s", 1e3, "m*s"), "ise_pos": ("ise_pos_mm2_s", 1e6, "m^2*s"),
    "itae_pos": ("itae_pos_mm_s2", 1e3, "m*s^2"), "rms_pos": ("rms_err_pos_mm", 1e3, "m"),
    "max_pos": ("max_abs_err_pos_mm", 1e3, "m"), "iae_vel": ("iae_vel_mm", 1e3, "m"),
    "ise_vel": ("ise_vel_mm2_s", 1e6, "m^2/s"), "itae_vel": ("itae_vel_mm_s", 1e3, "m*s"),
    "rms_vel": ("rms_err_vel_mm_s", 1e3, "m/s"), "max_vel": ("max_abs_err_vel_mm_s", 1e3, "m/s"),
    "ss_err_pos": ("ss_err_pos_mm", 1e3, "m"), "p2p_pos": ("p2p_err_pos_mm", 1e3, "m"),
    "p2p_vel": ("p2p_err_vel_mm_s", 1e3, "m/s"),
    "peak_load_rate": ("peak_load_rate_mm_s", 1e3, "m/s"),
    "peak_torque": ("peak_force_shaft_n", 1.0, "N"),
}
"""The names and units of the load-side columns on a translational axis (mm, mm/s, N: never
deg or N*m); the others (motor speed, current, voltages, times) read the same on both axes."""


def for_axis(columns: tuple[Column, ...], axis: str = "rotary") -> tuple[Column, ...]:
    """``columns`` named and scaled for ``axis``: the rotary names as they are, the
    translational ones from :data:`TRANSLATIONAL_NAMES`."""
    if axis == "rotary":
        return columns
    import dataclasses

    out = []
    for c in columns:
        t = TRANSLATIONAL_NAMES.get(c.name)
        out.append(c if t is None else dataclasses.replace(c, edge=t[0], factor=t[1],
                                                           si_unit=t[2]))
    return tuple(out)


def shown(params: Mapping[str, float], motor: bool = True) -> frozenset[str]:
    """The kernel names of the signals and metrics that mean something for the actuator of
    ``params`` (SI parameters): the paper's EMA shows its 17 signals and every metric; a rigid
    axis has no shaft (deflection, shaft torque), an amplifier without a torque constant no
    current, a site without friction no friction signal, a translational axis without a ratio
    (``motor`` False) no motor side."""
    names = {c.name for c in SIGNALS} | {c.name for c in METRICS}
    if params.get("thermal", 0.0) == 0.0:
        names -= set(THERMAL_SIGNALS)
    paper = (params.get("rigid", 0.0) == 0.0 and params.get("drive", 0.0) == 0.0
             and params.get("ctrl", 0.0) == 0.0 and params.get("friction_L", 0.0) == 0.0
             and params.get("friction", 0.0) != 2.0)
    if paper:
        return frozenset(names - {"drive_force", "friction_load"})
    drop = set()
    if params.get("rigid", 0.0) == 1.0:
        drop |= {"dtheta", "domega", "torque_shaft", "peak_torque"}
    if params.get("drive", 0.0) == 1.0 and params.get("Kt", 0.0) <= 0.0:
        drop |= {"current", "peak_current"}
    if params.get("friction", 0.0) != 1.0:
        drop.add("bristle_z")
    if params.get("friction", 0.0) == 0.0:
        drop.add("torque_friction")
    if params.get("friction_L", 0.0) == 0.0:
        drop.add("friction_load")
    if not motor:
        drop |= {"theta_motor", "omega_motor"}
    return frozenset(names - drop)


def edge_unit(col: Column) -> str:
    """The unit of a signal or metric column at the edge (``deg``, ``rpm``, ``mm/s``, ``N``)."""
    import math

    from ema_cli.units import RPM

    if math.isclose(col.factor, 1 / DEG):
        return col.si_unit.replace("rad", "deg")
    if math.isclose(col.factor, 1 / DEG**2):
        return col.si_unit.replace("rad^2", "deg^2")
    if math.isclose(col.factor, 1 / RPM):
        return "rpm"
    if math.isclose(col.factor, 1e3) and "m" in col.si_unit:
        return col.si_unit.replace("m", "mm", 1)
    if math.isclose(col.factor, 1e6) and "m^2" in col.si_unit:
        return col.si_unit.replace("m^2", "mm^2", 1)
    return col.si_unit


SIG: dict[str, int] = {c.name: i for i, c in enumerate(SIGNALS)}
MET: dict[str, int] = {c.name: i for i, c in enumerate(METRICS)}
N_SIGNALS = len(SIGNALS)
N_METRICS = len(METRICS)
METRIC_BY_EDGE: dict[str, Column] = {c.edge: c for c in METRICS}


@dataclass(frozen=True)
class Accumulator:
    """A running quantity of the metrics: name, initial value, its update at every step (an
    expression of its own previous value and the step's quantities, ``sim.layout.STEP``, by
    name) and what it holds."""

    name: str
    init: float
    update: str
    description: str


_INF = float("inf")
ACCUMULATORS: tuple[Accumulator, ...] = (
    Accumulator("iae", 0.0, "iae + wgt * ae", "trapezoid sum of |e| dt"),
    Accumulator("ise", 0.0, "ise + wgt * e * e", "trapezoid sum of e^2 dt"),
    Accumulator("itae", 0.0, "itae + wgt * t * ae", "trapezoid sum of t |e| dt"),
    Accumulator("iaev", 0.0, "iaev + wgt * aev", "trapezoid sum of |ev| dt"),
    Accumulator("isev", 0.0, "isev + wgt * ev * ev", "trapezoid sum of ev^2 dt"),
    Accumulator("itaev", 0.0, "itaev + wgt * t * aev", "trapezoid sum of t |ev| dt"),
    Accumulator("emax", 0.0, "max(emax, ae)", "max |e|"),
    Accumulator("evmax", 0.0, "max(evmax, aev)", "max |ev|"),
    Accumulator("ss", 0.0, "ss + e if in_ss else ss", "sum of e over the steady-state window"),
    Accumulator("emin_o", _INF, "min(emin_o, e) if in_osc else emin_o",
                "min e over the oscillation window"),
    Accumulator("emax_o", -_INF, "max(emax_o, e) if in_osc else emax_o",
                "max e over the oscillation window"),
    Accumulator("evmin_o", _INF, "min(evmin_o, ev) if in_osc else evmin_o",
                "min ev over the oscillation window"),
    Accumulator("evmax_o", -_INF, "max(evmax_o, ev) if in_osc else evmax_o",
                "max ev over the oscillation window"),
    Accumulator("smax", -_INF, "max(smax, s) if act else smax",
                "largest share of the step reached"),
    Accumulator("t10", float("nan"), "t if (act and t10 != t10 and s >= 0.1) else t10",
                "first time at 10 % of the step"),
    Accumulator("t50", float("nan"), "t if (act and t50 != t50 and s >= 0.5) else t50",
                "first time at 50 % of the step"),
    Accumulator("t90", float("nan"), "t if (act and t90 != t90 and s >= 0.9) else t90",
                "first time at 90 % of the step"),
    Accumulator("last_out", -1.0, "k if (act and abs(s - 1.0) > SETTLE_BAND) else last_out",
                "last step outside the settling band"),
    Accumulator("pki", 0.0, "max(pki, abs(cur))", "max |current|"),
    Accumulator("pku", 0.0, "max(pku, abs(u_out))", "max |command|"),
    Accumulator("pkwl", 0.0, "max(pkwl, abs(w_L))", "max |load speed|"),
    Accumulator("pkt", 0.0, "max(pkt, abs(t_shaft))", "max |shaft torque|"),
)
SETTLE_BAND = 0.02  # settling band, fraction of the step

