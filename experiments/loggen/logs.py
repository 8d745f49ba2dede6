"""One closed-loop log: the independent ODE run at the sample times, the edge-unit channels of
``ema simulate`` with Gaussian noise, and its ``<stem>.truth.json`` sidecar. Files are written
atomically (a temporary sibling, then ``os.replace``)."""

from __future__ import annotations

import json
import math
import os
import tempfile
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from experiments.loggen import odemodel
from experiments.loggen.excitations import make_command
from experiments.loggen.params import DEG, RPM, resolve

COLUMNS = ("t_s", "theta_ref_deg", "theta_load_deg", "omega_motor_rpm", "current_a",
           "voltage_cmd_v")
MEASURED = COLUMNS[2:]
"""The measured channels (noisy); t_s and the command are exact."""
TRUTH_NAMES = ("kL", "alpha", "Fc", "sigma2", "Fs", "sigma0", "sigma1", "c", "vs", "delta",
               "zeta_t", "Jm", "JL", "bL", "m")
"""The parameters a sidecar states, under ema's names (``ema params``), SI."""
LAW_TAU = {"jump": 0.0, "ramp": 1.0e-4}
"""ema's ``contact_tau`` [s] equivalent to each law ema has (hunt_crossley: none)."""
EXC_STREAM, NOISE_STREAM = 1, 2  # second entropy words of a log's two random streams [-]


@dataclass(frozen=True)
class Log:
    """A log's columns (edge units) and its sidecar."""

    columns: dict[str, np.ndarray]
    sidecar: dict


def log_rngs(seed: int) -> tuple[np.random.Generator, np.random.Generator]:
    """(excitation stream, noise stream) of a log's seed."""
    return (np.random.default_rng([seed, EXC_STREAM]), np.random.default_rng([seed, NOISE_STREAM]))


def make_log(truth: Mapping[str, float], law: str, excitation: str, sample_rate_hz: float,
             noise_pct: float, seed: int, *, duration_s: float = 4.0,
             rtol: float = odemodel.RTOL, max_step: float = odemodel.MAX_STEP) -> Log:
    """Simulate and sample one log. ``truth``: SI overrides of the defaults (e.g. kL, alpha,
    Fc, sigma2); ``law`` one of ``odemodel.LAWS``; ``excitation`` one of
    ``excitations.KINDS``; noise ``noise_pct`` % of each measured channel's RMS, drawn from
    ``seed``'s noise stream (the excitation's random parts from its excitation stream)."""
    p = resolve({**truth, "contact_tau": LAW_TAU.get(law, resolve()["contact_tau"])})
    rng_exc, rng_noise = log_rngs(seed)
    cmd = make_command(excitation, rng_exc, duration_s)
    n = int(round(duration_s * sample_rate_hz))
    if not math.isclose(n / sample_rate_hz, duration_s, rel_tol=1e-12):
        raise ValueError(f"duration {duration_s} s is not a whole number of samples at "
                         f"{sample_rate_hz} Hz")
    t = np.arange(n + 1) / sample_rate_hz
    t0 = time.perf_counter()
    tr = odemodel.simulate(p, law, cmd.value, t, rtol=rtol, max_step=max_step)
    wall = time.perf_counter() - t0
    clean = {"theta_load_deg": tr.state("theta_L") / DEG,
             "omega_motor_rpm": tr.state("w_m") / RPM,
             "current_a": tr.state("i"),
             "voltage_cmd_v": tr.u_dem}
    cols: dict[str, np.ndarray] = {"t_s": t, "theta_ref_deg": tr.theta_ref / DEG}
    stds = {}
    for name in MEASURED:
        y = clean[name]
        std = noise_pct / 100.0 * float(np.sqrt(np.mean(y**2)))
        cols[name] = y + std * rng_noise.standard_normal(y.shape[0])
        stds[name] = std
    law_params: dict[str, float] = {}
    truth_out = {k: p[k] for k in TRUTH_NAMES}
    if law in LAW_TAU:
        truth_out["contact_tau"] = p["contact_tau"]
        law_params["contact_tau_s"] = p["contact_tau"]
    else:
        law_params = {"lambda_s_per_rad": odemodel.hc_lambda(p),
                      "pen_ref_rad": odemodel.HC_PEN_REF,
                      "rule": "lambda = c/(kL*pen_ref): damping kL*lambda*pen equals c at "
                              "pen_ref"}
    i_abs = np.abs(tr.state("i"))
    sidecar = {
        "truth": truth_out,
        "units": "SI (names as `ema params`)",
        "law": law,
        "law_parameters": law_params,
        "excitation": cmd.describe(),
        "sample_rate_hz": float(sample_rate_hz),
        "duration_s": float(duration_s),
        "noise_pct": float(noise_pct),
        "noise_std_edge_units": stds,
        "seed": int(seed),
        "generator": (f"experiments/loggen (scipy solve_ivp {odemodel.METHOD}, rtol {rtol:g}, "
                      f"atol rtol*{list(odemodel.STATE_SCALE)}, max_step {max_step:g} s, "
                      "terminal events at contact entry/exit and at the current limit)"),
        "limits_reached": {"sat1": tr.sat1_reached, "sat2": tr.sat2_reached,
                           "sat3": tr.stats.ilim_entries > 0,
                           "max_abs_current_a": float(i_abs.max())},
        "integration": tr.stats.to_json(),
        "generation_s": wall,
    }
    return Log(cols, sidecar)


def _atomic(path: Path, write: Callable[[Path], None]) -> None:
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    os.close(fd)
    try:
        write(Path(tmp))
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def write_json(path: Path, obj: object) -> None:
    """Write ``obj`` as indented JSON to ``path``, atomically."""
    _atomic(path, lambda p: p.write_text(json.dumps(obj, indent=1) + "\n", encoding="utf-8"))


def sidecar_path(csv_path: Path) -> Path:
    """``<stem>.truth.json`` beside the log (where ema looks for it)."""
    return csv_path.with_name(csv_path.stem + ".truth.json")


def write_log(csv_path: Path, log: Log) -> None:
    """Write the sidecar, then the CSV (both atomic): a CSV present means a complete log."""
    csv_path = Path(csv_path)
    write_json(sidecar_path(csv_path), log.sidecar)
    data = np.column_stack([log.columns[c] for c in COLUMNS])

    def put(p: Path) -> None:
        np.savetxt(p, data, fmt="%.12g", delimiter=",", header=",".join(COLUMNS), comments="")

    _atomic(csv_path, put)
