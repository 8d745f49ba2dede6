"""The independent log generator (experiments/loggen, issue 21): convergence in its tolerance,
agreement with ema's kernel on the laws ema has, the contact laws by hand, and logs ema reads.

Tolerances come from measurements (numbers in the comments; `python -m
experiments.loggen.verify` prints the 4 s versions) with a margin of 3-10x.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from experiments.loggen import odemodel
from experiments.loggen.battery import plan
from experiments.loggen.excitations import Chirp, Multisine, Steps, make_command
from experiments.loggen.logs import make_log, sidecar_path, write_log
from experiments.loggen.params import resolve
from experiments.loggen.verify import CASES, CHANNELS, convergence, crosscheck, ema_step_study

CASE = {name: (truth, exc) for name, truth, exc in CASES}


# -- (a) convergence: rtol 1e-9 (the logs) vs 1e-11 --------------------------------------------
@pytest.mark.parametrize("law", ["jump", pytest.param("ramp", marks=pytest.mark.slow),
                                 "hunt_crossley"])
def test_converged_far_below_the_noise(law: str) -> None:
    """0.3 s of the default chirp log (impacts at every reversal): every channel of the rtol
    1e-9 run is within 1e-2 of the 1 % noise level of the rtol 1e-11 run (measured over 0.4 s,
    jump: theta_load 3e-5, current 2.2e-3 of it; the current moves fastest at the impacts).
    The ramp law (slow tier) is also held to 5e-5 of ema's kernel below."""
    truth, exc = CASE["default"]
    r = convergence(truth, law, exc, 0.3)
    assert max(r.values()) < 1e-2, r


# -- (b) cross-check against ema's kernel -------------------------------------------------------
# max |generator - ema| / RMS over [0, 0.5] s, chirp of the battery. ema steps RK4 at 1e-5 s on
# the command sampled every 1e-4 s. ema's current limit switches on its step grid (and clamps
# i after each step), where the generator locates it by events. The jump law's torque jump is
# spread by ema over the one step centred on the touch (model.transmission, hw = dt/2), where
# the generator locates the touch by an event; before that band the jump fell on ema's first
# RK4 stage in contact (default 9.2e-5, 5.9e-4; large_alpha 8.6e-5, 4.0e-4). Measured over
# 0.5 s (theta_load, omega_motor): default jump 4.6e-6, 6.4e-5; ramp 4.4e-6, 6.7e-5;
# large_alpha jump 6.8e-6, 4.0e-5; ramp 6.9e-6, 4.1e-5; current_limit (ramp) 2.7e-5, 1.5e-4.
# Hunt-Crossley (ema: contact_hc = 1, contact_tau = 0, contact_pen = the generator's pen_ref):
# default 5.2e-6, 1.1e-4; large_alpha 3.2e-6, 5.5e-5 (no jump: as close as the ramp law).
# Tolerances: 3-7x those.
XCHECK = [("default", "jump", 3e-5, 3e-4), ("default", "ramp", 3e-5, 3e-4),
          ("default", "hunt_crossley", 3e-5, 4e-4), ("large_alpha", "hunt_crossley", 3e-5, 2e-4),
          ("large_alpha", "jump", 3e-5, 2e-4), ("large_alpha", "ramp", 3e-5, 2e-4),
          ("current_limit", "ramp", 1e-4, 6e-4)]


@pytest.mark.parametrize(("case", "law", "tol_theta", "tol_omega"), XCHECK)
def test_agrees_with_ema_kernel(case: str, law: str, tol_theta: float, tol_omega: float) -> None:
    truth, exc = CASE[case]
    r = crosscheck(truth, law, exc, 0.5, window_s=0.5)
    assert r["theta_load_deg"][0] < tol_theta, r
    assert r["omega_motor_rpm"][0] < tol_omega, r


def test_current_limit_is_reached_and_held() -> None:
    """With sat3 = 0.5 A the chirp's first 0.5 s reaches the limit (unlimited: |i| > 0.5 A at
    75 of the 500 samples, from 0.03 s; limited: 6 entries, 63 ms held, measured): the limit is
    entered, and |i| never exceeds sat3 (it is held exactly)."""
    truth, _ = CASE["current_limit"]
    p = resolve(truth)
    t = np.arange(501) * 1e-3
    tr = odemodel.simulate(p, "ramp", Chirp().value, t)
    assert tr.stats.ilim_entries >= 3
    assert tr.stats.time_in_ilim_s > 0.03
    assert np.max(np.abs(tr.state("i"))) <= 0.5 + 1e-12


# Whole 4 s logs (slow tier). Measured theta_load max |diff| / RMS, first second and worst of
# 1-4 s: ramp 7e-6 .. 4.5e-5 and up to 3.2e-2 (small_alpha multisine, 2-3 s); jump 6.9e-6 ..
# 8.8e-5 and up to 2.3e-2 (small_alpha; before the jump band: 2.8e-4 .. 1.3e-2 and up to
# 0.14). Later in a log the impacts drift apart in time (the load flies free in the gap, so a
# timing difference grows), and the drift is ema's step: it falls as ema's dt is refined.
FIRST_S_TOL = {"ramp": 2e-4, "jump": 3e-4}
LATER_TOL = {"ramp": 0.1, "jump": 0.1}


@pytest.mark.slow
@pytest.mark.parametrize(("case", "law"), [(c, law) for c, *_ in CASES for law in ("jump", "ramp")])
def test_agrees_with_ema_over_4_s(case: str, law: str) -> None:
    truth, exc = CASE[case]
    th = crosscheck(truth, law, exc, 4.0)["theta_load_deg"]
    assert th[0] < FIRST_S_TOL[law], th
    assert max(th[1:]) < LATER_TOL[law], th


@pytest.mark.slow
def test_disagreement_is_emas_step() -> None:
    """large_alpha, jump law, 4 s: the worst 1 s window of |generator - ema| / RMS is 3.5e-3
    at ema's dt = 1e-5 s and 1.15e-3 at 2.5e-6 s (measured; before the jump band 0.142 and
    0.011). Asserted: below 1e-2 at 1e-5 s, and at least 2x smaller at 2.5e-6 s."""
    truth, exc = CASE["large_alpha"]
    r = ema_step_study(truth, "jump", exc, 4.0, dts=(1e-5, 2.5e-6))
    assert max(r[1e-5]) < 1e-2, r
    assert max(r[2.5e-6]) < max(r[1e-5]) / 2, r


# -- the contact laws by hand -------------------------------------------------------------------
def test_contact_laws_by_hand() -> None:
    p = resolve({"alpha": 0.002})
    kL, c, a, tau = p["kL"], p["c"], p["alpha"], p["contact_tau"]
    plants = {law: odemodel.Plant(p, law, lambda t: 0.0) for law in odemodel.LAWS}
    # + side, penetration 1e-3 rad (= HC_PEN_REF), closing at 0.5 rad/s
    dth, dw = a + 1e-3, 0.5
    assert plants["jump"].torque(dth, dw, 1) == pytest.approx(kL * 1e-3 + c * 0.5, rel=1e-14)
    # ramp: damping limited to (c/tau)*pen = c*10 rad/s here, so not limited
    assert plants["ramp"].torque(dth, dw, 1) == pytest.approx(kL * 1e-3 + c * 0.5, rel=1e-14)
    # Hunt-Crossley at pen = HC_PEN_REF damps exactly like c
    assert plants["hunt_crossley"].torque(dth, dw, 1) == pytest.approx(kL * 1e-3 + c * 0.5,
                                                                       rel=1e-12)
    # small penetration 1e-6 rad: ramp limits the damping to (c/tau)*1e-6 = c*0.01 rad/s
    assert plants["ramp"].torque(a + 1e-6, dw, 1) == pytest.approx(kL * 1e-6 + c * 1e-6 / tau)
    # HC damping at 1e-6 rad is 1e-3 of c: kL*1e-6*(1 + lam*0.5), lam = c/(kL*1e-3)
    assert plants["hunt_crossley"].torque(a + 1e-6, dw, 1) == pytest.approx(
        kL * 1e-6 + c * 1e-3 * 0.5)
    # - side mirrors; separating fast: pushes only (0, never pulls)
    for law, pl in plants.items():
        assert pl.torque(-dth, -dw, -1) == pytest.approx(-pl.torque(dth, dw, 1)), law
        assert pl.torque(dth, -50.0, 1) == 0.0, law
        assert pl.torque(0.0, 1.0, 0) == 0.0, law
    # no backlash: a linear shaft for every law
    p0 = resolve()
    for law in odemodel.LAWS:
        assert odemodel.Plant(p0, law, lambda t: 0.0).torque(1e-3, -0.2, 0) == pytest.approx(
            p0["kL"] * 1e-3 - p0["c"] * 0.2)


def test_sampling_does_not_change_the_trajectory() -> None:
    """Samples every 50 ms (several contact events between two samples: segments without a
    sample) equal every 50th sample of a 1 ms log to 1e-12 (the samples come from the
    solver's dense output; measured 2e-14)."""
    p = resolve({"alpha": 0.003, "sigma2": 1e-4})
    sparse = odemodel.simulate(p, "jump", Chirp().value, np.arange(7) * 0.05)
    dense = odemodel.simulate(p, "jump", Chirp().value, np.arange(301) * 1e-3)
    assert sparse.stats.segments > 7
    assert np.max(np.abs(sparse.x - dense.x[::50]) / odemodel.STATE_SCALE) < 1e-12


def test_derived_parameters_follow_ema_rules() -> None:
    """c = 2*zeta_t*sqrt(kL*Jeq) = 0.7733 N*m*s/rad at the defaults (docs: c/tau = 7,733
    N*m/rad); Fs = 1.5*Fc, sigma0 = 1e3*Fc, sigma1 = sqrt(sigma0*Jm)."""
    p = resolve({"Fc": 0.04})
    jeq = 3e-5 * 24**2 * 0.01 / (3e-5 * 24**2 + 0.01)
    assert p["c"] == pytest.approx(2 * 0.2 * math.sqrt(590 * jeq), rel=1e-14)
    assert p["c"] / 1e-4 == pytest.approx(7733, rel=1e-4)
    assert (p["Fs"], p["sigma0"]) == pytest.approx((0.06, 40.0))
    assert p["sigma1"] == pytest.approx(math.sqrt(40.0 * 3e-5))


# -- excitations and files ----------------------------------------------------------------------
def test_excitations_start_at_rest_and_stay_in_range() -> None:
    t = np.linspace(0.0, 4.0, 40001)
    for kind in ("chirp", "multisine", "steps"):
        cmd = make_command(kind, np.random.default_rng(7), 4.0)
        y = cmd.sample(t)
        assert y[0] == 0.0, kind
        assert np.max(np.abs(y)) <= 5.0 * math.pi / 180 + 1e-12, kind
        assert cmd.sample(t).tolist() == make_command(kind, np.random.default_rng(7),
                                                      4.0).sample(t).tolist(), kind
    ms = make_command("multisine", np.random.default_rng(7), 4.0)
    assert isinstance(ms, Multisine) and min(ms.freqs) >= 0.3 and max(ms.freqs) <= 10.0
    st = make_command("steps", np.random.default_rng(7), 4.0)
    assert isinstance(st, Steps) and all(0.02 <= r <= 0.05 for r in st.ramps)
    holds = np.diff(st.starts) - np.array(st.ramps[:-1])
    assert np.all((holds >= 0.3) & (holds <= 0.8))


def test_battery_plan_is_deterministic_and_pairs_the_laws() -> None:
    a, b = plan(6, 2026), plan(6, 2026)
    assert a == b and plan(6, 2027) != a
    assert len(a) == 18
    for i in range(6):
        trio = a[3 * i:3 * i + 3]
        assert [j["law"] for j in trio] == list(odemodel.LAWS)
        assert all(j["truth"] == trio[0]["truth"] and j["seed"] == trio[0]["seed"]
                   and j["noise_pct"] == trio[0]["noise_pct"] for j in trio)
    kl = sorted(j["truth"]["kL"] for j in a[::3])  # one per LHS stratum of [300, 900]
    assert [int((x - 300) // 100) for x in kl] == list(range(6))


def test_a_log_ema_reads(tmp_path) -> None:
    """A 0.3 s log at 500 Hz with 1 % noise: ema's closed-loop reader accepts it and reads
    the truth from the sidecar; the noise is 1 % of each channel's RMS."""
    from ema_cli.identify.closed_loop.problem import load_log

    truth = {"kL": 700.0, "alpha": 0.002, "Fc": 0.03, "sigma2": 0.01}
    log = make_log(truth, "hunt_crossley", "chirp", 500.0, 1.0, 11, duration_s=0.3)
    path = tmp_path / "x.csv"
    write_log(path, log)
    sc = json.loads(sidecar_path(path).read_text())
    assert sc["law"] == "hunt_crossley" and sc["seed"] == 11
    lg = load_log(path)
    assert lg.n == 151
    for k, v in truth.items():
        assert lg.truth[k] == v
    assert lg.truth["c"] == pytest.approx(resolve(truth)["c"])
    for ch in CHANNELS:
        assert sc["noise_std_edge_units"][ch] > 0
    again = make_log(truth, "hunt_crossley", "chirp", 500.0, 1.0, 11, duration_s=0.3)
    assert all(np.array_equal(log.columns[k], again.columns[k]) for k in log.columns)
