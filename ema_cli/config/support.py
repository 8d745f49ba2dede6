"""Which command runs which actuator description: every command takes any description it can
run, and refuses the others in one line saying why (before anything is computed).

Today's limits:

* a translational axis runs in ``simulate`` and the identification (its tables and figures in
  mm, mm/s, N); the other commands report in the rotary units of the paper's EMA (degrees,
  N*m, deg/s metrics, limits and figures) and refuse it;
* ``margins`` and ``freqresp`` build the linear limit of the paper's topology (compliant shaft,
  armature, the paper's cascade: ``analysis/linear.py``) and refuse another topology;
* ``tune``, ``design``, ``acceptance`` and ``yield`` need a controller to tune or test and refuse
  a plant without one (``controller.type: none``).
"""

from __future__ import annotations

from typing import Any

from ema_cli.errors import EmaError

TRANSLATIONAL_OK = ("simulate", "identify", "validate", "duty")
"""Commands that run a translational axis."""
PAPER_TOPOLOGY_ONLY = ("margins", "freqresp")
"""Commands that need the paper's topology (their linear limit)."""
NEEDS_CONTROLLER = ("tune", "design", "acceptance", "yield")


def departures(params: dict[str, Any]) -> list[str]:
    """How a description's parameters depart from the paper's topology, in words."""
    out = []
    if params.get("rigid") in (1, 1.0):
        out.append("a rigid transmission")
    if params.get("drive") in ("amplifier", 1.0):
        out.append("an amplifier drive")
    if params.get("friction") in ("static", 2.0):
        out.append("static friction at the motor")
    if params.get("friction_L") not in (None, 0.0, "off"):
        out.append("friction at the load")
    if params.get("ctrl") in ("discrete", 1.0):
        out.append("a discrete cascade")
    if params.get("ctrl") in ("none", 2.0):
        out.append("no controller")
    if params.get("dist_out") in (1, 1.0):
        out.append("a disturbance input")
    return out


def check_command(cfg: Any, command: str) -> None:
    """Refuse ``ema <command>`` on the actuator of run config ``cfg`` when it cannot run it
    (module docstring); a config without an actuator description (the paper's EMA) passes."""
    a = getattr(cfg, "actuator", None)
    if a is None:
        return
    name = a.name or "of this config"
    if a.axis == "translational" and command not in TRANSLATIONAL_OK:
        raise EmaError(f"ema {command}: the actuator {name} is translational and {command} "
                       "reports in the rotary units of the paper's EMA (deg, N*m); it runs in "
                       f"{', '.join('ema ' + c for c in TRANSLATIONAL_OK[:2])}")
    params = a.params()
    away = departures(params)
    if command in PAPER_TOPOLOGY_ONLY and away:
        raise EmaError(f"ema {command}: the actuator {name} has {' and '.join(away)}; {command}"
                       " builds the linear limit of the paper's topology (a compliant shaft, an "
                       "armature, the paper's cascade) only")
    if command in NEEDS_CONTROLLER and params.get("ctrl") == "none":
        raise EmaError(f"ema {command}: the actuator {name} has no controller (controller.type:"
                       f" none) to {'tune' if command in ('tune', 'design') else 'test'}")


def checked(cfg: Any, command: str) -> Any:
    """``cfg`` after :func:`check_command` (for expressions)."""
    check_command(cfg, command)
    return cfg
