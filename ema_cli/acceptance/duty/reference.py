"""The brute-force reference: the whole profile simulated at the mechanical step, the thermal
network integrated by the kernel's RK4 with the mechanics (its states ``th_w``, ``th_h`` and
R(T) inside the armature's equation: ``model/thermal.py``).

One kernel run: the profile's position as a table (every ``h`` seconds, linear between rows:
:func:`table_step`), its load force as another when it varies, from the static equilibrium at
its start, the temperatures starting at ambient. What the multirate method (``duty.thermal``)
approximates -- the cycle averages, the blocks simulated from rest, the current's dependence
on R interpolated -- this does not; it costs every step of the profile (minutes for hours).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass

import numpy as np

from ema_cli.acceptance.duty.mechanics import rest_state
from ema_cli.acceptance.duty.profile import Expanded
from ema_cli.errors import EmaError

MAX_TABLE = 10_000_000  # rows of the position table, at most [-]
RECORD_S = 0.01  # recording interval of the reference [s]


@dataclass
class Reference:
    """The reference run: time [s], winding and housing temperatures [K] every ``RECORD_S``,
    the winding's peak [K], the kernel's wall time [s] and its steps."""

    t: np.ndarray
    t_w: np.ndarray
    t_h: np.ndarray
    current: np.ndarray
    wall_s: float
    steps: int

    @property
    def peak_w(self) -> float:
        return float(np.max(self.t_w))


def table_step(duration: float) -> float:
    """The position table's spacing for a profile of ``duration`` [s]: 0.1 ms, coarser only to
    keep :data:`MAX_TABLE` rows."""
    return max(1e-4, duration / MAX_TABLE)


def full_resolution(exp: Expanded, p: Mapping[str, float], dt: float,
                    progress: Callable[[float], None] | None = None) -> Reference:
    """Simulate the whole profile ``exp`` on the actuator ``p`` (SI) at the step ``dt`` [s]
    with the thermal element in the kernel (module docstring). One spring and one ambient over
    the whole profile (a kernel run has one of each)."""
    from ema_cli.limits import check_steps
    from ema_cli.model.params import resolve, to_row
    from ema_cli.sim.runner import simulate_batch
    from ema_cli.sim.signals import InputSignal
    from ema_cli.sim.tables import SIG

    blocks = [exp.blocks[i] for i in exp.order]
    if len({b.spring for b in blocks}) > 1 or len({b.ambient_k for b in blocks}) > 1:
        raise EmaError("the full-resolution reference needs one load spring and one ambient "
                       "over the whole profile (one kernel run)")
    total = exp.duration
    check_steps(total / dt, "the full-resolution reference", "shorten the profile")
    h = table_step(total)
    n = int(math.ceil(total / h)) + 1
    t = np.arange(n) * h
    pos = np.empty(n)
    force = np.empty(n)
    start = 0.0
    for b in blocks:
        end = start + b.duration
        a, z = int(math.ceil(start / h - 1e-9)), min(n, int(math.ceil(end / h - 1e-9)))
        pos[a:z] = b.position(t[a:z] - start)
        force[a:z] = b.load(t[a:z] - start)
        start = end
    pos[-1] = blocks[-1].end
    force[-1] = force[-2]
    varying = bool(np.ptp(force) > 0)
    amb = blocks[0].ambient_k
    q = dict(p)
    q.update({"thermal": 1.0, "T_amb": amb, "k_h": blocks[0].spring,
              "T_load": 0.0 if varying else float(force[0])})
    q.update(rest_state(q, blocks[0].start, float(force[0])))
    sig = InputSignal(kind="csv", table=(tuple(t), tuple(pos)), path="profile",
                      load_table=(tuple(t), tuple(force)) if varying else None)
    n_steps = math.ceil(total / dt - 1e-6)
    dec = max(1, round(RECORD_S / dt))
    t0 = time.perf_counter()
    res = simulate_batch(np.array([to_row(resolve(q))]), [sig], None, dt, n_steps, dec,
                         progress=progress)
    wall = time.perf_counter() - t0
    s = res.signals[0]
    return Reference(res.t_out, amb + s[:, SIG["winding_rise"]], amb + s[:, SIG["housing_rise"]],
                     s[:, SIG["current"]], wall, n_steps)
