"""The state table: every state of the actuator, its unit, how it is integrated, its equation.

One row per state (the kernel's state vector, the initial-state parameters ``x0_<name>``, the
linearisation and the identification's segment states all come from it)::

    State(name, unit, description, kind, rate, side)

``kind``: ``"rk4"`` (integrated by the kernel's RK4 from ``rate``), ``"exact"`` (advanced once
per step by its own exact update, e.g. the LuGre bristles: ``model.lugre``), ``"held"`` (set by
the step logic, e.g. the speed PI's integral of a digital controller between samples, which
``rate`` makes 0). ``rate`` is a compiled function whose *argument names* say what it reads: a
state (``w_m``), a quantity of the actuator's algebra (``model.actuator.ALG``: ``t_shaft``,
``u_amp`` ...), a parameter or derived constant (``Kt``, ``inv_Jm``: ``sim.layout``), or a
structural flag (``rigid``, ``amp_bw``: ``model.actuator.FLAGS``). The kernel binds them by name
(``sim.layout.rates_source``), so a new state is one row here and its equation
(docs/extending.md, "Add a state"). ``side``: ``"motor"`` (motor shaft units, always rotary),
``"load"`` (the axis's units: rad or m), or ``""`` (electrical, controller).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from ema_cli.model import drive, plant, thermal, transmission


@dataclass(frozen=True)
class State:
    """One state of the actuator: name, SI unit (rotary reading of load-side units), meaning,
    how it is integrated, its rate equation (``kind == "rk4"``) and its side."""

    name: str
    unit: str
    description: str
    kind: str = "rk4"
    rate: Callable[..., float] | None = None
    side: str = ""
    hold: tuple[str, ...] = ()
    """Conditions (names bound like ``rate``'s arguments) under which the state is held: its rate
    is then 0 (the locked motor, a rigid axis's motor, a site that sticks)."""
    active: tuple[str, ...] = ()
    """Structural flags (``model.actuator.FLAGS``) the state needs to evolve at all: in a variant
    without one of them the state keeps its initial value and takes no part in the integration
    (its element is absent: no arithmetic, the other states' code unchanged)."""


STATES: tuple[State, ...] = (
    State("theta_m", "rad", "motor angle", rate=plant.motor_angle_rate_nb, side="motor",
          hold=("locked", "rigid")),
    State("w_m", "rad/s", "motor speed", rate=plant.motor_speed_rate_nb, side="motor",
          hold=("locked", "rigid", "stuck_m")),
    State("i", "A", "armature current", rate=plant.current_rate_nb, hold=("locked", "amp")),
    State("theta_L", "rad", "load angle (or position)", rate=plant.load_position_rate_nb,
          side="load"),
    State("w_L", "rad/s", "load speed", rate=plant.load_speed_rate_nb, side="load",
          hold=("stuck_L",)),
    State("z", "rad", "LuGre bristle deflection at the motor", kind="exact", side="motor"),
    State("xI", "rad", "speed-PI integral of the speed error (motor side)",
          rate=plant.speed_integral_rate_nb, side="motor", hold=("locked",)),
    State("f_amp", "N*m", "amplifier output (force or torque on the axis, load side)",
          rate=drive.amplifier_rate_nb, side="load", active=("amp_bw",)),
    State("z_L", "rad", "LuGre bristle deflection at the load", kind="exact", side="load"),
    State("f_t", "N*m", "transmission friction torque (Dahl element), load side",
          rate=transmission.friction_rate_nb, side="load", active=("trans",)),
    State("th_w", "K", "winding temperature rise above ambient (thermal element)",
          rate=thermal.winding_rate_nb, active=("thermal",)),
    State("th_h", "K", "housing temperature rise above ambient (thermal element)",
          rate=thermal.housing_rate_nb, active=("thermal",)),
)
STATE_INDEX: dict[str, int] = {s.name: k for k, s in enumerate(STATES)}
N_STATES = len(STATES)
KINDS = ("rk4", "exact", "held")
for _s in STATES:  # the table is code: check it where it is written
    if _s.kind not in KINDS or (_s.kind == "rk4") != (_s.rate is not None):
        raise ValueError(f"state {_s.name}: kind {_s.kind!r} with rate {_s.rate!r}")
