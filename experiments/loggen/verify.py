"""Verification of the independent generator (issue 21): its convergence in the tolerance and
its agreement with ema's kernel on the laws ema has.

- :func:`convergence`: the same log at two tolerances (or two max steps); the largest
  difference of each channel over 1 % of the channel's RMS (the battery's noise level at 1 %).
- :func:`crosscheck`: the generator against ema's numba kernel (RK4, dt = 1e-5 s) following
  the same command as a ``csv`` reference sampled every 1e-4 s; the largest difference of each
  channel per 1 s window over the channel's RMS. This is the one module here that imports
  ``ema_cli`` (inside :func:`ema_run`); the generator itself never does.

Run: ``python -m experiments.loggen.verify [--duration 4]`` prints both tables.
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Mapping

import numpy as np

from experiments.loggen import odemodel
from experiments.loggen.excitations import Chirp, make_command
from experiments.loggen.logs import LAW_TAU, log_rngs
from experiments.loggen.params import DEG, RPM, resolve

CHANNELS = ("theta_load_deg", "omega_motor_rpm", "current_a", "voltage_cmd_v")
EMA_DT = 1.0e-5  # ema's step in the cross-check [s]
REF_DT = 1.0e-4  # spacing of the csv reference given to ema [s]
CHIRP_SWEEP_S = 4.0  # the chirp's sweep time, as in the battery [s]
CASES = (  # (name, truth overrides SI, excitation)
    ("default", {"alpha": 0.003, "sigma2": 1e-4}, "chirp"),
    ("large_alpha", {"alpha": 0.008, "kL": 400.0, "Fc": 0.06, "sigma2": 0.05}, "chirp"),
    ("small_alpha", {"alpha": 0.0005, "kL": 850.0, "Fc": 0.008, "sigma2": 0.002}, "multisine"),
    ("steps", {"alpha": 0.005, "kL": 600.0, "Fc": 0.03, "sigma2": 0.02}, "steps"),
    ("current_limit", {"alpha": 0.003, "sigma2": 1e-4, "sat3": 0.5}, "chirp"),
)


def channels(tr: odemodel.Trajectory) -> dict[str, np.ndarray]:
    """A trajectory's logged channels, edge units, noise-free."""
    return {"theta_load_deg": tr.state("theta_L") / DEG, "omega_motor_rpm": tr.state("w_m") / RPM,
            "current_a": tr.state("i"), "voltage_cmd_v": tr.u_dem}


def run(truth: Mapping[str, float], law: str, excitation: str, duration_s: float,
        rate_hz: float = 1000.0, seed: int = 0, **kw) -> tuple[np.ndarray, dict, object]:
    """The generator's noise-free channels -> (t, channels, command). The chirp sweeps over
    CHIRP_SWEEP_S whatever the duration (a short run is the start of a battery log)."""
    p = resolve({**truth, "contact_tau": LAW_TAU.get(law, 1e-4)})
    cmd = (Chirp(sweep_s=CHIRP_SWEEP_S) if excitation == "chirp"
           else make_command(excitation, log_rngs(seed)[0], duration_s))
    t = np.arange(int(round(duration_s * rate_hz)) + 1) / rate_hz
    tr = odemodel.simulate(p, law, cmd.value, t, **kw)
    return t, channels(tr), cmd


def convergence(truth: Mapping[str, float], law: str, excitation: str, duration_s: float,
                rtol: float = odemodel.RTOL, rtol_fine: float = 1e-11,
                max_step_fine: float | None = None) -> dict[str, float]:
    """max |y(rtol) - y(fine)| / (1 % of RMS y) per channel (``max_step_fine``: also a
    smaller max step in the fine run)."""
    _, a, _ = run(truth, law, excitation, duration_s, rtol=rtol)
    kw = {"rtol": rtol_fine}
    if max_step_fine is not None:
        kw["max_step"] = max_step_fine
    _, b, _ = run(truth, law, excitation, duration_s, **kw)
    return {c: float(np.max(np.abs(a[c] - b[c])) / (0.01 * np.sqrt(np.mean(b[c] ** 2))))
            for c in CHANNELS}


EMA_LAW = {"jump": {"contact_tau": 0.0}, "ramp": {"contact_tau": LAW_TAU["ramp"]},
           "hunt_crossley": {"contact_tau": 0.0, "contact_hc": 1.0,
                             "contact_pen": odemodel.HC_PEN_REF}}
"""Each law as ema's parameters: the jump and ramp laws by contact_tau; Hunt-Crossley as
ema's contact form with its whole damping penetration-proportional (contact_hc = 1) and the
same reference penetration, so c/(kL*contact_pen) is the generator's lambda."""


def ema_run(truth: Mapping[str, float], law: str, cmd, duration_s: float,
            rate_hz: float = 1000.0, dt: float = EMA_DT) -> dict[str, np.ndarray]:
    """ema's kernel (``ema_cli.sim.runner.simulate``, friction on, the law's :data:`EMA_LAW`) on
    the command sampled every REF_DT as a ``csv`` reference -> channels at rate_hz."""
    from ema_cli.model.params import resolve as ema_resolve
    from ema_cli.sim.runner import simulate
    from ema_cli.sim.signals import InputSignal

    tf = np.arange(int(round(duration_s / REF_DT)) + 1) * REF_DT
    ref = InputSignal("csv", table=(tuple(tf.tolist()), tuple(cmd.sample(tf).tolist())),
                      path="(loggen command)")
    pe = ema_resolve({**truth, "friction": 1.0, **EMA_LAW[law]})
    res = simulate(pe, ref, duration=duration_s, dt=dt, output_interval=1.0 / rate_hz)
    return {c: np.asarray(res.signal(c, edge=True)) for c in CHANNELS}


def window_errors(t: np.ndarray, a: Mapping[str, np.ndarray], b: Mapping[str, np.ndarray],
                  window_s: float) -> dict[str, list[float]]:
    """Per channel: max |a - b| / RMS(b) in each window of ``window_s`` from 0."""
    out: dict[str, list[float]] = {}
    edges = np.arange(0.0, t[-1] + 1e-9, window_s)
    for c in CHANNELS:
        rms = float(np.sqrt(np.mean(b[c] ** 2)))
        d = np.abs(a[c] - b[c])
        out[c] = [float(d[(t >= lo) & (t <= hi)].max() / rms)
                  for lo, hi in zip(edges[:-1], edges[1:], strict=True)]
    return out


def crosscheck(truth: Mapping[str, float], law: str, excitation: str, duration_s: float,
               window_s: float = 1.0) -> dict[str, list[float]]:
    """Per channel: max |generator - ema| / RMS(ema) in each window of ``window_s``."""
    t, a, cmd = run(truth, law, excitation, duration_s)
    return window_errors(t, a, ema_run(truth, law, cmd, duration_s), window_s)


def ema_step_study(truth: Mapping[str, float], law: str, excitation: str, duration_s: float,
                   dts: tuple[float, ...] = (1e-5, 5e-6, 2.5e-6)) -> dict[float, list[float]]:
    """Whose error is a disagreement? theta_load: max |generator - ema(dt)| / RMS per 1 s
    window for each of ema's steps ``dts``: it falls with dt when ema's discretisation is the
    cause (the jump law's torque jump lands on ema's step grid)."""
    t, a, cmd = run(truth, law, excitation, duration_s)
    return {dt: window_errors(t, a, ema_run(truth, law, cmd, duration_s, dt=dt), 1.0)[
        "theta_load_deg"] for dt in dts}


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description="verify the independent log generator")
    ap.add_argument("--duration", type=float, default=4.0, help="log length [s]")
    ap.add_argument("--skip-convergence", action="store_true")
    ap.add_argument("--skip-crosscheck", action="store_true")
    ap.add_argument("--step-study", nargs="*", default=[], metavar="CASE:LAW",
                    help="ema's step refined against the generator, e.g. large_alpha:jump")
    a = ap.parse_args(argv)
    if not a.skip_convergence:
        print(f"convergence: rtol {odemodel.RTOL:g} vs 1e-11, max |diff| / (1 % of RMS), "
              f"{a.duration:g} s, case 'default'")
        for law in odemodel.LAWS:
            t0 = time.perf_counter()
            r = convergence(CASES[0][1], law, CASES[0][2], a.duration)
            print(f"  {law:14s} " + "  ".join(f"{c} {v:.2e}" for c, v in r.items())
                  + f"  ({time.perf_counter() - t0:.0f} s)", flush=True)
    if not a.skip_crosscheck:
        print(f"cross-check vs ema (dt {EMA_DT:g} s, csv reference every {REF_DT:g} s): "
              "max |diff| / RMS per 1 s window")
        for name, truth, exc in CASES:
            for law in ("jump", "ramp"):
                r = crosscheck(truth, law, exc, a.duration)
                for c, v in r.items():
                    print(f"  {name:11s} {exc:9s} {law:5s} {c:16s} "
                          + " ".join(f"{x:.2e}" for x in v), flush=True)


    cases = {name: (truth, exc) for name, truth, exc in CASES}
    for item in a.step_study:
        name, law = item.split(":")
        r = ema_step_study(cases[name][0], law, cases[name][1], a.duration)
        for dt, v in r.items():
            print(f"  step study {name} {law} ema dt {dt:g} s: theta_load "
                  + " ".join(f"{x:.2e}" for x in v), flush=True)


if __name__ == "__main__":
    main()
