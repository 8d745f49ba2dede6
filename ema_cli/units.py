"""Unit conversions between SI (inside the code) and the paper's units (configs, CSVs, plots)."""

import math
from typing import Any

DEG = math.pi / 180.0
"""One degree in radians."""
RPM = 2.0 * math.pi / 60.0
"""One revolution per minute in rad/s."""


def deg_to_rad(x: float) -> float:
    """Degrees -> radians."""
    return x * DEG


def rad_to_deg(x):
    """Radians -> degrees (works on floats and arrays)."""
    return x / DEG


def rpm_to_rad_s(x: float) -> float:
    """rpm -> rad/s."""
    return x * RPM


def rad_s_to_rpm(x):
    """rad/s -> rpm (works on floats and arrays)."""
    return x / RPM


# Units a user may write at the edges (acceptance limits): name -> (dimension, SI per unit).
# SI dimensions: time s, angle rad, frequency Hz, rate rad/s, stiffness N*m/rad, current A,
# torque N*m, voltage V; percent and dB are their own.
UNITS: dict[str, tuple[str, float]] = {
    "s": ("time", 1.0), "ms": ("time", 1e-3),
    "rad": ("angle", 1.0), "mrad": ("angle", 1e-3), "deg": ("angle", DEG),
    "arcmin": ("angle", DEG / 60.0), "arcsec": ("angle", DEG / 3600.0),
    "Hz": ("frequency", 1.0),
    "rad/s": ("rate", 1.0), "deg/s": ("rate", DEG), "rpm": ("rate", RPM),
    "N*m/rad": ("stiffness", 1.0), "N*m/deg": ("stiffness", 1.0 / DEG),
    "kN*m/rad": ("stiffness", 1e3),
    "A": ("current", 1.0), "N*m": ("torque", 1.0), "V": ("voltage", 1.0),
    "%": ("percent", 1.0), "dB": ("decibel", 1.0),
}
SI_UNIT = {"time": "s", "angle": "rad", "frequency": "Hz", "rate": "rad/s",
           "stiffness": "N*m/rad", "current": "A", "torque": "N*m", "voltage": "V",
           "percent": "%", "decibel": "dB"}
"""The SI (internal) unit of each dimension."""


LOG_UNITS: dict[str, dict[str, tuple[float, float]]] = {
    "time": {"s": (1.0, 1.0), "ms": (1.0, 1e3), "us": (1.0, 1e6)},
    "angle": {"deg": (DEG, 1.0), "rad": (1.0, 1.0), "mrad": (1.0, 1e3)},
    "speed": {"rpm": (RPM, 1.0), "rad/s": (1.0, 1.0), "deg/s": (DEG, 1.0)},
    "current": {"A": (1.0, 1.0), "mA": (1.0, 1e3)},
    "voltage": {"V": (1.0, 1.0), "mV": (1.0, 1e3)},
    "length": {"m": (1.0, 1.0), "mm": (1.0, 1e3), "um": (1.0, 1e6)},
    "force": {"N": (1.0, 1.0), "kN": (1e3, 1.0), "N*m": (1.0, 1.0)},
}
"""Units of a log column (``ema identify --columns CHANNEL=COLUMN:UNIT``): kind -> unit ->
(factor, divisor), SI = value * factor / divisor. The decimal prefixes divide by an exact
integer, so 1500 ms is exactly 1.5 s (a product with 1e-3 would round twice)."""


def log_to_si(values: Any, unit: str, kind: str) -> Any:
    """Log values in ``unit`` (a unit of ``kind`` in :data:`LOG_UNITS`) -> SI (floats or
    arrays); a factor or divisor of 1 leaves the values bit for bit."""
    factor, divisor = LOG_UNITS[kind][unit]
    if factor != 1.0:
        values = values * factor
    if divisor != 1.0:
        values = values / divisor
    return values


def units_of(dimension: str) -> list[str]:
    """The unit names of one dimension."""
    return [u for u, (d, _) in UNITS.items() if d == dimension]


def to_si(value: float, unit: str) -> float:
    """``value`` in ``unit`` (a key of :data:`UNITS`) -> SI."""
    return value * UNITS[unit][1]


def from_si(value: float, unit: str) -> float:
    """An SI value -> ``unit`` (a key of :data:`UNITS`)."""
    return value / UNITS[unit][1]


def fmt_num(value: float | int | str | None, unit: str = "", digits: int = 4, *,
            nan: str = "n/a", inf: str | None = None, neg_inf: str | None = None,
            none: str = "n/a") -> str:
    """One number as the console prints it: ``digits`` significant digits and its unit
    (``"12.3 dB"``), or a word for what a non-finite value means (``nan``: not measured or not
    reached, ``inf``/``neg_inf``: e.g. "no phase crossover"; both default to the signed
    infinity sign with the unit). Strings pass through unchanged; ``None`` -> ``none``."""
    if value is None:
        return none
    if isinstance(value, str):
        return value
    v = float(value)
    if math.isnan(v):
        return nan
    if math.isinf(v):
        word = inf if v > 0 else neg_inf
        if word is not None:
            return word
        text = "inf" if v > 0 else "-inf"
    else:
        text = f"{v:.{digits}g}"
    return f"{text} {unit}" if unit and unit != "-" else text


# ---- quantities of an actuator description (config section `actuator`) ---------------------
ROTARY, TRANSLATIONAL = "rotary", "translational"
AXES = (ROTARY, TRANSLATIONAL)
QUANTITY_UNITS: dict[str, dict[str, tuple[float, str]]] = {
    "position": {"rad": (1.0, ROTARY), "mrad": (1e-3, ROTARY), "deg": (DEG, ROTARY),
                 "arcmin": (DEG / 60.0, ROTARY), "m": (1.0, TRANSLATIONAL),
                 "mm": (1e-3, TRANSLATIONAL), "um": (1e-6, TRANSLATIONAL)},
    "velocity": {"rad/s": (1.0, ROTARY), "deg/s": (DEG, ROTARY), "rpm": (RPM, ROTARY),
                 "m/s": (1.0, TRANSLATIONAL), "mm/s": (1e-3, TRANSLATIONAL)},
    "force": {"N*m": (1.0, ROTARY), "mN*m": (1e-3, ROTARY), "N": (1.0, TRANSLATIONAL),
              "kN": (1e3, TRANSLATIONAL)},
    "mass": {"kg*m^2": (1.0, ROTARY), "g*cm^2": (1e-7, ROTARY), "kg": (1.0, TRANSLATIONAL),
             "g": (1e-3, TRANSLATIONAL)},
    "stiffness": {"N*m/rad": (1.0, ROTARY), "N*m/deg": (1.0 / DEG, ROTARY),
                  "kN*m/rad": (1e3, ROTARY), "N/m": (1.0, TRANSLATIONAL),
                  "N/mm": (1e3, TRANSLATIONAL), "N/um": (1e6, TRANSLATIONAL)},
    "damping": {"N*m*s/rad": (1.0, ROTARY), "N*s/m": (1.0, TRANSLATIONAL)},
    "gain": {"N*m/V": (1.0, ROTARY), "N/V": (1.0, TRANSLATIONAL), "N*m/A": (1.0, ROTARY),
             "N/A": (1.0, TRANSLATIONAL)},
    "velocity_gain": {"V*s/rad": (1.0, ROTARY), "V*s/m": (1.0, TRANSLATIONAL),
                      "V*s/mm": (1e3, TRANSLATIONAL)},
    "position_gain_i": {"V/rad": (1.0, ROTARY), "V/m": (1.0, TRANSLATIONAL)},
    "ratio": {"-": (1.0, ROTARY), "rad/m": (1.0, TRANSLATIONAL)},
}
"""Units of the load-side quantities of an actuator description, by kind: unit -> (SI factor of
the axis, the axis it belongs to). A value of the other axis's domain is refused."""
MOTOR_UNITS: dict[str, dict[str, float]] = {
    "inertia": {"kg*m^2": 1.0, "g*cm^2": 1e-7},
    "damping": {"N*m*s/rad": 1.0},
    "torque": {"N*m": 1.0, "mN*m": 1e-3},
    "torque_constant": {"N*m/A": 1.0},
    "emf_constant": {"V*s/rad": 1.0, "V/krpm": 1.0 / (1000.0 * RPM)},
    "resistance": {"ohm": 1.0, "mohm": 1e-3},
    "inductance": {"H": 1.0, "mH": 1e-3, "uH": 1e-6},
    "current": {"A": 1.0},
    "voltage": {"V": 1.0},
    "time": {"s": 1.0, "ms": 1e-3},
    "frequency": {"Hz": 1.0},
    "rate": {"1/s": 1.0},
    "rate2": {"1/s^2": 1.0},
    "speed": {"rad/s": 1.0, "rpm": RPM},
    "length": {"m": 1.0, "mm": 1e-3},
    "command": {"V": 1.0, "A": 1.0, "N": 1.0, "N*m": 1.0},
}
"""Units of the motor-side and electrical quantities (always rotary or axis-free)."""
AXIS_SI = {ROTARY: {"position": "rad", "velocity": "rad/s", "force": "N*m", "mass": "kg*m^2",
                    "stiffness": "N*m/rad", "damping": "N*m*s/rad", "gain": "N*m/V",
                    "velocity_gain": "V*s/rad", "position_gain_i": "V/rad", "ratio": "-"},
           TRANSLATIONAL: {"position": "m", "velocity": "m/s", "force": "N", "mass": "kg",
                           "stiffness": "N/m", "damping": "N*s/m", "gain": "N/V",
                           "velocity_gain": "V*s/m", "position_gain_i": "V/m",
                           "ratio": "rad/m"}}
"""The SI unit of each load-side kind on each axis."""


def parse_quantity(value: Any, kind: str, axis: str | None) -> float:
    """A description's value -> SI of the axis: a number (already SI of the axis) or a string
    ``"<number> <unit>"`` with a unit of ``kind`` (load-side kinds check the unit's axis;
    ``axis`` None: a motor-side or electrical kind of :data:`MOTOR_UNITS`). Raises ValueError
    with a message that says what was expected."""
    if isinstance(value, bool):
        raise ValueError(f"expected a number or '<number> <unit>', got the boolean "
                         f"{str(value).lower()}")
    if isinstance(value, int | float):
        x = float(value)
        if not math.isfinite(x):
            raise ValueError(f"must be finite, got {value}")
        return x
    if not isinstance(value, str):
        raise ValueError(f"expected a number or '<number> <unit>', got {value!r}")
    parts = value.strip().split(None, 1)
    try:
        x = float(parts[0])
    except (ValueError, IndexError):
        raise ValueError(f"expected '<number> <unit>', got {value!r}") from None
    if not math.isfinite(x):
        raise ValueError(f"must be finite, got {value!r}")
    if len(parts) == 1:
        return x
    unit = parts[1].strip().replace("·", "*").replace("²", "^2").replace("µ", "u")
    if axis is None:
        table = MOTOR_UNITS[kind]
        if unit not in table:
            raise ValueError(f"unit {unit!r} is not a unit of {kind}; expected one of "
                             f"{', '.join(table)}")
        return x * table[unit]
    table2 = QUANTITY_UNITS[kind]
    if unit not in table2:
        raise ValueError(f"unit {unit!r} is not a unit of {kind}; expected one of "
                         f"{', '.join(u for u, (_, d) in table2.items() if d == axis)}")
    factor, domain = table2[unit]
    if domain != axis:
        ok = ", ".join(u for u, (_, d) in table2.items() if d == axis)
        raise ValueError(f"{unit} is a {domain} unit; a {axis} axis expects {kind} in {ok}")
    return x * factor
