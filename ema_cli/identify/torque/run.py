"""Library entry point of an identification: data -> problem -> exact optimum -> GA runs -> result.

``run_identification(settings)`` needs no CLI: it loads or simulates the data, builds the Eq. 8
problem, computes the least-squares certificate, runs the GA ``settings.runs`` times (seeds
``SeedSequence(settings.seed).spawn(runs)``, in parallel with joblib when ``n_jobs != 1``) and
returns an :class:`IdentificationResult` with errors against the truth (synthetic data) and
distances to the least-squares optimum.
"""

from __future__ import annotations

import time
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pandas as pd

from ema_cli.errors import EmaError
from ema_cli.identify.torque.data import (
    MIN_CONTACT_SAMPLES,
    IdentData,
    check_exercises_gap,
    load_csv,
    synthetic_data,
)
from ema_cli.identify.torque.exact import ExactResult, profile, solve_exact
from ema_cli.identify.torque.problem import PARAM_UNITS, TorqueProblem
from ema_cli.identify.torque.settings import IdentifySettings
from ema_cli.model.params import CONTACT_TAU
from ema_cli.optim.ga import GAHistory, GAOptions, run_ga
from ema_cli.units import DEG

DEADBAND_MARGIN = 0.10  # the dead band is "outside the range" if J beyond it is 10 % lower [-]
DEADBAND_GRID = 401  # alpha grid of the out-of-range check [points]
COLUMN_SUFFIX = {"kL": "kL_Nm_per_rad", "alpha": "alpha_rad", "c": "c_Nms_per_rad"}
"""CSV column names of the parameters (units in the header)."""


@dataclass
class RunRecord:
    """One GA run (or the exact solve): identified parameters in ``names`` order, cost, budget."""

    run: int
    method: str
    x: np.ndarray
    cost: float
    evaluations: int
    generations: int
    wall_time_s: float
    stopped_early: bool = False
    history: GAHistory | None = field(default=None, repr=False)


@dataclass
class IdentificationResult:
    """Everything an identification produced (SI units throughout).

    ``runs`` holds one record per GA seed (one record for ``method="exact"``); ``optimum`` is the
    least-squares certificate; ``truth`` the generating values for synthetic data, else None.
    """

    settings: IdentifySettings
    data: IdentData
    problem: TorqueProblem
    optimum: ExactResult
    runs: list[RunRecord]
    ga_options: GAOptions | None
    wall_time_s: float
    warnings: list[str] = field(default_factory=list)

    @property
    def names(self) -> tuple[str, ...]:
        """Identified parameter names, in column order."""
        return self.problem.names

    @property
    def truth(self) -> dict[str, float] | None:
        """True values of the identified parameters (synthetic data), else None."""
        if self.data.truth is None:
            return None
        return {n: self.data.truth[n] for n in self.names}

    @property
    def X(self) -> np.ndarray:
        """Identified parameters of every run, ``[n_runs, n_par]``."""
        return np.array([r.x for r in self.runs])

    def errors_pct(self) -> np.ndarray | None:
        """Signed errors against the truth, 100*(x - truth)/truth, ``[n_runs, n_par]`` [%]."""
        if self.truth is None:
            return None
        t = np.array([self.truth[n] for n in self.names])
        return 100.0 * (self.X - t) / t

    def distance_to_optimum_pct(self) -> np.ndarray:
        """Signed distance to the LS optimum, 100*(x - x_opt)/x_opt, ``[n_runs, n_par]`` [%]."""
        return 100.0 * (self.X - self.optimum.x) / self.optimum.x

    def optimum_errors_pct(self) -> np.ndarray | None:
        """Signed error of the LS optimum against the truth [%] (the data's own bias)."""
        if self.truth is None:
            return None
        t = np.array([self.truth[n] for n in self.names])
        return 100.0 * (self.optimum.x - t) / t

    def summary(self) -> dict[str, dict[str, float | None]]:
        """Per parameter: median/best-J/spread of the runs, truth, |error| median and worst [%],
        LS optimum with standard error, |distance to the optimum| median and worst [%]."""
        err = self.errors_pct()
        dist = self.distance_to_optimum_pct()
        best = int(np.argmin([r.cost for r in self.runs]))
        out: dict[str, dict[str, float | None]] = {}
        for j, n in enumerate(self.names):
            col = self.X[:, j]
            out[n] = {
                "unit": PARAM_UNITS[n],  # type: ignore[dict-item]
                "median": float(np.median(col)),
                "best_run": float(col[best]),
                "spread_std": float(np.std(col, ddof=1)) if col.shape[0] > 1 else 0.0,
                "truth": None if self.truth is None else self.truth[n],
                "error_pct_median": None if err is None else float(np.median(np.abs(err[:, j]))),
                "error_pct_worst": None if err is None else float(np.max(np.abs(err[:, j]))),
                "optimum": float(self.optimum.x[j]),
                "optimum_se": float(self.optimum.se[j]),
                "optimum_error_pct": (None if self.truth is None
                                      else float(self.optimum_errors_pct()[j])),  # type: ignore[index]
                "dist_opt_pct_median": float(np.median(np.abs(dist[:, j]))),
                "dist_opt_pct_worst": float(np.max(np.abs(dist[:, j]))),
            }
        return out

    def runs_frame(self) -> pd.DataFrame:
        """One row per run: identified values, J, budget, errors and distances (% columns)."""
        err = self.errors_pct()
        dist = self.distance_to_optimum_pct()
        rows = []
        for i, r in enumerate(self.runs):
            row: dict[str, Any] = {"run": r.run, "method": r.method}
            for j, n in enumerate(self.names):
                row[COLUMN_SUFFIX[n]] = r.x[j]
            row.update({"J_N2m2": r.cost, "evaluations": r.evaluations,
                        "generations": r.generations, "wall_time_s": r.wall_time_s,
                        "stopped_early": r.stopped_early})
            for j, n in enumerate(self.names):
                if err is not None:
                    row[f"{n}_error_pct"] = err[i, j]
                row[f"{n}_dist_opt_pct"] = dist[i, j]
            rows.append(row)
        return pd.DataFrame(rows)

    def history_frame(self) -> pd.DataFrame:
        """Long table of the GA histories: one row per (run, generation)."""
        frames = []
        for r in self.runs:
            h = r.history
            if h is None:
                continue
            data: dict[str, Any] = {
                "run": r.run, "generation": np.arange(h.best.shape[0]),
                "evaluations": h.evaluations, "best_J_N2m2": h.best, "mean_J_N2m2": h.mean,
                "best_ever_J_N2m2": h.best_ever,
            }
            for j, n in enumerate(self.names):
                data[f"best_{COLUMN_SUFFIX[n]}"] = h.x_best[:, j]
            for j, n in enumerate(self.names):
                data[f"best_ever_{COLUMN_SUFFIX[n]}"] = h.x_best_ever[:, j]
            frames.append(pd.DataFrame(data))
        if not frames:
            return pd.DataFrame(columns=["run", "generation"])
        return pd.concat(frames, ignore_index=True)

    def to_json(self) -> dict[str, Any]:
        """The content of identification.json."""
        opt = self.optimum
        err = self.errors_pct()
        dist = self.distance_to_optimum_pct()
        s = self.settings
        data_form = self.data.damping
        runs = []
        for i, r in enumerate(self.runs):
            runs.append({
                "run": r.run, "method": r.method,
                "identified": {n: float(r.x[j]) for j, n in enumerate(self.names)},
                "J": r.cost, "evaluations": r.evaluations, "generations": r.generations,
                "wall_time_s": r.wall_time_s, "stopped_early": r.stopped_early,
                "error_pct": None if err is None else {
                    n: float(err[i, j]) for j, n in enumerate(self.names)},
                "distance_to_optimum_pct": {n: float(dist[i, j]) for j, n in enumerate(self.names)},
            })
        return {
            "method": s.method,
            "model": s.model,
            "data": self.data.describe(),
            "experiment": (
                "user data" if data_form is None else
                f"{data_form}-damping data fitted with the {s.model} form: "
                + ("matched" if data_form == s.model else "MISMATCHED (model-form bias)")),
            "contact_fraction_at_optimum": self.data.contact_fraction(float(opt.x[1])),
            "parameters": list(self.names),
            "units": {n: PARAM_UNITS[n] for n in self.names},
            "bounds": {n: [float(self.problem.lower[j]), float(self.problem.upper[j])]
                       for j, n in enumerate(self.names)},
            "c_fixed": None if self.problem.fit_c else float(self.problem.c_fixed),
            "truth": self.truth,
            "ga_options": None if self.ga_options is None else vars(self.ga_options),
            "budget_evaluations": None if self.ga_options is None else self.ga_options.budget,
            "least_squares_optimum": {
                "params": opt.params,
                "J": opt.cost,
                "standard_error": {n: float(opt.se[j]) for j, n in enumerate(self.names)},
                "covariance": opt.cov.tolist(),
                "corr_kL_alpha": opt.corr_k_alpha,
                "error_pct_vs_truth": (None if self.truth is None else
                                       {n: float(v) for n, v in
                                        zip(self.names, self.optimum_errors_pct(), strict=True)}),
                "alpha_on_bound": opt.at_bound,
                "function_evaluations": opt.nfev,
                "wall_time_s": opt.wall_time_s,
            },
            "runs": runs,
            "summary": self.summary(),
            "warnings": self.warnings,
            "wall_time_s": self.wall_time_s,
        }


def load_data(settings: IdentifySettings) -> IdentData:
    """The settings' data: the CSV file if given, else synthetic data from the simulator."""
    if settings.data is not None:
        return load_csv(settings.data, settings.columns)
    syn = settings.synthetic
    return synthetic_data(
        syn.plant, syn.kL, syn.alpha, syn.damping, syn.amplitude_deg * DEG, syn.freq_hz,
        syn.freq_end_hz, syn.sweep_time_s, syn.duration_s, syn.dt_s, syn.sample_interval_s,
        syn.noise_pct, settings.seed)


def build_problem(settings: IdentifySettings, data: IdentData) -> TorqueProblem:
    """Eq. 8 over ``data`` with the settings' form, bounds and c (fixed or fitted)."""
    lo = [settings.k_range[0], settings.alpha_range[0]]
    hi = [settings.k_range[1], settings.alpha_range[1]]
    c_fixed = 0.0
    if settings.fits_c:
        lo.append(settings.c_range[0])
        hi.append(settings.c_range[1])
    elif settings.c is not None:
        c_fixed = settings.c
    elif data.truth is not None:
        c_fixed = data.truth["c"]
    else:
        raise EmaError("c is neither fitted nor given: pass --c VALUE or --fit-c")
    tau = (settings.contact_tau if settings.contact_tau is not None
           else data.tau if data.tau is not None else CONTACT_TAU)
    return TorqueProblem(data.dth, data.dw, data.torque, settings.model, np.array(lo),
                         np.array(hi), c_fixed, tau)


def check_deadband(problem: TorqueProblem, optimum: ExactResult, source: str) -> None:
    """EmaError when the LS alpha sits on a range bound and the cost is clearly lower outside.

    "Clearly": the profile minimum over ``[0, max |dth|]`` (leaving at least
    ``MIN_CONTACT_SAMPLES`` samples in contact) is more than ``DEADBAND_MARGIN`` below the
    in-range optimum, at an alpha outside the range.
    """
    if not optimum.at_bound:
        return
    lo, hi = float(problem.lower[1]), float(problem.upper[1])
    ad = np.sort(np.abs(problem.dth))
    top = float(ad[-(MIN_CONTACT_SAMPLES + 1)]) if ad.shape[0] > MIN_CONTACT_SAMPLES else 0.0
    grid = np.linspace(0.0, max(top, hi), DEADBAND_GRID)
    J, _ = profile(problem, grid)
    outside = (grid < lo) | (grid > hi)
    if not np.any(outside & np.isfinite(J)):
        return
    j = int(np.argmin(np.where(outside, J, np.inf)))
    if J[j] < (1.0 - DEADBAND_MARGIN) * optimum.cost:
        raise EmaError(
            f"{source}: the dead band lies outside the alpha search range [{lo:g}, {hi:g}] rad: "
            f"the best alpha in range sits on its bound ({optimum.x[1]:.6g} rad, "
            f"J = {optimum.cost:.4g}) while alpha = {grid[j]:.4g} rad gives J = {J[j]:.4g}; "
            f"widen --alpha-range")


def warm_kernels() -> None:
    """Compile (or load from numba's cache) the cost and profile kernels on a tiny problem, so
    the timings recorded in a result measure the computation, not the first-call load."""
    tiny = TorqueProblem(np.array([-2.0, 2.0, 3.0]), np.zeros(3), np.array([-1.0, 1.0, 2.0]),
                         "contact", np.array([0.5, 0.0]), np.array([1.5, 1.0]), 0.0)
    tiny.evaluate(np.array([[1.0, 1.0]]))
    profile(tiny, np.array([1.0]))


def _ga_run(problem: TorqueProblem, options: GAOptions, seq: np.random.SeedSequence,
            index: int, method: str) -> RunRecord:
    res = run_ga(problem, options, np.random.default_rng(seq))
    return RunRecord(index, method, res.x, res.cost, res.evaluations, res.generations,
                     res.wall_time_s, res.stopped_early, res.history)


def run_identification(
    settings: IdentifySettings, data: IdentData | None = None
) -> IdentificationResult:
    """Identify kL, alpha (and c) as ``settings`` say; ``data`` overrides the settings' data.

    Raises EmaError for bad data (file problems, data that never reach gear contact, a dead band
    outside the alpha range).
    """
    t0 = time.perf_counter()
    if data is None:
        data = load_data(settings)
    source = settings.data or "synthetic data"
    check_exercises_gap(data, settings.alpha_range[0], source)
    problem = build_problem(settings, data)
    warm_kernels()
    try:
        optimum = solve_exact(problem)
    except ValueError as exc:
        raise EmaError(f"{source}: the data do not determine {', '.join(problem.names)}: "
                       f"{exc} (is a column constant?)") from None
    check_deadband(problem, optimum, source)

    if settings.method == "exact":
        runs = [RunRecord(0, "exact", optimum.x.copy(), optimum.cost, optimum.nfev, 0,
                          optimum.wall_time_s)]
        options = None
    else:
        options = settings.ga.options(settings.method)
        problem.evaluate(problem.lower[None, :])  # compile / load the kernel before any worker
        seqs = np.random.SeedSequence(settings.seed).spawn(settings.runs)
        if settings.n_jobs != 1 and settings.runs > 1:
            from joblib import Parallel, delayed

            runs = Parallel(n_jobs=settings.n_jobs)(
                delayed(_ga_run)(problem, options, s, i, settings.method)
                for i, s in enumerate(seqs))
        else:
            runs = [_ga_run(problem, options, s, i, settings.method) for i, s in enumerate(seqs)]
    return IdentificationResult(settings, data, problem, optimum, list(runs), options,
                                time.perf_counter() - t0, bound_warnings(problem, optimum))


def bound_warnings(problem: TorqueProblem, optimum: ExactResult) -> list[str]:
    """Warnings for LS optima of kL or c outside the GA's ranges (the GA cannot reach them)."""
    out = []
    for j, n in enumerate(problem.names):
        if n == "alpha":
            continue  # alpha is searched within its range by both solvers (see check_deadband)
        lo, hi, v = float(problem.lower[j]), float(problem.upper[j]), float(optimum.x[j])
        if not lo <= v <= hi:
            out.append(f"the least-squares {n} = {v:.6g} {PARAM_UNITS[n]} lies outside the "
                       f"search range [{lo:g}, {hi:g}]: the GA cannot reach it; widen the range")
    return out


def _flat(res: IdentificationResult, prefix: str = "") -> dict[str, Any]:
    out: dict[str, Any] = {}
    for n, s in res.summary().items():
        for key in ("median", "error_pct_median", "error_pct_worst", "optimum", "optimum_se",
                    "optimum_error_pct", "dist_opt_pct_median", "dist_opt_pct_worst"):
            if s[key] is not None:
                out[f"{prefix}{n}_{'identified' if key == 'median' else key}"] = s[key]
    return out


@dataclass
class IdentificationSummary:
    """Flat scalars of an identification (for the reproduction's claims) and the results they
    came from: ``results[""]`` is the requested method's, ``results["ga-paper"]`` the paper-mode
    GA's on the same data and seeds (when it ran). The report layer writes each result's folder
    (``out`` and ``out/<key>``)."""

    scalars: dict[str, Any]
    results: dict[str, IdentificationResult]


def summarize_identification(
    settings: Mapping[str, Any] | IdentifySettings,
    with_paper_mode: bool = True,
    with_mismatch: bool = True,
) -> IdentificationSummary:
    """Run an identification and return flat scalars (for the paper reproduction and claims).

    ``settings``: an IdentifySettings or a mapping validated into one (EmaError on bad keys).
    Keys (``P`` in kL, alpha[, c]): ``P_identified`` (median over runs), ``P_error_pct_median``
    / ``P_error_pct_worst`` (|error| vs truth, %), ``P_optimum``, ``P_optimum_se``,
    ``P_optimum_error_pct`` (signed, %), ``P_dist_opt_pct_median`` / ``_worst`` (% of the
    optimum), ``corr_kL_alpha``, ``runs``, ``evaluations_per_run``, ``wall_time_per_run_s``,
    ``exact_wall_time_s``. With ``with_paper_mode`` (and a method other than ga-paper) the
    paper-mode GA runs on the same data and seeds: ``paper_mode_P_error_pct_median`` / ``_worst``
    etc. With ``with_mismatch`` the other torque form is fitted by least squares to the same
    data: ``mismatch_P_bias_pct`` (signed % vs truth; synthetic data only). Writes nothing
    (``report.identify_figures.identification_summary`` also writes the folders).
    """
    from ema_cli.config.loader import validate

    if not isinstance(settings, IdentifySettings):
        settings = validate(IdentifySettings, dict(settings), "identification settings")
    res = run_identification(settings)
    flat: dict[str, Any] = {
        "method": settings.method, "model": settings.model,
        "data_damping": res.data.damping, "runs": len(res.runs),
        "n_samples": res.data.n_samples,
        "corr_kL_alpha": res.optimum.corr_k_alpha,
        "evaluations_per_run": float(np.median([r.evaluations for r in res.runs])),
        "wall_time_per_run_s": float(np.median([r.wall_time_s for r in res.runs])),
        "exact_wall_time_s": res.optimum.wall_time_s,
    }
    flat.update(_flat(res))
    results = {"": res}
    if with_paper_mode and settings.method != "ga-paper":
        paper = run_identification(settings.model_copy(update={"method": "ga-paper"}),
                                   data=res.data)
        flat.update(_flat(paper, "paper_mode_"))
        results["ga-paper"] = paper
    if with_mismatch and res.truth is not None:
        other = "paper" if settings.model == "contact" else "contact"
        mm = solve_exact(build_problem(settings.model_copy(update={"model": other}), res.data))
        flat["mismatch_model"] = other
        for j, n in enumerate(res.names):
            flat[f"mismatch_{n}_bias_pct"] = float(100.0 * (mm.x[j] / res.truth[n] - 1.0))
    return IdentificationSummary(flat, results)
