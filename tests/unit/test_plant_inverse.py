"""The inverse model alone (identify/plant/inverse.py): a geared robot joint integrated by scipy
(independent of the kernel), no controller described, units at the edge; its terms within their
cluster-robust intervals, a gravity torque the law lacks named by the adequacy report."""

from __future__ import annotations

import numpy as np
import pytest

from ema_cli.identify.plant.fit import run_plant
from ema_cli.identify.plant.settings import PlantSettings


def _contains(lf, want):
    u = lf.uncertainty
    for j, n in enumerate(u.names):
        assert u.ci_low[j] <= want[n] <= u.ci_high[j], (n, u.x[j], u.ci_low[j], u.ci_high[j])


ROBOT_DESC = """actuator:
  name: robot-joint
  axis: rotary
  transmission: {type: rigid}
  motor: {inertia: 0}
  load: {inertia: 0.8 kg*m^2, viscous: 0}
  drive: {type: amplifier, gain: 12 N*m/A}
  friction:
    load: {law: coulomb, coulomb: 2 N*m, viscous: 1.5 N*m*s/rad}
  controller: {type: none}
"""


def _robot_record(path, gravity):
    """A geared robot joint integrated by scipy (independent of the kernel): J q'' = k i -
    Fv q' - Fc sign(q') - m g l cos(q), driven open loop by a current that swings it over
    about 100 deg; current sampled at 1 kHz with noise, angle in degrees."""
    import pandas as pd
    from scipy.integrate import solve_ivp

    J, k, fv, fc = 0.8, 12.0, 1.5, 2.0
    t = np.arange(0, 30.0, 1e-3)

    def cur(tt):
        return 1.2 * np.sin(2 * np.pi * 0.4 * tt) + 0.6 * np.sin(2 * np.pi * 1.1 * tt + 1.0) \
            + (gravity / k) * np.cos(np.deg2rad(20) * np.sin(2 * np.pi * 0.05 * tt))

    def rhs(tt, x):
        tau = k * cur(tt) - fv * x[1] - fc * np.tanh(x[1] / 1e-3) - gravity * np.cos(x[0])
        return [x[1], tau / J]

    sol = solve_ivp(rhs, (0, t[-1]), [0.0, 0.0], t_eval=t, method="LSODA", rtol=1e-9,
                    atol=1e-11, max_step=1e-3)
    rng = np.random.default_rng(3)
    i_meas = cur(t) + 0.01 * rng.standard_normal(t.size)
    pd.DataFrame({"time_ms": t * 1e3, "angle_deg": np.rad2deg(sol.y[0]),
                  "current": i_meas}).to_csv(path, index=False)
    return path


@pytest.mark.parametrize("gravity", [0.0, 6.0])
def test_a_robot_joint_without_a_controller_by_the_inverse_model(tmp_path, gravity):
    """A rotary joint with no controller described (inverse model only), units at the edge
    (ms, deg, A): inertia and friction within their intervals without gravity; with a gravity
    torque the model misses it and the adequacy names it."""
    desc = tmp_path / "robot.yaml"
    desc.write_text(ROBOT_DESC)
    p = _robot_record(tmp_path / "joint.csv", gravity)
    fit = run_plant(PlantSettings(
        data=str(p), actuator=str(desc), law="symmetric", split=0.0,
        columns={"time": "time_ms:ms", "position": "angle_deg:deg", "actuation": "current:A"}))
    assert fit.controller is None and "inverse model" in fit.mode
    lf = fit.best
    names = lf.uncertainty.names
    if gravity == 0.0:
        _contains(lf, {"M": 0.8, "Fv": 1.5, "Fc": 2.0, "OF": 0.0})
        assert lf.adequacy.verdict == "ADEQUATE", lf.adequacy.reasons
    else:
        missed = [o.name for o in lf.adequacy.omitted if o.missed]
        assert lf.adequacy.verdict == "NOT ADEQUATE" and "gravity cos q" in missed, missed
    assert names == ("M", "Fv", "Fc", "OF")


def test_a_window_shorter_than_the_mechanical_time_constant_is_refused_by_the_inverse_model(
        tmp_path):
    """The inverse model's path refuses a window shorter than the axis' mechanical time
    constant as the closed loop's does: J/Fv = 0.8/1.5 = 0.533 s against a 0.3 s window, in
    one EmaError naming the file, the span and the time constant."""
    from ema_cli.errors import EmaError

    desc = tmp_path / "robot.yaml"
    desc.write_text(ROBOT_DESC)
    p = _robot_record(tmp_path / "joint.csv", 0.0)
    settings = PlantSettings(
        data=str(p), actuator=str(desc), law="symmetric", split=0.0, window=(1.0, 1.3),
        columns={"time": "time_ms:ms", "position": "angle_deg:deg", "actuation": "current:A"})
    with pytest.raises(EmaError) as err:
        run_plant(settings)
    msg = err.value.message
    assert "joint.csv" in msg and "span 0.3" in msg and f"M/Fv = {0.8 / 1.5:.4g} s" in msg, msg
    assert "\n" not in msg
