"""GA operators on whole populations (numpy): coding, selection, crossover, mutation.

Every operator takes arrays for the whole population and an injected ``np.random.Generator``;
none keeps state. Shapes: real populations ``X[n_pop, n_par]``, binary populations
``B[n_pop, n_par*bits]`` (``uint8``, most significant bit first within each parameter).
"""

from __future__ import annotations

import numpy as np

MAX_BITS = 52  # bits per parameter: float64 resolves at most 2**-52 of a range [-]
MIN_BITS = 2  # fewer bits cannot represent an interior point [-]
TINY_COST = 1e-300  # floor of J in the roulette fitness 1/J, and of 1-u in line SBX [-]
SBX_SAME_TOL = 1e-14  # SBX leaves a gene alone when the parents differ by less than this [-]


# ---------------------------------------------------------------------------- binary coding
def decode(B: np.ndarray, lower: np.ndarray, upper: np.ndarray, bits: int) -> np.ndarray:
    """Binary chromosomes ``B[n_pop, n_par*bits]`` -> real values ``X[n_pop, n_par]``.

    Plain (not Gray) binary, most significant bit first: the integer ``k`` in ``0 .. 2**bits-1``
    maps to ``lower + k*(upper - lower)/(2**bits - 1)``, so both bounds are representable and the
    resolution is ``(upper - lower)/(2**bits - 1)`` (see :func:`resolution`).
    """
    n_pop = B.shape[0]
    n_par = lower.shape[0]
    weights = 2.0 ** np.arange(bits - 1, -1, -1)  # exact in float64 for bits <= 52
    k = B.reshape(n_pop, n_par, bits).astype(np.float64) @ weights
    return lower + k * ((upper - lower) / (2.0**bits - 1.0))


def encode(X: np.ndarray, lower: np.ndarray, upper: np.ndarray, bits: int) -> np.ndarray:
    """Real values ``X[n_pop, n_par]`` -> the nearest binary chromosomes (inverse of decode)."""
    n_pop, n_par = X.shape
    frac = (np.clip(X, lower, upper) - lower) / (upper - lower)
    k = np.rint(frac * (2.0**bits - 1.0)).astype(np.int64)
    shifts = np.arange(bits - 1, -1, -1, dtype=np.int64)
    B = (k[:, :, None] >> shifts) & 1
    return B.reshape(n_pop, n_par * bits).astype(np.uint8)


def resolution(lower: np.ndarray, upper: np.ndarray, bits: int) -> np.ndarray:
    """Step between neighbouring decoded values, per parameter [parameter units]."""
    return (np.asarray(upper) - np.asarray(lower)) / (2.0**bits - 1.0)


def random_binary(rng: np.random.Generator, n_pop: int, n_bits: int) -> np.ndarray:
    """A uniformly random binary population ``B[n_pop, n_bits]``."""
    return rng.integers(0, 2, size=(n_pop, n_bits), dtype=np.uint8)


def random_real(
    rng: np.random.Generator, n_pop: int, lower: np.ndarray, upper: np.ndarray
) -> np.ndarray:
    """A uniformly random real population ``X[n_pop, n_par]`` inside the bounds."""
    return lower + rng.random((n_pop, lower.shape[0])) * (upper - lower)


# ---------------------------------------------------------------------------- selection
def roulette(rng: np.random.Generator, cost: np.ndarray, n_select: int) -> np.ndarray:
    """Fitness-proportional selection on ``1/J`` -> indices ``[n_select]``.

    The fitness of an individual is ``1/max(J, TINY_COST)``; a non-finite J has fitness 0.
    If no individual has positive fitness the draw is uniform.
    """
    with np.errstate(divide="ignore", over="ignore"):
        fit = np.where(np.isfinite(cost), 1.0 / np.maximum(cost, TINY_COST), 0.0)
    fit = np.where(np.isfinite(fit), fit, np.finfo(np.float64).max / cost.shape[0])
    cum = np.cumsum(fit)
    total = cum[-1]
    if not (total > 0.0 and np.isfinite(total)):
        return rng.integers(0, cost.shape[0], size=n_select)
    idx = np.searchsorted(cum, rng.random(n_select) * total, side="right")
    return np.minimum(idx, cost.shape[0] - 1)


def tournament(
    rng: np.random.Generator, cost: np.ndarray, n_select: int, size: int = 2
) -> np.ndarray:
    """Tournament selection (with replacement): the lowest J of ``size`` random entrants wins."""
    entrants = rng.integers(0, cost.shape[0], size=(n_select, size))
    c = np.where(np.isfinite(cost), cost, np.inf)[entrants]
    return entrants[np.arange(n_select), np.argmin(c, axis=1)]


# ---------------------------------------------------------------------------- binary variation
def single_point_crossover(rng: np.random.Generator, B: np.ndarray, pc: float) -> np.ndarray:
    """Pair rows (0,1), (2,3), ...; each pair swaps its tails after one random cut with prob. pc.

    ``pc`` is per pair. The cut lies between bits, uniformly in ``1 .. n_bits-1``, across the
    whole chromosome (parameters are concatenated). An odd last row is copied unchanged.
    """
    out = B.copy()
    n_pairs, n_bits = B.shape[0] // 2, B.shape[1]
    if n_pairs == 0 or n_bits < 2:
        return out
    a, b = B[0 : 2 * n_pairs : 2], B[1 : 2 * n_pairs : 2]
    do = rng.random(n_pairs) < pc
    cut = rng.integers(1, n_bits, size=n_pairs)
    swap = do[:, None] & (np.arange(n_bits)[None, :] >= cut[:, None])
    out[0 : 2 * n_pairs : 2] = np.where(swap, b, a)
    out[1 : 2 * n_pairs : 2] = np.where(swap, a, b)
    return out


def bit_flip(rng: np.random.Generator, B: np.ndarray, pm: float, per: str = "bit") -> np.ndarray:
    """Bit-flip mutation.

    ``per="bit"``: every bit flips independently with probability ``pm`` (expected
    ``pm*n_bits`` flips per chromosome). ``per="chromosome"``: each chromosome, with probability
    ``pm``, has one uniformly chosen bit flipped.
    """
    if per == "bit":
        return B ^ (rng.random(B.shape) < pm).astype(np.uint8)
    if per == "chromosome":
        out = B.copy()
        rows = np.flatnonzero(rng.random(B.shape[0]) < pm)
        cols = rng.integers(0, B.shape[1], size=rows.shape[0])
        out[rows, cols] ^= 1
        return out
    raise ValueError(f"per must be 'bit' or 'chromosome', got {per!r}")


# ---------------------------------------------------------------------------- real variation
def sbx(
    rng: np.random.Generator,
    X: np.ndarray,
    lower: np.ndarray,
    upper: np.ndarray,
    pc: float,
    eta: float,
) -> np.ndarray:
    """Simulated binary crossover (Deb & Agrawal 1995, bounded form as in NSGA-II / pymoo).

    Rows are paired (0,1), (2,3), ...; each pair crosses with probability ``pc`` (per pair) and
    then every gene of a crossing pair with probability 1/2. ``eta`` is the distribution index
    (large: children near their parents). Children stay inside ``[lower, upper]``.
    """
    out = X.copy()
    n_pairs = X.shape[0] // 2
    if n_pairs == 0:
        return out
    p1, p2 = X[0 : 2 * n_pairs : 2], X[1 : 2 * n_pairs : 2]
    shape = p1.shape
    do = (rng.random(n_pairs)[:, None] < pc) & (rng.random(shape) < 0.5)
    do &= np.abs(p1 - p2) > SBX_SAME_TOL * (upper - lower)
    u = rng.random(shape)
    y1, y2 = np.minimum(p1, p2), np.maximum(p1, p2)
    span = np.where(do, y2 - y1, 1.0)
    e1 = 1.0 / (eta + 1.0)

    def beta_q(beta: np.ndarray) -> np.ndarray:
        alpha = 2.0 - np.power(beta, -(eta + 1.0))
        low = u <= 1.0 / alpha
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.where(low, np.power(u * alpha, e1), np.power(1.0 / (2.0 - u * alpha), e1))

    c1 = 0.5 * (y1 + y2 - beta_q(1.0 + 2.0 * (y1 - lower) / span) * (y2 - y1))
    c2 = 0.5 * (y1 + y2 + beta_q(1.0 + 2.0 * (upper - y2) / span) * (y2 - y1))
    c1, c2 = np.clip(c1, lower, upper), np.clip(c2, lower, upper)
    flip = rng.random(shape) < 0.5  # which child goes to which slot
    a = np.where(flip, c2, c1)
    b = np.where(flip, c1, c2)
    out[0 : 2 * n_pairs : 2] = np.where(do, a, p1)
    out[1 : 2 * n_pairs : 2] = np.where(do, b, p2)
    return out


def line_sbx(
    rng: np.random.Generator,
    X: np.ndarray,
    lower: np.ndarray,
    upper: np.ndarray,
    pc: float,
    eta: float,
) -> np.ndarray:
    """SBX along the line through the parents (one spread factor per pair, all genes).

    Rows are paired (0,1), (2,3), ...; a pair crosses with probability ``pc`` (per pair).
    With ``u ~ U(0, 1)`` drawn once per pair, ``beta = (2u)^(1/(eta+1))`` for u <= 1/2 and
    ``(2(1-u))^(-1/(eta+1))`` otherwise, the children are
    ``0.5*((1 +- beta)*p1 + (1 -+ beta)*p2)``: points on the parents' line, inside the segment
    for beta < 1, beyond it (extrapolating) for beta > 1; clipped to the bounds afterwards.
    Unlike gene-wise SBX it is invariant to rotations of the parameter space, so it keeps
    progressing along a narrow correlated valley (kL and alpha are strongly correlated in the
    torque fit); a small ``eta`` (1-2) allows the long steps that need.
    """
    out = X.copy()
    n_pairs = X.shape[0] // 2
    if n_pairs == 0:
        return out
    p1, p2 = X[0 : 2 * n_pairs : 2], X[1 : 2 * n_pairs : 2]
    do = rng.random(n_pairs)[:, None] < pc
    u = rng.random((n_pairs, 1))
    e1 = 1.0 / (eta + 1.0)
    beta = np.where(u <= 0.5, (2.0 * u) ** e1, (0.5 / np.maximum(1.0 - u, TINY_COST)) ** e1)
    c1 = np.clip(0.5 * ((1.0 + beta) * p1 + (1.0 - beta) * p2), lower, upper)
    c2 = np.clip(0.5 * ((1.0 - beta) * p1 + (1.0 + beta) * p2), lower, upper)
    out[0 : 2 * n_pairs : 2] = np.where(do, c1, p1)
    out[1 : 2 * n_pairs : 2] = np.where(do, c2, p2)
    return out


def polynomial_mutation(
    rng: np.random.Generator,
    X: np.ndarray,
    lower: np.ndarray,
    upper: np.ndarray,
    pm: float,
    eta: float,
) -> np.ndarray:
    """Bounded polynomial mutation (Deb & Goyal 1996): each gene mutates with probability ``pm``.

    ``pm`` is per gene (parameter). ``eta`` is the distribution index (large: small steps).
    The result stays inside ``[lower, upper]``.
    """
    do = rng.random(X.shape) < pm
    u = rng.random(X.shape)
    span = upper - lower
    d1 = (X - lower) / span
    d2 = (upper - X) / span
    e1 = 1.0 / (eta + 1.0)
    low = u < 0.5
    xy = np.where(low, 1.0 - d1, 1.0 - d2)
    val = np.where(
        low,
        2.0 * u + (1.0 - 2.0 * u) * xy ** (eta + 1.0),
        2.0 * (1.0 - u) + 2.0 * (u - 0.5) * xy ** (eta + 1.0),
    )
    dq = np.where(low, val**e1 - 1.0, 1.0 - val**e1)
    return np.where(do, np.clip(X + dq * span, lower, upper), X)
