"""The compiled simulator (``sim.runner.simulate_batch``) against the independent reference of
tests/helpers/reference_actuator.py (scipy DOP853, every mode switch located by an event), on
random descriptions of every element of the actuator description.

Every element has its own test, parametrized over 10 random descriptions (fixed seeds: the first
4 in the fast tier, all 10 with the slow tier, ``make test-all``) spanning
rotary (rad, N*m, kg*m^2) and translational (m, N, kg) scales; each compares every recorded
sample of every signal the description defines and requires agreement within 1e-6 of that
signal's range (ptp). The compiled simulator is a fixed-step RK4: the step ``DT`` is a power of
two so that every controller sample, input breakpoint and recorded instant falls exactly on its
grid, and small enough for the tolerance (checked by halving it: the disagreements fall as
dt^4, 1e-9 of the range or less where the kernel's integration is smooth; a limit switching
inside a kernel step costs it O(dt^2..3), 2e-7 at 2^-16 s, so the amplifier element runs at
2^-17 s).

Two kernel errors this reference found, fixed since (their minimal cases stay as tests):

* rigid axis: the motor-speed terms (motor viscous ``bm*w_m`` and back-EMF ``Ke*w_m``) used
  the motor speed of the step's start in every RK4 stage (first order in ``dt``): the motor now
  follows the load at every stage (``sim.integrate.motor_follows``);
* a held input signal (``ext_hold``) was sampled at the RK4 stages' instants, so the last stage
  of the step ending at a sample's instant already saw the new sample: a held input is now
  constant over each step, its value after the step's start.

The other elements' rigid descriptions put the viscous damping on the load (``bm = 0``) and
drive with a force (amplifier or force input), and their input signals are interpolated
(``ext_hold=False``) except in the held test, as when the two errors were open.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np
import pytest

from ema_cli.model.params import resolve, to_row
from ema_cli.sim.runner import simulate_batch
from ema_cli.sim.signals import InputSignal
from tests.helpers.reference_actuator import simulate

TOL = 1e-6  # agreement required, relative to each compared signal's range
N_CASES = 10
DT = 2.0**-16  # kernel step [s] (15.3 us): a power of two, every instant below is on its grid
TS_CHOICES = (2.0**-10, 2.0**-9)  # controller sample times [s] (0.98 ms, 1.95 ms)


@dataclass
class Case:
    """One random description: parameter overrides, the run's signal, what to check."""

    overrides: dict
    signal: InputSignal
    stick: tuple[str, ...] = ()  # bodies that must stick, break away and reverse


@dataclass
class Element:
    cases: list[Case]
    n_steps: int
    dec: int
    dt: float = DT


def _grid(t: float, dt: float = DT) -> float:
    """``t`` rounded to the kernel's step grid (exact in binary)."""
    return round(t / dt) * dt


def _lu(rng: np.random.Generator, lo: float, hi: float) -> float:
    """Log-uniform in [lo, hi]."""
    return float(math.exp(rng.uniform(math.log(lo), math.log(hi))))


def _un(rng: np.random.Generator, lo: float, hi: float) -> float:
    return float(rng.uniform(lo, hi))


# ---------------------------------------------------------------- the axes, drives, controllers


@dataclass
class Axis:
    """Mechanics of a description and its scales: ``force`` what the drive gives on the axis
    (load side: N*m or N), ``travel`` a distance it covers in ~0.2 s (rad or m)."""

    ov: dict
    force: float
    travel: float

    @property
    def inertia(self) -> float:
        """Total inertia (mass) on the axis, load side."""
        return self.ov["JL"] + self.ov["m"] ** 2 * self.ov["Jm"]


def _axis(rng, kind: str) -> Axis:
    """``rotary``: a rigid rotary axis (rad, N*m, kg*m^2); ``linear``: a rigid translational
    axis (m, N, kg), a ball screw of lead 4..20 mm (m = 2*pi/lead rad/m) and a 1..200 kg
    carriage; ``compliant``: the paper's compliant rotary EMA, its values spread by +-30 %.
    Rigid axes put all the viscous damping on the load (bm = 0)."""
    if kind == "rotary":
        ov = dict(rigid=1, Jm=_lu(rng, 1e-5, 1e-4), m=_un(rng, 5, 60), JL=_lu(rng, 1e-3, 0.05),
                  bm=0.0, bL=_lu(rng, 1e-3, 0.05))
        acc = _lu(rng, 20.0, 300.0)  # rad/s^2
    elif kind == "linear":
        ov = dict(rigid=1, Jm=_lu(rng, 1e-6, 2e-5), m=2 * math.pi / _un(rng, 4e-3, 20e-3),
                  JL=_lu(rng, 1.0, 200.0), bm=0.0, bL=_lu(rng, 1.0, 100.0))
        acc = _lu(rng, 1.0, 10.0)  # m/s^2
    else:
        s = lambda x: x * _un(rng, 0.7, 1.3)  # noqa: E731
        ov = dict(rigid=0, damping="paper", alpha=0.0, Jm=s(3e-5), bm=s(1e-5), m=s(24.0),
                  JL=s(0.01), bL=s(0.02), kL=s(590.0), c=s(0.25))
        acc = _lu(rng, 20.0, 150.0)
    ax = Axis(ov, 0.0, 0.0)
    ax.force = min(ax.inertia * acc, 500.0)
    ax.travel = min(ax.force / ax.inertia * 0.2**2 / 8, 0.5)
    return ax


def _kind(i: int, kinds: tuple[str, ...]) -> str:
    return kinds[i % len(kinds)]


def _amplifier(rng, ax: Axis, tau: bool, limit: bool = True) -> None:
    """An amplifier drive: gain (load side, per V) for the axis's force at 5..20 V, a limit of
    0.5..1.5 times that force, a first-order bandwidth (``tau``: 0.3..5 ms)."""
    ax.ov.update(drive="amplifier", amp_gain=ax.force / _un(rng, 5.0, 20.0),
                 amp_limit=ax.force * _un(rng, 0.5, 1.5) if limit else "off",
                 amp_tau=_lu(rng, 3e-4, 5e-3) if tau else 0.0)


def _armature(rng, ax: Axis) -> None:
    s = lambda x: x * _un(rng, 0.7, 1.3)  # noqa: E731
    kt = s(0.08)
    ax.ov.update(drive="armature", sat3="off", R=s(0.5), L=s(3e-4), Kt=kt,
                 Ke=kt * _un(rng, 0.9, 1.1))


def _discrete(rng, ax: Axis, lag_samples: float = 1.0, vsrc: str | None = None,
              ts: float | None = None, integral: bool | None = None) -> None:
    """A discrete cascade tuned for the axis: a PI velocity loop whose zero cancels the
    mechanical pole (velocity bandwidth below the shaft's resonance and below what the loop's
    lag of ``lag_samples`` samples allows), a position loop 3..6 times slower, a position
    integral sometimes."""
    ov = ax.ov
    ts = ts or TS_CHOICES[int(rng.integers(len(TS_CHOICES)))]
    fmax = 30.0 if ov["rigid"] == 1 else 8.0  # Hz
    wv = min(2 * math.pi * _un(rng, 0.25, 1.0) * fmax,
             _un(rng, 0.12, 0.25) / (lag_samples * ts))
    damping = ov["bL"] + ov["m"] ** 2 * ov["bm"]
    if ov["drive"] == "amplifier":
        gain = ov["amp_gain"]
    else:  # armature: force per volt at stall, and the back-EMF's damping
        gain = ov["m"] * ov["Kt"] / ov["R"]
        damping += ov["m"] ** 2 * ov["Kt"] * ov["Ke"] / ov["R"]
    kv = ax.inertia * wv / gain
    integral = ov["drive"] == "armature" or (bool(rng.integers(2)) if integral is None
                                             else integral)
    kvi = max(damping * wv / gain, kv * wv / _un(rng, 4, 10)) if integral else 0.0
    ov.update(ctrl="discrete", Ts=ts, dc_kv=kv, dc_kvi=kvi, dc_kp=wv / _un(rng, 3, 6),
              dc_vsrc=vsrc or ("encoder" if rng.integers(2) else "sensor"))
    if rng.integers(2):
        ov["dc_ki"] = ov["dc_kp"] ** 2 / _un(rng, 8, 20)


def _reference(rng, scale: float, t_end: float, continuous: bool = False) -> InputSignal:
    """A position reference of amplitude ~``scale``: a step (between the step grid's instants:
    only for the sampled controllers, which see it at their next sample), a ramp that stops,
    or a sine."""
    kinds = ("ramp", "sine") if continuous else ("step", "ramp", "sine")
    kind = kinds[int(rng.integers(len(kinds)))]
    amp = scale * _un(rng, 0.3, 1.0) * (1 if rng.integers(2) else -1)
    if kind == "step":
        return InputSignal("step", amplitude=amp, start=_grid(_un(rng, 0.01, 0.05)) + DT / 8)
    if kind == "ramp":
        return InputSignal("ramp", amplitude=amp, rate=math.copysign(abs(amp) / _un(rng, 0.05,
                                                                                 0.2), amp),
                           start=_grid(_un(rng, 0.0, 0.03)))
    return InputSignal("sine", amplitude=amp, freq=_un(rng, 0.5, 2.0) / t_end, start=0.0)


def _interp_signal(t: list[float], v: list[float], hold: bool = False,
                   ref: InputSignal | None = None) -> InputSignal:
    """The run's signal: the input table (its instants on the step grid) and a reference
    (default: none)."""
    ref = ref or InputSignal("step", amplitude=0.0)
    return InputSignal(ref.kind, amplitude=ref.amplitude, start=ref.start, rate=ref.rate,
                       freq=ref.freq, ext_table=(tuple(_grid(x) for x in t), tuple(v)),
                       ext_hold=hold)


def _profile(rng, levels: list[float], t_end: float) -> tuple[list[float], list[float]]:
    """A piecewise-linear profile through ``levels``, its knots spread over [0, 0.95 t_end]."""
    w = rng.uniform(0.5, 1.5, len(levels) - 1)
    t = np.concatenate([[0.0], np.cumsum(w) / w.sum() * t_end * 0.95])
    return [float(x) for x in t], [float(x) for x in levels]


def _fir(rng) -> dict:
    """A random position FIR: 1..8 positive taps summing to 1 (a smoothing filter)."""
    n = int(rng.integers(1, 9))
    b = rng.uniform(0.2, 1.0, n)
    b = b / b.sum()
    return {f"dc_fir{k}": float(b[k]) if k < n else 0.0 for k in range(8)}


def _lag(ov: dict, ts: float) -> float:
    """Lag of the velocity estimate and of the command, in samples (for tuning)."""
    taps = [ov.get(f"dc_fir{k}", 1.0 if k == 0 else 0.0) for k in range(8)]
    centroid = sum(k * b for k, b in enumerate(taps)) / sum(taps)
    lp = 1.0 / (2 * math.pi * ov["dc_vfc"] * ts) if ov.get("dc_vfc") else 0.0
    return 1.0 + ov.get("dc_delay", 0) + centroid + (ov.get("dc_ndiff", 1) - 1) / 2 + lp


def _drive(rng, ax: Axis, tau: bool | None = None, limit: bool = True) -> None:
    """The armature on compliant axes, an amplifier (bandwidth sometimes) on rigid ones (see
    the module's docstring)."""
    if ax.ov["rigid"] == 0:
        _armature(rng, ax)
    else:
        _amplifier(rng, ax, bool(rng.integers(2)) if tau is None else tau, limit)


# ---------------------------------------------------------------- the elements


def _rigid_axis_cases() -> Element:
    """A rigid rotary axis with its armature drive and motor viscous damping under the paper's
    continuous cascade (sine or ramp reference)."""
    rng = np.random.default_rng(101)
    cases = []
    for _ in range(N_CASES):
        ax = _axis(rng, "rotary")
        ax.ov["bm"] = _lu(rng, 2e-6, 5e-5)
        _armature(rng, ax)
        ov = ax.ov
        jmot = ov["Jm"] + ov["JL"] / ov["m"] ** 2
        wv = 2 * math.pi * _un(rng, 15, 40)
        kps = wv * ov["R"] * jmot / ov["Kt"]
        ov.update(ctrl="paper", Ts=0.0, sat1="off", sat2="off", Kps=kps,
                  Kis=kps * wv / _un(rng, 4, 10), Kpp=wv / _un(rng, 4, 8))
        cases.append(Case(ov, _reference(rng, ax.travel, 0.25, continuous=True)))
    return Element(cases, n_steps=2**14, dec=2**6)


def _translational_cases() -> Element:
    """A rigid translational axis (m, N, kg) with an amplifier (force) drive and its limit
    under the discrete cascade, a velocity limit sometimes: the EMPS-like benchmark axis."""
    rng = np.random.default_rng(202)
    cases = []
    for _ in range(N_CASES):
        ax = _axis(rng, "linear")
        _amplifier(rng, ax, tau=False)
        _discrete(rng, ax)
        if rng.integers(2):
            ax.ov["dc_vmax"] = ax.travel / _un(rng, 0.05, 0.2)
        cases.append(Case(ax.ov, _reference(rng, ax.travel, 0.5)))
    return Element(cases, n_steps=2**15, dec=2**6)


def _amplifier_cases() -> Element:
    """The amplifier drive with a first-order bandwidth and its limit: rigid and compliant
    axes, driven by an interpolated command (plant only: the limit engages and releases
    between steps) or by the discrete cascade."""
    rng = np.random.default_rng(303)
    cases = []
    for i in range(N_CASES):
        ax = _axis(rng, _kind(i, ("rotary", "compliant", "linear", "compliant")))
        _amplifier(rng, ax, tau=True)
        ov = ax.ov
        if i % 3 == 0:  # plant only: a command of alternating sign, into the limit and out
            ulim = ov["amp_limit"] / ov["amp_gain"]
            lv = [0.0] + [float((-1) ** k * ulim * _un(rng, 0.3, 2.0)) for k in range(7)]
            ov.update(ctrl="none", plant_input="command")
            cases.append(Case(ov, _interp_signal(*_profile(rng, lv + [0.0], 0.25))))
        else:
            _discrete(rng, ax, lag_samples=1.0 + ov["amp_tau"] / 1e-3)
            cases.append(Case(ov, _reference(rng, ax.travel, 0.25)))
    # a step of DT/2: the limit's kinks inside the kernel's steps (plant only) cost it
    # O(dt^2..3): 2e-7 of the range at DT, 2e-8 at DT/2
    return Element(cases, n_steps=2**15, dec=2**7, dt=DT / 2)


def _friction_site(rng, ov: dict, site: str, level: float, vscale: float,
                   stribeck: bool) -> tuple[float, float]:
    """Static friction at ``site`` (motor or load), different in +x and -x: Coulomb ~``level``
    (the site's units), breakaway 1.05..1.6 times it, viscous up to the Coulomb level at the
    speed ``vscale`` (load side), Stribeck speed 0.05..1 vscale and exponent 1..2.5 when asked.
    Returns the site's breakaway (+, -) on the axis, load side."""
    fc, fcn = level * _un(rng, 0.5, 1.0), level * _un(rng, 0.5, 1.0)
    fs, fsn = fc * _un(rng, 1.05, 1.6), fcn * _un(rng, 1.05, 1.6)
    if site == "motor":
        w = vscale * ov["m"]  # motor speed scale
        ov.update(friction="static", Fc=fc, Fs=fs, Fc_neg=fcn, Fs_neg=fsn,
                  sigma2=fc / w * _un(rng, 0.0, 1.0), sigma2_neg=fcn / w * _un(rng, 0.0, 1.0),
                  vs=_lu(rng, 0.05, 1.0) * w if stribeck else 0.0,
                  delta=_un(rng, 1.0, 2.5) if stribeck else 1.0)
        return ov["m"] * fs, ov["m"] * fsn
    ov.update(friction_L="static", Fc_L=fc, Fs_L=fs, Fc_L_neg=fcn, Fs_L_neg=fsn,
              Fv_L=fc / vscale * _un(rng, 0.0, 1.0), Fv_L_neg=fcn / vscale * _un(rng, 0.0, 1.0),
              vs_L=_lu(rng, 0.05, 1.0) * vscale if stribeck else 0.0,
              delta_L=_un(rng, 1.0, 2.5) if stribeck else 1.0)
    return fs, fsn


def _friction_cases(seed: int, stribeck: bool) -> Element:
    """Asymmetric static friction (Coulomb + viscous, with Stribeck when asked) on rigid and
    compliant axes, at the load, the motor or both, driven by a force profile on the axis
    that breaks away, falls inside the band (the body stops and sticks: below the Coulomb
    levels), breaks away the other way (reversal), and so on."""
    rng = np.random.default_rng(seed)
    cases = []
    layout = (("linear", ("load",)), ("linear", ("motor", "load")), ("compliant", ("load",)),
              ("compliant", ("motor",)), ("compliant", ("motor", "load")),
              ("rotary", ("load",)), ("rotary", ("motor", "load")), ("compliant", ("load",)),
              ("compliant", ("motor",)), ("compliant", ("motor", "load")))
    for i in range(N_CASES):
        kind, sites = layout[i]
        ax = _axis(rng, kind)
        ov = ax.ov
        ov.update(drive="amplifier", ctrl="none", plant_input="force")
        level = ax.force * _un(rng, 0.2, 0.6)  # friction ~ a part of the drive's force
        vscale = ax.travel / 0.1
        bp = bn = 0.0
        for site in sites:
            lvl = level / len(sites) / (ov["m"] if site == "motor" else 1.0)
            p_, n_ = _friction_site(rng, ov, site, lvl, vscale, stribeck)
            bp, bn = bp + p_, bn + n_
        hi = lambda: _un(rng, 1.2, 2.0)  # noqa: E731
        lo = lambda: _un(rng, -0.3, 0.3)  # noqa: E731
        lv = [0.0, hi() * bp, lo() * bp, -hi() * bn, lo() * bn, hi() * bp, hi() * bp,
              -hi() * bn, lo() * bn, 0.0]
        stick = ("load",) if ov["rigid"] else sites
        cases.append(Case(ov, _interp_signal(*_profile(rng, lv, 0.5)), stick=stick))
    return Element(cases, n_steps=2**15, dec=2**6)


def _offset_cases() -> Element:
    """A constant offset force (gravity-like, either sign; a constant external force and a
    hinge gradient sometimes) held by the discrete cascade with its integrators."""
    rng = np.random.default_rng(404)
    cases = []
    for i in range(N_CASES):
        ax = _axis(rng, _kind(i, ("linear", "compliant", "rotary")))
        _drive(rng, ax, limit=False)
        _discrete(rng, ax, integral=True)
        ov = ax.ov
        ov["offset"] = ax.force * _un(rng, 0.1, 0.5) * (1 if rng.integers(2) else -1)
        if rng.integers(2):
            ov["T_load"] = ax.force * _un(rng, -0.2, 0.2)
        if rng.integers(2):
            ov["k_h"] = ax.force * _un(rng, 0.0, 0.3) / ax.travel
        cases.append(Case(ov, _reference(rng, ax.travel, 0.5)))
    return Element(cases, n_steps=2**15, dec=2**6)


def _encoder_cases() -> Element:
    """The encoder-difference velocity of the discrete cascade: an n-sample difference
    (1..16) after a position FIR of 1..8 taps, a low-pass sometimes, a position quantum
    (100..10000 counts over the travel) sometimes."""
    rng = np.random.default_rng(505)
    cases = []
    for i in range(N_CASES):
        ax = _axis(rng, _kind(i, ("linear", "rotary", "compliant")))
        _drive(rng, ax, tau=False, limit=False)
        ov = ax.ov
        ts = TS_CHOICES[int(rng.integers(2))]
        ov.update(_fir(rng), dc_ndiff=int(rng.integers(1, 17)))
        if rng.integers(2):
            ov["dc_vfc"] = _un(rng, 0.05, 0.3) / ts
        _discrete(rng, ax, lag_samples=_lag(ov, ts), vsrc="encoder", ts=ts)
        if i % 2:
            ov["q_pos"] = ax.travel * _lu(rng, 1e-4, 1e-2)
        cases.append(Case(ov, _reference(rng, ax.travel, 0.5)))
    return Element(cases, n_steps=2**15, dec=2**6)


def _delay_cases() -> Element:
    """A computation delay of 1..8 samples in the discrete cascade (either velocity source)."""
    rng = np.random.default_rng(606)
    cases = []
    for i in range(N_CASES):
        ax = _axis(rng, _kind(i, ("linear", "rotary", "compliant")))
        _drive(rng, ax)
        ov = ax.ov
        ts = TS_CHOICES[int(rng.integers(2))]
        ov.update(dc_delay=int(rng.integers(1, 9)), dc_ndiff=int(rng.integers(1, 4)))
        _discrete(rng, ax, lag_samples=_lag(ov, ts), ts=ts)
        cases.append(Case(ov, _reference(rng, ax.travel, 0.5)))
    return Element(cases, n_steps=2**15, dec=2**6)


def _disturbance_cases(hold: bool) -> Element:
    """A logged disturbance (a random walk with a jump, one value per controller sample, held
    or interpolated) added to the discrete cascade's output."""
    rng = np.random.default_rng(707 if hold else 708)
    cases = []
    for i in range(N_CASES):
        ax = _axis(rng, _kind(i, ("linear", "rotary", "compliant")))
        _drive(rng, ax)
        _discrete(rng, ax)
        ov = ax.ov
        ov["dist_out"] = 1
        ts = ov["Ts"]
        unit = ax.force / (ov["amp_gain"] if ov["drive"] == "amplifier"
                           else ov["m"] * ov["Kt"] / ov["R"])  # command for the axis's force
        n = int(0.5 / ts) + 1
        walk = np.cumsum(rng.normal(0.0, 0.05, n)) + np.where(np.arange(n) > n // 2, 0.3, 0.0)
        cases.append(Case(ov, _interp_signal([k * ts for k in range(n)],
                                             [float(x) for x in 0.5 * unit * walk], hold=hold,
                                             ref=_reference(rng, ax.travel, 0.5))))
    return Element(cases, n_steps=2**15, dec=2**6)


def _transmission_cases() -> Element:
    """The compliant transmission's friction (a Dahl element, level 2..20 % of the axis's force,
    stiffness 0.3..3 kL) and, on half the cases, a backlash (0.5..3 mrad half width) bridged by
    an anti-backlash preload (0..10 % of the force), under the discrete cascade; the reference
    reverses so that the twist rate does and the loop closes."""
    rng = np.random.default_rng(1010)
    cases = []
    for i in range(N_CASES):
        ax = _axis(rng, "compliant")
        _drive(rng, ax)
        _discrete(rng, ax)
        ov = ax.ov
        ov.update(Fc_t=ax.force * _un(rng, 0.02, 0.2), sigma_t=ov["kL"] * _lu(rng, 0.3, 3.0))
        if i % 2:
            ov.update(alpha=_lu(rng, 5e-4, 3e-3), preload=ax.force * _un(rng, 0.0, 0.1))
        cases.append(Case(ov, _reference(rng, ax.travel, 0.5)))
    return Element(cases, n_steps=2**15, dec=2**6)


ELEMENTS = {
    "transmission": _transmission_cases,
    "rigid_axis": _rigid_axis_cases,
    "translational": _translational_cases,
    "amplifier": _amplifier_cases,
    "coulomb": lambda: _friction_cases(808, stribeck=False),
    "stribeck": lambda: _friction_cases(909, stribeck=True),
    "offset": _offset_cases,
    "encoder": _encoder_cases,
    "delay": _delay_cases,
    "disturbance": lambda: _disturbance_cases(hold=False),
    "disturbance_held": lambda: _disturbance_cases(hold=True),
}


# ---------------------------------------------------------------- running and comparing


@functools.cache
def element(name: str) -> Element:
    return ELEMENTS[name]()


@functools.cache
def kernel_run(name: str):
    """Every description of an element in one batch of the compiled simulator."""
    el = element(name)
    P = np.array([to_row(resolve(c.overrides)) for c in el.cases])
    refs = [c.signal for c in el.cases]
    return simulate_batch(P, refs, np.arange(len(refs)), el.dt, el.n_steps, el.dec)


def compared_signals(p: dict, kernel_names) -> dict[str, str]:
    """Kernel signal -> reference signal, for every signal the description defines."""
    out = {n: n for n in ("theta_load", "omega_load", "theta_motor", "omega_motor")}
    ctrl, pin = p["ctrl"], p["plant_input"]
    drives = not (ctrl == 2.0 and pin != 0.0)  # the command goes through the drive
    if drives:
        out["voltage_cmd"] = "voltage_cmd"
    if drives and p["drive"] == 0.0:
        out["current"] = "current"
    if "drive_force" in kernel_names:
        out["drive_force"] = "drive_force"
    if p["rigid"] == 1.0:
        if p["friction"] == 2.0 or p["friction_L"] == 2.0:
            out["friction_load"] = "friction_total"  # the rigid axis reports the sum
    else:
        if p["friction_L"] == 2.0:
            out["friction_load"] = "friction_load"
        if p["friction"] == 2.0:
            out["torque_friction"] = "torque_friction"
    return {k: v for k, v in out.items() if k in kernel_names}


def disagreement(name: str, i: int) -> tuple[dict[str, float], str]:
    """(signal -> max|kernel - reference|/ptp, the worst sample described) for case i."""
    el = element(name)
    res = kernel_run(name)
    case = el.cases[i]
    p = resolve(case.overrides)
    ref = simulate(p, case.signal, res.t_out)
    rel: dict[str, float] = {}
    worst, where = -1.0, ""
    for kname, rname in compared_signals(p, res.signal_names).items():
        k, r = res.signal(kname, i), ref[rname]
        assert np.all(np.isfinite(k)) and np.all(np.isfinite(r)), kname
        span = float(np.ptp(r))
        err = np.abs(k - r)
        rel[kname] = float(err.max() / span) if span > 0 else float(err.max())
        if rel[kname] > worst:
            j = int(np.argmax(err > TOL * span)) if np.any(err > TOL * span) else int(
                np.argmax(err))
            worst = rel[kname]
            where = (f"{kname}: first sample over tolerance j={j} t={res.t_out[j]:.9g} s: "
                     f"kernel {k[j]!r}, reference {r[j]!r} (range {span:.6g}; max rel "
                     f"{rel[kname]:.3g})")
    _check_stick(case, res, i, ref)
    return rel, where


def _check_stick(case: Case, res, i: int, ref) -> None:
    """The friction cases must stick (speed exactly 0 over a stretch of samples, after moving),
    break away and reverse, in the kernel and in the reference alike."""
    for body in case.stick:
        kname = "omega_motor" if body == "motor" else "omega_load"
        w = res.signal(kname, i)
        moved = np.flatnonzero(w != 0)
        assert moved.size, f"{body} never moves"
        after = w[moved[0]:]
        zero = after == 0
        # longest run of exact zeros after the first motion
        runs = np.diff(np.flatnonzero(np.diff(np.concatenate([[0], zero.astype(int), [0]]))))
        longest = int(runs[::2].max()) if runs.size else 0
        assert longest >= 5, f"{body} does not stick after moving (longest rest {longest})"
        assert (w > 0).any() and (w < 0).any(), f"{body} does not reverse"
        rname = "omega_motor" if body == "motor" else "omega_load"
        np.testing.assert_array_equal(w == 0, ref[rname] == 0, err_msg=f"{body} rest samples")


def check(name: str, i: int) -> None:
    rel, where = disagreement(name, i)
    bad = {k: v for k, v in rel.items() if v > TOL}
    assert not bad, f"{name}[{i}] disagrees: {bad}; {where}"


FAST_CASES = 4  # descriptions per element in the fast tier; the other 6 run in the slow tier
CASES = [i if i < FAST_CASES else pytest.param(i, marks=pytest.mark.slow)
         for i in range(N_CASES)]
@pytest.mark.parametrize("i", CASES)
def test_rigid_axis(i):
    check("rigid_axis", i)


@pytest.mark.parametrize("i", CASES)
def test_translational_units(i):
    check("translational", i)


@pytest.mark.parametrize("i", CASES)
def test_amplifier_bandwidth(i):
    check("amplifier", i)


@pytest.mark.parametrize("i", CASES)
def test_asymmetric_coulomb_viscous_stiction(i):
    check("coulomb", i)


@pytest.mark.parametrize("i", CASES)
def test_stribeck_friction(i):
    check("stribeck", i)


@pytest.mark.parametrize("i", CASES)
def test_offset_force(i):
    check("offset", i)


@pytest.mark.parametrize("i", CASES)
def test_encoder_difference_velocity(i):
    check("encoder", i)


@pytest.mark.parametrize("i", CASES)
def test_computation_delay(i):
    check("delay", i)


@pytest.mark.parametrize("i", CASES)
def test_disturbance_interpolated(i):
    check("disturbance", i)


@pytest.mark.parametrize("i", CASES)
def test_disturbance_held(i):
    check("disturbance_held", i)


@pytest.mark.parametrize("i", CASES)
def test_transmission_friction_and_preload(i):
    check("transmission", i)


# ---------------------------------------------------------------- the reference on its own
# closed forms and hand-written recurrences: the reference must be right by itself (to 1e-10 of
# each range: the dense output's interpolation at rtol 1e-12; the comparisons need 1e-6)


def _force_run(over: dict, force: float, t: np.ndarray, **sig) -> dict:
    """The reference on a plant-only axis driven by a constant force (load side)."""
    p = resolve(dict(dict(drive="amplifier", ctrl="none", plant_input="force"), **over))
    table = ((0.0, 1.0), (force, force))
    return simulate(p, InputSignal("step", amplitude=0.0, ext_table=table, ext_hold=False,
                                   **sig), t)


def test_reference_mass_with_force_and_viscous_friction():
    # M v' = F - Fc - b v from rest: v = (F - Fc)/b (1 - e^{-bt/M}), x its integral; b includes
    # the motor viscous on the rigid axis (m^2 bm)
    t = np.linspace(0.0, 0.5, 201)
    JL, m, Jm, bL, bm, F = 20.0, 600.0, 2e-5, 30.0, 2e-5, 40.0
    M, b = JL + m * m * Jm, bL + m * m * bm
    for fc in (0.0, 7.0):
        over = dict(rigid=1, JL=JL, m=m, Jm=Jm, bL=bL, bm=bm)
        if fc:
            over.update(friction_L="static", Fc_L=fc, Fs_L=1.3 * fc)
        r = _force_run(over, F, t)
        v = (F - fc) / b * (1 - np.exp(-b * t / M))
        x = (F - fc) / b * (t - M / b * (1 - np.exp(-b * t / M)))
        np.testing.assert_allclose(r["omega_load"], v, rtol=0, atol=1e-10 * v.max())
        np.testing.assert_allclose(r["theta_load"], x, rtol=0, atol=1e-10 * x.max())
        np.testing.assert_allclose(r["omega_motor"], m * v, rtol=0, atol=1e-10 * m * v.max())
        np.testing.assert_allclose(r["friction_total"][1:], fc + 0 * t[1:], atol=1e-12)


def test_reference_sticks_inside_the_band_and_slips_outside():
    # asymmetric band: Fs+ = 3, Fs- = 2 (Coulomb 2.5 / 1.2, viscous 0.5 / 0.8)
    t = np.linspace(0.0, 0.3, 61)
    over = dict(rigid=1, JL=2.0, m=10.0, Jm=1e-3, bL=1.0, bm=0.0, friction_L="static",
                Fc_L=2.5, Fs_L=3.0, Fv_L=0.5, Fc_L_neg=1.2, Fs_L_neg=2.0, Fv_L_neg=0.8)
    M, b = 2.0 + 100 * 1e-3, 1.0
    for f in (2.99, -1.99, 0.0):
        r = _force_run(over, f, t)
        assert np.all(r["omega_load"] == 0) and np.all(r["theta_load"] == 0)
        np.testing.assert_allclose(r["friction_total"], f, atol=1e-15)  # holds what is asked
        assert r.stuck["rigid"].all()
    for f, fc, fv in ((3.01, 2.5, 0.5), (-2.01, -1.2, 0.8)):
        r = _force_run(over, f, t)
        v = (f - fc) / (b + fv) * (1 - np.exp(-(b + fv) * t / M))
        np.testing.assert_allclose(r["omega_load"], v, rtol=0, atol=1e-10 * abs(v).max())
        assert not r.stuck["rigid"][1:].any()


def test_reference_stops_at_the_closed_form_instant_and_sticks():
    # launched at v0 with no force: M v' = -Fc - b v until v = 0 at t* = M/b ln(1 + b v0/Fc),
    # then at rest for good (0 is inside the band)
    M, b, fc, v0 = 5.0, 2.0, 3.0, 1.5
    tstar = M / b * math.log(1 + b * v0 / fc)
    t = np.linspace(0.0, 2.0, 401)
    over = dict(rigid=1, JL=M, m=1.0, Jm=1e-9, bL=b, bm=0.0, friction_L="static", Fc_L=fc,
                Fs_L=fc, x0_w_L=v0)
    r = _force_run(over, 0.0, t)
    M += 1e-9
    v = np.where(t < tstar, (v0 + fc / b) * np.exp(-b * t / M) - fc / b, 0.0)
    tc = np.minimum(t, tstar)
    x = M / b * (v0 + fc / b) * (1 - np.exp(-b * tc / M)) - fc / b * tc
    np.testing.assert_allclose(r["omega_load"], v, rtol=0, atol=1e-10 * v0)
    np.testing.assert_allclose(r["theta_load"], x, rtol=0, atol=1e-10 * x.max())
    assert np.all(r["omega_load"][t > tstar] == 0) and np.all(r["omega_load"][t < tstar] > 0)
    assert r.stuck["rigid"][t > tstar].all()


def test_reference_amplifier_first_order_step_and_limit():
    # f = f* (1 - e^{-(t - t0)/tau}), f* = clip(gain*u, +-limit); a held command step at t0
    tau, gain = 2e-3, 5.0
    t = np.linspace(0.0, 0.03, 301)
    t0 = t[100]  # a recorded instant: there the new command (right-hand limits)
    for u, limit in ((1.5, math.inf), (1.5, 4.0), (-2.0, 4.0)):
        p = resolve(dict(rigid=1, drive="amplifier", ctrl="none", plant_input="command",
                         amp_tau=tau, amp_gain=gain, amp_limit=limit))
        sig = InputSignal("step", amplitude=0.0, ext_table=((0.0, t0), (0.0, u)), ext_hold=True)
        r = simulate(p, sig, t)
        fstar = min(max(gain * u, -limit), limit)
        f = np.where(t >= t0, fstar * (1 - np.exp(-(t - t0) / tau)), 0.0)
        np.testing.assert_allclose(r["drive_force"], f, rtol=0, atol=1e-10 * abs(fstar))
        np.testing.assert_array_equal(r["voltage_cmd"], np.where(t >= t0, u, 0.0))


def test_reference_compliant_paper_cascade_is_the_linear_model():
    # no limit, no backlash, no friction: the loop is linear; tests/helpers/linear.py writes its
    # state-space model by hand. A step r = A from t = 0: x(t) = int_0^t e^{A s} ds B A
    from scipy.linalg import expm

    from tests.helpers.linear import linear_ss

    p = resolve(dict(damping="paper", sat1="off", sat2="off", sat3="off", Kps=0.1, Kis=1.0))
    ss = linear_ss(p)
    amp = 0.1
    t = np.linspace(0.0, 0.1, 101)
    r = simulate(p, InputSignal("step", amplitude=amp, start=0.0), t)
    n = ss.A.shape[0]
    aug = np.zeros((n + 1, n + 1))
    aug[:n, :n], aug[:n, n] = ss.A, ss.B[:, 0] * amp
    x = np.array([expm(aug * tk)[:n, n] for tk in t])  # states [th_m, w_m, i, th_L, w_L, xI]
    for name, k in (("theta_load", 3), ("omega_load", 4), ("omega_motor", 1), ("current", 2)):
        np.testing.assert_allclose(r[name], x[:, k], rtol=0, atol=1e-9 * np.ptp(x[:, k]))
    np.testing.assert_allclose(r["theta_motor"], x[:, 0] / p["m"], rtol=0,
                               atol=1e-9 * np.ptp(x[:, 0] / p["m"]))


def _rigid_armature_exact(p: dict, volts: float, t: np.ndarray) -> np.ndarray:
    """Rigid axis, armature, constant voltage U from rest: states [i, w_L] with
    L i' = U - R i - Ke m w_L, M w_L' = m Kt i - (bL + m^2 bm) w_L, by the matrix exponential."""
    from scipy.linalg import expm

    m, M = p["m"], p["JL"] + p["m"] ** 2 * p["Jm"]
    A = np.array([[-p["R"] / p["L"], -p["Ke"] * m / p["L"]],
                  [m * p["Kt"] / M, -(p["bL"] + m * m * p["bm"]) / M]])
    aug = np.zeros((3, 3))
    aug[:2, :2], aug[0, 2] = A, volts / p["L"]
    return np.array([expm(aug * tk)[:2, 2] for tk in t])


RIGID_ARMATURE = dict(rigid=1, drive="armature", sat3="off", ctrl="none",
                      plant_input="command", m=24.0, JL=0.01, bL=0.02)
VOLTS = InputSignal("step", amplitude=0.0, ext_table=((0.0, 1.0), (10.0, 10.0)), ext_hold=False)


def test_reference_rigid_armature_is_the_linear_model():
    p = resolve(dict(RIGID_ARMATURE, bm=2e-5))
    t = np.linspace(0.0, 0.02, 81)
    x = _rigid_armature_exact(p, 10.0, t)
    r = simulate(p, VOLTS, t)
    np.testing.assert_allclose(r["current"], x[:, 0], rtol=0, atol=1e-10 * np.ptp(x[:, 0]))
    np.testing.assert_allclose(r["omega_load"], x[:, 1], rtol=0, atol=1e-10 * np.ptp(x[:, 1]))


def test_reference_discrete_cascade_by_hand():
    # a free mass M driven by F = g*u (zero-order hold): exact kinematics between samples,
    # x+ = x + v Ts + a Ts^2/2, v+ = v + a Ts; the cascade written out by hand, array style
    M, g, ts = 3.0, 2.0, 2.0**-10
    taps = np.array([0.4, 0.3, 0.2, 0.1, 0, 0, 0, 0])
    n, d, fc = 5, 3, 60.0
    kp, ki, kv, kvi, vmax, umax = 20.0, 50.0, 40.0, 400.0, 0.05, 2.0
    over = dict(rigid=1, JL=M, m=1.0, Jm=1e-12, bL=0.0, bm=0.0, drive="amplifier", amp_gain=g,
                ctrl="discrete", Ts=ts, dc_kp=kp, dc_ki=ki, dc_kv=kv, dc_kvi=kvi,
                dc_vmax=vmax, dc_umax=umax, dc_ndiff=n, dc_delay=d, dc_vfc=fc,
                **{f"dc_fir{k}": float(b) for k, b in enumerate(taps)})
    p = resolve(over)
    M = M + 1e-12
    a_lp = math.exp(-2 * math.pi * fc * ts)
    K = 300
    x = v = vf = xp = xv = 0.0
    qs: list[float] = []
    us: list[float] = []

    def qf(j: int) -> float:  # the FIR on the position history (q[j] = q[0] for j < 0)
        return sum(b * qs[max(j - i, 0)] for i, b in enumerate(taps))

    for k in range(K):
        r = 0.01
        qs.append(x)
        vf = a_lp * vf + (1 - a_lp) * (qf(k) - qf(k - n)) / (n * ts)
        e = r - x
        pre = kp * e + ki * xp
        vs = float(np.clip(pre, -vmax, vmax))
        pre_u = kv * (vs - vf) + kvi * xv
        u = float(np.clip(pre_u, -umax, umax))
        if not (abs(pre) > vmax and e * pre > 0):
            xp += ts * e
        if not (abs(pre_u) > umax and (vs - vf) * pre_u > 0):
            xv += ts * (vs - vf)
        us.append(u)
        ua = us[k - d] if k >= d else 0.0
        acc = g * ua / M
        x, v = x + v * ts + acc * ts * ts / 2, v + acc * ts
    t = np.arange(K) * ts
    res = simulate(p, InputSignal("step", amplitude=0.01, start=0.0), t)
    np.testing.assert_allclose(res["theta_load"], qs, rtol=0, atol=1e-10 * np.ptp(qs))
    applied = [us[k - d] if k >= d else 0.0 for k in range(K)]
    np.testing.assert_allclose(res["voltage_cmd"], applied, rtol=0, atol=1e-10 * umax)
    assert max(abs(np.array(us))) == umax  # the limits were exercised


# ---------------------------------------------------------------- minimal reproductions


def test_rigid_motor_viscous_minimal():
    # rigid axis, 300 N from rest, m = 600 rad/m, Jm = 3e-5, JL = 2 kg, bL = 1, bm = 1e-5:
    # M = 12.8 kg, b = 4.6 N*s/m, v(T) = F/b (1 - e^{-bT/M}) at T = 2^-10 s (64 steps)
    dt, steps = DT, 64
    over = dict(rigid=1, drive="amplifier", ctrl="none", plant_input="force", m=600.0,
                Jm=3e-5, JL=2.0, bL=1.0, bm=1e-5)
    sig = InputSignal("step", amplitude=0.0, ext_table=((0.0, 1.0), (300.0, 300.0)),
                      ext_hold=False)
    res = simulate_batch(np.array([to_row(resolve(over))]), [sig], None, dt, steps, steps)
    T, M, b = steps * dt, 12.8, 4.6
    exact = 300.0 / b * (1 - math.exp(-b * T / M))  # 0.022884167734952...
    assert abs(res.signal("omega_load")[1] - exact) <= 1e-9 * exact  # kernel: 0.0228842168...


def test_rigid_back_emf_minimal():
    # rigid axis, armature (paper values, bm = 0), 10 V from rest, 20 ms at dt = 2^-16 s: the
    # kernel's load speed is 9e-4 of its range off the matrix exponential (current 1.6e-3)
    p = resolve(dict(RIGID_ARMATURE, bm=0.0))
    steps, dec = 1280, 64
    res = simulate_batch(np.array([to_row(p)]), [VOLTS], None, DT, steps, dec)
    x = _rigid_armature_exact(p, 10.0, res.t_out)
    for k, name in ((0, "current"), (1, "omega_load")):
        err = np.abs(res.signal(name) - x[:, k]).max() / np.ptp(x[:, k])
        assert err <= TOL, f"{name}: {err:.3g} of its range"


def test_held_input_minimal():
    # a held force 0 -> 1 N at t = 2^-10 s on a free 1 kg mass: at rest until then
    over = dict(rigid=1, drive="amplifier", ctrl="none", plant_input="force", m=1.0,
                Jm=1e-12, JL=1.0, bL=0.0, bm=0.0)
    sig = InputSignal("step", amplitude=0.0, ext_table=((0.0, 2.0**-10), (0.0, 1.0)),
                      ext_hold=True)
    res = simulate_batch(np.array([to_row(resolve(over))]), [sig], None, DT, 128, 1)
    w = res.signal("omega_load")
    assert w[64] == 0.0  # kernel: dt/6 = 2.54e-6 m/s
    np.testing.assert_allclose(w[65:], (np.arange(65, 129) - 64) * DT / (1 + 1e-12),
                               rtol=1e-12)
