"""sim/signals.py: reference shapes against closed forms, CSV profiles, and the sample() grid."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from ema_cli.errors import EmaError
from ema_cli.sim.signals import InputSignal, Reference, load_profile, sample
from ema_cli.units import DEG

D = math.pi / 180  # one degree, written out


def grids(dt: float, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Half-step and full-step times, as j*dt/2 and k*dt."""
    return np.arange(2 * n + 1) * (dt / 2), np.arange(n + 1) * dt


# ------------------------------------------------------------------------------------------
# sample(): grid and Reference fields


def test_sample_grid_sizes_and_fields():
    dt, n = 1e-3, 250
    ref = sample(InputSignal("step", 0.5 * D, start=0.1), dt, n)
    assert isinstance(ref, Reference)
    assert ref.pos_half.shape == (2 * n + 1,) and ref.vel.shape == (n + 1,)
    for a in (ref.pos_half, ref.vel, ref.step_info):
        assert a.dtype == np.float64 and a.flags.c_contiguous
    np.testing.assert_array_equal(ref.step_info, [1.0, 0.5 * D, 0.1])
    assert ref.load_half is None


def test_step():
    dt, n = 1e-3, 100
    th, t = grids(dt, n)
    ref = sample(InputSignal("step", 2 * D, start=0.0205), dt, n)
    np.testing.assert_array_equal(ref.pos_half, np.where(th >= 0.0205, 2 * D, 0.0))
    assert ref.pos_half[40] == 0.0 and ref.pos_half[41] == 2 * D  # 0.0200 s | 0.0205 s
    np.testing.assert_array_equal(ref.vel, np.zeros(n + 1))
    # a step at t = 0 is applied at t = 0
    assert sample(InputSignal("step", 1.0), dt, n).pos_half[0] == 1.0


@pytest.mark.parametrize("kind", ["ramp", "sine", "chirp", "csv"])
def test_step_info_only_for_steps(kind):
    sig = InputSignal(kind, 1.0, rate=1.0, table=((0.0, 1.0), (0.0, 1.0)))
    np.testing.assert_array_equal(sample(sig, 1e-3, 10).step_info, [0.0, 1.0, 0.0])
    assert sample(InputSignal("step", 0.0), 1e-3, 10).step_info[0] == 0.0  # zero step


def test_ramp_stops_at_amplitude():
    dt, n = 0.01, 300
    th, t = grids(dt, n)
    A, r, t0 = 10 * D, 5 * D, 0.5  # reaches 10 deg at t = 2.5 s
    ref = sample(InputSignal("ramp", A, start=t0, rate=r), dt, n)
    expected = np.clip(r * np.maximum(th - t0, 0.0), 0.0, A)
    np.testing.assert_allclose(ref.pos_half, expected, rtol=0, atol=1e-15)
    moving = (t >= t0) & (r * (t - t0) < A)
    np.testing.assert_array_equal(ref.vel, np.where(moving, r, 0.0))
    assert ref.vel[int(round(1.0 / dt))] == r and ref.vel[int(round(2.6 / dt))] == 0.0


def test_ramp_negative_rate_positive_amplitude_stops_at_minus_amplitude():
    ref = sample(InputSignal("ramp", 10 * D, rate=-5 * D), 0.5, 10)
    np.testing.assert_allclose(ref.pos_half[::2] / D,
                               [0, -2.5, -5, -7.5, -10, -10, -10, -10, -10, -10, -10], atol=1e-12)


def test_ramp_without_end():
    ref = sample(InputSignal("ramp", 0.0, rate=3.0), 0.1, 20)
    th, t = grids(0.1, 20)
    np.testing.assert_allclose(ref.pos_half, 3.0 * th, rtol=1e-15)
    np.testing.assert_array_equal(ref.vel, np.full(21, 3.0))


def test_sine():
    dt, n = 1e-3, 1000
    th, t = grids(dt, n)
    A, f, off, t0 = 5 * D, 3.0, 1 * D, 0.1
    ref = sample(InputSignal("sine", A, start=t0, freq=f, offset=off), dt, n)
    w = 2 * math.pi * f
    np.testing.assert_allclose(ref.pos_half,
                               np.where(th >= t0, off + A * np.sin(w * (th - t0)), 0.0),
                               rtol=0, atol=1e-12)
    np.testing.assert_allclose(ref.vel, np.where(t >= t0, A * w * np.cos(w * (t - t0)), 0.0),
                               rtol=0, atol=1e-12)


def chirp_closed_form(t, A, f0, f1, T, t0, off):
    """Linear chirp: f(tau) = f0 + (f1-f0)*tau/T for tau <= T, then f1, phase continuous."""
    tau = t - t0
    k = (f1 - f0) / T
    phase_end = 2 * math.pi * (f0 * T + 0.5 * k * T * T)
    phase = np.where(tau <= T, 2 * math.pi * (f0 * tau + 0.5 * k * tau * tau),
                     phase_end + 2 * math.pi * f1 * (tau - T))
    freq = np.where(tau <= T, f0 + k * tau, f1)
    pos = np.where(tau >= 0, off + A * np.sin(phase), 0.0)
    vel = np.where(tau >= 0, A * 2 * math.pi * freq * np.cos(phase), 0.0)
    return pos, vel


@pytest.mark.parametrize(("t0", "T"), [(0.0, 0.6), (0.15, 0.5), (0.0, 0.0)])
def test_chirp_matches_closed_form(t0, T):
    dt, n = 1e-4, 10_000  # 1 s
    th, t = grids(dt, n)
    A, f0, f1, off = 5 * D, 0.5, 8.0, -0.5 * D
    sig = InputSignal("chirp", A, start=t0, freq=f0, freq_end=f1, sweep_time=T, offset=off)
    ref = sample(sig, dt, n)
    T_eff = T or (1.0 - t0)  # sweep_time 0: the whole run after the start
    pos_h, _ = chirp_closed_form(th, A, f0, f1, T_eff, t0, off)
    pos, vel = chirp_closed_form(t, A, f0, f1, T_eff, t0, off)
    np.testing.assert_allclose(ref.pos_half, pos_h, rtol=0, atol=1e-12)
    # the velocity peaks at A*2*pi*f1 = 4.4 rad/s; the same formula, so tight as well
    np.testing.assert_allclose(ref.vel, vel, rtol=0, atol=1e-12)
    # and it is the derivative of the position: central difference over the half steps,
    # error (dt/2)^2/6 * |x'''| <= 1e-8/24 * A*(2*pi*8)^3 = 4.6e-6 rad/s (+ the f' terms)
    # (away from the start and from the end of the sweep, where f(t) has a kink)
    on = (t > t0 + dt) & (t < 1.0 - dt) & (np.abs(t - t0 - T_eff) > dt)
    k = np.nonzero(on)[0]
    fd = (ref.pos_half[2 * k + 1] - ref.pos_half[2 * k - 1]) / dt
    np.testing.assert_allclose(fd, ref.vel[k], rtol=0, atol=1e-5)


def test_chirp_instantaneous_frequency():
    # zero crossings of sin(phase) sit at phase = j*pi; with f0 = 1, f1 = 5 over T = 2 s,
    # phase(tau) = 2*pi*(tau + tau^2) -> the j-th crossing at tau = (-1 + sqrt(1 + 2j))/2
    dt, n = 1e-5, 200_000
    ref = sample(InputSignal("chirp", 1.0, freq=1.0, freq_end=5.0, sweep_time=2.0), dt, n)
    x = ref.pos_half[::2]
    t = np.arange(n + 1) * dt
    idx = np.nonzero(np.sign(x[1:]) != np.sign(x[:-1]))[0]
    idx = idx[x[idx] != 0.0]
    crossings = t[idx] - x[idx] * dt / (x[idx + 1] - x[idx])  # linear interpolation
    j = np.arange(1, len(crossings) + 1)
    np.testing.assert_allclose(crossings, (-1 + np.sqrt(1 + 2 * j)) / 2, rtol=0, atol=1e-8)
    assert len(crossings) == 11  # phase(2 s) = 2*pi*6 = 12*pi -> crossings 1..11 before t = 2


# ------------------------------------------------------------------------------------------
# CSV profiles


def _csv(tmp_path: Path, text: str, name: str = "p.csv") -> Path:
    p = tmp_path / name
    p.write_text(text, encoding="utf-8")
    return p


def test_csv_profile_interpolates_and_holds(tmp_path):
    p = _csv(tmp_path, "t_s,theta_ref_deg,extra\n0.1,0,x\n0.3,10,y\n0.4,-2,z\n")
    t_tab, y_tab = load_profile(p)
    np.testing.assert_array_equal(t_tab, [0.1, 0.3, 0.4])
    np.testing.assert_allclose(y_tab, [0.0, 10 * D, -2 * D], rtol=1e-15)
    sig = InputSignal("csv", path=str(p))
    dt, n = 0.01, 60
    ref = sample(sig, dt, n)
    th, t = grids(dt, n)

    def expected(tt):  # piecewise linear, by hand
        y = np.where(tt < 0.1, 0.0, 0.0)
        y = np.where((tt >= 0.1) & (tt <= 0.3), (tt - 0.1) / 0.2 * 10, y)
        y = np.where((tt > 0.3) & (tt <= 0.4), 10 - (tt - 0.3) / 0.1 * 12, y)
        return np.where(tt > 0.4, -2.0, y) * D

    np.testing.assert_allclose(ref.pos_half, expected(th), rtol=0, atol=1e-14)
    assert ref.pos_half[2 * 20] == pytest.approx(5 * D, abs=1e-15)  # t = 0.2: midway
    assert ref.pos_half[-1] == pytest.approx(-2 * D, abs=1e-15)  # held after the last row
    # velocity: finite differences of the interpolated profile
    assert ref.vel[15] == pytest.approx(50 * D, rel=1e-9)   # t = 0.15 inside segment 1
    assert ref.vel[35] == pytest.approx(-120 * D, rel=1e-9)  # t = 0.35 inside segment 2
    assert ref.vel[5] == 0.0 and ref.vel[50] == 0.0  # before the first / after the last row
    np.testing.assert_allclose(ref.vel, np.gradient(ref.pos_half[::2], t), rtol=0, atol=1e-12)
    # a table given in-line gives the same samples as the file
    sig2 = InputSignal("csv", table=(tuple(t_tab), tuple(y_tab)))
    np.testing.assert_array_equal(sample(sig2, dt, n).pos_half, ref.pos_half)


def test_load_profile_torque_unscaled_and_sampled(tmp_path):
    p = _csv(tmp_path, "t_s,torque_nm\n0,1\n0.02,3\n")
    t, tq = load_profile(p, value="torque_nm", scale=1.0)
    np.testing.assert_array_equal(tq, [1.0, 3.0])
    sig = InputSignal("step", 0.0, load_table=(tuple(t), tuple(tq)))
    ref = sample(sig, 0.01, 4)
    np.testing.assert_allclose(ref.load_half, [1, 1.5, 2, 2.5, 3, 3, 3, 3, 3], rtol=1e-15)
    assert ref.load_half.shape == ref.pos_half.shape


@pytest.mark.parametrize(("text", "match"), [
    ("t_s,theta\n0,1\n1,2\n", r"lacks column\(s\) \['theta_ref_deg'\]"),
    ("time,theta_ref_deg\n0,1\n1,2\n", r"lacks column\(s\) \['t_s'\]"),
    ("t_s,theta_ref_deg\n0,1\n", r"needs at least 2 rows, has 1"),
    ("t_s,theta_ref_deg\n0,1\n1,abc\n", r"empty, non-numeric, NaN or inf"),
    ("t_s,theta_ref_deg\n0,1\n1,\n", r"empty, non-numeric, NaN or inf"),
    ("t_s,theta_ref_deg\n0,1\n0,2\n", r"t_s must be strictly increasing"),
    ("t_s,theta_ref_deg\n1,1\n0,2\n", r"t_s must be strictly increasing"),
    ("", r"is not a readable CSV"),
])
def test_bad_csv_names_the_file(tmp_path, text, match):
    p = _csv(tmp_path, text)
    with pytest.raises(EmaError, match=match) as ei:
        load_profile(p)
    assert f"profile '{p}'" in ei.value.message


def test_missing_profile(tmp_path):
    with pytest.raises(EmaError, match=r"does not exist"):
        load_profile(tmp_path / "none.csv")
    with pytest.raises(EmaError, match=r"does not exist"):  # a csv signal without a table
        sample(InputSignal("csv", path=str(tmp_path / "none.csv")), 1e-3, 10)


def test_unknown_kind():
    with pytest.raises(EmaError, match=r"unknown input kind 'square'"):
        sample(InputSignal("square"), 1e-3, 10)


@pytest.mark.parametrize(("sig", "text"), [
    (InputSignal("step", 20 * D, start=0.5), "20 deg step at t = 0.5 s"),
    (InputSignal("ramp", 0.0, rate=90 * D), "ramp 90 deg/s from t = 0 s"),
    (InputSignal("sine", 5 * D, freq=2.0), "sine 5 deg, 2 Hz"),
    (InputSignal("chirp", 5 * D, freq=0.5, freq_end=8.0), "chirp 5 deg, 0.5 -> 8 Hz"),
    (InputSignal("csv", path="x.csv"), "profile x.csv"),
])
def test_describe(sig, text):
    assert sig.describe() == text


@pytest.mark.parametrize(("end_deg", "rate_deg_s", "expected_deg"), [
    (-10.0, -5.0, -10.0), (10.0, 5.0, 10.0), (10.0, -5.0, -10.0), (-10.0, 5.0, 10.0),
    (0.0, -5.0, -25.0)])
def test_a_ramp_stops_its_amplitude_away_in_the_rate_direction(end_deg, rate_deg_s, expected_deg):
    sig = InputSignal("ramp", end_deg * DEG, rate=rate_deg_s * DEG)
    ref = sample(sig, 0.5, 10)  # 5 s
    assert ref.pos_half[-1] == pytest.approx(expected_deg * DEG, rel=1e-12)
    moving = abs(expected_deg) > 24  # no end: still moving at 5 s
    assert ref.vel[-1] == pytest.approx(rate_deg_s * DEG if moving else 0.0, abs=1e-15)


def test_a_profile_that_is_not_a_file(tmp_path):
    with pytest.raises(EmaError, match=r"is not a file \(a CSV with columns t_s, theta_ref_deg\)"):
        load_profile(tmp_path)
    with pytest.raises(EmaError, match=r"'/dev/null' is not a file"):
        load_profile("/dev/null")
