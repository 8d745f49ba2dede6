"""The parameter table of the reference EMA (docs/model.md §4): name, SI unit, default, meaning.

Everything else is derived from this one table: the kernel's column indices, the CSV/manifest
names, the GA bounds and the `--set plant.NAME=VALUE` overrides. All values are SI.
A default of ``None`` marks a parameter derived from the others unless it is set explicitly
(see :func:`resolve`).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

from ema_cli.errors import EmaError
from ema_cli.units import DEG


@dataclass(frozen=True)
class Param:
    """One model parameter.

    ``default`` is SI; ``None`` means derived (see :func:`resolve`); ``inf`` means "no limit"
    for saturations. ``choices`` lists the accepted words of an enumerated parameter and
    maps each to the number the kernel sees.
    """

    name: str
    unit: str
    default: float | None
    description: str
    choices: Mapping[str, float] | None = None
    nonnegative: bool = True


DAMPING_CHOICES = {"contact": 0.0, "paper": 1.0}
"""Transmission damping forms: 0 = contact (T never pulls, 0 inside the gap), 1 = paper Eq. 2."""
CONTACT_TAU = 1.0e-4  # contact form: damping ramp-in time at impact (docs/model.md §2) [s]
CONTACT_PEN = 1.0e-3  # contact form: reference penetration of the Hunt-Crossley share [rad]

PARAMS: tuple[Param, ...] = (
    # armature and motor
    Param("R", "ohm", 0.5, "armature resistance"),
    Param("L", "H", 0.3e-3, "armature inductance"),
    Param("Kt", "N*m/A", 0.08, "torque constant"),
    Param("Ke", "V*s/rad", 0.08, "back-EMF constant"),
    Param("Jm", "kg*m^2", 3.0e-5, "rotor + pinion inertia"),
    Param("bm", "N*m*s/rad", 1.0e-5, "motor viscous damping"),
    # transmission and load
    Param("m", "-", 24.0, "gear ratio (motor angle / load angle)"),
    Param("JL", "kg*m^2", 0.01, "load + output gear inertia"),
    Param("bL", "N*m*s/rad", 0.02, "load bearing viscous damping"),
    Param("kL", "N*m/rad", 590.0, "transmission stiffness, load side"),
    Param("zeta_t", "-", 0.2, "transmission damping ratio (sets c when c is not given)"),
    Param("c", "N*m*s/rad", None, "transmission damping, load side; default 2*zeta_t*sqrt(kL*Jeq)"),
    Param("alpha", "rad", 0.0, "half backlash (transmission dead band), load side"),
    Param("damping", "-", 0.0, "transmission damping form: contact | paper",
          choices=DAMPING_CHOICES),
    Param("contact_tau", "s", CONTACT_TAU, "contact form: damping ramp-in time at impact; "
          "damping torque limited to (c/tau)*penetration (0: none, the torque jumps)"),
    Param("contact_hc", "-", 0.0, "contact form: Hunt-Crossley share h of the damping, 0..1: "
          "damping coefficient c*((1-h) + h*penetration/contact_pen) (0: linear damping)"),
    Param("contact_pen", "rad", CONTACT_PEN, "contact form: penetration at which the "
          "Hunt-Crossley share's damping coefficient equals c"),
    # controllers
    Param("Kpp", "1/s", 50.0, "position P gain (w*_L = Kpp*e_theta)"),
    Param("Kps", "V*s/rad", 0.15, "speed PI proportional gain (motor side)"),
    Param("Kis", "V/rad", 1.5, "speed PI integral gain"),
    Param("fb_motor", "-", 0.0, "position feedback blend b: theta_meas = (1-b)*theta_L + "
          "b*theta_m/m (0: load sensor, 1: motor angle / m)"),
    # compensators (config section `controller`; docs/model.md §2, controller)
    Param("dzi_v", "V", 0.0, "dead-zone inverse: estimated amplifier dead zone added to the "
          "voltage demand (0: off)"),
    Param("dzi_band", "V", 0.02, "dead-zone inverse smoothing band: the added voltage ramps "
          "linearly over |u| < band"),
    Param("ff_fc", "N*m", 0.0, "friction feed-forward: estimated Coulomb friction (0: off)"),
    Param("ff_fs", "N*m", 0.0, "friction feed-forward: estimated static friction (<= ff_fc: "
          "no Stribeck peak)"),
    Param("ff_vs", "rad/s", 1.0, "friction feed-forward: estimated Stribeck velocity"),
    Param("ff_sigma2", "N*m*s/rad", 0.0, "friction feed-forward: estimated viscous "
          "coefficient (0: off)"),
    Param("ff_sigma0", "N*m/rad", 0.0, "friction compensation: LuGre observer bristle "
          "stiffness (0: static Coulomb-Stribeck feed-forward on the speed command; > 0: a LuGre "
          "observer on the measured motor speed)"),
    Param("ff_sigma1", "N*m*s/rad", 0.0, "friction compensation: LuGre observer bristle "
          "damping"),
    Param("ff_band", "rad/s", 0.5, "friction feed-forward: smoothing band of the Coulomb "
          "sign, motor speed command"),
    Param("notch_hz", "Hz", 0.0, "speed-loop notch filter centre frequency (0: off)"),
    Param("notch_depth", "-", 0.1, "notch gain at its centre, zeta_z/zeta_p in [0, 1]"),
    Param("notch_zeta", "-", 0.5, "notch width: damping of its poles zeta_p"),
    # saturations (inf = removed)
    Param("sat1", "rad/s", 800.0 * DEG, "position-regulator output limit (load speed)"),
    Param("sat2", "V", 40.0, "speed-regulator output limit (voltage demand)"),
    Param("sat3", "A", 6.07 * 5.0, "current limit"),
    # dead zones
    Param("d1", "V", 0.0, "amplifier input dead zone half-width"),
    Param("d3", "rad/s", 0.0, "speed sensor dead zone half-width (motor speed)"),
    Param("d4", "rad", 0.0, "position sensor dead zone half-width (load angle)"),
    # LuGre friction at the motor shaft
    Param("friction", "-", 0.0, "LuGre friction at the motor shaft: 0 off, 1 on"),
    Param("Fc", "N*m", 0.02, "Coulomb friction"),
    Param("Fs", "N*m", None, "static friction; default 1.5*Fc"),
    Param("vs", "rad/s", 1.0, "Stribeck velocity"),
    Param("delta", "-", 1.0, "Stribeck exponent"),
    Param("sigma0", "N*m/rad", None, "bristle stiffness; default 1e3*Fc"),
    Param("sigma1", "N*m*s/rad", None, "bristle damping; default 2*0.5*sqrt(sigma0*Jm)"),
    Param("sigma2", "N*m*s/rad", 0.0, "viscous friction coefficient (the paper's friction1)"),
    # external load on the output (config section `load`)
    Param("T_load", "N*m", 0.0, "constant external torque on the load, + along +theta_L",
          nonnegative=False),
    Param("k_h", "N*m/rad", 0.0, "hinge-moment gradient: external torque -k_h*theta_L",
          nonnegative=False),
    Param("locked", "-", 0.0, "motor shaft held fixed, controller and armature off: 0 no, 1 yes"),
    # digital controller and sensors (config sections `controller`, `sensors`)
    Param("Ts", "s", 0.0, "controller sample time (0: continuous); a whole multiple of dt"),
    Param("q_pos", "rad", 0.0, "position sensor quantum, 2*pi/counts per rev (0: none)"),
    Param("q_speed", "rad/s", 0.0, "speed sensor resolution (0: none)"),
    # initial state (default: at rest at 0); a closed-loop fit starts its log segments here
    Param("x0_theta_m", "rad", 0.0, "initial motor angle", nonnegative=False),
    Param("x0_w_m", "rad/s", 0.0, "initial motor speed", nonnegative=False),
    Param("x0_i", "A", 0.0, "initial armature current", nonnegative=False),
    Param("x0_theta_L", "rad", 0.0, "initial load angle", nonnegative=False),
    Param("x0_w_L", "rad/s", 0.0, "initial load speed", nonnegative=False),
    Param("x0_z", "rad", 0.0, "initial LuGre bristle deflection", nonnegative=False),
    Param("x0_xI", "rad", 0.0, "initial speed-PI integral", nonnegative=False),
)
INITIAL_STATE = ("x0_theta_m", "x0_w_m", "x0_i", "x0_theta_L", "x0_w_L", "x0_z", "x0_xI")
"""The initial-state parameters, in the order of ``model.plant.STATES``."""
FLAGS = ("friction", "locked")
CONTROLLER_PARAMS = ("Kpp", "Kps", "Kis", "fb_motor", "dzi_v", "dzi_band", "ff_fc", "ff_fs",
                     "ff_vs", "ff_sigma2", "ff_sigma0", "ff_sigma1", "ff_band", "notch_hz",
                     "notch_depth", "notch_zeta")
"""The continuous parameters of the controller and its compensators (what `ema tune` may
free); the sample time Ts is not among them (it must stay a multiple of the step)."""
"""0/1 parameters: accept off/on, false/true, 0/1."""

INDEX: dict[str, int] = {p.name: i for i, p in enumerate(PARAMS)}
"""Column of each parameter in the parameter matrix P[n_cases, N_PARAMS]."""
N_PARAMS = len(PARAMS)
BY_NAME: dict[str, Param] = {p.name: p for p in PARAMS}

SIGMA0_PER_FC = 1.0e3  # bristle stiffness per N*m of Coulomb friction [1/rad]
FS_PER_FC = 1.5  # static / Coulomb friction ratio [-]
BRISTLE_DAMPING_RATIO = 0.5  # sigma1 = 2*ratio*sqrt(sigma0*Jm) [-]


def equivalent_inertia(p: Mapping[str, float]) -> float:
    """Load-side equivalent inertia Jeq = Jm*m^2*JL/(Jm*m^2 + JL) [kg*m^2]."""
    jm_load = p["Jm"] * p["m"] ** 2
    return jm_load * p["JL"] / (jm_load + p["JL"])


def check_value(name: str, value: object) -> float:
    """Convert one user value for parameter ``name`` to its SI float, or raise EmaError."""
    if name not in BY_NAME:
        raise EmaError(f"unknown model parameter '{name}'; expected one of: {', '.join(INDEX)}")
    spec = BY_NAME[name]
    if spec.choices is not None:
        if isinstance(value, str) and value in spec.choices:
            return spec.choices[value]
        raise EmaError(f"parameter '{name}' must be one of {sorted(spec.choices)}, got {value!r}")
    if isinstance(value, str) and value.strip().lower() in ("off", "inf", "none", "false"):
        if name.startswith("sat"):
            return math.inf
        if name in FLAGS:
            return 0.0
        raise EmaError(f"parameter '{name}' cannot be '{value}'; expected a number in {spec.unit}")
    if isinstance(value, str) and value.strip().lower() in ("on", "true") and name in FLAGS:
        return 1.0
    if isinstance(value, bool):
        value = float(value)
    try:
        x = float(value)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        raise EmaError(
            f"parameter '{name}' expects a number in {spec.unit}, got {value!r}"
        ) from None
    if math.isnan(x):
        raise EmaError(f"parameter '{name}' is NaN; expected a number in {spec.unit}")
    if spec.nonnegative and x < 0:
        raise EmaError(f"parameter '{name}' must be >= 0 ({spec.unit}), got {x}")
    if math.isinf(x) and not name.startswith("sat"):
        raise EmaError(f"parameter '{name}' must be finite ({spec.unit}), got {x}")
    return x


def resolve(overrides: Mapping[str, object] | None = None) -> dict[str, float]:
    """Defaults + overrides -> a complete dict of SI parameter values, derived ones filled in.

    Derived unless set: ``c = 2*zeta_t*sqrt(kL*Jeq)``, ``Fs = 1.5*Fc``, ``sigma0 = 1e3*Fc``,
    ``sigma1 = 2*0.5*sqrt(sigma0*Jm)``.
    """
    values: dict[str, float | None] = {p.name: p.default for p in PARAMS}
    for name, raw in (overrides or {}).items():
        values[name] = check_value(name, raw)
    for name in ("m", "Jm", "JL", "L"):
        if not values[name]:
            raise EmaError(f"parameter '{name}' must be > 0, got {values[name]}")
    if values["contact_hc"] > 1.0:  # type: ignore[operator]
        raise EmaError(f"parameter 'contact_hc' must be in [0, 1] (-), got {values['contact_hc']}")
    if not values["contact_pen"]:
        raise EmaError(f"parameter 'contact_pen' must be > 0 (rad), got {values['contact_pen']}")
    if values["Fs"] is None:
        values["Fs"] = FS_PER_FC * values["Fc"]  # type: ignore[operator]
    if values["sigma0"] is None:
        values["sigma0"] = SIGMA0_PER_FC * values["Fc"]  # type: ignore[operator]
    if values["sigma1"] is None:
        values["sigma1"] = 2.0 * BRISTLE_DAMPING_RATIO * math.sqrt(values["sigma0"] * values["Jm"])  # type: ignore[operator]
    if values["c"] is None:
        values["c"] = 2.0 * values["zeta_t"] * math.sqrt(values["kL"] * equivalent_inertia(values))  # type: ignore[arg-type,operator]
    if values["notch_depth"] > 1.0:  # type: ignore[operator]
        raise EmaError(f"parameter 'notch_depth' (gain at the notch centre) must lie in [0, 1],"
                       f" got {values['notch_depth']}")
    for name in ("dzi_band", "ff_band", "ff_vs", "notch_zeta"):
        if values["dzi_v" if name == "dzi_band" else "ff_fc" if name in ("ff_band", "ff_vs")
                  else "notch_hz"] and not values[name] > 0:  # type: ignore[operator]
            raise EmaError(f"parameter '{name}' must be > 0 when its compensator is on, got "
                           f"{values[name]}")
    if values["ff_sigma0"] and not values["ff_fc"] > 0:  # type: ignore[operator]
        raise EmaError(f"parameter 'ff_sigma0' (LuGre friction observer) needs ff_fc > 0, got "
                       f"ff_fc = {values['ff_fc']}")
    if values["fb_motor"] > 1.0:  # type: ignore[operator]
        raise EmaError(f"parameter 'fb_motor' (position feedback blend) must lie in [0, 1], "
                       f"got {values['fb_motor']}")
    for flag in FLAGS:
        if values[flag] not in (0.0, 1.0):
            raise EmaError(f"parameter '{flag}' must be 0/off or 1/on, got {values[flag]}")
    if values["friction"] == 1.0 and (values["Fc"] <= 0 or values["vs"] <= 0):  # type: ignore[operator]
        raise EmaError("LuGre friction needs Fc > 0 and vs > 0")
    return {k: float(v) for k, v in values.items()}  # type: ignore[arg-type]


def to_row(values: Mapping[str, float]) -> list[float]:
    """A resolved parameter dict -> one row of the parameter matrix, in table order."""
    return [values[p.name] for p in PARAMS]
