"""The actuator description (config section ``actuator``): your actuator, not only the paper's.

A description names the axis (rotary or translational), the transmission (compliant or rigid,
backlash), the motor and load, the drive (armature or current/force amplifier), the friction at
the motor and at the load (Coulomb, Stribeck, LuGre, per direction), a constant offset, the
controller (the paper's cascade, a described discrete cascade, or none: the actuation is a
measured input) and where the run's input signal enters. It compiles to SI overrides of the
parameter table (:meth:`Actuator.params`), which every command runs.

Values are numbers in the axis's SI units (rad, N*m, kg*m^2 on a rotary axis; m, N, kg on a
translational one) or strings with a unit, ``"12 mm"``, ``"590 N*m/rad"``: a unit of the other
axis is refused (``ema_cli.units.parse_quantity``). Motor-side and electrical values are always
rotary or axis-free (``"3e-5 kg*m^2"``, ``"0.3 mH"``). docs/model.md §3 gives every element's
equations.
"""

from __future__ import annotations

import math
from typing import Any, Literal

from pydantic import Field, model_validator

from ema_cli.config.base import NonNegFloat, PositiveFloat, Strict
from ema_cli.config.thermal import Thermal
from ema_cli.model.params import MAX_DELAY, MAX_DIFF, MAX_FIR
from ema_cli.units import AXES, ROTARY, TRANSLATIONAL, parse_quantity

Q = float | int | str
"""A value: a number (SI of the axis) or ``"<number> <unit>"``."""
KEY = "\x00"  # wraps a key path at the start of a message (config.run.KEY_MARK)


def _q(value: Any, kind: str, axis: str | None, key: str) -> float:
    """A value of ``kind`` -> SI, or a ValueError naming ``key``."""
    try:
        return parse_quantity(value, kind, axis)
    except ValueError as exc:
        raise ValueError(f"{KEY}{key}{KEY}{exc}") from None


class Ratio(Strict):
    """The transmission ratio: motor angle per unit of load travel. Give one."""

    gear: PositiveFloat | None = Field(
        None, description="rotary: gear ratio, motor angle / load angle [-]")
    screw_lead: Q | None = Field(
        None, description="translational: load travel per motor revolution, e.g. '10 mm' "
                          "(ratio 2*pi/lead rad/m)")
    value: Q | None = Field(
        None, description="the ratio itself: [-] rotary, rad/m translational")

    @model_validator(mode="after")
    def _one(self) -> Ratio:
        given = [k for k in ("gear", "screw_lead", "value") if getattr(self, k) is not None]
        if len(given) != 1:
            raise ValueError(f"give one of gear, screw_lead, value (got {given or 'none'})")
        return self


class Transmission(Strict):
    """Between the motor and the load: compliant (a spring, damping, backlash) or rigid."""

    type: Literal["compliant", "rigid"] = Field(
        "compliant", description="compliant: two masses and a shaft; rigid: one mass")
    stiffness: Q | None = Field(None, description="shaft stiffness, load side [N*m/rad | N/m]")
    damping: Q | None = Field(None, description="shaft damping, load side [N*m*s/rad | N*s/m] "
                                                 "(default from damping_ratio)")
    damping_ratio: NonNegFloat | None = Field(
        None, description="shaft damping ratio (sets damping when it is not given) [-]")
    backlash: Q | None = Field(None, description="half backlash, load side [rad | m], e.g. "
                                                  "'0.01 deg', '20 um'")
    contact: Literal["contact", "paper"] | None = Field(
        None, description="damping form in the backlash: contact (pushes, never pulls) or "
                          "paper (Eq. 2 literally)")
    friction: Q | None = Field(
        None, description="friction inside the transmission, load side [N*m | N]: a Dahl "
                          "element in parallel with the shaft, the half height of the "
                          "torque-twist loop (the hysteresis of a real gearbox)")
    friction_stiffness: Q | None = Field(
        None, description="the transmission friction's Dahl stiffness, the loop's slope just "
                          "after a reversal [N*m/rad | N/m] (default: the stiffness)")
    preload: Q | None = Field(
        None, description="anti-backlash preload, load side [N*m | N]: inside the backlash the "
                          "torque rises linearly from -preload to +preload (needs backlash)")


class Motor(Strict):
    """The motor's rotor (motor side, always rotary)."""

    inertia: Q | None = Field(None, description="rotor inertia [kg*m^2] (a rigid axis may lump "
                                                 "it in the load's: 0)")
    viscous: Q | None = Field(None, description="rotor viscous damping [N*m*s/rad]")


class Load(Strict):
    """The load: its inertia (rotary) or mass (translational), bearing damping, external
    forces."""

    inertia: Q | None = Field(None, description="rotary: load inertia [kg*m^2]")
    mass: Q | None = Field(None, description="translational: moving mass [kg]")
    viscous: Q | None = Field(None, description="bearing viscous damping [N*m*s/rad | N*s/m]")
    offset: Q | None = Field(None, description="constant force opposing +x (gravity, bias; "
                                                "EMPS's OF) [N*m | N]")
    force: Q | None = Field(None, description="constant external force along +x [N*m | N]")
    spring: Q | None = Field(None, description="external spring (hinge gradient): force "
                                                "-spring*x [N*m/rad | N/m]")


class Drive(Strict):
    """The drive: an armature (voltage in) or a current/force amplifier (command in)."""

    type: Literal["armature", "amplifier"] = Field("armature", description="drive type")
    resistance: Q | None = Field(None, description="armature: resistance [ohm]")
    inductance: Q | None = Field(None, description="armature: inductance [H]")
    torque_constant: Q | None = Field(None, description="torque constant [N*m/A]")
    emf_constant: Q | None = Field(None, description="armature: back-EMF constant [V*s/rad]")
    current_limit: Q | Literal["off"] | None = Field(
        None, description="armature: current limit [A] or off")
    gain: Q | None = Field(None, description="amplifier: force (torque) on the axis per unit of "
                                              "command, transmission included [N/V | N*m/V]")
    limit: Q | Literal["off"] | None = Field(
        None, description="amplifier: output limit, load side [N | N*m] or off")
    bandwidth_hz: PositiveFloat | None = Field(
        None, description="amplifier: first-order bandwidth [Hz] (absent: instantaneous)")
    thermal: Thermal | None = Field(
        None, description="the thermal element (config/thermal.py): winding and housing "
                          "temperatures, R(T); absent: none in the simulation")


class FrictionNegative(Strict):
    """The law's values moving in -x (absent: the + direction's)."""

    coulomb: Q | None = None
    static: Q | None = None
    viscous: Q | None = None


class FrictionSite(Strict):
    """Friction at one site (docs/model.md §3): none, Coulomb (+ viscous, with stiction), a
    Stribeck curve, or LuGre."""

    law: Literal["none", "coulomb", "stribeck", "lugre"] = Field("none", description="law")
    coulomb: Q | None = Field(None, description="Coulomb level [N*m | N] (+x)")
    static: Q | None = Field(None, description="breakaway (static) level, >= coulomb [N*m | N] "
                                                "(default: coulomb, no stiction peak)")
    stribeck_velocity: Q | None = Field(
        None, description="Stribeck velocity [rad/s | m/s] (stribeck, lugre)")
    exponent: PositiveFloat | None = Field(None, description="Stribeck exponent [-]")
    viscous: Q | None = Field(None, description="viscous coefficient [N*m*s/rad | N*s/m]")
    bristle_stiffness: Q | None = Field(None, description="lugre: sigma0 [N*m/rad | N/m]")
    bristle_damping: Q | None = Field(None, description="lugre: sigma1 [N*m*s/rad | N*s/m]")
    negative: FrictionNegative | None = Field(
        None, description="the values moving in -x when they differ (static laws)")


class Friction(Strict):
    """Friction at the motor shaft (motor units) and at the load (the axis's units)."""

    motor: FrictionSite = Field(default_factory=FrictionSite)
    load: FrictionSite = Field(default_factory=FrictionSite)


class PositionLoop(Strict):
    kp: Q = Field(0.0, description="position gain: velocity command per position error [1/s]")
    ki: Q = Field(0.0, description="position integral gain [1/s^2] (0: P)")
    limit: Q | Literal["off"] = Field("off", description="velocity command limit "
                                                         "[rad/s | m/s] or off")


class VelocityLoop(Strict):
    kv: Q = Field(0.0, description="velocity gain: command per velocity error "
                                   "[V*s/rad | V*s/m]")
    ki: Q = Field(0.0, description="velocity integral gain [V/rad | V/m] (0: P)")


class Controller(Strict):
    """The controller: the paper's cascade (position P, speed PI on the motor speed, current
    limit; the run config's ``controller`` section sets its options), a described discrete
    cascade, or none (plant only: the run's input signal is the actuation)."""

    type: Literal["paper", "discrete", "none"] = Field("paper", description="controller")
    sample_time_s: PositiveFloat | None = Field(
        None, description="sample time [s] (discrete: required; paper: digital)")
    position: PositionLoop = Field(default_factory=PositionLoop)
    velocity: VelocityLoop = Field(default_factory=VelocityLoop)
    output_limit: Q | Literal["off"] = Field("off", description="command limit [V] or off")
    velocity_source: Literal["encoder", "sensor"] = Field(
        "encoder", description="encoder: a difference of the measured position; sensor: the "
                               "motor speed sensor over the ratio")
    difference_samples: int = Field(
        1, ge=1, le=MAX_DIFF, description=f"samples the position difference spans (1..{MAX_DIFF})")
    fir: list[float] = Field(
        default_factory=lambda: [1.0], min_length=1, max_length=MAX_FIR,
        description=f"FIR taps on the position before the difference (at most {MAX_FIR}); "
                    "EMPS: [0.5, 0.5]")
    velocity_filter_hz: NonNegFloat = Field(
        0.0, description="first-order low-pass on the velocity estimate [Hz] (0: none)")
    delay_samples: int = Field(
        0, ge=0, le=MAX_DELAY, description=f"computation delay (0..{MAX_DELAY} samples): the "
                                           "command applied this many samples late")
    input: Literal["command", "force", "current"] = Field(
        "command", description="controller none: what the input signal is (the drive's "
                               "command, the force on the axis, the armature current)")


class Sensors(Strict):
    """Sensor quantisation (absent: ideal)."""

    position_quantum: Q | None = Field(None, description="position sensor step [rad | m]")
    speed_quantum: Q | None = Field(None, description="motor speed sensor step [rad/s]")


class Actuator(Strict):
    """An actuator description: every element in the axis's units (module docstring)."""

    name: str = Field("", description="the actuator's name (reports, titles)")
    description: str = Field("", description="what it is, where its values come from")
    axis: Literal["rotary", "translational"] = Field("rotary", description="rotary | "
                                                                          "translational")
    ratio: Ratio | None = Field(None, description="motor angle per unit of load travel")
    transmission: Transmission = Field(default_factory=Transmission)
    motor: Motor = Field(default_factory=Motor)
    load: Load = Field(default_factory=Load)
    drive: Drive = Field(default_factory=Drive)
    friction: Friction = Field(default_factory=Friction)
    controller: Controller = Field(default_factory=Controller)
    sensors: Sensors = Field(default_factory=Sensors)
    disturbance: Literal["none", "output"] = Field(
        "none", description="output: the run's input signal is added to the controller's "
                            "output (after its limit and delay)")

    @model_validator(mode="after")
    def _compiles(self) -> Actuator:
        self.params()  # every unit and combination checked once, here
        return self

    # ---- the compiled parameters ------------------------------------------------------------
    def params(self) -> dict[str, float | str]:
        """The SI overrides of ``model.params`` this description sets (values it leaves out
        keep the parameter table's defaults)."""
        a = self.axis
        out: dict[str, float | str] = {}

        def put(name: str, value: Any, kind: str, key: str, axis: str | None = a) -> None:
            if value is not None:
                out[name] = _q(value, kind, axis, key)

        if self.ratio is not None:
            r = self.ratio
            if r.gear is not None:
                if a == TRANSLATIONAL:
                    raise ValueError(f"{KEY}ratio.gear{KEY}a translational axis gives "
                                     "screw_lead (load travel per motor revolution)")
                out["m"] = float(r.gear)
            elif r.screw_lead is not None:
                if a == ROTARY:
                    raise ValueError(f"{KEY}ratio.screw_lead{KEY}a rotary axis gives gear "
                                     "(motor angle / load angle)")
                lead = _q(r.screw_lead, "position", TRANSLATIONAL, "ratio.screw_lead")
                if not lead > 0:
                    raise ValueError(f"{KEY}ratio.screw_lead{KEY}must be > 0, got {lead:g} m")
                out["m"] = 2.0 * math.pi / lead
            else:
                out["m"] = _q(r.value, "ratio", a, "ratio.value")
                if not out["m"] > 0:
                    raise ValueError(f"{KEY}ratio.value{KEY}must be > 0")
        elif a == TRANSLATIONAL:
            out["m"] = 1.0  # the motor in load coordinates (a rigid axis lumps it: EMPS)
        t = self.transmission
        if t.type == "rigid":
            out["rigid"] = 1.0
            for k in ("stiffness", "damping", "damping_ratio", "backlash", "contact",
                      "friction", "friction_stiffness", "preload"):
                if getattr(t, k) is not None:
                    raise ValueError(f"{KEY}transmission.{k}{KEY}a rigid transmission has no "
                                     f"{k.replace('_', ' ')} (type: compliant has)")
        else:
            put("kL", t.stiffness, "stiffness", "transmission.stiffness")
            put("c", t.damping, "damping", "transmission.damping")
            if t.damping_ratio is not None:
                out["zeta_t"] = float(t.damping_ratio)
            put("alpha", t.backlash, "position", "transmission.backlash")
            if t.contact is not None:
                out["damping"] = t.contact
            put("Fc_t", t.friction, "force", "transmission.friction")
            put("sigma_t", t.friction_stiffness, "stiffness", "transmission.friction_stiffness")
            put("preload", t.preload, "force", "transmission.preload")
            if t.preload is not None and t.backlash is None and out.get("preload", 0.0) > 0.0:
                raise ValueError(f"{KEY}transmission.preload{KEY}a preload bridges the backlash: "
                                 "give transmission.backlash > 0")
        put("Jm", self.motor.inertia, "inertia", "motor.inertia", None)
        put("bm", self.motor.viscous, "damping", "motor.viscous", None)
        ld = self.load
        if a == ROTARY and ld.mass is not None:
            raise ValueError(f"{KEY}load.mass{KEY}a rotary axis has an inertia (load.inertia, "
                             "kg*m^2), not a mass")
        if a == TRANSLATIONAL and ld.inertia is not None:
            raise ValueError(f"{KEY}load.inertia{KEY}a translational axis has a mass "
                             "(load.mass, kg), not an inertia")
        put("JL", ld.inertia if a == ROTARY else ld.mass, "mass",
            "load.inertia" if a == ROTARY else "load.mass")
        put("bL", ld.viscous, "damping", "load.viscous")
        put("offset", ld.offset, "force", "load.offset")
        put("T_load", ld.force, "force", "load.force")
        put("k_h", ld.spring, "stiffness", "load.spring")
        self._drive(out)
        self._friction(out, "motor", self.friction.motor)
        self._friction(out, "load", self.friction.load)
        self._controller(out)
        s = self.sensors
        put("q_pos", s.position_quantum, "position", "sensors.position_quantum")
        put("q_speed", s.speed_quantum, "speed", "sensors.speed_quantum", None)
        if self.disturbance == "output":
            if self.controller.type == "none":
                raise ValueError(f"{KEY}disturbance{KEY}with controller none the input signal "
                                 "is the actuation itself, not a disturbance")
            out["dist_out"] = 1.0
        for name, v in out.items():  # lengths, masses, gains: none negative but the offset
            if isinstance(v, float) and v < 0 and name not in ("offset", "T_load", "k_h"):
                raise ValueError(f"{KEY}{_KEY_OF.get(name, name)}{KEY}must be >= 0, got {v:g}")
        positive = ["JL", "amp_gain", "L", "m"] + ([] if t.type == "rigid" else ["Jm"])
        for name in positive:
            if name in out and not out[name] > 0:  # type: ignore[operator]
                key = ("load.mass" if a == TRANSLATIONAL else "load.inertia") if name == "JL" \
                    else _KEY_OF.get(name, name)
                raise ValueError(f"{KEY}{key}{KEY}must be > 0, got {out[name]:g}")
        return out

    def _drive(self, out: dict[str, float | str]) -> None:
        d, a = self.drive, self.axis
        if d.thermal is not None:
            out.update(d.thermal.params(d.type))
        if d.type == "armature":
            for k in ("gain", "limit", "bandwidth_hz"):
                if getattr(d, k) is not None:
                    raise ValueError(f"{KEY}drive.{k}{KEY}is an amplifier's (drive.type: "
                                     "amplifier); an armature has resistance, inductance, "
                                     "torque_constant, emf_constant, current_limit")
            for k, name, kind in (("resistance", "R", "resistance"),
                                  ("inductance", "L", "inductance"),
                                  ("torque_constant", "Kt", "torque_constant"),
                                  ("emf_constant", "Ke", "emf_constant")):
                if getattr(d, k) is not None:
                    out[name] = _q(getattr(d, k), kind, None, f"drive.{k}")
            if d.current_limit is not None:
                out["sat3"] = (math.inf if d.current_limit == "off"
                               else _q(d.current_limit, "current", None, "drive.current_limit"))
            return
        out["drive"] = "amplifier"
        for k in ("resistance", "inductance", "emf_constant", "current_limit"):
            if getattr(d, k) is not None:
                raise ValueError(f"{KEY}drive.{k}{KEY}is an armature's (drive.type: armature); "
                                 "an amplifier has gain, limit, bandwidth_hz")
        if d.gain is None:
            raise ValueError(f"{KEY}drive.gain{KEY}an amplifier needs its gain (force on the "
                             "axis per unit of command, e.g. '35.15 N/V')")
        out["amp_gain"] = _q(d.gain, "gain", a, "drive.gain")
        if d.limit is not None:
            out["amp_limit"] = (math.inf if d.limit == "off"
                                else _q(d.limit, "force", a, "drive.limit"))
        if d.bandwidth_hz is not None:
            out["amp_tau"] = 1.0 / (2.0 * math.pi * d.bandwidth_hz)
        # the current the drive's torque stands for (T/Kt) is known only with a torque constant
        out["Kt"] = (_q(d.torque_constant, "torque_constant", None, "drive.torque_constant")
                     if d.torque_constant is not None else 0.0)

    def _friction(self, out: dict[str, float | str], site: str, f: FrictionSite) -> None:
        motor = site == "motor"
        axis = None if motor else self.axis
        kf, kv, kd = ("torque", "speed", "damping") if motor else ("force", "velocity",
                                                                     "damping")
        names = (("friction", "Fc", "Fs", "vs", "delta", "sigma2", "sigma0", "sigma1", "Fc_neg",
                  "Fs_neg", "sigma2_neg") if motor else
                 ("friction_L", "Fc_L", "Fs_L", "vs_L", "delta_L", "Fv_L", "sigma0_L",
                  "sigma1_L", "Fc_L_neg", "Fs_L_neg", "Fv_L_neg"))
        (law, fc, fs, vs, delta, fv, s0, s1, fcn, fsn, fvn) = names
        key = f"friction.{site}"
        if f.law == "none":
            given = [k for k in FrictionSite.model_fields if k != "law"
                     and getattr(f, k) is not None]
            if given:
                raise ValueError(f"{KEY}{key}.{given[0]}{KEY}needs a law (coulomb, stribeck, "
                                 "lugre)")
            return
        if f.coulomb is None:
            raise ValueError(f"{KEY}{key}.coulomb{KEY}the {f.law} law needs its Coulomb level")
        out[law] = "lugre" if f.law == "lugre" else "static"
        for k in ("coulomb", "static", "viscous", "bristle_stiffness", "bristle_damping"):
            v = getattr(f, k)
            if v is not None and _q(v, "stiffness" if k == "bristle_stiffness" else
                                    ("damping" if k in ("viscous", "bristle_damping") else kf),
                                    (self.axis if not motor else ROTARY)
                                    if k.startswith("bristle") else axis, f"{key}.{k}") < 0:
                raise ValueError(f"{KEY}{key}.{k}{KEY}must be >= 0, got {v}")
        c = _q(f.coulomb, kf, axis, f"{key}.coulomb")
        out[fc] = c
        out[fs] = _q(f.static, kf, axis, f"{key}.static") if f.static is not None else c
        if f.law != "lugre" and out[fs] < c:  # type: ignore[operator]
            raise ValueError(f"{KEY}{key}.static{KEY}the breakaway level ({f.static}) must be "
                             f">= the Coulomb level ({f.coulomb})")
        if f.law == "coulomb":
            for k in ("stribeck_velocity", "exponent", "bristle_stiffness", "bristle_damping"):
                if getattr(f, k) is not None:
                    raise ValueError(f"{KEY}{key}.{k}{KEY}the coulomb law has none (stribeck "
                                     "or lugre have)")
            out[vs] = 0.0
        else:
            if f.stribeck_velocity is None:
                raise ValueError(f"{KEY}{key}.stribeck_velocity{KEY}the {f.law} law needs it")
            out[vs] = _q(f.stribeck_velocity, kv, axis, f"{key}.stribeck_velocity")
            if not out[vs] > 0:  # type: ignore[operator]
                raise ValueError(f"{KEY}{key}.stribeck_velocity{KEY}must be > 0")
            if f.exponent is not None:
                out[delta] = float(f.exponent)
        if f.viscous is not None:
            out[fv] = _q(f.viscous, kd, axis, f"{key}.viscous")
        if f.law == "lugre":
            if f.negative is not None:
                raise ValueError(f"{KEY}{key}.negative{KEY}the LuGre law is symmetric (a "
                                 "static law, coulomb or stribeck, has per-direction values)")
            if f.bristle_stiffness is not None:
                out[s0] = _q(f.bristle_stiffness, "stiffness", self.axis if not motor
                             else ROTARY, f"{key}.bristle_stiffness")
            elif not motor and self.axis == TRANSLATIONAL:
                out[s0] = c / PRESLIDING_M  # 1 um of pre-sliding, not 1 mm
            if f.bristle_damping is not None:
                out[s1] = _q(f.bristle_damping, "damping", self.axis if not motor else ROTARY,
                             f"{key}.bristle_damping")
        elif f.bristle_stiffness is not None or f.bristle_damping is not None:
            raise ValueError(f"{KEY}{key}.bristle_stiffness{KEY}only the lugre law has "
                             "bristles")
        if f.negative is not None:
            n = f.negative
            for k in ("coulomb", "static", "viscous"):
                v = getattr(n, k)
                if v is not None and _q(v, kd if k == "viscous" else kf, axis,
                                        f"{key}.negative.{k}") < 0:
                    raise ValueError(f"{KEY}{key}.negative.{k}{KEY}must be >= 0 (the magnitude "
                                     f"moving in -x), got {v}")
            if n.coulomb is not None:
                out[fcn] = _q(n.coulomb, kf, axis, f"{key}.negative.coulomb")
            if n.static is not None:
                out[fsn] = _q(n.static, kf, axis, f"{key}.negative.static")
            elif n.coulomb is not None and f.static is None:
                out[fsn] = out[fcn]
            if n.viscous is not None:
                out[fvn] = _q(n.viscous, kd, axis, f"{key}.negative.viscous")

    def _controller(self, out: dict[str, float | str]) -> None:
        c, a = self.controller, self.axis
        if c.sample_time_s is not None:
            out["Ts"] = float(c.sample_time_s)
        if c.type == "paper":
            return
        if c.type == "none":
            out["ctrl"] = "none"
            out["plant_input"] = c.input
            return
        out["ctrl"] = "discrete"
        if c.sample_time_s is None:
            raise ValueError(f"{KEY}controller.sample_time_s{KEY}the discrete cascade needs "
                             "its sample time")
        out["dc_kp"] = _q(c.position.kp, "rate", None, "controller.position.kp")
        out["dc_ki"] = _q(c.position.ki, "rate2", None, "controller.position.ki")
        out["dc_vmax"] = (math.inf if c.position.limit == "off" else
                          _q(c.position.limit, "velocity", a, "controller.position.limit"))
        out["dc_kv"] = _q(c.velocity.kv, "velocity_gain", a, "controller.velocity.kv")
        out["dc_kvi"] = _q(c.velocity.ki, "position_gain_i", a, "controller.velocity.ki")
        out["dc_umax"] = (math.inf if c.output_limit == "off" else
                          _q(c.output_limit, "command", None, "controller.output_limit"))
        out["dc_vsrc"] = c.velocity_source
        out["dc_ndiff"] = float(c.difference_samples)
        for k in range(MAX_FIR):
            out[f"dc_fir{k}"] = float(c.fir[k]) if k < len(c.fir) else 0.0
        if abs(sum(c.fir) - 1.0) > 1e-9:
            raise ValueError(f"{KEY}controller.fir{KEY}the taps must sum to 1 (a filter of the "
                             f"position, unit gain at rest), got {sum(c.fir):g}")
        out["dc_vfc"] = float(c.velocity_filter_hz)
        out["dc_delay"] = float(c.delay_samples)


PRESLIDING_M = 1e-6  # a translational load's LuGre default: sigma0 = Fc/this [m]
_KEY_OF = {"m": "ratio", "kL": "transmission.stiffness", "c": "transmission.damping",
           "alpha": "transmission.backlash", "Jm": "motor.inertia", "bm": "motor.viscous",
           "JL": "load.inertia or load.mass", "bL": "load.viscous", "amp_gain": "drive.gain",
           "amp_limit": "drive.limit", "R": "drive.resistance", "L": "drive.inductance",
           "Kt": "drive.torque_constant", "Ke": "drive.emf_constant",
           "Fc_t": "transmission.friction", "sigma_t": "transmission.friction_stiffness",
           "preload": "transmission.preload"}
"""The description key a parameter comes from (for messages)."""
AXIS_NAMES = AXES
