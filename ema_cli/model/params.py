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
from ema_cli.model import thermal
from ema_cli.model.states import STATES
from ema_cli.units import DEG, ZERO_CELSIUS


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
    side: str = ""
    """``load``: a load-side quantity, in the axis's units (rad or m: ``units.axis_unit``);
    otherwise motor side (always rotary), electrical or dimensionless."""
    limit: bool = False
    """A limit: ``inf`` (or the words off, none, inf) means no limit."""


DAMPING_CHOICES = {"contact": 0.0, "paper": 1.0}
FRICTION_CHOICES = {"off": 0.0, "lugre": 1.0, "static": 2.0}
"""Friction laws of a site: 0 none, 1 LuGre (dynamic, bristles), 2 static (Coulomb, Stribeck and
viscous per direction, with stiction: ``model.friction``); ``on`` reads as ``lugre``."""
DRIVE_CHOICES = {"armature": 0.0, "amplifier": 1.0}
CTRL_CHOICES = {"paper": 0.0, "discrete": 1.0, "none": 2.0}
VSRC_CHOICES = {"encoder": 0.0, "sensor": 1.0}
PLANT_INPUT_CHOICES = {"command": 0.0, "force": 1.0, "current": 2.0}
ON_OFF_CHOICES = ("friction", "friction_L")
"""Enumerated parameters that also read on/off (on: LuGre, as before the static law existed)."""
MAX_FIR = 8  # taps of the discrete cascade's position FIR [-]
MAX_DIFF = 16  # longest position difference of the discrete cascade's velocity [samples]
MAX_DELAY = 8  # longest computation delay of the discrete cascade [samples]
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
    Param("Fc_t", "N*m", 0.0, "transmission friction, load side: the level of a Dahl element "
          "in parallel with the shaft, the half height of the torque-twist loop (0: none)",
          side="load"),
    Param("sigma_t", "N*m/rad", None, "transmission friction: Dahl stiffness, the loop's slope "
          "right after a reversal, load side; default kL", side="load"),
    Param("preload", "N*m", 0.0, "anti-backlash preload, load side: inside the gap the torque "
          "rises linearly from -preload to +preload, in contact it adds to the teeth's "
          "(needs alpha > 0)", side="load"),
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
    Param("sat1", "rad/s", 800.0 * DEG, "position-regulator output limit (load speed)",
          side="load", limit=True),
    Param("sat2", "V", 40.0, "speed-regulator output limit (voltage demand)", limit=True),
    Param("sat3", "A", 6.07 * 5.0, "current limit", limit=True),
    # dead zones
    Param("d1", "V", 0.0, "amplifier input dead zone half-width"),
    Param("d3", "rad/s", 0.0, "speed sensor dead zone half-width (motor speed)"),
    Param("d4", "rad", 0.0, "position sensor dead zone half-width (load angle)"),
    # LuGre friction at the motor shaft
    Param("friction", "-", 0.0, "friction at the motor shaft: off | lugre (on) | static "
          "(Coulomb, Stribeck, viscous per direction, with stiction)", choices=FRICTION_CHOICES),
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
    # ---- the actuator description (docs/model.md §3; config section `actuator`) ----
    # structure: each choice selects a kernel variant (sim.kernel.variant_codes)
    Param("rigid", "-", 0.0, "transmission: 0 compliant (motor and load coupled by kL, c, "
          "alpha), 1 rigid (one mass JL + m^2*Jm in load coordinates)"),
    Param("drive", "-", 0.0, "drive: armature (voltage in, R, L, Ke, Kt, current limit) | "
          "amplifier (command in, force or torque out: amp_gain, amp_limit, amp_tau)",
          choices=DRIVE_CHOICES),
    Param("amp_gain", "N*m/V", 1.0, "amplifier gain, load side: force (torque) on the axis per "
          "unit of command, transmission included", side="load"),
    Param("amp_limit", "N*m", math.inf, "amplifier output limit, load side (inf: none)",
          side="load", limit=True),
    Param("amp_tau", "s", 0.0, "amplifier first-order time constant (0: instantaneous)"),
    Param("offset", "N*m", 0.0, "constant offset force (torque) on the load opposing +theta_L "
          "(gravity, bias; the EMPS benchmark's OF)", nonnegative=False, side="load"),
    # the static friction law (friction = static) at the motor: Fc, Fs, vs, delta, sigma2 above
    # are the + direction's; these the - direction's (default: the same)
    Param("Fc_neg", "N*m", None, "motor Coulomb friction moving in -x (static law; default Fc)"),
    Param("Fs_neg", "N*m", None, "motor breakaway friction moving in -x (static law; default Fs)"),
    Param("sigma2_neg", "N*m*s/rad", None, "motor viscous friction moving in -x (static law; "
          "default sigma2)"),
    # friction at the load: off | lugre | static, its own parameters (load side)
    Param("friction_L", "-", 0.0, "friction at the load: off | lugre | static (Coulomb, "
          "Stribeck, viscous with stiction)", choices=FRICTION_CHOICES),
    Param("Fc_L", "N*m", 0.0, "load Coulomb friction (+x)", side="load"),
    Param("Fs_L", "N*m", None, "load breakaway (static) friction (+x); default Fc_L",
          side="load"),
    Param("vs_L", "rad/s", 0.0, "load Stribeck velocity (0: Coulomb, no Stribeck curve; LuGre "
          "needs > 0)", side="load"),
    Param("delta_L", "-", 1.0, "load Stribeck exponent"),
    Param("Fv_L", "N*m*s/rad", 0.0, "load viscous friction coefficient (+x)", side="load"),
    Param("Fc_L_neg", "N*m", None, "load Coulomb friction moving in -x; default Fc_L",
          side="load"),
    Param("Fs_L_neg", "N*m", None, "load breakaway friction moving in -x; default Fs_L",
          side="load"),
    Param("Fv_L_neg", "N*m*s/rad", None, "load viscous friction moving in -x; default Fv_L",
          side="load"),
    Param("sigma0_L", "N*m/rad", None, "load LuGre bristle stiffness; default Fc_L/1e-3",
          side="load"),
    Param("sigma1_L", "N*m*s/rad", None, "load LuGre bristle damping; default "
          "2*0.5*sqrt(sigma0_L*JL)", side="load"),
    # controller: the paper's cascade, a described discrete cascade, or none (plant only)
    Param("ctrl", "-", 0.0, "controller: paper (position P, speed PI, current limit; "
          "continuous or sampled at Ts) | discrete (the described cascade dc_*, sampled at Ts) | "
          "none (plant only: the actuation is the run's input signal)", choices=CTRL_CHOICES),
    Param("dc_kp", "1/s", 0.0, "discrete cascade: position gain (velocity command per position "
          "error)"),
    Param("dc_ki", "1/s^2", 0.0, "discrete cascade: position integral gain (0: P)"),
    Param("dc_vmax", "rad/s", math.inf, "discrete cascade: velocity command limit (inf: none)",
          side="load", limit=True),
    Param("dc_kv", "V*s/rad", 0.0, "discrete cascade: velocity gain (command per velocity "
          "error)", side="load"),
    Param("dc_kvi", "V/rad", 0.0, "discrete cascade: velocity integral gain (0: P)",
          side="load"),
    Param("dc_umax", "V", math.inf, "discrete cascade: output limit (inf: none)", limit=True),
    Param("dc_vsrc", "-", 0.0, "discrete cascade velocity source: encoder (a difference of the "
          "position over dc_ndiff samples, after the FIR dc_fir*) | sensor (the motor speed "
          "sensor over the ratio)", choices=VSRC_CHOICES),
    Param("dc_ndiff", "-", 1.0, "discrete cascade: samples the position difference spans "
          f"(1..{MAX_DIFF})"),
    *(Param(f"dc_fir{k}", "-", 1.0 if k == 0 else 0.0, f"discrete cascade: FIR tap {k} on the "
            "measured position before the difference (default: 1, 0, ...: none)",
            nonnegative=False) for k in range(MAX_FIR)),
    Param("dc_vfc", "Hz", 0.0, "discrete cascade: first-order low-pass on the velocity estimate "
          "(0: none)"),
    Param("dc_delay", "-", 0.0, f"computation delay: the command applied this many samples "
          f"after it is computed (0..{MAX_DELAY}; discrete cascade)"),
    Param("dist_out", "-", 0.0, "the run's input signal is a disturbance added to the "
          "controller output (after its limit and delay): 0 no, 1 yes"),
    Param("ext_hold", "-", 0.0, "the input signal is held between its samples (1: a logged DAC "
          "output, constant over each step) or interpolated (0); set from the run's input"),
    Param("plant_input", "-", 0.0, "controller none: the input signal is the drive command "
          "(command), the force (torque) on the load (force) or the armature current (current)",
          choices=PLANT_INPUT_CHOICES),
    # the drive's thermal element (model/thermal.py; actuator drive.thermal): off by default
    Param("thermal", "-", 0.0, "thermal element: winding and housing temperatures as states, "
          "the armature's resistance R(T) = R*(1 + alpha_cu*(T_w - T_ref)): 0 off, 1 on"),
    Param("alpha_cu", "1/K", thermal.ALPHA_CU, "temperature coefficient of the winding's "
          "resistance (copper)"),
    Param("T_ref", "K", thermal.T_REF_C + ZERO_CELSIUS, "temperature at which R is given"),
    Param("T_amb", "K", thermal.T_AMB_C + ZERO_CELSIUS, "ambient temperature"),
    Param("Rth_wh", "K/W", thermal.RTH_WH, "thermal resistance winding-housing"),
    Param("Rth_ha", "K/W", thermal.RTH_HA, "thermal resistance housing-ambient"),
    Param("Cth_w", "J/K", thermal.CTH_W, "heat capacity of the winding"),
    Param("Cth_h", "J/K", thermal.CTH_H, "heat capacity of the housing (stator, frame)"),
    Param("fric_heat", "-", 1.0, "share of the motor's friction losses (bm, the friction law) "
          "heating the housing, 0..1"),
    Param("fe_hyst", "N*m", 0.0, "iron (hysteresis) loss per motor speed: fe_hyst*|w_m| [W] "
          "into the housing"),
    Param("fe_eddy", "N*m*s/rad", 0.0, "iron (eddy-current) loss: fe_eddy*w_m^2 [W] into the "
          "housing"),
    # initial state (default: at rest at 0); a closed-loop fit starts its log segments here
    *(Param(f"x0_{st.name}", st.unit, 0.0, f"initial {st.description}", nonnegative=False,
            side=st.side if st.side == "load" else "") for st in STATES),
)
INITIAL_STATE = tuple(f"x0_{st.name}" for st in STATES)
"""The initial-state parameters, in the order of ``model.states.STATES``."""
FLAGS = ("locked", "rigid", "dist_out", "ext_hold", "thermal")
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

THERMAL_POSITIVE = ("T_ref", "T_amb", "Rth_wh", "Rth_ha", "Cth_w", "Cth_h")
"""The thermal element's parameters that must be > 0 (absolute temperatures, the network)."""
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
        word = value.strip().lower() if isinstance(value, str) else value
        if isinstance(word, str) and word in spec.choices:
            return spec.choices[word]
        if name in ON_OFF_CHOICES and (isinstance(word, bool)
                                       or word in ("on", "true", "off", "false", "none")):
            return 1.0 if word in (True, "on", "true") else 0.0
        if (isinstance(word, int | float) and not isinstance(word, bool)
                and float(word) in spec.choices.values()):
            return float(word)
        words = ", ".join(f"{k} ({v:g})" for k, v in spec.choices.items())
        raise EmaError(f"parameter '{name}' must be one of {words}, got {value!r}")
    if isinstance(value, str) and value.strip().lower() in ("off", "inf", "none", "false"):
        if spec.limit:
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
    if math.isinf(x) and not spec.limit:
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
    rigid = values["rigid"] == 1.0
    amp = values["drive"] == 1.0
    for name in ("m", "Jm", "JL", "L"):
        if (name == "Jm" and rigid) or (name == "L" and amp):
            continue  # a rigid axis lumps the motor's inertia in JL; an amplifier has no L
        if not values[name]:
            raise EmaError(f"parameter '{name}' must be > 0, got {values[name]}")
    if rigid and not values["JL"] + values["m"] ** 2 * values["Jm"] > 0:  # type: ignore[operator]
        raise EmaError("a rigid axis needs a mass (inertia) JL + m^2*Jm > 0")
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
    for name in THERMAL_POSITIVE:
        if not values[name] > 0:  # type: ignore[operator]
            raise EmaError(f"parameter '{name}' must be > 0 ({BY_NAME[name].unit}), got "
                           f"{values[name]}")
    if values["fric_heat"] > 1.0:  # type: ignore[operator]
        raise EmaError(f"parameter 'fric_heat' must lie in [0, 1] (-), got {values['fric_heat']}")
    if values["friction"] == 1.0 and (values["Fc"] <= 0 or values["vs"] <= 0):  # type: ignore[operator]
        raise EmaError("LuGre friction needs Fc > 0 and vs > 0")
    _resolve_description(values)
    return {k: float(v) for k, v in values.items()}  # type: ignore[arg-type]


DEFAULTS_FROM = {"Fc_neg": "Fc", "Fs_neg": "Fs", "sigma2_neg": "sigma2", "Fs_L": "Fc_L",
                 "Fc_L_neg": "Fc_L", "Fs_L_neg": "Fs_L", "Fv_L_neg": "Fv_L"}
"""Parameters whose default is another's value (the - direction's friction the + one's)."""


def _whole(values: Mapping[str, float | None], name: str, lo: int, hi: int, what: str) -> None:
    x = values[name]
    if x is None or x != math.floor(x) or not lo <= x <= hi:
        raise EmaError(f"parameter '{name}' ({what}) must be a whole number in {lo}..{hi}, got "
                       f"{x:g}")


def _resolve_description(values: dict[str, float | None]) -> None:
    """Fill the derived parameters of the actuator description's elements and check that they
    make one actuator (in place)."""
    for name, source in DEFAULTS_FROM.items():
        if values[name] is None:
            values[name] = values[source]
    if values["sigma0_L"] is None:
        values["sigma0_L"] = SIGMA0_PER_FC * values["Fc_L"]  # type: ignore[operator]
    if values["sigma1_L"] is None:
        values["sigma1_L"] = (2.0 * BRISTLE_DAMPING_RATIO
                              * math.sqrt(values["sigma0_L"] * values["JL"]))  # type: ignore[operator]
    v = values
    for site, (fc, fs, fcn, fsn) in (("friction", ("Fc", "Fs", "Fc_neg", "Fs_neg")),
                                     ("friction_L", ("Fc_L", "Fs_L", "Fc_L_neg", "Fs_L_neg"))):
        if v[site] == 2.0:
            for a, b in ((fs, fc), (fsn, fcn)):
                if v[a] < v[b]:  # type: ignore[operator]
                    raise EmaError(f"parameter '{a}' (breakaway friction, {v[a]:g}) must be >= "
                                   f"'{b}' (Coulomb friction, {v[b]:g}) for the static law")
    if v["friction_L"] == 1.0 and (v["Fc_L"] <= 0 or v["vs_L"] <= 0):  # type: ignore[operator]
        raise EmaError("LuGre friction at the load needs Fc_L > 0 and vs_L > 0")
    if v["sigma_t"] is None:
        v["sigma_t"] = v["kL"]
    if v["Fc_t"] > 0.0 and not v["sigma_t"] > 0.0:  # type: ignore[operator]
        raise EmaError(f"parameter 'sigma_t' (transmission friction's Dahl stiffness) must be > 0"
                       f" when Fc_t > 0, got {v['sigma_t']}")
    if v["preload"] > 0.0 and v["alpha"] <= 0.0:  # type: ignore[operator]
        raise EmaError(f"parameter 'preload' ({v['preload']:g} N*m) bridges the backlash: it needs "
                       "a half backlash alpha > 0")
    if v["rigid"] == 1.0 and (v["Fc_t"] > 0.0 or v["preload"] > 0.0):  # type: ignore[operator]
        raise EmaError("transmission friction (Fc_t) and preload need a compliant transmission: a "
                       "rigid axis has no twist")
    if v["rigid"] == 1.0:
        if v["alpha"]:
            raise EmaError(f"parameter 'alpha' (backlash, {v['alpha']:g} rad) needs a compliant "
                           "transmission; a rigid one (rigid = 1) has none")
        if v["locked"]:
            raise EmaError("a locked motor (locked = 1) needs a compliant transmission: on a "
                           "rigid one (rigid = 1) the load is locked too")
    if v["ctrl"] == 1.0:
        if not v["Ts"]:
            raise EmaError("the discrete cascade (ctrl = discrete) needs a sample time Ts > 0 "
                           "(controller.sample_time_s)")
        _whole(v, "dc_ndiff", 1, MAX_DIFF, "samples of the velocity's position difference")
        _whole(v, "dc_delay", 0, MAX_DELAY, "computation delay in samples")
    elif v["dc_delay"]:
        raise EmaError("parameter 'dc_delay' (a computation delay) needs the discrete cascade "
                       "(ctrl = discrete)")


def to_row(values: Mapping[str, float]) -> list[float]:
    """A resolved parameter dict -> one row of the parameter matrix, in table order."""
    return [values[p.name] for p in PARAMS]
