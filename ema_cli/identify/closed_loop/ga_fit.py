"""The closed-loop fit: GA (one batched kernel call per generation) -> least-squares polish
(batched finite-difference Jacobian) -> uncertainty -> cost profile along alpha.

1. GA (``optim.ga``, improved mode) over the bounds at the coarse step ``ga_dt``, on the
   first ``ga_horizon_s`` of the log (:func:`horizons`).
2. ``scipy.optimize.least_squares`` (bounded TRF) on the weighted residuals at the fine step
   ``dt``, in variables scaled to the bounds (u = (x - lo)/(hi - lo)); its Jacobian is a
   central finite difference whose 2p perturbed parameter sets run in ONE kernel call. The
   polish is continued over growing horizons (the GA's, then doubled, up to the whole log),
   each stage starting from the previous optimum: with backlash the output-error cost of a
   long log is multimodal (the impacts of the simulated and the logged motion fall in or out
   of step), while that of a short log has one wide valley around the truth, so each stage
   starts inside the basin of the next (docs/identification.md, "Backlash: a continuous
   contact and a continuation").
3. Uncertainty (``identify.uncertainty``): standard errors from the Jacobian at the optimum
   (sandwich with one noise level per channel), Student-t 95 % intervals, correlations and the
   "not determined" flags.
4. Alpha (when free): the cost along alpha with the other parameters at the optimum (a slice),
   and the profile linearised in the others (each slice point's residuals re-fitted over the
   other parameters with the Jacobian at the optimum), all alpha values in one kernel call. If
   the slice finds a clearly lower cost than the polish, the polish is restarted there (the
   cost is not smooth in alpha: backlash switches contact on and off).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ema_cli.errors import EmaError
from ema_cli.identify.closed_loop.problem import (
    CHANNELS,
    CONTACT_SHAPE,
    NOISE_NOTE,
    NUISANCE,
    ClosedLoopLog,
    ClosedLoopProblem,
    channel_scale,
    check_free,
    load_log,
)
from ema_cli.identify.closed_loop.shooting_fit import ShootingOutcome, shooting_estimate, too_high
from ema_cli.identify.closed_loop.whole_log import FD_REL_STEP, fd_jacobian, polish
from ema_cli.identify.log_settings import ClosedLoopSettings
from ema_cli.identify.uncertainty import Uncertainty, assess, covariance
from ema_cli.model.params import BY_NAME
from ema_cli.optim.ga import GAHistory, preset, run_ga
from ema_cli.progress import report

RESTART_MARGIN = 1e-3  # restart the polish when the slice is 0.1 % lower than its optimum [-]
QUADRATIC_RATIO = 3.0  # the cost 1 SE away must rise 1/3 .. 3 x what J^T J predicts [-]
HORIZON_GROWTH = 2.0  # continuation: each polish stage fits this many times the last horizon
HORIZON_MERGE = 1.5  # a stage within this factor of the whole log is the whole log [-]
NOISE_LEVEL_RATIO = 2.0  # warn when a channel's residual RMS exceeds its noise estimate x this


def horizons(duration: float, first: float | None) -> list[float]:
    """The log horizons [s] of the continuation: ``first``, then doubled while a stage stays
    :data:`HORIZON_MERGE` x shorter than the log, then the whole ``duration`` (``first``
    None or not shorter than that: the whole log only). E.g. 4 s with 1 s: [1, 2, 4]."""
    out: list[float] = []
    t = first
    while t is not None and t * HORIZON_MERGE < duration:
        out.append(float(t))
        t *= HORIZON_GROWTH
    return [*out, float(duration)]


@dataclass
class ClosedLoopFit:
    """A closed-loop identification (SI): estimate, uncertainty, data and diagnostics."""

    settings: ClosedLoopSettings
    problem: ClosedLoopProblem
    x_ga: np.ndarray
    cost_ga: float
    x: np.ndarray
    cost: float
    residuals: np.ndarray  # weighted residuals at x [n_ch*n]
    jacobian: np.ndarray  # d residuals / d x at x [n_ch*n, p]
    uncertainty: Uncertainty
    prediction: np.ndarray  # simulated channels at x [n_ch, n] (SI)
    history: GAHistory | None
    scale_notes: dict[str, str]
    alpha_grid: np.ndarray | None = None
    alpha_slice: np.ndarray | None = None
    alpha_profile: np.ndarray | None = None
    polish_nfev: int = 0
    polish_njev: int = 0
    polish_status: str = ""
    restarted: bool = False
    horizons: list[float] = field(default_factory=list)  # GA's first, polish stages [s]
    stages: list[dict[str, Any]] = field(default_factory=list)  # per polish stage
    timings: dict[str, float] = field(default_factory=dict)
    ga_throughput: float = 0.0  # kernel steps per second inside the GA [steps/s]
    warnings: list[str] = field(default_factory=list)
    quadratic_ratio: np.ndarray | None = None  # see quadratic_check
    shooting: ShootingOutcome | None = None  # the multiple-shooting stage (search: shooting)
    adequacy: dict[str, Any] | None = None
    """Whether the model is adequate for the log (:mod:`adequacy`): residual whiteness and
    cross-correlation with the command per channel, fit %, where it fails."""

    @property
    def names(self) -> tuple[str, ...]:
        return self.problem.names

    @property
    def params(self) -> dict[str, float]:
        """Complete SI parameters at the estimate (fixed, free and derived)."""
        return self.problem.params(self.x)

    def fit_rms(self) -> dict[str, float]:
        """RMS of measured - simulated per channel, in the channel's edge unit."""
        out = {}
        for j, c in enumerate(self.problem.channels):
            r = (self.problem.measured[j] - self.prediction[j]) / CHANNELS[c][1]
            out[c] = float(np.sqrt(np.mean(r**2)))
        return out

    def rms_over_scale(self) -> dict[str, float]:
        """Per channel, the RMS of the weighted residuals: 1 when the fit leaves white noise
        of the channel's scale, for a scale that is the channel's noise estimate [-]."""
        n = self.problem.log.n
        return {c: float(np.sqrt(np.mean(self.residuals[j * n:(j + 1) * n] ** 2)))
                for j, c in enumerate(self.problem.channels)}

    def fit_quality(self) -> dict[str, Any]:
        """Whether the fit reaches the noise level of the channels scaled by their noise
        estimate (``None`` when no channel is): see :data:`NOISE_LEVEL_RATIO`."""
        whole = self.rms_over_scale()
        ratios = whole if self.shooting is None else self.shooting.ms_ratios
        judged = [c for c in ratios if self.scale_notes[c] == NOISE_NOTE]
        out = {"rms_over_scale": ratios, "limit": NOISE_LEVEL_RATIO,
               "reaches_noise_level": (all(ratios[c] <= NOISE_LEVEL_RATIO for c in judged)
                                       if judged else None)}
        if self.shooting is not None:  # the segments' fit; the whole log from rest apart
            out["of"] = "the segments of the multiple-shooting fit"
            out["whole_log_from_rest_rms_over_scale"] = whole
        return out

    def to_json(self) -> dict[str, Any]:
        """The content of identification.json."""
        p = self.problem
        u = self.uncertainty
        units = {n: BY_NAME[n].unit for n in self.names}
        truth = p.log.truth
        full = self.params
        ms = self.shooting
        # the contact's nuisance parameters (freed unless stated): reported, not judged
        nuisance = set(NUISANCE) if ms is not None and self.settings.free_contact else set()
        out: dict[str, Any] = {
            "mode": "closed-loop",
            "method": ("output error: GA (optim.ga improved, one batched kernel call per "
                       "generation) at ga_dt, then scipy least_squares (TRF, bounds) at dt "
                       "with a batched central-difference Jacobian") if ms is None else (
                "output error by multiple shooting (segments with estimated initial states, "
                "Sobol starts, batched joint Levenberg-Marquardt with successive halving) at "
                "ga_dt, refined at dt; a whole-log least-squares polish from rest as a check"),
            "optimum": None if ms is None else {
                "confirmed": ms.confirmed, "estimate_from": ms.source,
                "not_confirmed_because": ms.reasons},
            "data": {"source": p.log.source, "n_samples": p.log.n,
                     "duration_s": p.log.duration, "t0_s": p.log.t0,
                     "channels": list(p.channels)},
            "free": {n: [float(p.lower[j]), float(p.upper[j])] for j, n in enumerate(self.names)},
            "fixed": p.fixed,
            "weights": {c: {"scale": float(p.scales[j] / CHANNELS[c][1]),
                            "unit": CHANNELS[c][2], "chosen_by": self.scale_notes[c]}
                        for j, c in enumerate(p.channels)},
            "dt_s": p.dt, "ga_dt_s": p.ga_dt,
            "parameters": {n: {**v, "role": "nuisance" if n in nuisance else "primary"}
                           for n, v in u.to_json(units).items()},
            "not_determined": [n for n, d in zip(self.names, u.determined, strict=True)
                               if not d],
            "correlation": {"names": list(self.names), "matrix": u.corr.tolist()},
            "covariance_si": u.cov.tolist(),
            "intervals": f"95 % (Student's t, {u.dof} dof: t = {u.t_quantile:.4f}); covariance "
                         + ("A^-1 B A^-1 from the Jacobian, one noise level per channel"
                            if ms is None else "A^-1 B A^-1, cluster-robust: the log's segments "
                            "as clusters, segment states profiled out"),
            "condition_number": u.cond,
            "quadratic_check": None if self.quadratic_ratio is None else {
                n: (float(v) if np.isfinite(v) else None)
                for n, v in zip(self.names, self.quadratic_ratio, strict=True)},
            "cost": {"J": self.cost, "J_ga": self.cost_ga, "definition":
                     "sum over channels and samples of ((measured - simulated)/scale)^2"},
            "fit_rms": self.fit_rms(),
            "fit_quality": self.fit_quality(),
            "adequacy": self.adequacy,
            "all_parameters": full,
            "ga": None if ms is not None else {
                "pop": self.settings.ga.pop, "generations": self.settings.ga.generations,
                "evaluations": None if self.history is None
                else int(self.history.evaluations[-1]),
                "x": {n: float(self.x_ga[j]) for j, n in enumerate(self.names)},
                "kernel_steps_per_s": self.ga_throughput},
            "polish": {"function_evaluations": self.polish_nfev,
                       "jacobian_evaluations": self.polish_njev, "status": self.polish_status,
                       "restarted_from_profile": self.restarted},
            "continuation": {"ga_horizon_s": self.horizons[0] if self.horizons else None,
                             "horizons_s": self.horizons, "stages": self.stages},
            "timings_s": self.timings,
            "warnings": self.warnings,
        }
        if ms is not None:
            out["shooting"] = ms.to_json()
        if truth is not None:
            out["truth"] = {n: truth[n] for n in self.names if n in truth}
            out["error_pct_vs_truth"] = {
                n: 100.0 * (float(self.x[j]) / truth[n] - 1.0)
                for j, n in enumerate(self.names) if truth.get(n)}
            out["truth_in_ci95"] = {
                n: bool(u.ci_low[j] <= truth[n] <= u.ci_high[j])
                for j, n in enumerate(self.names) if n in truth}
        return out


def build_problem(settings: ClosedLoopSettings, log: ClosedLoopLog) -> tuple[
        ClosedLoopProblem, dict[str, str]]:
    """The problem of ``log`` with the settings' free set, fixed plant, channels and scales."""
    free = dict(settings.free)
    if settings.search == "shooting" and settings.free_contact:
        stated = set(settings.plant) | set(free)
        if stated & set(CONTACT_SHAPE):  # a stated law: its whole shape, the rest at defaults
            stated |= set(CONTACT_SHAPE)
        for n, b in NUISANCE.items():
            if n not in stated and not (n == "zeta_t" and "c" in stated):
                free[n] = b
    names, lo, hi = check_free(free, settings.plant)
    chosen = settings.channels or {c: "auto" for c in log.channels}
    notes = {}
    scales = []
    for c, s in chosen.items():
        if c not in log.channels:
            raise EmaError(f"channels.{c}: the log {log.source} has no column '{c}'; it has "
                           f"{', '.join(log.channels)}")
        if s == "auto":
            v, note = channel_scale(log.channels[c], log.t)
        else:
            v, note = float(s) * CHANNELS[c][1], "given"
        scales.append(v)
        notes[c] = note
    problem = ClosedLoopProblem(log, names, lo, hi, dict(settings.plant), tuple(chosen),
                                np.array(scales), settings.dt_s, settings.ga_dt_s or settings.dt_s,
                                settings.command)
    try:  # parameters the model refuses (e.g. Fc = 0 fixed with friction free) before the GA
        problem.params(0.5 * (lo + hi))
    except EmaError as exc:
        raise EmaError(f"plant: {exc.message}") from None
    return problem, notes


def alpha_scan(problem: ClosedLoopProblem, x: np.ndarray, r: np.ndarray, J: np.ndarray,
               n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The cost along alpha over its bounds with the others at ``x`` (slice), and linearised
    in the others (profile) -> (alpha grid [rad], slice J, profile J); one kernel call."""
    ja = problem.names.index("alpha")
    grid = np.linspace(problem.lower[ja], problem.upper[ja], n)
    grid = np.union1d(grid, [x[ja]])
    X = np.repeat(x[None], grid.shape[0], axis=0)
    X[:, ja] = grid
    R = problem.weighted_residuals(X)
    slice_J = np.sum(R**2, axis=1)
    others = [k for k in range(x.shape[0]) if k != ja]
    if others:
        Jo = J[:, others]
        coef, *_ = np.linalg.lstsq(Jo, R.T, rcond=None)  # R_i + Jo d_i ~ 0 -> d_i = -coef_i
        prof = np.sum((R.T - Jo @ coef) ** 2, axis=0)
        prof = np.minimum(prof, slice_J)
    else:
        prof = slice_J.copy()
    return grid, slice_J, prof


def run_closed_loop(settings: ClosedLoopSettings, log: ClosedLoopLog | None = None
                    ) -> ClosedLoopFit:
    """Identify the free parameters of ``settings`` from the log (``settings.data`` unless
    ``log`` is given). Raises EmaError for bad logs, bounds and settings."""
    t_start = time.perf_counter()
    if log is None:
        if settings.data is None:
            raise EmaError("--closed-loop needs --data LOG.csv (or data: in the config)")
        log = load_log(settings.data, columns=settings.columns, window=settings.window)
    problem, notes = build_problem(settings, log)
    timings: dict[str, float] = {}
    warnings: list[str] = []

    t0 = time.perf_counter()
    problem.evaluate(problem.lower[None])  # load the kernel before timing
    timings["load_s"] = time.perf_counter() - t0
    problem.kernel_steps, problem.kernel_s, problem.evaluations = 0, 0.0, 0

    ms = None
    if settings.search == "shooting":

        t0 = time.perf_counter()
        sh = settings.shooting
        ms = shooting_estimate(problem, notes, n_starts=sh.starts, segment_s=sh.segment_s,
                               dt_search=problem.ga_dt, seed=settings.seed,
                               max_iter=sh.max_iter,
                               polish_iter=settings.max_iter if settings.polish else 0,
                               nuisance=tuple(n for n in NUISANCE if settings.free_contact),
                               lengthen=tuple(sh.lengthen_s),
                               report=report, tie=sh.tie_motor_angle)
        x = ms.x.copy()
        x_first, cost_first, history = ms.x_ms, ms.search.cost, None
        spans, stages, restarted = [log.duration], [], False
        nfev = int(ms.polish.get("function_evaluations", 0))
        njev = int(ms.polish.get("jacobian_evaluations", 0))
        status = str(ms.polish.get("status", "no polish"))
        timings["search_s"] = time.perf_counter() - t0
        timings["ga_s"] = 0.0
        timings["polish_s"] = ms.timings.get("polish_s", 0.0)
        sp = ms.search.sp
        throughput = sp.work.kernel_steps / sp.work.kernel_s if sp.work.kernel_s > 0 else 0.0
    else:
        t0 = time.perf_counter()
        spans = horizons(log.duration, settings.ga_horizon_s if settings.polish else None)
        ga_problem = problem.prefix(spans[0])
        opts = preset("improved", pop=settings.ga.pop, generations=settings.ga.generations,
                      patience=settings.ga.patience)
        ga = run_ga(ga_problem, opts,
                    np.random.default_rng(np.random.SeedSequence(settings.seed)))
        timings["ga_s"] = time.perf_counter() - t0
        throughput = (ga_problem.kernel_steps / ga_problem.kernel_s if ga_problem.kernel_s > 0
                      else 0.0)
        if not np.isfinite(ga.cost):
            raise EmaError(f"{log.source}: every simulation of the GA diverged; check the "
                           "bounds and the fixed plant parameters", 1)

        x = ga.x.copy()
        nfev = njev = 0
        status = "no polish"
        restarted = False
        stages: list[dict[str, Any]] = []
        t0 = time.perf_counter()
        if settings.polish:
            for k, span in enumerate(spans):  # continuation: growing horizons, the whole log last
                report(f"polish over {span:g} s", k, len(spans))
                t1 = time.perf_counter()
                res, nj = polish(problem.prefix(span), x, settings.max_iter)
                x, status = res.x, str(res.message)
                nfev += int(res.nfev)
                njev += nj
                stages.append({"horizon_s": span, "function_evaluations": int(res.nfev),
                               "jacobian_evaluations": nj, "J": float(2.0 * res.cost),
                               "x": {n: float(v)
                                     for n, v in zip(problem.names, x, strict=True)},
                               "wall_time_s": time.perf_counter() - t1})
        timings["polish_s"] = time.perf_counter() - t0
        x_first, cost_first, history = ga.x, ga.cost, ga.history

    t0 = time.perf_counter()
    report("uncertainty and alpha profile")
    r, J = fd_jacobian(problem, x)
    grid = slc = prof = None
    if "alpha" in problem.names:
        grid, slc, prof = alpha_scan(problem, x, r, J, settings.profile_points)
        cost = float(r @ r)
        k = int(np.argmin(slc))
        if slc[k] < (1.0 - RESTART_MARGIN) * cost and settings.polish and ms is None:
            x1 = x.copy()
            x1[problem.names.index("alpha")] = grid[k]
            res, nj = polish(problem, x1, settings.max_iter)
            r1, J1 = fd_jacobian(problem, res.x)
            if float(r1 @ r1) < cost:
                x, r, J, restarted = res.x, r1, J1, True
                nfev += int(res.nfev)
                njev += nj
                status = str(res.message)
                grid, slc, prof = alpha_scan(problem, x, r, J, settings.profile_points)
    timings["uncertainty_profile_s"] = time.perf_counter() - t0

    if ms is None:
        cov, cond, dof = covariance(J, r, problem.groups())
        unc = assess(problem.names, x, cov, dof, cond, problem.lower, problem.upper)
    else:
        unc = ms.unc_ms
    for j, n in enumerate(problem.names):
        span = problem.upper[j] - problem.lower[j]
        if min(x[j] - problem.lower[j], problem.upper[j] - x[j]) <= 1e-6 * span:
            warnings.append(f"{n} = {x[j]:.6g} {BY_NAME[n].unit} sits on its bound "
                            f"[{problem.lower[j]:g}, {problem.upper[j]:g}]: widen the bounds "
                            "(its interval assumes an interior optimum)")
    smooth = (quadratic_check(problem, x, r, J, unc) if ms is None
              else np.full(x.shape[0], np.nan))
    if ms is not None and not ms.confirmed:
        for j in range(x.shape[0]):
            if problem.names[j] in NUISANCE and settings.free_contact:
                continue
            unc.determined[j] = False
            unc.reasons[j].append("the optimum is not confirmed: " + "; ".join(ms.reasons))
        warnings.append("the optimum is NOT confirmed: " + "; ".join(ms.reasons))
    for j, ratio in enumerate(smooth):
        if np.isfinite(ratio) and not 1.0 / QUADRATIC_RATIO <= ratio <= QUADRATIC_RATIO:
            unc.determined[j] = False
            unc.reasons[j].append(
                f"the cost is not smooth at the scale of the standard error: moving "
                f"{problem.names[j]} by 1 SE raises J {ratio:.3g} x what J^T J predicts (backlash "
                "impacts make output-error costs rugged, docs/identification.md)")
    # the contact's nuisance parameters are reported (identification.json), not judged
    judged = [n for n in problem.names
              if not (ms is not None and settings.free_contact and n in NUISANCE)]
    undetermined = [n for n, d in zip(problem.names, unc.determined, strict=True)
                    if not d and n in judged]
    if undetermined:
        warnings.append("not determined: " + ", ".join(undetermined)
                        + " (see identification.json, parameters.*.not_determined_because)")
    Y = problem.predict(x[None])[0]
    timings["total_s"] = time.perf_counter() - t_start
    fit = ClosedLoopFit(settings, problem, x_first, cost_first, x, float(r @ r), r, J, unc, Y,
                        history, notes, grid, slc, prof, nfev, njev, status, restarted,
                        spans, stages, timings, throughput, warnings, smooth, ms)
    fit.adequacy = judge_adequacy(problem, notes, ms, Y)
    if fit.adequacy is not None and not fit.adequacy["adequate"]:
        warnings.append("the model is NOT adequate for the log (its residuals are not white "
                        "noise independent of the command): " + " | ".join(
                            fit.adequacy["failures"]))
    ratios = fit.fit_quality()["rms_over_scale"]
    high = {c: v for c, v in ratios.items()
            if notes[c] == NOISE_NOTE and v > NOISE_LEVEL_RATIO}
    if ms is not None:
        whole = too_high(fit.rms_over_scale(), notes)
        if whole and not high:
            warnings.append(
                "the whole log simulated from rest at the estimate does not stay at the noise "
                "level (" + ", ".join(f"{c} {v:.3g} x" for c, v in whole.items()) + "), while "
                "its segments do: small differences grow over a long log (free flight in the "
                "gap, a command known only at the samples); fit.csv and fitted.yaml show the "
                "run from rest")
    if high:
        warnings.append(
            "the fit does not reach the noise level: residual RMS " + ", ".join(
                f"{v:.3g} x the noise estimate of {c}" for c, v in high.items())
            + ": a local minimum (try other bounds, a larger ga.pop or another ga_horizon_s) "
            "or a model that cannot explain the log; the standard errors assume neither")
    return fit


def judge_adequacy(problem: ClosedLoopProblem, notes: dict[str, str],
                   ms: ShootingOutcome | None, whole: np.ndarray) -> dict[str, Any]:
    """The adequacy of the fit (:func:`adequacy.adequacy`): the segments' prediction of a
    multiple-shooting fit (the fit itself), else the whole log from rest ``whole``
    [n_ch, n] (SI), against the logged command; the channels with an automatic scale judged;
    the failing windows among the fit's segments (a tenth of the log without them)."""
    from ema_cli.identify.closed_loop.adequacy import adequacy
    from ema_cli.identify.closed_loop.shooting_quality import JUDGED_NOTES

    n = problem.log.n
    pred = whole
    first = np.unique(np.linspace(0, n, 11).astype(int)[:-1])
    if ms is not None and ms.segment_prediction is not None:
        pred = ms.segment_prediction
        if ms.fit_first is not None:
            first = ms.fit_first
    judged = tuple(c for c in problem.channels if notes[c] in JUDGED_NOTES)
    return adequacy(problem.channels, problem.measured, pred, problem.log.theta_ref,
                    problem.log.t, first, judged)


def quadratic_check(problem: ClosedLoopProblem, x: np.ndarray, r: np.ndarray, J: np.ndarray,
                    unc: Uncertainty) -> np.ndarray:
    """Whether the cost is locally quadratic at the scale of the uncertainty -> per parameter
    the ratio of the actual mean rise of J at x +- d (others fixed; d = 1 SE, at least the
    finite-difference step) to the rise ``d^2 * |J_j|^2`` the Jacobian predicts (1 for a
    smooth cost; NaN where not checked). All 2p points run in one kernel call."""
    p = x.shape[0]
    ok = np.isfinite(unc.se) & (unc.se > 0)
    ratio = np.full(p, np.nan)
    idx = np.flatnonzero(ok)
    if idx.size == 0:
        return ratio
    # at least the finite-difference step: on noise-free data the SE is at rounding level
    step = np.maximum(unc.se, FD_REL_STEP * np.maximum(
        np.abs(x), 1e-3 * (problem.upper - problem.lower)))
    X = np.repeat(x[None], 2 * idx.size, axis=0)
    for k, j in enumerate(idx):
        X[2 * k, j] = min(x[j] + step[j], problem.upper[j])
        X[2 * k + 1, j] = max(x[j] - step[j], problem.lower[j])
    R = problem.weighted_residuals(X)
    J0 = float(r @ r)
    Jx = np.sum(R**2, axis=1)
    for k, j in enumerate(idx):
        d = np.array([X[2 * k, j] - x[j], X[2 * k + 1, j] - x[j]])
        pred = d**2 * float(J[:, j] @ J[:, j])
        act = np.array([Jx[2 * k], Jx[2 * k + 1]]) - J0
        if np.all(pred > 0):
            ratio[j] = float(np.mean(act) / np.mean(pred))
    return ratio
