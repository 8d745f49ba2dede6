"""Sensitivity indices from a design and one output vector (SALib), and their convergence.

:func:`indices` is the one path from metric values to the indices table: ``ema sensitivity``
calls it for every input and metric, and the tests call it on the Ishigami function, whose
indices are known in closed form.

Sobol (no second order): first-order S1 and total ST indices with SALib's estimators
(``SALib.analyze.sobol.first_order``, ``total_order``: Saltelli 2010 and Jansen 1999, each over
the population variance of [A; B], on the output standardised as SALib does) and bootstrap
confidence intervals over the base samples as ``SALib.analyze.sobol.analyze`` computes them
(``*_conf``: ``z * std(ddof=1)`` of the estimates over the resamples, a half-width at
``conf_level``). :func:`sobol_estimates` evaluates the estimators for every resample at once from
its draw counts (one matrix product), so thousands of resamples cost about a second at N = 4096,
where SALib's indexed copies take tens of seconds; given the same resamples it gives SALib's numbers
(checked in the tests), though it draws its resamples in another order than SALib, so the
half-widths of one seed differ from SALib's by the bootstrap's own scatter. That scatter is
not small: a half-width is itself a Monte Carlo estimate, scattering by about 3-5 % (relative)
at 200 resamples and 1 % at 10,000 on the bundled study; use thousands when a half-width is
compared with a threshold. :func:`sobol_conf_asymptotic` gives the limit they approach (delta
method), without resampling.

Morris (``SALib.analyze.morris``): mu (mean elementary effect), mu_star (mean absolute), sigma
(standard deviation) and mu_star_conf (bootstrap half-width). Elementary effects are output
changes per unit of the normalised factor range (the design's unit hypercube), so mu_star of
two factors compare directly whatever their units.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Iterator
from typing import Any

import numpy as np
import pandas as pd

from ema_cli.sensitivity.sampling import Design, problem

SOBOL_COLUMNS = ("S1", "S1_conf", "ST", "ST_conf")
MORRIS_COLUMNS = ("mu", "mu_star", "mu_star_conf", "sigma")
INDEX_COLUMNS = ("S1", "S1_conf", "ST", "ST_conf", "mu_star", "mu_star_conf", "sigma", "mu")
"""The columns of the indices table after ``factor`` (the other method's columns are NaN)."""
CONVERGENCE_LEVELS = 6  # prefixes shown in the convergence: n/32, ..., n/2, n [-]
MIN_PREFIX = 8  # the smallest prefix (base samples or trajectories) in the convergence [-]
RELATIVE_SPREAD = 1e-12  # an output whose spread is below this share of its scale is constant
BOOTSTRAP_BLOCK = 2**22  # resample draws (resamples x base samples) held at once [-]


def analysis_seed(seed: int) -> int:
    """The bootstrap's seed, derived from the study seed (never 0: SALib's Sobol analysis
    falls back to numpy's global generator for a false seed)."""
    return int(np.random.SeedSequence([int(seed), 0x5A1B]).generate_state(1)[0]) | 1


def empty_table(design: Design) -> pd.DataFrame:
    """An indices table of NaN (a metric that could not be analysed)."""
    data: dict[str, object] = {"factor": [f.name for f in design.factors]}
    for c in INDEX_COLUMNS:
        data[c] = np.full(design.d, np.nan)
    return pd.DataFrame(data)


def check_output(design: Design, y: np.ndarray) -> str | None:
    """Why ``y`` cannot be analysed (None: it can): wrong length or non-finite values."""
    if y.shape != (design.n_rows,):
        return f"expected {design.n_rows} values (one per design row), got shape {y.shape}"
    bad = int(np.count_nonzero(~np.isfinite(y)))
    if bad:
        return (f"{bad} of {y.size} runs gave a non-finite value (a diverged run, or a metric "
                "that is undefined for them)")
    return None


def indices(design: Design, y: np.ndarray, conf_level: float = 0.95,
            num_resamples: int = 200, seed: int = 0) -> pd.DataFrame:
    """The indices of every factor for the output ``y[n_rows]`` (one value per design row).

    Returns one row per factor, in design order: ``factor`` and :data:`INDEX_COLUMNS` (those of
    the other method NaN). An output that does not vary (spread below
    :data:`RELATIVE_SPREAD` of its scale) has every index 0. Raises ValueError for a ``y`` of
    the wrong length or with non-finite values (:func:`check_output`).
    """
    y = np.asarray(y, dtype=np.float64)
    why = check_output(design, y)
    if why is not None:
        raise ValueError(why)
    out = empty_table(design)
    scale = max(float(np.max(np.abs(y))), np.finfo(float).tiny)
    if float(np.ptp(y)) <= RELATIVE_SPREAD * scale:  # a constant output: nothing to apportion
        cols = SOBOL_COLUMNS if design.method == "sobol" else MORRIS_COLUMNS
        for c in cols:
            out[c] = 0.0
        return out
    prob = problem(design.factors)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        if design.method == "sobol":
            for c, v in zip(SOBOL_COLUMNS, sobol_indices(y, design.d, conf_level, num_resamples,
                                                          analysis_seed(seed)), strict=True):
                out[c] = v
        else:
            from SALib.analyze import morris

            res = morris.analyze(prob, design.unit, y, num_resamples=num_resamples,
                                 conf_level=conf_level, num_levels=design.num_levels,
                                 seed=analysis_seed(seed))
            for c in MORRIS_COLUMNS:
                out[c] = np.asarray(res[c], dtype=np.float64)
    return out


def sobol_blocks(y: np.ndarray, d: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """SALib's Saltelli layout without second order, ``y[n*(d+2)]`` -> ``A[n]``, ``AB[n, d]``,
    ``B[n]`` (row blocks A, AB_1 .. AB_d, B per base sample), standardised as SALib does
    (``(y - mean)/std`` over every row; the indices do not depend on it)."""
    y = np.asarray(y, dtype=np.float64)
    y = (y - y.mean()) / y.std()
    blocks = y.reshape(-1, d + 2)
    return blocks[:, 0], blocks[:, 1:d + 1], blocks[:, d + 1]


def sobol_estimates(a: np.ndarray, ab: np.ndarray, b: np.ndarray,
                    counts: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(S1, ST) of every factor with SALib's estimators, for the sample (``counts`` None:
    arrays [d]) or for each of k bootstrap resamples (arrays [k, d]).

    ``counts[k, n]``: how often resample k draws each base sample (every row sums to n); a
    resample's estimate is then the count-weighted one, the same as the estimator on the
    resampled rows ``A[r], AB[r], B[r]`` that SALib evaluates::

        V  = var([A; B])                    population variance of the 2n outputs
        S1 = mean(B * (AB_j - A)) / V       Saltelli et al. 2010
        ST = mean((A - AB_j)**2) / (2 V)    Jansen 1999
    """
    terms = np.column_stack([b[:, None] * (ab - a[:, None]), 0.5 * (a[:, None] - ab) ** 2,
                             a + b, a * a + b * b])
    n, d = a.shape[0], ab.shape[1]
    means = terms.mean(axis=0)[None, :] if counts is None else (counts @ terms) / n
    mean_y = 0.5 * means[:, 2 * d]
    var = 0.5 * means[:, 2 * d + 1] - mean_y * mean_y
    with np.errstate(divide="ignore", invalid="ignore"):
        s1 = means[:, :d] / var[:, None]
        st = means[:, d:2 * d] / var[:, None]
    return (s1[0], st[0]) if counts is None else (s1, st)


def resample_counts(n: int, num_resamples: int, seed: int) -> Iterator[np.ndarray]:
    """The bootstrap resamples of ``n`` base samples as blocks of draw counts ``[k, n]``
    (``num_resamples`` in all, at most :data:`BOOTSTRAP_BLOCK` draws per block): resample i
    draws n base samples with replacement, ``numpy.random.default_rng(seed)``."""
    gen = np.random.default_rng(seed)
    block = max(1, min(num_resamples, BOOTSTRAP_BLOCK // n))
    dtype = np.int32 if block * n < 2**31 else np.int64
    for start in range(0, num_resamples, block):
        k = min(block, num_resamples - start)
        draws = gen.integers(n, size=(k, n), dtype=dtype)
        draws += (n * np.arange(k, dtype=dtype))[:, None]  # resample i: bins i*n .. i*n + n-1
        yield np.bincount(draws.ravel(), minlength=k * n).reshape(k, n).astype(np.float64)


def sobol_indices(y: np.ndarray, d: int, conf_level: float = 0.95, num_resamples: int = 200,
                  seed: int = 1) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(S1, S1_conf, ST, ST_conf)[d] of the output ``y[n*(d+2)]`` of a Saltelli design
    (no second order): the estimates of :func:`sobol_estimates` and their bootstrap
    half-widths at ``conf_level`` (``z * std(ddof=1)`` over ``num_resamples`` resamples of the
    base samples, as ``SALib.analyze.sobol.analyze``)."""
    from scipy.stats import norm

    a, ab, b = sobol_blocks(y, d)
    s1, st = sobol_estimates(a, ab, b)
    boot = [sobol_estimates(a, ab, b, c) for c in resample_counts(a.shape[0], num_resamples,
                                                                   seed)]
    z = float(norm.ppf(0.5 + conf_level / 2))
    s1_conf = z * np.concatenate([x[0] for x in boot]).std(axis=0, ddof=1)
    st_conf = z * np.concatenate([x[1] for x in boot]).std(axis=0, ddof=1)
    return s1, s1_conf, st, st_conf


def sobol_conf_asymptotic(y: np.ndarray, d: int, conf_level: float = 0.95
                          ) -> tuple[np.ndarray, np.ndarray]:
    """(S1_conf, ST_conf)[d]: the half-widths at ``conf_level`` from the estimators' asymptotic
    normal distribution (delta method over the base samples, taken as independent), the limit
    the bootstrap half-widths of :func:`sobol_indices` approach as resamples grow, without
    their resampling scatter: a cross-check of them.

    Each index is a ratio ``m / V`` of means over the base samples (:func:`sobol_estimates`);
    its influence on base sample i is ``(t_i - m)/V - m (v_i - V)/V**2``, with ``t_i`` the
    sample's term of ``m`` and ``v_i = (A_i**2 + B_i**2)/2 - 2 ybar (A_i + B_i)/2`` its
    term of V; the half-width is ``z * std(influence)/sqrt(n)``.
    """
    from scipy.stats import norm

    a, ab, b = sobol_blocks(y, d)
    n = a.shape[0]
    ybar = 0.5 * float(np.mean(a + b))
    var = 0.5 * float(np.mean(a * a + b * b)) - ybar * ybar
    v_terms = 0.5 * (a * a + b * b) - ybar * (a + b)
    v_infl = v_terms - v_terms.mean()
    z = float(norm.ppf(0.5 + conf_level / 2))
    out = []
    for t in (b[:, None] * (ab - a[:, None]), 0.5 * (a[:, None] - ab) ** 2):
        m = t.mean(axis=0)
        infl = (t - m) / var - np.outer(v_infl, m) / var**2
        out.append(z * infl.std(axis=0) / math.sqrt(n))
    return out[0], out[1]


def prefix_sizes(n: int, levels: int = CONVERGENCE_LEVELS, smallest: int = MIN_PREFIX
                 ) -> list[int]:
    """The prefix sizes of the convergence: n, n/2, n/4, ... (``levels`` at most, none below
    ``smallest`` unless that leaves only n), ascending."""
    sizes = [n >> k for k in range(levels) if n >> k >= smallest and (n >> k) << k == n]
    return sorted(sizes) if sizes else [n]


def convergence(design: Design, y: np.ndarray, conf_level: float = 0.95,
                num_resamples: int = 200, seed: int = 0,
                sizes: list[int] | None = None, full: pd.DataFrame | None = None
                ) -> pd.DataFrame:
    """The indices on nested prefixes of the design (``n`` doubling up to the full design):
    one row per (n, factor) with ``n`` and the :func:`indices` columns. Uses only the runs the
    full design already has (see ``sampling.Design.prefix``). ``full``: the full design's
    table from :func:`indices` with the same arguments, if already computed (reused for
    ``n = design.n`` instead of computing it again)."""
    y = np.asarray(y, dtype=np.float64)
    frames = []
    for k in sizes or prefix_sizes(design.n):
        sub = design.prefix(k)
        if k == design.n and full is not None:
            df = full.copy()
        else:
            df = indices(sub, y[:sub.n_rows], conf_level, num_resamples, seed)
        df.insert(0, "n", k)
        frames.append(df)
    return pd.concat(frames, ignore_index=True)


def ranking(table: pd.DataFrame, method: str) -> pd.DataFrame:
    """The factors of one indices table (one input and metric), most influential first: by ST
    (Sobol) or mu_star (Morris), with ``rank`` 1, 2, ..."""
    key = "ST" if method == "sobol" else "mu_star"
    out = table.sort_values(key, ascending=False, kind="stable", ignore_index=True)
    out.insert(0, "rank", np.arange(1, len(out) + 1))
    return out


IMPRECISE_SHARE = 0.2  # an index whose confidence half-width is over this share of it [-]


def index_text(row: Any, method: str) -> str:
    """``Kpp 0.41 ± 0.12``: a factor's ranking index (ST, or mu* for Morris) with its
    confidence half-width (``*_conf``), as the console prints it."""
    key = "ST" if method == "sobol" else "mu_star"
    value, conf = float(row[key]), float(row.get(f"{key}_conf", math.nan))
    ci = f" ± {conf:.2g}" if math.isfinite(conf) else ""
    return f"{row['factor']} {value:.3g}{ci}"


def imprecise(table: pd.DataFrame, method: str) -> list[str]:
    """The factors of one indices table whose index is not estimated well enough to rank:
    its confidence half-width over :data:`IMPRECISE_SHARE` of the value, or (Sobol) ST outside
    [0, 1] (a total index is a share of the variance) -> short reasons, most influential first."""
    key = "ST" if method == "sobol" else "mu_star"
    out = []
    ordered = table.sort_values(key, ascending=False, kind="stable")  # ranked or not
    for _, row in ordered.iterrows():
        value, conf = float(row[key]), float(row.get(f"{key}_conf", math.nan))
        if method == "sobol" and math.isfinite(value) and not 0.0 <= value <= 1.0:
            out.append(f"{row['factor']} ST = {value:.3g} (outside [0, 1])")
        elif math.isfinite(conf) and conf > IMPRECISE_SHARE * abs(value):
            out.append(f"{row['factor']} {key} = {value:.3g} ± {conf:.2g}")
    return out


def spearman(a: np.ndarray, b: np.ndarray) -> float:
    """Spearman rank correlation of two index vectors (e.g. Morris mu_star and Sobol ST of
    the same factors); NaN if either is constant."""
    from scipy.stats import spearmanr

    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    if np.ptp(a) == 0 or np.ptp(b) == 0:
        return math.nan
    return float(spearmanr(a, b).statistic)
