"""Parameters of the reference EMA for the independent generator: defaults copied from
docs/model.md §4 / ``ema_cli/model/params.py`` (numbers only, nothing imported) and the
derived-parameter rules, all SI."""

from __future__ import annotations

import math
from collections.abc import Mapping

DEG = math.pi / 180.0  # one degree [rad]
RPM = 2.0 * math.pi / 60.0  # one rpm [rad/s]

DEFAULTS: dict[str, float] = {
    # armature and motor
    "R": 0.5,  # armature resistance [ohm]
    "L": 0.3e-3,  # armature inductance [H]
    "Kt": 0.08,  # torque constant [N*m/A]
    "Ke": 0.08,  # back-EMF constant [V*s/rad]
    "Jm": 3.0e-5,  # rotor + pinion inertia [kg*m^2]
    "bm": 1.0e-5,  # motor viscous damping [N*m*s/rad]
    # transmission and load (load side)
    "m": 24.0,  # gear ratio, motor angle / load angle [-]
    "JL": 0.01,  # load inertia [kg*m^2]
    "bL": 0.02,  # load bearing viscous damping [N*m*s/rad]
    "kL": 590.0,  # transmission stiffness [N*m/rad]
    "zeta_t": 0.2,  # transmission damping ratio (sets c) [-]
    "alpha": 0.0,  # half backlash [rad]
    "contact_tau": 1.0e-4,  # ramp law: damping ramp-in time [s]
    # controller
    "Kpp": 50.0,  # position P gain [1/s]
    "Kps": 0.15,  # speed PI proportional gain [V*s/rad]
    "Kis": 1.5,  # speed PI integral gain [V/rad]
    # saturations
    "sat1": 800.0 * DEG,  # load-speed command limit [rad/s]
    "sat2": 40.0,  # voltage demand limit [V]
    "sat3": 6.07 * 5.0,  # current limit [A]
    # dead zones (half-widths)
    "d1": 0.0,  # amplifier input [V]
    "d3": 0.0,  # speed sensor [rad/s]
    "d4": 0.0,  # position sensor [rad]
    # LuGre friction at the motor shaft (on in every log of this generator)
    "Fc": 0.02,  # Coulomb friction [N*m]
    "vs": 1.0,  # Stribeck velocity [rad/s]
    "delta": 1.0,  # Stribeck exponent [-]
    "sigma2": 0.0,  # viscous friction [N*m*s/rad]
}
"""The model's defaults (``ema params``), SI. Derived unless given: c, Fs, sigma0, sigma1."""

FS_PER_FC = 1.5  # static / Coulomb friction [-]
SIGMA0_PER_FC = 1.0e3  # bristle stiffness per N*m of Coulomb friction [1/rad]
BRISTLE_DAMPING_RATIO = 0.5  # sigma1 = 2*ratio*sqrt(sigma0*Jm) [-]
DERIVED = ("c", "Fs", "sigma0", "sigma1")


def equivalent_inertia(p: Mapping[str, float]) -> float:
    """Load-side equivalent inertia Jeq = Jm*m^2*JL/(Jm*m^2 + JL) [kg*m^2]."""
    jm = p["Jm"] * p["m"] ** 2
    return jm * p["JL"] / (jm + p["JL"])


def resolve(overrides: Mapping[str, float] | None = None) -> dict[str, float]:
    """Defaults + ``overrides`` (SI) -> every parameter, the derived ones filled in unless given:
    c = 2*zeta_t*sqrt(kL*Jeq) [N*m*s/rad], Fs = 1.5*Fc, sigma0 = 1e3*Fc [N*m/rad],
    sigma1 = 2*0.5*sqrt(sigma0*Jm) [N*m*s/rad]."""
    over = dict(overrides or {})
    unknown = sorted(set(over) - set(DEFAULTS) - set(DERIVED))
    if unknown:
        raise ValueError(f"unknown parameter(s) {unknown}; expected {sorted(DEFAULTS)} or "
                         f"{list(DERIVED)}")
    p = {**DEFAULTS, **{k: float(v) for k, v in over.items() if k in DEFAULTS}}
    if p["Fc"] <= 0 or p["vs"] <= 0:
        raise ValueError(f"LuGre friction needs Fc > 0 and vs > 0, got Fc={p['Fc']}, "
                         f"vs={p['vs']}")
    p["Fs"] = float(over.get("Fs", FS_PER_FC * p["Fc"]))
    p["sigma0"] = float(over.get("sigma0", SIGMA0_PER_FC * p["Fc"]))
    p["sigma1"] = float(over.get("sigma1", 2.0 * BRISTLE_DAMPING_RATIO
                                 * math.sqrt(p["sigma0"] * p["Jm"])))
    p["c"] = float(over.get("c", 2.0 * p["zeta_t"] * math.sqrt(p["kL"] * equivalent_inertia(p))))
    return p
