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
