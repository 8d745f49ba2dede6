"""Shape adequacy of a fitted curve: its residual RMS against the data's own scatter, a
three-valued verdict and where the model fails (friction sweep, torque-twist fit).

The scatter is estimated from the data alone, never from the fit:

* ``repeats``: points measured more than once at the same abscissa (a friction map's repeated
  speeds): the pooled within-group standard deviation (pure error, ``n - g`` degrees of
  freedom); the lack-of-fit F-test then compares the model's residual with it (Draper & Smith,
  Applied Regression Analysis, §2.1).
* ``second differences``: a time series sampled finely (a torque-twist log): the noise of a
  smooth signal is what its second differences hold, ``var(d2 y) = 6 sigma^2`` for white
  noise; the median absolute deviation (``MAD/0.6745``) keeps a few kinks (reversals, contact)
  from inflating it.
* ``neighbour differences``: sparse points without repeats, sorted by abscissa: the same
  estimate on second differences of neighbours, which also holds the curve's own bending
  between points: an UPPER BOUND of the scatter. Against it only "does not fit" can hold.

Verdict (ratio = residual RMS / scatter):
``fits`` when ratio <= FIT_RATIO (and no lack of fit at p < LOF_ALPHA where repeats give the
test) with an unbiased scatter; ``does not fit`` when ratio >= MISFIT_RATIO (with repeats:
and the lack-of-fit p < LOF_ALPHA); otherwise ``inconclusive``, with the reason. Where: the
residual RMS per region (direction x range bins) against the same scatter; the regions at or
above MISFIT_RATIO are named.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

FIT_RATIO = 1.5  # residual RMS within 1.5x the scatter: the shape fits [-]
MISFIT_RATIO = 3.0  # residual RMS 3x the scatter or more: the model does not fit [-]
LOF_ALPHA = 0.01  # level of the lack-of-fit F-test (repeats) [-]
MAD_NORMAL = 0.6744897501960817  # MAD of a standard normal [-]
MIN_SCATTER_DOF = 3  # fewest degrees of freedom of a scatter estimate [-]
REPEAT_RTOL = 1e-9  # abscissae equal within this relative tolerance are repeats [-]
MAX_WHERE = 3  # failing regions named in the verdict line, the worst first [regions]
DIFF_AGREE = 1.25  # 2nd- and 3rd-difference noise estimates within this factor: white [-]


@dataclass
class Region:
    """One region of the data: a label, its sample count, residual RMS and mean [data unit]."""

    label: str
    n: int
    rms: float
    mean: float
    ratio: float

    def to_json(self) -> dict[str, Any]:
        return {"region": self.label, "n": self.n, "residual_rms": self.rms,
                "residual_mean": self.mean, "ratio_to_scatter": self.ratio}


@dataclass
class Adequacy:
    """The shape verdict of a fit: ``verdict`` fits | does not fit | inconclusive, ``why``."""

    verdict: str
    why: str
    residual_rms: float
    scatter: float
    scatter_method: str
    scatter_dof: int
    ratio: float
    unit: str
    lack_of_fit_p: float | None = None
    regions: list[Region] = field(default_factory=list)

    @property
    def failing(self) -> list[Region]:
        """The regions whose residual RMS is MISFIT_RATIO x the scatter or more."""
        return [r for r in self.regions if r.ratio >= MISFIT_RATIO]

    def where(self) -> str:
        """The failing regions in words, the worst MAX_WHERE of them ('' when none)."""
        bad = sorted(self.failing, key=lambda r: -r.ratio)
        if not bad:
            return ""
        head = (f"all {len(bad)} regions, worst " if len(bad) == len(self.regions) > 1
                else f"{len(bad)} of {len(self.regions)} regions, worst " if len(bad) > 1
                else "")
        return head + "; ".join(f"{r.label}: residual RMS {r.rms:.3g} {self.unit} = "
                                f"{r.ratio:.1f}x the scatter, mean {r.mean:+.3g}"
                                for r in bad[:MAX_WHERE])

    def line(self) -> str:
        """One line for the console and the summary."""
        head = {"fits": "the model fits", "does not fit": "THE MODEL DOES NOT FIT",
                "inconclusive": "INCONCLUSIVE"}[self.verdict]
        w = self.where()
        return f"shape: {head}: {self.why}" + (f"; where: {w}" if w and self.verdict != "fits"
                                              else "")

    def to_json(self) -> dict[str, Any]:
        return {"verdict": self.verdict, "why": self.why, "residual_rms": self.residual_rms,
                "scatter": self.scatter, "scatter_method": self.scatter_method,
                "scatter_dof": self.scatter_dof, "ratio": self.ratio, "unit": self.unit,
                "lack_of_fit_p": self.lack_of_fit_p,
                "thresholds": {"fits_at_most": FIT_RATIO, "does_not_fit_from": MISFIT_RATIO,
                               "lack_of_fit_alpha": LOF_ALPHA},
                "regions": [r.to_json() for r in self.regions],
                "failing_regions": [r.label for r in self.failing]}


def repeat_groups(x: np.ndarray) -> list[np.ndarray]:
    """Index groups of equal abscissae (within REPEAT_RTOL), every group, singletons too."""
    order = np.argsort(x, kind="stable")
    xs = x[order]
    groups, start = [], 0
    for i in range(1, xs.shape[0] + 1):
        if i == xs.shape[0] or abs(xs[i] - xs[start]) > REPEAT_RTOL * max(abs(xs[start]),
                                                                           1e-300):
            groups.append(order[start:i])
            start = i
    return groups


def pure_error(y: np.ndarray, groups: list[np.ndarray]) -> tuple[float, int]:
    """(sum of squares within the groups, its degrees of freedom n - g)."""
    ss, dof = 0.0, 0
    for g in groups:
        if g.shape[0] > 1:
            v = y[g]
            ss += float(np.sum((v - v.mean()) ** 2))
            dof += g.shape[0] - 1
    return ss, dof


def _mad_std(d: np.ndarray, gain: float) -> float:
    """Robust std of white noise whose differences ``d`` have variance ``gain * sigma^2``."""
    return float(np.median(np.abs(d - np.median(d)))) / MAD_NORMAL / math.sqrt(gain)


def second_difference_scatter(y: np.ndarray) -> tuple[float, int, bool]:
    """Robust white-noise std of the sequence ``y`` from its second differences
    (MAD/0.6745/sqrt(6)) -> (std, n - 2, white). ``white``: the third differences
    (``var = 20 sigma^2``) give the same std within DIFF_AGREE; if not, the signal's own
    curvature shows in the differences (sampled too coarsely) and the std is an upper
    bound."""
    y = np.asarray(y, dtype=np.float64)
    d2 = np.diff(y, 2)
    if d2.shape[0] < MIN_SCATTER_DOF + 1:
        return math.nan, 0, False
    s2 = _mad_std(d2, 6.0)
    s3 = _mad_std(np.diff(y, 3), 20.0)
    white = bool(s2 > 0 and 1.0 / DIFF_AGREE <= s3 / s2 <= DIFF_AGREE)
    return s2, int(d2.shape[0]), white


def assess_shape(resid: np.ndarray, scatter: float, dof: int, method: str, unit: str,
                 regions: list[tuple[str, np.ndarray]], *, unbiased: bool = True,
                 lof: tuple[float, int, float, int] | None = None) -> Adequacy:
    """The verdict of residuals ``resid`` against ``scatter`` (see the module docstring).

    ``regions``: (label, index array) pairs; ``unbiased``: False when the scatter is an upper
    bound (then "fits" is not said); ``lof``: (SS_lack_of_fit, its dof, SS_pure_error, its
    dof) for the F-test when there are repeats.
    """
    from scipy.stats import f as f_dist

    rms = float(np.sqrt(np.mean(resid**2))) if resid.size else math.nan
    ok = math.isfinite(scatter) and scatter > 0 and dof >= MIN_SCATTER_DOF
    ratio = rms / scatter if ok else math.nan
    p = None
    if lof is not None and lof[1] > 0 and lof[3] > 0 and lof[2] > 0:
        F = (lof[0] / lof[1]) / (lof[2] / lof[3])
        p = float(f_dist.sf(F, lof[1], lof[3]))
    regs = []
    for label, idx in regions:
        if idx.size == 0:
            continue
        r = resid[idx]
        rr = float(np.sqrt(np.mean(r**2)))
        regs.append(Region(label, int(idx.size), rr, float(r.mean()),
                           rr / scatter if ok else math.nan))
    if not ok:
        verdict, why = "inconclusive", (f"the data's scatter could not be estimated "
                                        f"({method}, {dof} dof)")
    elif ratio >= MISFIT_RATIO and (p is None or p < LOF_ALPHA):
        verdict = "does not fit"
        why = (f"residual RMS {rms:.3g} {unit} is {ratio:.1f}x the data's scatter "
               f"{scatter:.3g} {unit} ({method})" + (f", lack-of-fit p = {p:.2g}"
                                                     if p is not None else ""))
    elif ratio <= FIT_RATIO and unbiased and (p is None or p >= LOF_ALPHA):
        verdict = "fits"
        why = (f"residual RMS {rms:.3g} {unit} is {ratio:.2f}x the data's scatter "
               f"{scatter:.3g} {unit} ({method})" + (f", lack-of-fit p = {p:.2g}"
                                                     if p is not None else ""))
    else:
        verdict = "inconclusive"
        if not unbiased and ratio < MISFIT_RATIO:
            why = (f"residual RMS {rms:.3g} {unit} is {ratio:.2f}x an upper bound of the "
                   f"scatter ({method}): no repeated points to measure the scatter itself")
        else:
            why = (f"residual RMS {rms:.3g} {unit} is {ratio:.2f}x the data's scatter "
                   f"{scatter:.3g} {unit} ({method}), between {FIT_RATIO:g}x and "
                   f"{MISFIT_RATIO:g}x" + (f", lack-of-fit p = {p:.2g}" if p is not None
                                           else ""))
    return Adequacy(verdict, why, rms, float(scatter), method, int(dof), float(ratio), unit,
                    p, regs)


def quantile_bins(x: np.ndarray, n_bins: int) -> list[np.ndarray]:
    """Indices of ``x`` split into ``n_bins`` bins of equal count by value (fewer when short)."""
    order = np.argsort(x, kind="stable")
    k = max(1, min(n_bins, order.shape[0]))
    return [b for b in np.array_split(order, k) if b.size]
