"""The static LuGre friction curve from a constant-speed sweep: Fc, Fs, vs, sigma2 by variable
projection, with standard errors.

The model is the simulator's own steady-state friction at the motor shaft
(``model.lugre.steady_friction_nb``, docs/model.md §2)::

    T(w) = sign(w)*g(w) + sigma2*w,    g(w) = Fc + (Fs - Fc)*exp(-|w/vs|^delta)     [N*m]

with w the motor speed [rad/s] and the Stribeck exponent ``delta`` fixed (the model's, default
1). For a fixed vs the curve is linear in (Fc, Fs, sigma2)::

    T = Fc*sign(w)*(1 - E) + Fs*sign(w)*E + sigma2*w,     E = exp(-|w/vs|^delta)

so the linear coefficients are a linear least-squares solve and only vs is searched (variable
projection): a log-spaced grid over the speeds of the data, then a bounded scalar search of the
projected residual, then a Gauss-Newton polish of all four together, whose Jacobian gives the
standard errors (``identify.uncertainty``). The dynamic sigma0 (and sigma1) do not act at
constant speed: they come from the closed-loop fit or a pre-sliding test.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ema_cli._numba import njit
from ema_cli.errors import EmaError
from ema_cli.files import read_csv
from ema_cli.identify.friction.laws import LAWS, LawFit, fit_law, min_points, select_law
from ema_cli.identify.shape_adequacy import (
    MAD_NORMAL,
    MIN_SCATTER_DOF,
    Adequacy,
    assess_shape,
    pure_error,
    quantile_bins,
    repeat_groups,
)
from ema_cli.identify.uncertainty import Uncertainty, assess, covariance
from ema_cli.model.lugre import steady_friction_nb, stribeck_nb

SWEEP_COLUMNS = ("omega_rpm", "torque_nm")
"""Columns of a friction-sweep CSV: motor speed [rpm], steady friction torque [N*m]."""
SWEEP_NAMES = ("Fc", "Fs", "vs", "sigma2")
SWEEP_UNITS = {"Fc": "N*m", "Fs": "N*m", "vs": "rad/s", "sigma2": "N*m*s/rad"}
MIN_SWEEP_ROWS = 8  # fewest speeds accepted (4 parameters, both directions) [rows]
MIN_PER_DIRECTION = 3  # fewest speeds per direction [rows]
VS_GRID = 241  # log-spaced vs values scanned before the scalar search [points]
VS_SPAN = 10.0  # vs is searched from min|w|/VS_SPAN to max|w|*VS_SPAN [-]
POLISH_TOL = 1e-15  # xtol/ftol/gtol of the four-parameter polish [-]
SHAPE_BINS = 4  # speed ranges per direction in the shape verdict's "where" [bins]


@njit(cache=True, error_model="numpy", entry=True)
def stribeck_shape_nb(w, vs, delta, out):
    """E(w) = exp(-|w/vs|^delta) [-] for every speed of ``w`` [rad/s] into ``out``: the
    model's Stribeck function with Fc = 0, Fs = 1."""
    for i in range(w.shape[0]):
        out[i] = stribeck_nb(w[i], 0.0, 1.0, vs, delta)


@njit(cache=True, error_model="numpy", entry=True)
def static_curve_nb(w, fc, fs, vs, delta, sigma2, out):
    """The model's steady-state friction torque T(w) [N*m] at every speed of ``w`` [rad/s]."""
    for i in range(w.shape[0]):
        out[i] = steady_friction_nb(w[i], fc, fs, vs, delta, sigma2)


def static_curve(w: np.ndarray, Fc: float, Fs: float, vs: float, sigma2: float,
                 delta: float = 1.0) -> np.ndarray:
    """Steady-state LuGre friction torque [N*m] at motor speeds ``w`` [rad/s]."""
    w = np.ascontiguousarray(w, dtype=np.float64)
    out = np.empty_like(w)
    static_curve_nb(w, float(Fc), float(Fs), float(vs), float(delta), float(sigma2), out)
    return out


def _shape(w: np.ndarray, vs: float, delta: float) -> np.ndarray:
    out = np.empty_like(w)
    stribeck_shape_nb(w, float(vs), float(delta), out)
    return out


def basis(w: np.ndarray, vs: float, delta: float) -> np.ndarray:
    """Columns of the linear part for a fixed vs: ``[sign(w)*(1-E), sign(w)*E, w]`` [n, 3]."""
    s = np.sign(w)
    E = _shape(w, vs, delta)
    return np.column_stack([s * (1.0 - E), s * E, w])


def project(w: np.ndarray, T: np.ndarray, vs: float, delta: float) -> tuple[np.ndarray, float]:
    """The linear least-squares (Fc, Fs, sigma2) for a fixed vs -> (coefficients, RSS [N^2*m^2])."""
    A = basis(w, vs, delta)
    coef, *_ = np.linalg.lstsq(A, T, rcond=None)
    r = T - A @ coef
    return coef, float(r @ r)


def jacobian(w: np.ndarray, x: np.ndarray, delta: float) -> np.ndarray:
    """d T / d (Fc, Fs, vs, sigma2) at ``x`` [n, 4] (analytic)."""
    Fc, Fs, vs, _ = x
    s = np.sign(w)
    E = _shape(w, vs, delta)
    u = np.abs(w / vs)
    with np.errstate(divide="ignore", invalid="ignore"):
        du = np.where(u > 0, delta * u**delta / vs, 0.0)  # d(-|w/vs|^delta)/d vs
    return np.column_stack([s * (1.0 - E), s * E, s * (Fs - Fc) * E * du, w])


@dataclass(frozen=True)
class SweepData:
    """A friction sweep: speeds ``omega`` [rad/s, or m/s for a linear sweep] and steady
    friction torques [N*m, or forces N]; ``notes`` say what loading changed (rows dropped,
    signs restored)."""

    omega: np.ndarray
    torque: np.ndarray
    source: str
    truth: dict[str, float] | None = None
    linear: bool = False
    notes: tuple[str, ...] = ()

    @property
    def n(self) -> int:
        return int(self.omega.shape[0])

    @property
    def speed_unit(self) -> str:
        """The SI unit of the speeds: rad/s or m/s."""
        return "m/s" if self.linear else "rad/s"

    @property
    def force_unit(self) -> str:
        """The SI unit of the friction: N*m or N."""
        return "N" if self.linear else "N*m"


def read_truth(path: Path) -> dict[str, float] | None:
    """The truths of synthetic data from the sidecar ``<stem>.truth.json`` beside ``path``,
    if there is one (written by ``ema identify --make-data``), else None."""
    import json

    side = path.with_name(path.stem + ".truth.json")
    if not side.is_file():
        return None
    try:
        data = json.loads(side.read_text(encoding="utf-8"))
        return {str(k): float(v) for k, v in data["truth"].items()}
    except (OSError, ValueError, KeyError, TypeError, AttributeError):
        raise EmaError(f"truth file '{side}' is not a truth file written by ema identify "
                       "--make-data (a JSON object with 'truth': {name: value})") from None


def read_table(path: str | Path, required: tuple[str, ...],
               optional: tuple[str, ...] = ()) -> tuple[dict[str, np.ndarray], list[str]]:
    """Read a CSV and check it: the file, the ``required`` columns, every value of the used
    columns finite -> (column -> float array, the optional columns present). Errors name the
    file, the column and the line (1 = the header)."""
    import pandas as pd

    p = Path(path)
    df = read_csv(p)
    missing = [c for c in required if c not in df.columns]
    if missing:
        raise EmaError(f"data file '{p}' lacks column(s) {', '.join(missing)}; expected "
                       f"{', '.join(required)}" + (f" (optional: {', '.join(optional)})"
                                                   if optional else "")
                       + f"; found {', '.join(map(str, df.columns)) or 'none'}")
    present = [c for c in optional if c in df.columns]
    out = {}
    for col in (*required, *present):
        values = pd.to_numeric(df[col], errors="coerce").to_numpy(np.float64)
        bad = ~np.isfinite(values)
        if bad.any():
            line = int(np.flatnonzero(bad)[0]) + 2  # +1 header, +1 one-based
            raise EmaError(f"data file '{p}': column '{col}' has {int(bad.sum())} empty, "
                           f"non-numeric, NaN or inf value(s) (first at line {line})")
        out[col] = values
    return out, present


SWEEP_CHANNELS: dict[str, tuple[str, str]] = {"omega_rpm": ("sweep speed", "rpm"),
                                               "torque_nm": ("torque or force", "N*m")}
"""The channels of a friction sweep -> (kind of unit, own unit) for ``--columns``."""


def load_sweep(path: str | Path, columns: dict[str, str] | None = None) -> SweepData:
    """Read and validate a friction sweep (``omega_rpm``, ``torque_nm``, or mapped with
    ``columns``: channel -> ``COLUMN[:UNIT]``, units rpm, rad/s, deg/s, m/s, mm/s and N*m,
    mN*m, N, kN; CSV, Parquet or .mat). Rows need not be sorted and may repeat; rows at
    exactly zero speed are dropped (at rest the friction is not on the static curve), and a
    map giving the friction's magnitude in both directions gets the sign of the speed back
    (both noted). Errors name the file, column and line."""
    from ema_cli.identify.logs.channels import read_log
    from ema_cli.units import LINEAR_UNITS

    p = Path(path)
    cols = read_log(p, tuple(SWEEP_CHANNELS), (), columns, SWEEP_CHANNELS)
    w = cols.values["omega_rpm"]
    T = cols.values["torque_nm"]
    linear = bool(LINEAR_UNITS & set(cols.units.values()))
    label = cols.label("omega_rpm")
    notes = []
    zero = np.flatnonzero(w == 0.0)
    if zero.size:
        keep = w != 0.0
        notes.append(f"{zero.size} row(s) at zero speed dropped ({label} is 0 at "
                     f"{cols.table.where(int(zero[0]))}): at rest the friction is not on the "
                     "static curve")
        w, T = w[keep], T[keep]
    n = w.shape[0]
    if n < MIN_SWEEP_ROWS:
        raise EmaError(f"data file '{p}' has {n} speed(s) other than 0; a friction sweep needs "
                       f"at least {MIN_SWEEP_ROWS} (4 parameters, both directions)")
    n_pos, n_neg = int(np.sum(w > 0)), int(np.sum(w < 0))
    if min(n_pos, n_neg) < MIN_PER_DIRECTION:
        raise EmaError(f"data file '{p}': {label} has {n_pos} positive and {n_neg} "
                       f"negative speeds; the sweep needs both directions, at least "
                       f"{MIN_PER_DIRECTION} speeds each")
    if np.unique(np.abs(w)).shape[0] < 4:
        raise EmaError(f"data file '{p}': {label} has fewer than 4 distinct |speeds|;"
                       " Fc, Fs, vs and sigma2 need at least 4")
    if np.median(T[w < 0]) > 0 and np.median(T[w > 0]) > 0:
        T = np.where(w < 0, -np.abs(T), T)
        notes.append("the friction is positive at negative speeds too (a map of magnitudes): "
                     "the - direction's values were given the sign of the speed")
    return SweepData(w, T, f"file: {p}", read_truth(p), linear, tuple(notes))


@dataclass
class FrictionFit:
    """A friction-sweep fit (SI): the estimate, its uncertainty, the data and the vs scan."""

    data: SweepData
    delta: float
    x: np.ndarray
    rss: float
    uncertainty: Uncertainty
    vs_grid: np.ndarray
    vs_rss: np.ndarray
    wall_time_s: float
    warnings: list[str] = field(default_factory=list)
    laws: dict[str, LawFit] = field(default_factory=dict)
    chosen: str = "stribeck"
    selection: dict[str, Any] = field(default_factory=dict)
    adequacy: Adequacy | None = None

    @property
    def law(self) -> LawFit:
        """The chosen law's fit (``laws[chosen]``)."""
        return self.laws[self.chosen]

    def law_units(self) -> dict[str, str]:
        """Units of the candidate laws' parameters (rotary or linear sweep)."""
        f, v = self.data.force_unit, self.data.speed_unit
        base = {"Fc": f, "Fs": f, "vs": v, "sigma2": f"{f}*s/{'m' if self.data.linear else 'rad'}",
                "delta": "-"}
        return {**base, **{f"{k}_neg": u for k, u in base.items()}}

    @property
    def params(self) -> dict[str, float]:
        return {n: float(v) for n, v in zip(SWEEP_NAMES, self.x, strict=True)}

    def model(self, w: np.ndarray | None = None) -> np.ndarray:
        """The fitted static curve at ``w`` [rad/s] (default: the data's speeds) [N*m]."""
        return static_curve(self.data.omega if w is None else w, *self.x, delta=self.delta)

    def to_json(self) -> dict[str, Any]:
        """The content of identification.json (values under the names of ``ema params``):
        ``parameters`` are the chosen law's; ``symmetric_stribeck`` the model's own law (the
        simulator's LuGre curve) fitted as before; ``laws`` every candidate."""
        u = self.uncertainty
        resid = self.data.torque - self.model()
        truth = self.data.truth
        units = self.law_units()
        law = self.law
        out: dict[str, Any] = {
            "mode": "friction-sweep",
            "chosen_law": self.chosen,
            "selection": self.selection,
            "parameters": law.uncertainty.to_json(units),
            "differences_neg_minus_pos": law.differences(),
            "adequacy": None if self.adequacy is None else self.adequacy.to_json(),
            "laws": {k: v.to_json(units) for k, v in self.laws.items()},
            "units": {"speed": self.data.speed_unit, "friction": self.data.force_unit},
            "data_notes": list(self.data.notes),
            "model": "steady-state LuGre friction at the motor shaft: T(w) = sign(w)*(Fc + "
                     "(Fs - Fc)*exp(-|w/vs|^delta)) + sigma2*w (model.lugre.steady_friction_nb)",
            "method": "variable projection: linear least squares for (Fc, Fs, sigma2) at each "
                      "vs, scalar search over vs, then a four-parameter Gauss-Newton polish",
            "data": {"source": self.data.source, "n_speeds": self.data.n,
                     "omega_range_rad_s": [float(self.data.omega.min()),
                                           float(self.data.omega.max())]},
            "fixed": {"delta": self.delta},
            "symmetric_stribeck": u.to_json(SWEEP_UNITS),
            "correlation": {"names": list(SWEEP_NAMES), "matrix": u.corr.tolist()},
            "covariance_si": u.cov.tolist(),
            "cost": {"rss_N2m2": self.rss, "dof": u.dof,
                     "residual_std_nm": math.sqrt(self.rss / u.dof)},
            "fit_rms": {"torque_nm": float(np.sqrt(np.mean(resid**2)))},
            "intervals": f"95 % (Student's t, {u.dof} dof: t = {u.t_quantile:.4f}) from "
                         "s^2 (J^T J)^-1",
            "condition_number": u.cond,
            "not_determined": [n for n, d in zip(SWEEP_NAMES, u.determined, strict=True)
                               if not d],
            "sigma0": "not identifiable from steady-state data (use --closed-loop with sigma0 "
                      "free, or a pre-sliding test)",
            "warnings": self.warnings,
            "wall_time_s": self.wall_time_s,
        }
        if truth is not None:
            out["truth"] = {n: truth[n] for n in law.names if n in truth}
            out["error_pct_vs_truth"] = {
                n: 100.0 * (float(law.x[j]) / truth[n] - 1.0)
                for j, n in enumerate(law.names) if truth.get(n)}
        return out


def fit_friction_sweep(data: SweepData, delta: float = 1.0,
                       vs_bounds: tuple[float, float] | None = None,
                       laws: tuple[str, ...] = LAWS, fit_delta: bool = False) -> FrictionFit:
    """Fit Fc, Fs, vs, sigma2 to ``data`` by variable projection (see the module docstring),
    then every candidate law of ``laws`` (``friction.laws``), choose one by BIC and judge its
    shape against the data's scatter (``identify.shape_adequacy``).

    ``delta`` the Stribeck exponent (fixed unless ``fit_delta``); ``vs_bounds`` [rad/s] the
    vs search range of the symmetric law (default: min|w|/10 .. max|w|*10).
    """
    from scipy.optimize import least_squares, minimize_scalar

    t0 = time.perf_counter()
    if not (math.isfinite(delta) and delta > 0):
        raise EmaError(f"delta (the Stribeck exponent) must be > 0, got {delta}")
    w, T = data.omega, data.torque
    aw = np.abs(w)
    lo, hi = vs_bounds or (float(aw.min()) / VS_SPAN, float(aw.max()) * VS_SPAN)
    if not (0 < lo < hi and math.isfinite(hi)):
        raise EmaError(f"vs search range must be 0 < LO < HI, got [{lo:g}, {hi:g}] rad/s")
    grid = np.geomspace(lo, hi, VS_GRID)
    rss = np.array([project(w, T, v, delta)[1] for v in grid])
    k = int(np.argmin(rss))
    a, b = math.log(grid[max(k - 1, 0)]), math.log(grid[min(k + 1, VS_GRID - 1)])
    best = minimize_scalar(lambda lv: project(w, T, math.exp(lv), delta)[1],
                           bounds=(a, b), method="bounded", options={"xatol": 1e-12})
    vs = math.exp(float(best.x))
    coef, _ = project(w, T, vs, delta)
    x0 = np.array([coef[0], coef[1], vs, coef[2]])

    def resid(x: np.ndarray) -> np.ndarray:
        return static_curve(w, x[0], x[1], x[2], x[3], delta) - T

    pol = least_squares(resid, x0, jac=lambda x: jacobian(w, x, delta), method="lm",
                        xtol=POLISH_TOL, ftol=POLISH_TOL, gtol=POLISH_TOL, x_scale="jac")
    x = pol.x if pol.cost <= 0.5 * float(resid(x0) @ resid(x0)) else x0
    r = resid(x)
    J = jacobian(w, x, delta)
    cov, cond, dof = covariance(J, r)
    unc = assess(SWEEP_NAMES, x, cov, dof, cond)
    warnings = []
    if x[2] <= lo * 1.0001 or x[2] >= hi * 0.9999:
        warnings.append(f"vs = {x[2]:.4g} rad/s sits on its search bound [{lo:.4g}, {hi:.4g}]: "
                        "the sweep does not resolve the Stribeck velocity")
    if x[0] < 0 or x[1] < 0:
        warnings.append("a negative Coulomb or static friction: the data do not look like a "
                        "friction curve (torque sign convention: friction opposes the motion)")
    fits = fit_laws(data, laws, delta, fit_delta, warnings)
    chosen, selection = select_law(fits)
    adequacy = sweep_adequacy(data, fits[chosen])
    warnings.extend(data.notes)
    return FrictionFit(data, float(delta), x, float(r @ r), unc, grid, rss,
                       time.perf_counter() - t0, warnings, fits, chosen, selection, adequacy)


def fit_laws(data: SweepData, laws: tuple[str, ...], delta: float, fit_delta: bool,
             warnings: list[str]) -> dict[str, LawFit]:
    """Every candidate law the data have points enough for (the others noted in
    ``warnings``)."""
    out = {}
    w, T = data.omega, data.torque
    n_pos = np.unique(w[w > 0]).shape[0]
    n_neg = np.unique(w[w < 0]).shape[0]
    for law in laws:
        if law not in LAWS:
            raise EmaError(f"unknown friction law '{law}'; expected one of {', '.join(LAWS)}")
        need = min_points(law, fit_delta)
        have = min(n_pos, n_neg) if law.endswith("-dir") else np.unique(np.abs(w)).shape[0]
        if have < need:
            warnings.append(f"law {law} skipped: it needs {need} distinct speeds"
                            f"{' per direction' if law.endswith('-dir') else ''}, the data "
                            f"have {have}")
            continue
        out[law] = fit_law(law, w, T, delta, fit_delta)
    if not out:
        raise EmaError(f"{data.source}: no candidate law has enough distinct speeds")
    return out


def sweep_adequacy(data: SweepData, law: LawFit) -> Adequacy:
    """The chosen law's residuals against the sweep's scatter: pure error of repeated speeds
    when there are any, else second differences of neighbours (an upper bound); regions:
    up to SHAPE_BINS speed ranges per direction."""
    w, T = data.omega, data.torque
    resid = T - law.curve(w)
    groups = repeat_groups(w)
    ss_pe, dof_pe = pure_error(T, groups)
    unit = data.force_unit
    regions = []
    for sign, name in ((1.0, "+"), (-1.0, "-")):
        idx = np.flatnonzero(np.sign(w) == sign)
        for b in quantile_bins(np.abs(w[idx]), SHAPE_BINS):
            sel = idx[b]
            lo, hi = float(np.abs(w[sel]).min()), float(np.abs(w[sel]).max())
            regions.append((f"{name} direction, |speed| {lo:.3g} .. {hi:.3g} "
                            f"{data.speed_unit}", sel))
    if dof_pe >= MIN_SCATTER_DOF:
        k = len(law.names)
        g = len(groups)
        lof = (max(law.rss - ss_pe, 0.0), g - k, ss_pe, dof_pe)
        return assess_shape(resid, math.sqrt(ss_pe / dof_pe), dof_pe,
                            f"repeated speeds: {dof_pe} dof", unit, regions, lof=lof)
    d2 = []
    for sign in (1.0, -1.0):
        idx = np.flatnonzero(np.sign(w) == sign)
        order = idx[np.argsort(np.abs(w[idx]), kind="stable")]
        d2.append(np.diff(T[order], 2))
    d2a = np.concatenate(d2)
    if d2a.shape[0] < MIN_SCATTER_DOF:
        return assess_shape(resid, math.nan, 0, "neighbour differences", unit, regions)
    mad = float(np.median(np.abs(d2a - np.median(d2a))))
    scatter = mad / MAD_NORMAL / math.sqrt(6.0)
    return assess_shape(resid, scatter, int(d2a.shape[0]),
                        "second differences of neighbouring speeds, an upper bound", unit,
                        regions, unbiased=False)
