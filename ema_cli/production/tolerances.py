"""Tolerance files: the laws of toleranced run-config values, their correlation, and the units
sampled from them (random or scrambled Sobol, through a Gaussian copula).

A tolerance file (``ema yield SPEC --tolerances TOL.yaml``; example: configs/tolerances.yaml)::

    tolerances:                      # dotted run-config paths (as --set), in the config's unit
      plant.kL:    {dist: normal, mean: 590, sd: 15}
      plant.alpha: {dist: uniform, low: 0.0005, high: 0.002}
      plant.Kt:    {dist: truncnormal, mean: 0.08, sd: 0.002, low: 0.075, high: 0.085}
      plant.Fc:    {dist: lognormal, median: 0.02, sigma: 0.2}     # sigma of ln(x)
      nonlinearities.deadzone2: {dist: triangular, low: 0, mode: 0.001, high: 0.004}
    correlation:                     # optional: Gaussian copula on the normal scores
      "plant.kL, plant.alpha": -0.3
    worst_case: {k: 3}               # optional: the worst-case box, +-k sd of normal laws

Values are in the unit the run config uses at the path: SI for ``plant.NAME`` (`ema params`),
the placement's edge unit for ``nonlinearities.NAME`` (`ema locations`: deg for deadzone2).

Sampling (:meth:`Tolerances.sample`): unit ``i`` gets ``d`` uniforms ``u`` (random: the first
``d`` draws of ``np.random.default_rng([seed, i])``; sobol: point ``i`` of the scrambled Sobol'
sequence of ``seed``), clipped to ``[U_MIN, 1 - U_MIN]``; with a correlation, ``z = Phi^-1(u)``,
``z' = L z`` (``L = cholesky(corr)``), ``u' = Phi(z')``; then each law's quantile function.
Unit ``i``'s values depend on (seed, i, method, the file) only, never on how the units are
batched. The correlation coefficients are those of the normal scores (the copula's), which
the Spearman rank correlation follows closely: ``rho_S = (6/pi) asin(rho/2)``.

Every value the sampler can draw is a valid value of its parameter: the laws' extremes (for a
normal law ``mean -+ Z_MAX sd``, the quantile of ``U_MIN``) are checked when the file is read,
so a normal law that could draw a negative backlash is refused (use truncnormal).
"""

from __future__ import annotations

import math
import re
import warnings
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from scipy import stats
from scipy.stats import qmc

from ema_cli.config.base import MAX_SEED
from ema_cli.config.loader import read_yaml, validate
from ema_cli.errors import EmaError
from ema_cli.model.nonlinearities import lookup, nonlinearity_updates
from ema_cli.model.params import BY_NAME, FLAGS, check_value, resolve
from ema_cli.production.laws import (
    _AT_MOST_ONE,
    _NOT_TOLERANCED,
    _STRICTLY_POSITIVE,
    MAX_UNITS,
    METHODS,
    U_MIN,
    Normal,
    ToleranceFile,
    _g,
    _Law,
)


@dataclass(frozen=True)
class _Target:
    """What a path sets: the unit of its values and their closed range (to clip the box)."""

    unit: str
    lower: float
    upper: float

    def clip(self, x: float) -> float:
        return min(max(x, self.lower), self.upper)


def _target(path: str) -> _Target:
    """The checked target of a tolerance path, or EmaError (message without the file)."""
    section, _, name = path.partition(".")
    if section == "plant" and name:
        if name not in BY_NAME:
            raise EmaError(f"unknown model parameter '{name}'; expected plant.NAME with NAME "
                           "one of `ema params`")
        spec = BY_NAME[name]
        if spec.choices is not None or name in FLAGS:
            raise EmaError(f"'{name}' is a switch ({' | '.join(spec.choices or ('0', '1'))}), "
                           "not a value that can scatter")
        if name in _NOT_TOLERANCED:
            raise EmaError(f"'{name}' cannot be toleranced: {_NOT_TOLERANCED[name]}")
        lower = 0.0 if spec.nonnegative else -math.inf
        return _Target(spec.unit, lower, 1.0 if name in _AT_MOST_ONE else math.inf)
    if section == "nonlinearities" and name:
        try:
            pl = lookup(name)
        except EmaError as exc:
            raise EmaError(f"{exc.message} (`ema locations`)") from None
        return _Target(pl.unit, 0.0, math.inf)
    if section in BY_NAME and not name:
        raise EmaError(f"expected a dotted run-config path: plant.{section}")
    raise EmaError("expected plant.NAME (a model parameter, `ema params`) or "
                   "nonlinearities.NAME (a placement or paper name, `ema locations`)")


_BASE = resolve()


def _check(path: str, x: float) -> float:
    """``x`` if it is a valid value at ``path``, else EmaError (the parameter's own message)."""
    section, _, name = path.partition(".")
    if section == "plant":
        x = check_value(name, x)
        if name in _STRICTLY_POSITIVE and not x > 0:
            raise EmaError(f"parameter '{name}' must be > 0 ({BY_NAME[name].unit}), got {x}")
        if name in _AT_MOST_ONE and x > 1.0:
            raise EmaError(f"parameter '{name}' must lie in [0, 1] (-), got {x}")
        return x
    nonlinearity_updates(name, x, _BASE)
    return x


def _writes(path: str, values: list[float]) -> set[str]:
    """The model parameters a path sets (a nonlinearity may set several)."""
    section, _, name = path.partition(".")
    if section == "plant":
        return {name}
    out: set[str] = set()
    for x in values:
        out |= set(nonlinearity_updates(name, x, _BASE))
    return out


# -------------------------------------------------------------------------- the tolerances


@dataclass(frozen=True, eq=False)
class Tolerances:
    """A validated tolerance file.

    ``paths`` in file order, ``laws`` one per path, ``units`` the unit of each path's values,
    ``corr[d, d]`` the copula's correlation matrix (identity when none is given),
    ``correlations`` the pairs as given, ``k`` the worst-case box half-width, ``source`` the
    file (or "dict") for messages.
    """

    paths: tuple[str, ...]
    laws: tuple[_Law, ...]
    units: tuple[str, ...]
    corr: np.ndarray
    correlations: tuple[tuple[str, str, float], ...]
    k: float
    source: str
    _targets: tuple[_Target, ...]
    _writes: tuple[tuple[str, str], ...] = ()

    @property
    def d(self) -> int:
        """Number of tolerances."""
        return len(self.paths)

    def uniforms(self, start: int, stop: int, seed: int, method: str = "random") -> np.ndarray:
        """U[stop-start, d]: units start..stop-1's uniforms, clipped to [U_MIN, 1-U_MIN],
        before the copula."""
        if not isinstance(seed, int | np.integer) or isinstance(seed, bool) \
                or not 0 <= seed <= MAX_SEED:
            raise EmaError(f"seed must be an integer 0 .. 2**63-1, got {seed!r}")
        if method not in METHODS:
            raise EmaError(f"sampling method must be one of {', '.join(METHODS)}, got "
                           f"{method!r}")
        for name, v in (("start", start), ("stop", stop)):
            if not isinstance(v, int | np.integer) or isinstance(v, bool):
                raise EmaError(f"{name} must be an integer, got {v!r}")
        if not 0 <= start <= stop <= MAX_UNITS:
            raise EmaError(f"units {start}..{stop}: expected 0 <= start <= stop <= "
                           f"{MAX_UNITS} (2**30)")
        n, d = stop - start, self.d
        if method == "random":
            u = np.empty((n, d))
            for row, i in enumerate(range(start, stop)):
                u[row] = np.random.default_rng([int(seed), i]).random(d)
        else:
            engine = qmc.Sobol(d, scramble=True, seed=int(seed))
            if start:
                engine.fast_forward(start)
            with warnings.catch_warnings():  # batches need not be powers of two
                warnings.filterwarnings("ignore", message=".*balance properties of Sobol")
                u = engine.random(n) if n else np.empty((0, d))
        return np.clip(u, U_MIN, 1.0 - U_MIN)

    def correlate(self, u: np.ndarray) -> np.ndarray:
        """The copula: U[n, d] independent -> U'[n, d] whose normal scores have ``corr``."""
        if not self.correlations:
            return u
        chol = np.linalg.cholesky(self.corr)
        z = stats.norm.ppf(u)
        zc = np.zeros_like(z)
        for j in range(self.d):  # z' = L z, element by element: a BLAS product's rounding
            for i in range(j + 1):  # depends on the batch's shape, this sum's does not
                if chol[j, i] != 0.0:
                    zc[:, j] += chol[j, i] * z[:, i]
        return np.clip(stats.norm.cdf(zc), U_MIN, 1.0 - U_MIN)

    def values(self, u: np.ndarray) -> np.ndarray:
        """Independent uniforms U[n, d] -> X[n, d], each column in its path's unit."""
        u = self.correlate(np.asarray(u, dtype=np.float64))
        out = np.empty_like(u)
        for j, law in enumerate(self.laws):
            out[:, j] = law.ppf(u[:, j])
        return out

    def sample(self, start: int, stop: int, seed: int, method: str = "random") -> np.ndarray:
        """X[stop-start, d]: the values of units start..stop-1, each column in its path's
        unit. Unit i's row depends only on (seed, i, method, the file): ``sample(0, 10)``
        equals ``vstack(sample(0, 4), sample(4, 10))`` exactly. ``sobol``: points start..stop-1
        of the scrambled Sobol' sequence of ``seed`` (its balance needs powers of two)."""
        return self.values(self.uniforms(start, stop, seed, method))

    def model_parameters(self) -> dict[str, str]:
        """Model parameter -> the tolerance path that sets it (``plant.NAME`` sets NAME; a
        nonlinearity may set several, e.g. friction1: friction and sigma2), to refuse a spec
        whose actuator sets the same parameter."""
        return dict(self._writes)

    def box(self) -> tuple[np.ndarray, np.ndarray]:
        """(lower[d], upper[d]): the worst-case search box (normal: mean -+ k sd; truncnormal:
        that within [low, high]; uniform, triangular: [low, high]; lognormal:
        median*exp(-+k sigma)), clipped to the parameter's range."""
        lo, hi = np.empty(self.d), np.empty(self.d)
        for j, (law, tgt) in enumerate(zip(self.laws, self._targets, strict=True)):
            a, b = law.box(self.k)
            lo[j], hi[j] = tgt.clip(a), tgt.clip(b)
        return lo, hi

    def nominal(self) -> np.ndarray:
        """x[d]: the nominal unit (mean, median, mode or midpoint of each law)."""
        return np.array([law.nominal() for law in self.laws])

    def pairs(self, row: np.ndarray | list[float]) -> list[tuple[str, float]]:
        """One unit's values as (path, value) pairs, as ``--set`` takes them."""
        row = np.asarray(row, dtype=np.float64).reshape(-1)
        if row.size != self.d:
            raise EmaError(f"a unit has {self.d} values ({', '.join(self.paths)}), got "
                           f"{row.size}")
        return [(p, float(x)) for p, x in zip(self.paths, row, strict=True)]

    def describe(self) -> list[str]:
        """One line per law: ``plant.kL: normal, mean 590, sd 15 [N*m/rad]``."""
        return [f"{p}: {law.describe()} [{unit}]"
                for p, law, unit in zip(self.paths, self.laws, self.units, strict=True)]

    def to_dict(self) -> dict[str, Any]:
        """The file as a JSON-serialisable mapping; ``load_tolerances`` reads it back."""
        return {
            "tolerances": {p: law.model_dump() for p, law in zip(self.paths, self.laws,
                                                                   strict=True)},
            "correlation": {f"{a}, {b}": r for a, b, r in self.correlations},
            "worst_case": {"k": self.k},
        }


def _read(source: str | Path | Mapping[str, Any]) -> tuple[dict[str, Any], str]:
    if isinstance(source, Mapping):
        return dict(source), "dict"
    if not isinstance(source, str | Path):
        raise EmaError(f"tolerances: expected a YAML file path or a dict, got "
                       f"{type(source).__name__}")
    p = Path(source)
    if not p.exists():
        raise EmaError(f"tolerance file '{p}' does not exist")
    if not p.is_file():
        raise EmaError(f"tolerance file '{p}' is not a file")
    return read_yaml(p), str(p)


def load_tolerances(source: str | Path | Mapping[str, Any], *,
                    k: float | None = None) -> Tolerances:
    """Read and check a tolerance file (a YAML path, or the document as a dict).

    ``k`` (if given) replaces ``worst_case.k``. Every problem is one EmaError line naming the
    file and the key: unknown paths, bad laws, values the parameter cannot take at the laws'
    extremes or the box's edges, bad correlation pairs or a matrix that is not positive
    definite.
    """
    data, where = _read(source)
    if k is not None:
        wc = data.get("worst_case")
        data["worst_case"] = {**(wc if isinstance(wc, Mapping) else {}), "k": k}
    f = validate(ToleranceFile, data, where)
    paths = tuple(f.tolerances)
    laws = tuple(f.tolerances.values())
    targets = []
    writer: dict[str, str] = {}
    for path, law in f.tolerances.items():
        try:
            tgt = _target(path)
        except EmaError as exc:
            raise EmaError(f"{where}: tolerances.{path}: {exc.message}") from None
        edges = law.extremes()
        for label, x in edges:
            try:
                _check(path, x)
            except EmaError as exc:
                hint = ("; use truncnormal (e.g. low: 0) or a smaller sd"
                        if isinstance(law, Normal) else "")
                raise EmaError(f"{where}: tolerances.{path}: {label} = {_g(x)} is not a value "
                               f"the parameter can take: {exc.message}{hint}") from None
        a, b = law.box(f.worst_case.k)
        for label, x in (("lower", tgt.clip(a)), ("upper", tgt.clip(b))):
            try:
                _check(path, x)
            except EmaError as exc:
                raise EmaError(f"{where}: worst_case.k: the box's {label} edge of {path} "
                               f"({_g(x)}, k = {_g(f.worst_case.k)}) is not a value the "
                               f"parameter can take: {exc.message}; lower k") from None
        for param in sorted(_writes(path, [x for _, x in edges] + [law.nominal()])):
            if param in writer:
                raise EmaError(f"{where}: tolerances.{path}: '{writer[param]}' and '{path}' "
                               f"both set the model parameter '{param}'; give one")
            writer[param] = path
        targets.append(tgt)
    corr, pairs = _correlation(f.correlation, paths, where)
    return Tolerances(paths=paths, laws=laws, units=tuple(t.unit for t in targets), corr=corr,
                      correlations=pairs, k=float(f.worst_case.k), source=where,
                      _targets=tuple(targets), _writes=tuple(writer.items()))


def _correlation(given: Mapping[str, float], paths: tuple[str, ...], where: str
                 ) -> tuple[np.ndarray, tuple[tuple[str, str, float], ...]]:
    """The correlation matrix and the pairs, checked (one line naming the pair)."""
    d = len(paths)
    corr = np.eye(d)
    index = {p: j for j, p in enumerate(paths)}
    seen: dict[tuple[int, int], str] = {}
    pairs = []
    for key, r in given.items():
        head = f'{where}: correlation "{key}"'
        text = str(key).strip().strip("()[]")
        names = [s.strip() for s in re.split(r"[,~]", text)]
        if len(names) != 2 or not all(names):
            raise EmaError(f"{head}: expected two tolerance paths separated by a comma (or ~), "
                           f'e.g. "{paths[0]}, {paths[-1]}"')
        for name in names:
            if name not in index:
                raise EmaError(f"{head}: '{name}' is not in tolerances; expected one of "
                               f"{', '.join(paths)}")
        i, j = index[names[0]], index[names[1]]
        if i == j:
            raise EmaError(f"{head}: a path paired with itself; name two different tolerances")
        pair = (min(i, j), max(i, j))
        if pair in seen:
            raise EmaError(f'{head}: the pair is given twice (also as "{seen[pair]}"); give '
                           "it once")
        seen[pair] = key
        if not -1.0 <= r <= 1.0:
            raise EmaError(f"{head}: coefficient {_g(r)} is outside [-1, 1]")
        corr[i, j] = corr[j, i] = r
        pairs.append((names[0], names[1], float(r)))
    if pairs:
        try:
            np.linalg.cholesky(corr)
        except np.linalg.LinAlgError:
            lam = float(np.linalg.eigvalsh(corr).min())
            raise EmaError(f"{where}: correlation: the matrix of these coefficients is not "
                           f"positive definite (Cholesky fails; smallest eigenvalue "
                           f"{lam:.3g}): the pairs contradict each other (or one is +-1); "
                           "weaken them") from None
    return corr, tuple(pairs)
