"""Closed-loop records of a rigid axis with stated truths, made by the kernel through the EMPS
description (configs/actuators/emps.yaml) driven by the first seconds of the EMPS reference:
the command logged as the controller computed it (delay 0), the position quantised to the
encoder's 5e-8 m, and white noise added to the command on its way to the amplifier (a force
disturbance the model does not know, as a real axis' unmodelled forces are). For recovery tests of
``ema identify plant``; the independent checks are the EMPS record itself and the published
IDIM-LS estimate."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from scipy.io import savemat

ROOT = Path(__file__).resolve().parents[2]
EMPS = ROOT / "experiments" / "data" / "emps" / "DATA_EMPS.mat"
ACTUATOR = ROOT / "configs" / "actuators" / "emps.yaml"
GTAU = 35.15065188
STEP = 5e-8  # the EMPS encoder's step in load coordinates [m]


def make_record(path: Path, truth: dict[str, float], seconds: float = 8.0,
                noise_v: float = 0.01, seed: int = 7, pulses_v: float = 0.0) -> Path:
    """Write a .mat record (EMPS layout) of the description with the terms ``truth`` (M, Fv+,
    Fc+, Fv-, Fc-, OF in SI) over the first ``seconds`` of the EMPS reference, ``noise_v`` [V]
    the disturbance's standard deviation, ``pulses_v`` [V] the height of 50 ms pulses every
    second added to the controller's output and logged with it in ``vir`` (as a record with
    force pulses) -> path."""
    from ema_cli.config.loader import load_config, resolve_params
    from ema_cli.identify.plant.output_error import ClosedLoopPlant
    from ema_cli.identify.plant.records import read_plant_mat
    from ema_cli.sim.signals import InputSignal

    rec = read_plant_mat(EMPS)
    n = int(round(seconds / 1e-3)) + 1
    ref = rec.reference_m[:n]
    cfg = load_config({"actuator": str(ACTUATOR)}, [("actuator.controller.delay_samples", 0)])
    base = cfg.plant_overrides()
    tk = tuple(np.arange(n) * 1e-3)
    rng = np.random.default_rng(seed)
    d = noise_v * rng.standard_normal(n)
    k = np.arange(n)
    pulses = pulses_v * (((k % 1000) >= 500) & ((k % 1000) < 550)) * np.where(k % 2000 < 1000,
                                                                               1.0, -1.0)
    d = d + pulses
    sig = InputSignal(kind="csv", table=(tk, tuple(ref)), path="truth", ext_table=(tk, tuple(d)),
                      ext_hold=True, ext_name="noise")
    base = {**base, "dist_out": 1.0}
    names = tuple(truth)
    plant = ClosedLoopPlant(base, lambda raw: resolve_params(raw, {}, "sigma2"), sig, 1e-4,
                            (n - 1) * 10, 10, n, names, True)
    F, q, _, _ = plant.motion(np.array([truth[k] for k in names]))
    vir = F / GTAU - d + pulses  # the controller's output (+ the logged pulses): the
    # amplifier got the command plus the noise
    qm = np.round(q / STEP) * STEP
    savemat(path, {"t": (np.arange(n) * 1e-3)[:, None], "qm": qm[:, None], "qg": ref[:, None],
                   "vir": vir[:, None], "gtau": np.array([[GTAU]]),
                   "kp": np.array([[160.18]]), "kv": np.array([[243.45]])})
    return path
