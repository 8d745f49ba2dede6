"""Plant identification of a rigid axis from a closed-loop record: IDIM-LS as the start and the
baseline, the controller checked against the log, output-error refinement in closed loop
(``plant.output_error``), a two-part verdict (determined: cluster-robust intervals; adequate:
``plant.adequacy``) and validation on samples the fit did not use (a time split) or on
another record (:func:`validate`).

What the description must be: a rigid axis (one mass), a force or current amplifier, the
friction law at the load (Coulomb + viscous with static = Coulomb, or with a Stribeck peak: its
Coulomb and viscous levels are freed), and a discrete controller (the closed loop is simulated
from the record's reference). Anything else is refused with the key to change.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

import numpy as np

from ema_cli.errors import EmaError
from ema_cli.identify.plant import adequacy as adq
from ema_cli.identify.plant import output_error as oe
from ema_cli.identify.plant.benchmark import BenchmarkErrors, relative_error_pct
from ema_cli.identify.plant.controller_check import (
    check_controller,
    chosen_delay,
)
from ema_cli.identify.plant.idim import BENCHMARK, IdimEstimate, filtered_kinematics, idim_ls
from ema_cli.identify.plant.records import PlantRecord, read_plant_record
from ema_cli.identify.plant.result import (
    LAW_TERMS,
    LawFit,
    PlantFit,
    choose_law,
    mask,
    sliced,
)
from ema_cli.identify.plant.settings import PlantSettings
from ema_cli.identify.uncertainty import Uncertainty, assess, covariance_clustered

LAWS = ("auto", "symmetric", "per-direction")
SUBSTEPS = 10  # kernel steps per controller sample (a rigid axis' own time constant is long)
SAMPLE_TOL = 0.01  # the record's sample interval may differ from the controller's by 1 % [-]



def _description(settings: PlantSettings) -> tuple[Any, dict[str, Any], Callable, dict]:
    """The description -> (config, base overrides, resolver, resolved params); refuses what
    the plant fit cannot run, naming the key."""
    from ema_cli.config.actuator import Actuator
    from ema_cli.config.base import Strict
    from ema_cli.config.loader import load_config, resolve_params

    class Described(Strict):
        """An actuator description alone (no run: the record is the input)."""

        actuator: Actuator

        @property
        def axis(self) -> str:
            """rotary or translational."""
            return self.actuator.axis

    p = Path(settings.actuator)
    if not p.is_file():
        raise EmaError(f"--actuator: the actuator description '{p}' does not exist")
    cfg = load_config({"actuator": str(p.resolve())}, settings.overrides(), Described)
    base = cfg.actuator.params()
    nl, fr = {}, "sigma2"

    def resolve(raw: dict[str, Any]) -> dict[str, float]:
        return resolve_params(raw, nl, fr)

    prm = resolve(base)
    where = f"actuator description '{p.name}'"
    if prm.get("rigid") != 1.0:
        raise EmaError(f"{where}: transmission.type must be rigid for a plant fit (one mass: "
                       "M q'' = F - friction - offset); a compliant axis is identified with "
                       "`ema identify --closed-loop`")
    if prm.get("drive") != 1.0:
        raise EmaError(f"{where}: drive.type must be amplifier (the record's actuation is a "
                       "force or a current times a gain)")
    if prm.get("friction_L", 0.0) == 0.0:
        raise EmaError(f"{where}: friction.load.law is none; the plant fit frees the load's "
                       "Coulomb and viscous friction: give law coulomb (or stribeck)")
    if prm.get("friction_L") not in (1.0, 2.0):
        raise EmaError(f"{where}: friction.load.law must be coulomb, stribeck or lugre for a "
                       "plant fit")
    if prm.get("friction_L") == 1.0 and settings.law == "per-direction":
        raise EmaError(f"{where}: friction.load.law is lugre, a symmetric law; expected --law "
                       "symmetric or auto (or a coulomb/stribeck law per direction)")
    if prm.get("friction", 0.0) != 0.0:
        raise EmaError(f"{where}: friction.motor is set; the plant fit frees the friction at "
                       "the load (in load units): move it to friction.load")
    return cfg, base, resolve, prm


def _signal(record: PlantRecord, ts: float, disturbance: np.ndarray | None) -> Any:
    """The record's reference (and logged disturbance) as the kernel's input: sample k at
    ``k*ts`` (the controller's clock)."""
    from ema_cli.sim.signals import InputSignal

    tk = tuple(np.arange(record.n) * ts)
    ext = None if disturbance is None else (tk, tuple(disturbance))
    return InputSignal(kind="csv", table=(tk, tuple(record.reference_m)),
                       path=record.source, ext_table=ext, ext_hold=True,
                       ext_name=None if ext is None else record.names.get("disturbance"))


def _plant(settings: PlantSettings, base: dict, resolve: Callable, prm: dict,
           record: PlantRecord, extras: dict, delay: int, names: tuple[str, ...]
           ) -> oe.ClosedLoopPlant:
    ts = prm["Ts"]
    base = {**base, "dc_delay": float(delay), "x0_theta_L": float(record.q_m[0]),
            "x0_theta_m": float(record.q_m[0]) * prm.get("m", 1.0)}
    if extras.get("disturbance") is not None:
        base["dist_out"] = 1.0
    if "OF" not in names:  # a law without the offset: its per-direction Coulomb levels carry it
        base["offset"] = 0.0
    static_follows = base.get("Fs_L") == base.get("Fc_L")
    mass_extra = prm.get("m", 1.0) ** 2 * prm.get("Jm", 0.0)
    return oe.ClosedLoopPlant(base, resolve, _signal(record, ts, extras.get("disturbance")),
                              ts / SUBSTEPS, (record.n - 1) * SUBSTEPS, SUBSTEPS, record.n, names,
                              static_follows, mass_extra)


def benchmark_errors_on(record: PlantRecord, idx: np.ndarray, q_s: np.ndarray,
                        v_s: np.ndarray, a_s: np.ndarray, F_s: np.ndarray) -> BenchmarkErrors:
    """The benchmark's four relative errors [%] (``Simulation_EMPS.m``: simulated against the
    filtered measured motion and the measured force) over the samples ``idx``."""
    kin = filtered_kinematics(record.q_m, record.h_s, BENCHMARK)
    pairs = ((kin.q_m, q_s), (kin.dq_m_s, v_s), (kin.ddq_m_s2, a_s), (record.force_n, F_s))
    e = [relative_error_pct(m[idx], s[idx]) for m, s in pairs]
    return BenchmarkErrors(*e)


def _uncertainty(fit: oe.OutputErrorFit, use: np.ndarray, h: float
                 ) -> tuple[Uncertainty, list[np.ndarray], float]:
    m = int(np.count_nonzero(use))
    tc = max(oe.correlation_time(fit.r[:m], h), oe.correlation_time(fit.r[m:], h))
    block = oe.block_length(tc, m, h)
    clusters = oe.time_clusters(use, h, block)
    cov, cond, dof = covariance_clustered(fit.J, fit.r, clusters)
    return assess(fit.names, fit.x, cov, dof, cond), clusters, block


def _adequacy(record: PlantRecord, law: str, fit: oe.OutputErrorFit, F: np.ndarray,
              q: np.ndarray, use: np.ndarray, clusters: list[np.ndarray], block_s: float,
              v_unit: str = "m/s") -> adq.Adequacy:
    m = int(np.count_nonzero(use))
    t = record.t_s[use]
    rF = record.force_n[use] - F[use]
    rq = record.q_m[use] - q[use]
    kin = filtered_kinematics(record.q_m, record.h_s, BENCHMARK)
    v = kin.dq_m_s[use]
    vr = np.gradient(record.reference_m, record.h_s)[use]
    force_clusters = [c[c < m] for c in clusters]
    tests = [adq.correlation_test("force residual: autocorrelation", rF),
             adq.correlation_test("position residual: autocorrelation", rq),
             adq.correlation_test("force residual x reference velocity", rF, vr),
             adq.correlation_test("position residual x reference velocity", rq, vr)]
    a = adq.Adequacy(
        fit_pct={"force": adq.fit_percent(record.force_n[use], F[use]),
                 "position": adq.fit_percent(record.q_m[use], q[use])},
        tests=tests,
        omitted=adq.omitted_terms(rF, v, LAW_TERMS.get(law, fit.names), force_clusters,
                                  v_unit),
        ranges={"force": adq.failing_ranges(t, rF, block_s),
                "position": adq.failing_ranges(t, rq, block_s)},
        motion=adq.by_motion(rF, v),
        correlation_time_s={"force": oe.correlation_time(fit.r[:m], record.h_s),
                            "position": oe.correlation_time(fit.r[m:], record.h_s)})
    return adq.judge(a, len(clusters), oe.MIN_CLUSTERS)


def _fit_law(law: str, record: PlantRecord, use: np.ndarray, plant_of: Callable,
             ch_floor: tuple[float, float], max_iter: int, progress: Callable | None,
             free: Mapping[str, tuple[float, float]], prm: Mapping[str, float]
             ) -> tuple[IdimEstimate, oe.OutputErrorFit, oe.ClosedLoopPlant]:
    law_terms = LAW_TERMS[law]
    start = idim_ls(sliced(record, use), law_terms)
    terms = (*law_terms, *free)
    plant = plant_of(terms)
    ch = oe.Channels(record.force_n, record.q_m, use, *ch_floor)
    x_extra = np.array([min(max(float(prm.get(n, 0.0)), lo), hi) for n, (lo, hi) in
                        free.items()])
    x0 = np.concatenate([start.theta, x_extra])
    scale = np.concatenate([np.maximum(10.0 * start.std, 1e-3 * np.abs(start.theta)),
                            [max(0.05 * abs(x), 1e-3 * (hi - lo)) for x, (lo, hi) in
                             zip(x_extra, free.values(), strict=True)]])
    scale = np.where(scale > 0, scale, 1.0)
    lower = np.where(np.array([n in ("M",) or n.startswith("Fv") or n.startswith("Fc")
                               for n in law_terms]), 0.0, -np.inf)
    lower[np.array([n == "M" for n in law_terms])] = 1e-9 * max(abs(start.theta[0]), 1.0)
    lower = np.concatenate([lower, [lo for lo, _ in free.values()]])
    upper = np.concatenate([np.full(len(law_terms), np.inf), [hi for _, hi in free.values()]])

    def step(i: int, n: int, cost: float) -> None:
        if progress is not None:
            progress(f"output error ({law})", i, n)

    fit = oe.fit(plant, ch, x0, scale, lower, upper, max_iter=max_iter, progress=step)
    return start, fit, plant


def check_span(record: PlantRecord, use: np.ndarray, prm: Mapping[str, Any]) -> None:
    """Refuse a fit whose samples ``use`` span less than the slowest time constant to
    identify, the axis' mechanical one ``M/Fv`` (the rigid axis' mass or inertia, motor's
    reflected included, over its largest viscous friction; the description's nominal values),
    or fewer than 100 samples: a velocity that has not had that time to respond to the force
    does not separate the mass from the viscous friction."""
    mass = prm.get("JL", 0.0) + prm.get("m", 1.0) ** 2 * prm.get("Jm", 0.0)
    fv = max(prm.get("Fv_L", 0.0), prm.get("Fv_L_neg", 0.0))
    tau = mass / fv if fv > 0 else 0.0
    span = float(np.count_nonzero(use) * record.h_s)
    if span < max(tau, 0.0) or np.count_nonzero(use) < 100:
        raise EmaError(f"{record.source}: the fitted samples span {span:.4g} s "
                       f"({np.count_nonzero(use)} samples), shorter than the axis' mechanical "
                       f"time constant M/Fv = {tau:.4g} s (the slowest to identify; at least 100 "
                       "samples); expected a longer --window")


def run_plant(settings: PlantSettings, progress: Callable[[str, int | None, int | None], None]
              | None = None) -> PlantFit:
    """The whole identification (module docstring) -> :class:`PlantFit`; ``progress(stage,
    done, total)`` as it advances (default: ``ema_cli.progress.report``, what the command line
    shows)."""
    if progress is None:
        from ema_cli.progress import report as progress
    progress("reading the record", None, None)
    t0 = time.perf_counter()
    timings: dict[str, float] = {}
    cfg, base, resolve, prm = _description(settings)
    umax = prm.get("dc_umax", np.inf)
    record, extras = read_plant_record(settings.data, dict(settings.columns),
                                       gain=prm.get("amp_gain"),
                                       saturation=umax if np.isfinite(umax) else None,
                                       limit_force=(umax * prm.get("amp_gain", 1.0)
                                                    if np.isfinite(umax) else None),
                                       need_reference=False)
    # the slowest time constant to identify, from the description's nominal values: refused
    # on the closed loop's path and on the inverse model's alike
    check_span(record, mask(record, settings.window, BENCHMARK.first_sample), prm)
    why_open = ("the record has no reference channel" if record.reference_m is None else
                "the description has no discrete controller" if prm.get("ctrl") != 1.0 else "")
    if why_open:
        from ema_cli.identify.plant.inverse import run_inverse

        return run_inverse(settings, cfg, record, extras, why_open, t0)
    ts = prm["Ts"]
    if abs(record.h_s / ts - 1.0) > SAMPLE_TOL:
        raise EmaError(f"{record.source}: samples every {record.h_s:.6g} s but the described "
                       f"controller samples every {ts:.6g} s (controller.sample_time_s); "
                       "expected the controller's own samples")
    first = BENCHMARK.first_sample
    progress("checking the controller against the record", None, None)
    check = check_controller(prm, record.q_m, record.reference_m, extras["actuation"],
                             extras["unit"], extras.get("disturbance"), first=first)
    delay = chosen_delay(check, settings.delay, record.source)
    timings["read_and_check"] = time.perf_counter() - t0
    use = mask(record, settings.window, first)
    progress("IDIM-LS baseline", None, None)
    baseline = idim_ls(sliced(record, use), LAW_TERMS["symmetric"])
    floors = (oe.command_floor(record.force_n), oe.encoder_floor(record.q_m))

    def plant_of(terms: tuple[str, ...]) -> oe.ClosedLoopPlant:
        return _plant(settings, base, resolve, prm, record, extras, delay, terms)

    laws: dict[str, LawFit] = {}
    kernel = {"calls": 0, "lanes": 0, "kernel_s": 0.0, "load_s": 0.0}
    order = ["symmetric", "per-direction"] if settings.law == "auto" else [settings.law]
    if prm.get("friction_L") == 1.0:  # LuGre: symmetric only
        order = ["symmetric"]
    for law in order:
        t1 = time.perf_counter()
        start, fit, plant = _fit_law(law, record, use, plant_of, floors, settings.max_iter,
                                     progress, settings.free, prm)
        unc, clusters, block = _uncertainty(fit, use, record.h_s)
        F, q, v, a = plant.motion(fit.x)
        adequacy = _adequacy(record, law, fit, F, q, use, clusters, block,
                             "rad/s" if cfg.axis == "rotary" else "m/s")
        laws[law] = LawFit(law, start, fit, unc, adequacy, len(clusters), block, F, q, v, a,
                           _on_bound(fit, settings.free))
        for k, val in (("calls", plant.calls), ("lanes", plant.lanes_run),
                       ("kernel_s", plant.kernel_s), ("load_s", plant.load_s)):
            kernel[k] += val
        timings[f"fit_{law}"] = time.perf_counter() - t1
    chosen, choice = choose_law(settings.law, laws)
    # the baseline: IDIM-LS of the symmetric law simulated in the same closed loop
    bplant = plant_of(LAW_TERMS["symmetric"])
    bF, bq, bv, ba = bplant.motion(baseline.theta)
    idx = np.flatnonzero(use)
    best = laws[chosen]
    errors = {"output error": benchmark_errors_on(record, idx, best.q, best.v, best.a, best.F),
              "IDIM-LS": benchmark_errors_on(record, idx, bq, bv, ba, bF)}
    split = None
    if settings.split > 0:
        t1 = time.perf_counter()
        split = _split(settings, record, use, chosen, plant_of, floors, prm,
                       lambda stage, done, total: progress(f"time split, {stage}", done, total))
        timings["split_validation"] = time.perf_counter() - t1
    timings["total"] = time.perf_counter() - t0
    return PlantFit(settings, record, extras, str(cfg.axis),
                    check, delay, baseline, laws, chosen, choice, errors,
                    {"F": bF, "q": bq, "v": bv, "a": ba}, split, use, timings, kernel)


def _on_bound(fit: oe.OutputErrorFit, free: Mapping[str, tuple[float, float]]) -> np.ndarray:
    """Which parameters ended within 0.1 % of the span of a bound (freed kernel parameters)."""
    out = np.zeros(len(fit.names), dtype=bool)
    for j, n in enumerate(fit.names):
        if n in free:
            lo, hi = free[n]
            out[j] = min(fit.x[j] - lo, hi - fit.x[j]) <= 1e-3 * (hi - lo)
    return out


def _split(settings: PlantSettings, record: PlantRecord, use: np.ndarray, law: str,
           plant_of: Callable, floors: tuple[float, float], prm: dict,
           progress: Callable | None) -> dict[str, Any]:
    """Fit the first ``split`` of the used samples, score on the rest (the fit never sees
    them); IDIM-LS of the same first part scored alike."""
    idx = np.flatnonzero(use)
    cut = idx[int(settings.split * idx.size)]
    fit_use = use & (np.arange(record.n) < cut)
    held = use & (np.arange(record.n) >= cut)
    start, fit, plant = _fit_law(law, record, fit_use, plant_of, floors, settings.max_iter,
                                 progress, settings.free, prm)
    F, q, v, a = plant.motion(fit.x)
    base = idim_ls(sliced(record, fit_use), LAW_TERMS["symmetric"])
    bF, bq, bv, ba = plant_of(LAW_TERMS["symmetric"]).motion(base.theta)
    hidx = np.flatnonzero(held)
    return {"share": settings.split, "t_split_s": float(record.t_s[cut]),
            "estimate": dict(zip(fit.names, map(float, fit.x), strict=True)),
            "errors": {"output error": benchmark_errors_on(record, hidx, q, v, a, F),
                       "IDIM-LS": benchmark_errors_on(record, hidx, bq, bv, ba, bF)},
            "held_out_samples": int(hidx.size)}
