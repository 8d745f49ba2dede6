"""Sensitivity indices from a design and one output vector (SALib), and their convergence.

:func:`indices` is the one path from metric values to the indices table: ``ema sensitivity``
calls it for every input and metric, and the tests call it on the Ishigami function, whose
indices are known in closed form.

Sobol (``SALib.analyze.sobol``, no second order): first-order S1 and total ST indices (Saltelli
2010 and Jansen 1999 estimators on SALib's standardised output) with bootstrap confidence
intervals; the ``*_conf`` columns are half-widths at ``conf_level``. Morris
(``SALib.analyze.morris``): mu (mean elementary effect), mu_star (mean absolute), sigma
(standard deviation) and mu_star_conf (bootstrap half-width). Elementary effects are output
changes per unit of the normalised factor range (the design's unit hypercube), so mu_star of
two factors compare directly whatever their units.
"""

from __future__ import annotations

import math
import warnings

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
            from SALib.analyze import sobol

            res = sobol.analyze(prob, y, calc_second_order=False, num_resamples=num_resamples,
                                conf_level=conf_level, seed=analysis_seed(seed))
            for c in SOBOL_COLUMNS:
                out[c] = np.asarray(res[c], dtype=np.float64)
        else:
            from SALib.analyze import morris

            res = morris.analyze(prob, design.unit, y, num_resamples=num_resamples,
                                 conf_level=conf_level, num_levels=design.num_levels,
                                 seed=analysis_seed(seed))
            for c in MORRIS_COLUMNS:
                out[c] = np.asarray(res[c], dtype=np.float64)
    return out


def prefix_sizes(n: int, levels: int = CONVERGENCE_LEVELS, smallest: int = MIN_PREFIX
                 ) -> list[int]:
    """The prefix sizes of the convergence: n, n/2, n/4, ... (``levels`` at most, none below
    ``smallest`` unless that leaves only n), ascending."""
    sizes = [n >> k for k in range(levels) if n >> k >= smallest and (n >> k) << k == n]
    return sorted(sizes) if sizes else [n]


def convergence(design: Design, y: np.ndarray, conf_level: float = 0.95,
                num_resamples: int = 200, seed: int = 0,
                sizes: list[int] | None = None) -> pd.DataFrame:
    """The indices on nested prefixes of the design (``n`` doubling up to the full design):
    one row per (n, factor) with ``n`` and the :func:`indices` columns. Uses only the runs the
    full design already has (see ``sampling.Design.prefix``)."""
    y = np.asarray(y, dtype=np.float64)
    frames = []
    for k in sizes or prefix_sizes(design.n):
        sub = design.prefix(k)
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


def spearman(a: np.ndarray, b: np.ndarray) -> float:
    """Spearman rank correlation of two index vectors (e.g. Morris mu_star and Sobol ST of
    the same factors); NaN if either is constant."""
    from scipy.stats import spearmanr

    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    if np.ptp(a) == 0 or np.ptp(b) == 0:
        return math.nan
    return float(spearmanr(a, b).statistic)
