"""Nonlinearity types at signal points; the paper's nine names as aliases (docs/model.md §5).

Type and location are separate: a dead zone can sit at the amplifier, the speed sensor, the
position sensor or the transmission (where it is the backlash dead band); a saturation at either
regulator output or on the current. Each placement knows its magnitude's unit at the edge (the
paper's units) and how to turn a magnitude into SI parameter updates. This module is the one
place where paper units are converted for the nonlinearities.

Settings compose in any order: each placement writes its own SI parameters and no other's.
``gap1`` (compliance@transmission) sets the stiffness ``kL`` only; the dead band ``alpha`` is
``deadzone2``'s (default 0: the paper's gap without dead zone), so ``gap1=2`` with
``deadzone2=0.01`` is a compliant shaft with a 0.01 deg dead band whichever comes first. One
placement named twice (``deadzone2`` and ``deadzone@transmission``) is an error naming both
(:func:`check_distinct`, :func:`combined_updates`).

Magnitude 0 means the nonlinearity is absent, as ``off`` does: a dead zone of 0, and
``friction1=0`` is no friction in both readings (not LuGre with ``sigma2 = 0``; for that set
``plant.friction=1``, whose ``sigma2`` defaults to 0). A saturation limit or a stiffness of 0
is refused (``off`` removes a saturation; a compliance cannot be removed).
"""

from __future__ import annotations

import math
import numbers
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass

from ema_cli.errors import EmaError
from ema_cli.model.params import BRISTLE_DAMPING_RATIO, FS_PER_FC, SIGMA0_PER_FC
from ema_cli.units import DEG, RPM

OFF = "off"
FRICTION_READINGS = ("sigma2", "scale")
"""friction1 magnitude readings: ``sigma2`` (viscous coefficient, the default) or ``scale`` (Fc)."""

Updates = dict[str, float]


@dataclass(frozen=True)
class Placement:
    """A nonlinearity type at a location, its magnitude's edge unit and its SI effect."""

    type: str
    location: str
    unit: str
    meaning: str
    apply: Callable[[float | str, Mapping[str, float], str], Updates]
    default: str
    paper_sweep: str
    alias: str | None = None


def _number(name: str, value: float | str, unit: str, allow_off: bool) -> float | None:
    if isinstance(value, bool):  # YAML's yes/no/true/false: not a magnitude
        raise EmaError(f"'{name}' expects a number in {unit}{' or off' if allow_off else ''}, "
                       f"got the boolean {str(value).lower()}")
    if isinstance(value, str):
        if value.strip().lower() == OFF:
            if allow_off:
                return None
            raise EmaError(f"'{name}' cannot be 'off' (it has no off state); expected a number > 0 "
                           f"in {unit}")
        try:
            value = float(value)
        except ValueError:
            raise EmaError(
                f"'{name}' expects a number in {unit}{' or off' if allow_off else ''}, "
                f"got {value!r}"
            ) from None
    if not isinstance(value, numbers.Real):  # None, a list, a mapping...
        raise EmaError(f"'{name}' expects a number in {unit}{' or off' if allow_off else ''}, "
                       f"got {value!r}")
    x = float(value)
    if not math.isfinite(x) or x < 0:
        raise EmaError(f"'{name}' must be a finite number >= 0 in {unit}, got {value!r}")
    return x


def _deadzone(param: str, factor: float, unit: str) -> Callable[..., Updates]:
    def apply(value: float | str, _p: Mapping[str, float], name: str) -> Updates:
        x = _number(name, value, unit, allow_off=True)
        return {param: 0.0 if x is None else x * factor}

    return apply


def _saturation(param: str, factor: float, unit: str) -> Callable[..., Updates]:
    def apply(value: float | str, _p: Mapping[str, float], name: str) -> Updates:
        x = _number(name, value, unit, allow_off=True)
        if x == 0.0:
            raise EmaError(f"'{name}' limit must be > 0 {unit} (or 'off'), got 0")
        return {param: math.inf if x is None else x * factor}

    return apply


def _compliance(value: float | str, p: Mapping[str, float], name: str) -> Updates:
    x = _number(name, value, "N*m/rad", allow_off=False)
    if not x:
        raise EmaError(f"'{name}' stiffness must be > 0 N*m/rad (motor shaft), got {value!r}")
    return {"kL": x * p["m"] ** 2}  # the dead band is deadzone2's: settings compose


def _friction(value: float | str, p: Mapping[str, float], name: str, reading: str) -> Updates:
    x = _number(name, value, "N*m*s/rad" if reading == "sigma2" else "N*m", allow_off=True)
    if x is None or x == 0:  # off, or magnitude 0: no friction (either reading)
        return {"friction": 0.0}
    if reading == "sigma2":
        return {"friction": 1.0, "sigma2": x}
    sigma0 = SIGMA0_PER_FC * x
    return {
        "friction": 1.0,
        "Fc": x,
        "Fs": FS_PER_FC * x,
        "sigma0": sigma0,
        "sigma1": 2.0 * BRISTLE_DAMPING_RATIO * math.sqrt(sigma0 * p["Jm"]),
        "sigma2": 2e-3 * x,
    }


PLACEMENTS: tuple[Placement, ...] = (
    Placement("deadzone", "amplifier", "V", "half-width d1 of the amplifier input dead zone",
              _deadzone("d1", 1.0, "V"), "0", "0.01, 0.1, 1 V", "deadzone1"),
    Placement("deadzone", "transmission", "deg",
              "half-width alpha of the transmission dead band (backlash), load side",
              _deadzone("alpha", DEG, "deg"), "0", "0.001, 0.01, 0.1 deg", "deadzone2"),
    Placement("deadzone", "speed_sensor", "rpm",
              "half-width d3 of the motor speed sensor dead zone",
              _deadzone("d3", RPM, "rpm"), "0", "0.1, 1, 10 rpm", "deadzone3"),
    Placement("deadzone", "position_sensor", "deg",
              "half-width d4 of the load position sensor dead zone",
              _deadzone("d4", DEG, "deg"), "0", "0.001, 0.01, 0.1 deg", "deadzone4"),
    Placement("saturation", "position_regulator", "deg/s",
              "limit of the position-regulator output (load speed command), or off",
              _saturation("sat1", DEG, "deg/s"), "800", "+-800 deg/s vs removed", "saturation1"),
    Placement("saturation", "speed_regulator", "V",
              "limit of the speed-regulator output (voltage demand), or off",
              _saturation("sat2", 1.0, "V"), "40", "+-40 V vs removed", "saturation2"),
    Placement("saturation", "current", "A", "armature current limit, or off",
              _saturation("sat3", 1.0, "A"), "30.35", "+-30.35 A vs removed", "saturation3"),
    Placement("compliance", "transmission", "N*m/rad",
              "stiffness referred to the motor shaft (kL = value*m^2; dead band: deadzone2's)",
              _compliance, "1.024", "0.01, 0.1, 1, 10 N*m/rad", "gap1"),
    Placement("friction", "motor_shaft", "N*m*s/rad",
              "LuGre viscous coefficient sigma2 (Fc, Fs fixed); 0 or off: no friction; reading "
              "'scale': Fc [N*m]",
              lambda v, p, n: _friction(v, p, n, "sigma2"), "off",
              "0.0001, 0.001, 0.01, 0.1", "friction1"),
)

ALIASES: dict[str, Placement] = {pl.alias: pl for pl in PLACEMENTS if pl.alias}
BY_KEY: dict[str, Placement] = {f"{pl.type}@{pl.location}": pl for pl in PLACEMENTS}
TYPES = sorted({pl.type for pl in PLACEMENTS})
LOCATIONS = sorted({pl.location for pl in PLACEMENTS})


def lookup(name: str) -> Placement:
    """A paper name (``deadzone2``) or ``type@location`` -> its Placement."""
    if name in ALIASES:
        return ALIASES[name]
    if name in BY_KEY:
        return BY_KEY[name]
    if "@" in name:
        typ, loc = name.split("@", 1)
        if typ not in TYPES:
            raise EmaError(f"unknown nonlinearity type '{typ}'; expected one of {TYPES}")
        if loc not in LOCATIONS:
            raise EmaError(f"unknown location '{loc}'; expected one of {LOCATIONS}")
        possible = sorted(pl.location for pl in PLACEMENTS if pl.type == typ)
        raise EmaError(f"a {typ} cannot be placed at '{loc}'; possible locations: {possible}")
    raise EmaError(
        f"unknown nonlinearity '{name}'; expected a paper name ({', '.join(ALIASES)}) "
        f"or type@location ({', '.join(BY_KEY)})"
    )


def nonlinearity_updates(
    name: str, value: float | str, params: Mapping[str, float], friction_reading: str = "sigma2"
) -> Updates:
    """SI parameter updates for one nonlinearity set to ``value`` in its edge unit.

    ``params`` supplies the values a conversion depends on (the gear ratio for gap1, Jm for the
    scaled friction reading).
    """
    pl = lookup(name)
    if pl.type == "friction":
        if friction_reading not in FRICTION_READINGS:
            raise EmaError(
                f"friction reading must be one of {FRICTION_READINGS}, got {friction_reading!r}"
            )
        return _friction(value, params, name, friction_reading)
    return pl.apply(value, params, name)


def check_distinct(names: Iterable[str]) -> None:
    """Refuse one placement named twice (a paper name and its ``type@location``), naming both;
    every name must be known (:func:`lookup`)."""
    seen: dict[str, str] = {}
    for name in names:
        pl = lookup(name)
        key = f"{pl.type}@{pl.location}"
        if key in seen:
            raise EmaError(f"'{seen[key]}' and '{name}' set the same nonlinearity ({key}); "
                           "give it once")
        seen[key] = name


def combined_updates(
    settings: Mapping[str, float | str], params: Mapping[str, float],
    friction_reading: str = "sigma2",
) -> Updates:
    """The SI parameter updates of several settings together, the same in any order.

    A placement named twice, or two settings writing the same SI parameter, is an EmaError
    naming both.
    """
    check_distinct(settings)
    out: Updates = {}
    writer: dict[str, str] = {}
    for name, value in settings.items():
        for param, x in nonlinearity_updates(name, value, params, friction_reading).items():
            if param in writer:
                raise EmaError(f"'{writer[param]}' and '{name}' both set the model parameter "
                               f"'{param}'; give one")
            writer[param] = name
            out[param] = x
    return out
