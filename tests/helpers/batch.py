"""One-call batch runs of the simulator for tests, and the linear configuration."""

from __future__ import annotations

import numpy as np

from ema_cli.model.params import to_row
from ema_cli.sim.runner import plan_steps, simulate_batch
from ema_cli.sim.signals import InputSignal, sample
from ema_cli.units import DEG

LINEAR_OVERRIDES = {"sat1": "off", "sat2": "off", "sat3": "off", "alpha": 0.0, "friction": 0}
"""Every nonlinearity off: saturations removed, no dead zones, alpha 0, friction off."""


def run_rows(rows, signal=None, duration=0.2, dt=1e-5, output_interval=None, parallel=False):
    """Run parameter rows (dicts of SI values) as one batch; returns the BatchResult."""
    signal = signal or InputSignal("step", 0.1 * DEG)
    n_steps, dec = plan_steps(duration, dt, output_interval)
    ref = sample(signal, dt, n_steps)
    P = np.array([to_row(r) if isinstance(r, dict) else r for r in rows])
    return simulate_batch(P, [ref], None, dt, n_steps, dec, parallel=parallel)
