"""Bit-exact fingerprints of the kernel's outputs for the paper's EMA (a refactor guard).

Runs a fixed set of configurations through ``sim.runner.simulate_batch`` covering every kernel
variant of the reference EMA (no friction, LuGre with exponent 1 and another, the digital
controller, quantisers, every compensator, the locked motor, both damping forms, backlash,
load profiles and springs), every entry point (one lane and 16 lanes, serial and parallel) and
time chunks, and writes a SHA-256 of the recorded signals and of the metrics of each case.

    python experiments/goldens.py --out tests/goldens/kernel.json          # record
    python experiments/goldens.py --check tests/goldens/kernel.json        # compare

The fingerprints hold for one machine kind: fused multiply-adds are compiled for the host CPU,
so the file records the CPU model and instruction-set flags it was made on, and ``--check``
(and ``tests/system/test_goldens.py``) compares only on a machine that matches.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import sys
from pathlib import Path

import numpy as np

from ema_cli.model.params import resolve, to_row
from ema_cli.sim import runner
from ema_cli.sim.signals import InputSignal
from ema_cli.sim.tables import PAPER_SIGNALS
from ema_cli.units import DEG

CASES: dict[str, dict[str, float]] = {
    "default": {},
    "backlash_contact": {"alpha": 0.003},
    "backlash_paper": {"alpha": 0.003, "damping": "paper"},
    "backlash_jump": {"alpha": 0.002, "contact_tau": 0.0},
    "backlash_hc": {"alpha": 0.002, "contact_hc": 0.5},
    "lugre_exp1": {"friction": 1.0, "sigma2": 0.001},
    "lugre_exp": {"friction": 1.0, "delta": 1.7, "Fc": 0.03},
    "lugre_backlash": {"friction": 1.0, "alpha": 0.001, "sigma2": 0.01},
    "deadzones": {"d1": 0.1, "d3": 0.5, "d4": 1e-4},
    "no_sats": {"sat1": float("inf"), "sat2": float("inf"), "sat3": float("inf")},
    "locked": {"locked": 1.0, "T_load": 2.0, "alpha": 0.001},
    "spring": {"k_h": 50.0, "T_load": -1.0},
    "digital": {"Ts": 1e-3},
    "digital_friction": {"Ts": 5e-4, "friction": 1.0},
    "quantisers": {"q_pos": 2 * np.pi / 65536, "q_speed": 1.0 * 2 * np.pi / 60},
    "dzi": {"d1": 0.5, "dzi_v": 0.5},
    "ff": {"friction": 1.0, "ff_fc": 0.02, "ff_fs": 0.03, "ff_sigma2": 0.001},
    "observer": {"friction": 1.0, "ff_fc": 0.02, "ff_sigma0": 20.0, "ff_sigma1": 0.02},
    "notch": {"notch_hz": 36.0},
    "blend": {"fb_motor": 0.5, "alpha": 0.002},
    "motor_fb": {"fb_motor": 1.0},
    "x0": {"x0_theta_L": 0.01, "x0_w_m": 5.0, "x0_i": 1.0, "x0_xI": 0.1},
}
SIGNALS = {
    "step20": InputSignal(),
    "step_small": InputSignal(amplitude=0.1 * DEG, start=0.01),
    "sine": InputSignal(kind="sine", amplitude=2 * DEG, freq=5.0),
    "chirp": InputSignal(kind="chirp", amplitude=5 * DEG, freq=0.5, freq_end=8.0),
    "ramp": InputSignal(kind="ramp", amplitude=3 * DEG, rate=30 * DEG, start=0.02),
    "load": InputSignal(amplitude=1 * DEG, load_table=((0.0, 0.05, 0.1), (0.0, 3.0, -1.0)),
                        load_sine=(0.5, 7.0)),
}
DT = 1e-5
N_STEPS = 20000  # 0.2 s
DEC = 10


def _hash(a: np.ndarray) -> str:
    return hashlib.sha256(np.ascontiguousarray(a, dtype=np.float64).tobytes()).hexdigest()[:24]


def _fingerprint(res: runner.BatchResult, i: int) -> str:
    """Case ``i``'s signals (the paper's EMA's: the first ``PAPER_SIGNALS`` columns) and
    metrics."""
    return _hash(res.signals[i][:, :PAPER_SIGNALS]) + ":" + _hash(res.metrics[i])


def _cpu() -> dict[str, str]:
    info = {"model": "", "flags": ""}
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name") and not info["model"]:
                info["model"] = line.split(":", 1)[1].strip()
            if line.startswith("flags") and not info["flags"]:
                flags = set(line.split(":", 1)[1].split())
                keep = sorted(f for f in flags if f.startswith(("avx", "fma", "sse")))
                info["flags"] = " ".join(keep)
    except OSError:
        pass
    return info


def fingerprints() -> dict[str, str]:
    """Every case, signal and entry point -> hash of signals and metrics."""
    out: dict[str, str] = {}
    names = list(CASES)
    P = np.array([to_row(resolve(CASES[n])) for n in names])
    for sname, sig in SIGNALS.items():
        for parallel in (False, True):
            for lanes in (1, runner.LANES):
                res = runner.simulate_batch(P, [sig], None, DT, N_STEPS, DEC, parallel=parallel,
                                            lanes=lanes)
                for i, n in enumerate(names):
                    key = f"{sname}/{n}"
                    h = _fingerprint(res, i)
                    if key in out and out[key] != h:
                        raise SystemExit(f"{key}: lanes={lanes} parallel={parallel} differs "
                                         "from the other entry points")
                    out[key] = h
    # time chunks: the same run cut into chunks of 2**12 steps
    chunk = runner.TIME_CHUNK
    runner.TIME_CHUNK = 2**12
    try:
        res = runner.simulate_batch(P, [SIGNALS["chirp"]], None, DT, N_STEPS, DEC, lanes=16)
    finally:
        runner.TIME_CHUNK = chunk
    for i, n in enumerate(names):
        h = _fingerprint(res, i)
        if out[f"chirp/{n}"] != h:
            raise SystemExit(f"chirp/{n}: time chunks differ from the run in one call")
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path)
    ap.add_argument("--check", type=Path)
    a = ap.parse_args(argv)
    fp = fingerprints()
    if a.out:
        a.out.parent.mkdir(parents=True, exist_ok=True)
        a.out.write_text(json.dumps({"cpu": _cpu(), "cases": fp}, indent=1) + "\n")
        print(f"{len(fp)} fingerprints -> {a.out}")
    if a.check:
        ref = json.loads(a.check.read_text())
        if ref["cpu"] != _cpu():
            print("goldens: recorded on another CPU kind; not compared")
            return 0
        bad = [k for k, v in ref["cases"].items() if fp.get(k) != v]
        print(f"{len(ref['cases']) - len(bad)}/{len(ref['cases'])} bit-identical")
        for k in bad:
            print("  differs:", k)
        return 1 if bad else 0
    return 0


if __name__ == "__main__":
    sys.exit(main())
