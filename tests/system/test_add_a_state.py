"""The "add a state" recipe (docs/extending.md): a new state is one row of the state table
(``model/states.py``) with its equation, and one row of the signal table if it is to be
recorded; nothing else changes. Here, in a process of its own (a fresh compiled-code cache: the
tables are patched at run time, not in the source the cache is keyed on), a first-order filter
of the load speed is added, ``tau*dx_f/dt = w_L - x_f``, and the kernel integrates it: the
recorded ``x_f`` equals an independent integration of that equation driven by the recorded
load speed, its initial value is the generated parameter ``x0_x_f``, and every other signal is
the run's without it."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[2]

SCRIPT = textwrap.dedent("""
    import json, sys
    import numpy as np
    from ema_cli._numba import njit
    from ema_cli.model import states
    from ema_cli.sim import tables

    ADD = sys.argv[1] == "add"
    if ADD:
        @njit(forceinline=True)
        def filter_rate_nb(x_f, w_L):
            '''d(x_f)/dt = (w_L - x_f)/tau, tau = 10 ms [rad/s^2]'''
            return (w_L - x_f) * 100.0
        # 1. the state's row and its equation
        states.STATES = states.STATES + (
            states.State("x_f", "rad/s", "load speed through a 10 ms lag",
                         rate=filter_rate_nb, side="load"),)
        # 2. recorded: one row of the signal table
        tables.SIGNALS = tables.SIGNALS + (
            tables.Column("x_f", "rad/s", "x_f_rad_s", 1.0, "filtered load speed", "x_f"),)
        tables.SIG["x_f"] = len(tables.SIGNALS) - 1
        tables.N_SIGNALS = len(tables.SIGNALS)
    from ema_cli.model.params import INDEX, resolve, to_row
    from ema_cli.sim.runner import simulate_batch
    from ema_cli.sim.signals import InputSignal
    from ema_cli.units import DEG

    over = {"x0_x_f": 0.5} if ADD else {}
    P = np.array([to_row(resolve(over))])
    res = simulate_batch(P, [InputSignal(kind="sine", amplitude=2 * DEG, freq=5.0)], None,
                         1e-5, 20000, 10, n_signals=len(tables.SIGNALS))
    names = [c.name for c in tables.SIGNALS]
    out = {n: res.signals[0, :, k].tolist() for k, n in enumerate(names)}
    out["t"] = res.t_out.tolist()
    out["x0_index"] = INDEX.get("x0_x_f", -1)
    json.dump(out, sys.stdout)
""")


def _run(tmp_path: Path, mode: str) -> dict:
    env = dict(os.environ, EMA_CACHE_DIR=str(tmp_path / f"cache-{mode}"),
               PYTHONPATH=str(ROOT))
    r = subprocess.run([sys.executable, "-c", SCRIPT, mode], capture_output=True, text=True,
                       env=env, cwd=ROOT, timeout=900)
    assert r.returncode == 0, r.stderr[-2000:]
    return json.loads(r.stdout)


@pytest.mark.slow
def test_a_state_added_by_its_row_and_equation_is_integrated(tmp_path):
    from scipy.integrate import solve_ivp

    plain = _run(tmp_path, "plain")
    added = _run(tmp_path, "add")
    assert plain["x0_index"] == -1 and added["x0_index"] >= 0  # x0_x_f generated
    t = np.array(added["t"])
    w = np.array(added["omega_load"])
    xf = np.array(added["x_f"])
    assert xf[0] == 0.5  # started at its x0 parameter
    # independent: the lag's equation integrated by scipy on the recorded load speed
    # (cubic interpolation of the 1e-4 s record; its error sets the tolerance)
    from scipy.interpolate import CubicSpline

    ws = CubicSpline(t, w)
    ref = solve_ivp(lambda tt, y: [(ws(tt) - y[0]) * 100.0], (t[0], t[-1]), [0.5], t_eval=t,
                    rtol=1e-11, atol=1e-12, method="DOP853").y[0]
    assert np.max(np.abs(xf - ref)) <= 1e-6 * np.ptp(xf)
    # nothing else moved: every other signal is the run's without the state (the compiled
    # arithmetic of the other equations is the same; 1e-12 of the range allows for the
    # compiler's choice of fused multiply-adds in a larger function)
    for name, v in plain.items():
        if name in ("t", "x0_index"):
            continue
        a, b = np.array(v), np.array(added[name])
        assert np.max(np.abs(a - b)) <= 1e-12 * max(np.ptp(a), 1e-300), name
