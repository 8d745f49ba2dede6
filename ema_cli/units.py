"""Unit conversions between SI (inside the code) and the paper's units (configs, CSVs, plots)."""

import math

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
