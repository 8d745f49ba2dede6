"""Validation of a plant fit on another record: the fitted model and the IDIM-LS baseline
simulated in the described closed loop against it (the benchmark's four relative errors and the
RMS position error), or, for the inverse model, its force prediction error. The controller is
checked against the record first; a logged command that departs from the checked law carries an
input of its own (pulses, a feedforward) and is applied as a disturbance, said in a note."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ema_cli.errors import EmaError
from ema_cli.identify.plant.benchmark import BenchmarkErrors
from ema_cli.identify.plant.controller_check import (
    MATCH_MAX,
    ControllerCheck,
    check_controller,
)
from ema_cli.identify.plant.fit import (
    SAMPLE_TOL,
    PlantFit,
    _description,
    _plant,
    benchmark_errors_on,
)
from ema_cli.identify.plant.idim import BENCHMARK
from ema_cli.identify.plant.records import PlantRecord, read_plant_record
from ema_cli.identify.plant.settings import PlantSettings


@dataclass
class PlantValidation:
    """A fitted model simulated against another record: the benchmark's errors and the RMS
    position error [m] of the fit and of the IDIM-LS baseline, the controller check, the
    simulated channels."""

    record: PlantRecord
    controller: ControllerCheck | None
    errors: dict[str, BenchmarkErrors]
    rms_position_m: dict[str, float]
    sims: dict[str, dict[str, np.ndarray]]
    notes: list[str] = field(default_factory=list)


def validate(fit: PlantFit, data: str | Path, columns: Mapping[str, str] | None = None
             ) -> PlantValidation:
    """Simulate the fitted model and the IDIM-LS baseline against another record (the same
    description, delay and column map unless ``columns``)."""
    models = {"output error": fit.best.estimate,
              "IDIM-LS": dict(zip(fit.baseline.names, map(float, fit.baseline.theta),
                                  strict=True))}
    if fit.controller is None:
        models = {f"IDIM-LS ({fit.chosen})": fit.best.estimate}
    return validate_models(fit.settings, fit.delay, models, data, columns,
                           inverse=fit.controller is None)


def validate_models(settings: PlantSettings, delay: int, models: Mapping[str, Mapping[str, float]],
                    data: str | Path, columns: Mapping[str, str] | None = None,
                    inverse: bool = False) -> PlantValidation:
    """Simulate each model (name -> term -> value, SI) in the described closed loop against the
    record ``data`` -> the benchmark's errors and the RMS position error of each; ``inverse``:
    the inverse model's force prediction error only (no closed loop)."""
    cfg, base, resolve, prm = _description(settings)
    umax = prm.get("dc_umax", np.inf)
    record, extras = read_plant_record(data, dict(columns if columns is not None
                                                  else settings.columns),
                                       gain=prm.get("amp_gain"),
                                       saturation=umax if np.isfinite(umax) else None,
                                       limit_force=(umax * prm.get("amp_gain", 1.0)
                                                    if np.isfinite(umax) else None),
                                       need_reference=not inverse)
    if inverse:
        from ema_cli.identify.plant.inverse import prediction_pct

        nan = float("nan")
        errs = {k: BenchmarkErrors(nan, nan, nan, prediction_pct(
            record, tuple(m), np.array(list(m.values())))) for k, m in models.items()}
        return PlantValidation(record, None, errs, dict.fromkeys(models, nan), {})
    if record.reference_m is None:
        raise EmaError(f"{record.source}: no reference channel; expected the closed loop's "
                       "reference position (--columns reference=NAME[:UNIT])")
    if abs(record.h_s / prm["Ts"] - 1.0) > SAMPLE_TOL:
        raise EmaError(f"{record.source}: samples every {record.h_s:.6g} s but the described "
                       f"controller samples every {prm['Ts']:.6g} s")
    first = BENCHMARK.first_sample
    check = check_controller(prm, record.q_m, record.reference_m, extras["actuation"],
                             extras["unit"], extras.get("disturbance"), first=first)
    notes = []
    if extras.get("unused"):
        notes.append(f"{record.source} has variables the column map does not use: "
                     f"{', '.join(extras['unused'][:8])} (a logged disturbance is mapped with "
                     "--columns disturbance=NAME[:UNIT])")
    if check.rel_rms[delay] > MATCH_MAX and extras.get("disturbance") is None:
        # the same axis and controller (checked on the fitted record): what the log adds to
        # the law's output is an input of its own (pulses, a feedforward), applied as logged
        from ema_cli.identify.plant.controller_check import apply_law

        law = apply_law({**prm, "dc_delay": float(delay)}, record.q_m, record.reference_m,
                        delay)
        d = extras["actuation"] - law
        d[:first] = 0.0
        extras = {**extras, "disturbance": d}
        notes.append(f"the logged command departs from the described law by "
                     f"{100 * check.rel_rms[delay]:.3g} % RMS (largest {check.worst_abs:.3g} "
                     f"{check.unit} at index {check.worst_index}): the difference is applied as "
                     "a disturbance added to the controller's output, as the log records it")
    idx = np.arange(first, record.n)
    out, rms, sims = {}, {}, {}
    for name, est in models.items():
        terms = tuple(est)
        plant = _plant(settings, base, resolve, prm, record, extras, delay, terms)
        F, q, v, a = plant.motion(np.array([est[t] for t in terms]))
        out[name] = benchmark_errors_on(record, idx, q, v, a, F)
        rms[name] = float(np.sqrt(np.mean((q[idx] - record.q_m[idx]) ** 2)))
        sims[name] = {"F": F, "q": q, "v": v, "a": a}
    return PlantValidation(record, check, out, rms, sims, notes)
