"""The inverse model alone: a record with no closed loop to simulate (no reference channel, or a
description without a discrete controller: a robot's joint, an axis driven by hand or by an
unknown controller) is identified by IDIM-LS, with the same two-part verdict as the output
error: intervals from the CR3 cluster-robust covariance over contiguous blocks of the
regression's rows (the rows' residual is coloured too), and the adequacy tests on the force
residual (fit, whiteness, omitted terms — for a rotary axis also a gravity-like ``cos q``,
``sin q`` — and where it fails). Its scores are the inverse model's force prediction errors
(the benchmark's relative error ``100 ||y - W theta||/||y||``), on the fitted rows, on the
held-out part of a time split and on another record.
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np

from ema_cli.errors import EmaError
from ema_cli.identify.plant import adequacy as adq
from ema_cli.identify.plant import output_error as oe
from ema_cli.identify.plant.benchmark import BenchmarkErrors
from ema_cli.identify.plant.idim import (
    BENCHMARK,
    IdimEstimate,
    build_regression,
    filtered_kinematics,
    idim_ls,
)
from ema_cli.identify.plant.records import PlantRecord
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


def _rows(record: PlantRecord, est: IdimEstimate) -> tuple[np.ndarray, np.ndarray]:
    """The decimated velocity and position at the regression's rows."""
    from ema_cli.identify.plant import matlab

    s = est.regression.settings
    kin = filtered_kinematics(record.q_m, record.h_s, s)
    a, b = s.first_sample, record.n - s.drop_end
    r = s.decimation
    return matlab.decimate(kin.dq_m_s[a:b], r), matlab.decimate(kin.q_m[a:b], r)


def inverse_fit(record: PlantRecord, terms: tuple[str, ...], law: str, rotary: bool
                ) -> tuple[IdimEstimate, oe.OutputErrorFit, Uncertainty, adq.Adequacy, int,
                           float, np.ndarray]:
    """IDIM-LS of ``terms`` on ``record`` with the house's verdict -> (estimate, the fit as an
    :class:`OutputErrorFit` (r = residual, J = -W), CR3 uncertainty, adequacy, clusters, block
    length [s], the predicted force at the record's samples [N], NaN where no row is)."""
    est = idim_ls(record, terms)
    reg = est.regression
    e = est.residual_n
    h_row = reg.settings.decimation * record.h_s
    tc = oe.correlation_time(e, h_row)
    block = oe.block_length(tc, e.size, h_row)
    clusters = oe.time_blocks(e.size, h_row, block)
    J = -reg.W
    cov, cond, dof = covariance_clustered(J, e, clusters)
    unc = assess(est.names, est.theta, cov, dof, cond)
    v_rows, q_rows = _rows(record, est)
    y_hat = reg.W @ est.theta
    tests = [adq.correlation_test("force residual: autocorrelation", e),
             adq.correlation_test("force residual x velocity", e, v_rows)]
    a = adq.Adequacy(
        fit_pct={"force": adq.fit_percent(reg.y, y_hat)}, tests=tests,
        omitted=adq.omitted_terms(e, v_rows, terms, clusters, "rad/s" if rotary else "m/s",
                                  q_rows if rotary else None),
        ranges={"force": adq.failing_ranges(reg.t_s, e, block)},
        motion=adq.by_motion(e, v_rows), correlation_time_s={"force": tc})
    adq.judge(a, len(clusters), oe.MIN_CLUSTERS)
    fit = oe.OutputErrorFit(est.names, est.theta.copy(), e, J, (est.sigma_n, float("nan")), [],
                            0, True, "linear least squares on the decimated rows (IDIM-LS)")
    F = np.full(record.n, np.nan)
    s = reg.settings
    F[s.first_sample:record.n - s.drop_end] = reg.W_raw @ est.theta
    return est, fit, unc, a, len(clusters), block, F


def prediction_pct(record: PlantRecord, terms: tuple[str, ...], theta: np.ndarray) -> float:
    """The inverse model's force prediction error on a record [%] (the benchmark's
    cross-test validation, ``Script_IDIM_LS_CTV.m``)."""
    reg = build_regression(record, terms, BENCHMARK)
    y_hat = reg.W @ theta
    return float(100.0 * np.linalg.norm(reg.y - y_hat) / np.linalg.norm(reg.y))


def run_inverse(settings: PlantSettings, cfg: Any, record: PlantRecord, extras: dict,
                why: str, t0: float) -> PlantFit:
    """The inverse model alone (``plant.inverse``): every law by IDIM-LS with the two-part
    verdict, the time split scored by the force prediction error."""
    if settings.free:
        raise EmaError(f"free: {', '.join(settings.free)} need the closed loop ({why}); "
                       "expected a reference channel and a discrete controller in the "
                       "description")
    rotary = cfg.axis == "rotary"
    use = mask(record, settings.window, BENCHMARK.first_sample)
    sub = sliced(record, use)
    kin = filtered_kinematics(record.q_m, record.h_s, BENCHMARK)
    laws: dict[str, LawFit] = {}
    order = ["symmetric", "per-direction"] if settings.law == "auto" else [settings.law]
    for law in order:
        terms = LAW_TERMS[law]
        est, fit, unc, ad, g, block, F_sub = inverse_fit(sub, terms, law, rotary)
        a0 = int(np.flatnonzero(use)[0]) - BENCHMARK.first_sample
        a0 = max(a0, 0)
        F = np.full(record.n, np.nan)
        F[a0:a0 + sub.n] = F_sub
        laws[law] = LawFit(law, est, fit, unc, ad, g, block, F, record.q_m, kin.dq_m_s,
                           kin.ddq_m_s2, np.zeros(len(terms), dtype=bool))
    chosen, choice = choose_law(settings.law, laws)
    nan = float("nan")
    errors = {f"IDIM-LS ({lw})": BenchmarkErrors(nan, nan, nan, lf.start.relative_error_pct)
              for lw, lf in laws.items()}
    split = None
    if settings.split > 0:
        idx = np.flatnonzero(use)
        cut = idx[int(settings.split * idx.size)]
        first = use & (np.arange(record.n) < cut)
        held = use & (np.arange(record.n) >= cut)
        est = idim_ls(sliced(record, first), LAW_TERMS[chosen])
        split = {"share": settings.split, "t_split_s": float(record.t_s[cut]),
                 "estimate": dict(zip(est.names, map(float, est.theta), strict=True)),
                 "errors": {f"IDIM-LS ({chosen}), force prediction": BenchmarkErrors(
                     nan, nan, nan, prediction_pct(sliced(record, held), LAW_TERMS[chosen],
                                                   est.theta))},
                 "held_out_samples": int(np.count_nonzero(held))}
    baseline = laws["symmetric"].start if "symmetric" in laws else laws[chosen].start
    return PlantFit(settings, record, extras, str(cfg.axis), None, 0, baseline, laws, chosen,
                    choice, errors, {"F": laws[chosen].F, "q": record.q_m, "v": kin.dq_m_s,
                                     "a": kin.ddq_m_s2},
                    split, use, {"total": time.perf_counter() - t0},
                    {"calls": 0, "lanes": 0, "kernel_s": 0.0, "load_s": 0.0},
                    f"inverse model only ({why}: no closed loop to simulate)")
