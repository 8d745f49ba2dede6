"""Is the fitted model adequate for the record? Residual tests, fit per channel, where it fails,
and the terms it misses.

A model of a real machine never reaches the measurement noise: its residuals are coloured and
structured (at reversals, by direction). So the tests here are reported with their bounds, and
the verdict rests on what decides whether the model can be used:

- **fit per channel** ``100 (1 - ||y - y_hat|| / ||y - mean(y)||)`` [%] (MATLAB's ``compare``);
  a channel below :data:`FIT_MIN` is not adequate;
- **omitted terms**: the force residual regressed on each candidate term the law lacks
  (viscous asymmetry ``|v|``, a Stribeck bump ``sign(v) exp(-(|v|/vs)^2)`` at a few ``vs``, a
  quadratic drag ``v |v|``, an offset), one at a time, with the cluster-robust covariance of
  the fit; a term is *missed* when it is significant (two-sided Student t at 5 %, Bonferroni
  over the candidates) and lowers the force residual's RMS by at least :data:`MISSED_GAIN`;
  any missed term makes the model not adequate, and names it;
- **whiteness** (autocorrelation at lags 1..L against +-1.96/sqrt(N), and Ljung-Box's
  portmanteau test over them) and **independence from the input** (cross-correlation with the
  reference's velocity at lags 0..L, ``N sum r^2`` against chi-squared): reported, with the
  residual's correlation time, to say why the intervals come from a cluster-robust covariance;
  not a verdict on their own;
- **where**: the time blocks whose residual RMS exceeds :data:`BLOCK_FACTOR` times the median
  block's, merged into ranges, and the force residual's RMS moving forward, backward and near
  rest.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

FIT_MIN = 80.0  # fit per channel below which a model is not adequate [%]
MISSED_GAIN = 0.05  # a missed term lowers the force residual's RMS by at least this share [-]
BLOCK_FACTOR = 2.0  # a block with a residual RMS above this many median blocks fails [-]
MAX_LAG = 50  # lags of the correlation tests [samples]
ALPHA = 0.05  # significance of the omitted-term tests (before Bonferroni) [-]
REST_SHARE = 0.02  # |v| below this share of max |v| counts as near rest [-]


def fit_percent(y: np.ndarray, y_hat: np.ndarray) -> float:
    """``100 (1 - ||y - y_hat|| / ||y - mean(y)||)`` [%] (100: perfect; 0: no better than the
    mean; negative: worse)."""
    den = float(np.linalg.norm(y - np.mean(y)))
    return float(100.0 * (1.0 - np.linalg.norm(y - y_hat) / den)) if den > 0 else float("nan")


def _xcorr(a: np.ndarray, b: np.ndarray, max_lag: int) -> np.ndarray:
    """Normalised cross-correlation of ``a`` and ``b`` at lags 0..max_lag (b leading)."""
    a = a - a.mean()
    b = b - b.mean()
    n = a.size
    den = float(np.sqrt((a @ a) * (b @ b)))
    if den == 0:
        return np.zeros(max_lag + 1)
    return np.array([float(a[k:] @ b[:n - k]) / den for k in range(max_lag + 1)])


@dataclass
class CorrelationTest:
    """A correlation test: ``values`` at the lags tested, the 95 % ``bound`` 1.96/sqrt(N) of one
    lag, ``outside`` the share of lags beyond it, ``worst`` the largest |value| and its ``lag``;
    the portmanteau ``statistic`` over all lags (Ljung-Box ``N(N+2) sum r_k^2/(N-k)`` for an
    autocorrelation, ``N sum r_k^2`` for a cross-correlation; chi-squared with one degree of
    freedom per lag under the null) and its ``p_value``."""

    name: str
    values: np.ndarray
    bound: float
    outside: float
    worst: float
    lag: int
    statistic: float = 0.0
    p_value: float = 1.0

    @property
    def passes(self) -> bool:
        """The portmanteau test does not reject at 5 %."""
        return self.p_value >= 0.05

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready figures (values omitted)."""
        return {"bound": self.bound, "share_outside": self.outside, "worst": self.worst,
                "worst_lag": self.lag, "statistic": self.statistic, "p_value": self.p_value,
                "passes": self.passes}


def correlation_test(name: str, r: np.ndarray, other: np.ndarray | None = None,
                     max_lag: int = MAX_LAG) -> CorrelationTest:
    """Autocorrelation of ``r`` at lags 1..max_lag, or its cross-correlation with ``other`` at
    lags 0..max_lag, against +-1.96/sqrt(N)."""
    max_lag = max(1, min(max_lag, r.size // 4))
    if other is None:
        v = _xcorr(r, r, max_lag)[1:]
        lags = np.arange(1, max_lag + 1)
    else:
        v = _xcorr(r, other, max_lag)
        lags = np.arange(0, max_lag + 1)
    from scipy.stats import chi2

    n = r.size
    bound = 1.96 / np.sqrt(n)
    j = int(np.argmax(np.abs(v)))
    if other is None:
        stat = float(n * (n + 2) * np.sum(v**2 / (n - lags)))
    else:
        stat = float(n * np.sum(v**2))
    return CorrelationTest(name, v, float(bound), float(np.mean(np.abs(v) > bound)),
                           float(abs(v[j])), int(lags[j]), stat, float(chi2.sf(stat, v.size)))


def failing_ranges(t: np.ndarray, r: np.ndarray, block_s: float) -> list[tuple[float, float,
                                                                               float]]:
    """Time ranges [s] where the residual's RMS over blocks of ``block_s`` exceeds
    :data:`BLOCK_FACTOR` times the median block's -> [(t0, t1, RMS ratio to the median)],
    adjacent blocks merged, worst first."""
    h = float(np.median(np.diff(t))) if t.size > 1 else 1.0
    per = max(int(round(block_s / h)), 1)
    nb = r.size // per
    if nb < 3:
        return []
    rms = np.sqrt(np.mean(r[:nb * per].reshape(nb, per) ** 2, axis=1))
    med = float(np.median(rms))
    if med == 0:
        return []
    bad = rms > BLOCK_FACTOR * med
    out = []
    i = 0
    while i < nb:
        if bad[i]:
            j = i
            while j + 1 < nb and bad[j + 1]:
                j += 1
            out.append((float(t[i * per]), float(t[min((j + 1) * per, t.size - 1)]),
                        float(rms[i:j + 1].max() / med)))
            i = j + 1
        else:
            i += 1
    return sorted(out, key=lambda x: -x[2])


def by_motion(r: np.ndarray, v: np.ndarray) -> dict[str, float]:
    """The residual's RMS moving forward, backward and near rest (|v| below
    :data:`REST_SHARE` of the largest speed); NaN where the record has no such sample."""
    vmax = float(np.max(np.abs(v))) if v.size else 0.0
    rest = np.abs(v) <= REST_SHARE * vmax
    out = {}
    for k, m in (("forward", (v > 0) & ~rest), ("backward", (v < 0) & ~rest), ("near rest", rest)):
        out[k] = float(np.sqrt(np.mean(r[m] ** 2))) if m.any() else float("nan")
    return out


@dataclass
class OmittedTerm:
    """One candidate term tested on the force residual: its ``coefficient`` [N per unit of the
    column] with its cluster-robust ``se``, ``t`` and two-sided ``p``, ``gain`` the share of the
    residual's RMS it removes, ``missed`` the verdict."""

    name: str
    meaning: str
    coefficient: float
    se: float
    t: float
    p: float
    gain: float
    missed: bool

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready figures."""
        return {"meaning": self.meaning, "coefficient": self.coefficient, "se": self.se,
                "t": self.t, "p": self.p, "rms_reduction": self.gain, "missed": self.missed}


def candidate_columns(v: np.ndarray, law: Sequence[str], v_unit: str = "m/s",
                      q: np.ndarray | None = None) -> list[tuple[str, str, np.ndarray]]:
    """The candidate terms the law lacks, as (name, meaning, column [n]) on the velocity ``v``
    [``v_unit``: m/s or rad/s]; with a rotary axis' angle ``q`` [rad] also a gravity-like
    torque ``cos q`` and ``sin q``."""
    law = set(law)
    speed = np.abs(v)
    vref = float(np.percentile(speed, 90)) if speed.size else 1.0
    out = []
    per_dir_viscous = {"Fv+", "Fv-"} <= law
    if not per_dir_viscous:
        out.append(("Fv asymmetry", "viscous friction differing by direction (|v|)", speed))
    for k in (0.02, 0.05, 0.2):
        vs = k * vref
        if vs > 0:
            out.append((f"Stribeck vs={vs:.3g} {v_unit}", f"a static peak decaying over {vs:.3g} "
                        f"{v_unit} (sign(v) exp(-(|v|/vs)^2))",
                        np.sign(v) * np.exp(-(speed / vs) ** 2)))
    out.append(("drag v|v|", "quadratic drag (v |v|)", v * speed))
    if "OF" not in law and not ({"Fc+", "Fc-"} <= law):
        out.append(("offset", "a constant force", np.ones_like(v)))
    if q is not None and float(np.ptp(q)) > 0.05:  # an angle that moves enough to tell
        out.append(("gravity cos q", "a torque varying with the angle as cos q (gravity)",
                    np.cos(q)))
        out.append(("gravity sin q", "a torque varying with the angle as sin q (gravity)",
                    np.sin(q)))
    return out


def omitted_terms(r_force: np.ndarray, v: np.ndarray, law: Sequence[str],
                  clusters: Sequence[np.ndarray], v_unit: str = "m/s",
                  q: np.ndarray | None = None) -> list[OmittedTerm]:
    """Each candidate term (:func:`candidate_columns`) regressed alone on the force residual
    ``r_force`` = measured - simulated [N], with the CR3 cluster-robust standard error over
    ``clusters`` (index arrays of the samples) -> the tests, Bonferroni over the candidates."""
    from scipy.stats import t as student_t

    from ema_cli.identify.uncertainty import covariance_clustered

    cands = candidate_columns(v, law, v_unit, q)
    out = []
    rms0 = float(np.sqrt(np.mean(r_force**2)))
    k = max(len(cands), 1)
    for name, meaning, col in cands:
        X = np.column_stack([col, np.ones_like(col)]) if name != "offset" else col[:, None]
        beta, *_ = np.linalg.lstsq(X, r_force, rcond=None)
        e = r_force - X @ beta
        cov, _, dof = covariance_clustered(X, e, clusters)
        se = float(np.sqrt(cov[0, 0])) if np.isfinite(cov[0, 0]) else float("inf")
        tval = float(beta[0] / se) if se > 0 else 0.0
        p = float(2 * student_t.sf(abs(tval), dof))
        # the gain over the residual with only its mean removed (the offset is the baseline)
        base = r_force - (np.mean(r_force) if name != "offset" else 0.0)
        rms_base = float(np.sqrt(np.mean(base**2))) if name != "offset" else rms0
        gain = float(1.0 - np.sqrt(np.mean(e**2)) / rms_base) if rms_base > 0 else 0.0
        missed = p < ALPHA / k and gain >= MISSED_GAIN
        if name.startswith("Stribeck"):  # what the sign says: a peak, or a dip (pre-sliding)
            vs = name.split("=")[1]
            meaning = (f"friction above the Coulomb level near rest, decaying over |v| ~ {vs} "
                       "(a Stribeck peak)" if beta[0] > 0 else
                       f"friction below the Coulomb level near rest, over |v| ~ {vs} "
                       "(pre-sliding: a LuGre or Dahl law)")
        out.append(OmittedTerm(name, meaning, float(beta[0]), se, tval, p, gain, missed))
    # the Stribeck family at its best speed only (the Bonferroni count kept every speed)
    strib = [o for o in out if o.name.startswith("Stribeck")]
    if strib:
        best = max(strib, key=lambda o: o.gain)
        out = [o for o in out if not o.name.startswith("Stribeck") or o is best]
    return out


@dataclass
class Adequacy:
    """The adequacy report of a fit (module docstring): ``fit_pct`` per channel, the correlation
    ``tests``, ``omitted`` terms, failing ``ranges`` per channel [(t0, t1, ratio)],
    ``motion`` the force residual by direction [N], ``correlation_time_s`` per channel,
    ``verdict`` ADEQUATE | NOT ADEQUATE | INCONCLUSIVE and ``reasons``."""

    fit_pct: dict[str, float]
    tests: list[CorrelationTest]
    omitted: list[OmittedTerm]
    ranges: dict[str, list[tuple[float, float, float]]]
    motion: dict[str, float]
    correlation_time_s: dict[str, float]
    verdict: str = "INCONCLUSIVE"
    reasons: list[str] = field(default_factory=list)

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready report."""
        return {"verdict": self.verdict, "reasons": self.reasons, "fit_pct": self.fit_pct,
                "fit_min_pct": FIT_MIN,
                "correlation_tests": {t.name: t.as_dict() for t in self.tests},
                "omitted_terms": {o.name: o.as_dict() for o in self.omitted},
                "failing_time_ranges_s": {k: [list(x) for x in v] for k, v in self.ranges.items()},
                "force_residual_rms_by_motion_n": self.motion,
                "correlation_time_s": self.correlation_time_s}


def judge(a: Adequacy, n_clusters: int, min_clusters: int) -> Adequacy:
    """Set the verdict: NOT ADEQUATE for a channel below :data:`FIT_MIN` or a missed term;
    INCONCLUSIVE when the record has fewer than ``min_clusters`` independent blocks (the tests
    have no power); else ADEQUATE (with the coloured residuals stated)."""
    reasons = []
    for ch, f in a.fit_pct.items():
        if not f >= FIT_MIN:
            reasons.append(f"the {ch} channel fits {f:.3g} % < {FIT_MIN:g} %")
    for o in a.omitted:
        if o.missed:
            reasons.append(f"misses {o.name} ({o.meaning}): t = {o.t:.3g}, it would lower the "
                           f"force residual by {100 * o.gain:.3g} %")
    if reasons:
        a.verdict, a.reasons = "NOT ADEQUATE", reasons
    elif n_clusters < min_clusters:
        a.verdict = "INCONCLUSIVE"
        a.reasons = [f"{n_clusters} independent blocks of residuals < {min_clusters}: too short "
                     "a record to test the model"]
    else:
        a.verdict = "ADEQUATE"
        white = [t for t in a.tests if not t.passes]
        a.reasons = [f"every channel fits >= {FIT_MIN:g} % and no candidate term is missed"]
        if white:
            a.reasons.append("residuals are coloured (" + "; ".join(
                f"{t.name}: {100 * t.outside:.0f} % of lags beyond +-{t.bound:.2g}, "
                f"p = {t.p_value:.2g}"
                for t in white) + "): the intervals come from the cluster-robust covariance")
    return a
