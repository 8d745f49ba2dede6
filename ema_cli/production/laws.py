"""The laws of a tolerance file (normal, truncnormal, uniform, lognormal, triangular) and the
file's schema; ``production.tolerances`` validates the paths, the correlation and samples."""

from __future__ import annotations

import math
from abc import abstractmethod
from typing import Any, ClassVar, Literal

import numpy as np
from pydantic import Field, field_validator, model_validator
from scipy import stats

from ema_cli.config.base import FiniteFloat, PositiveFloat, Strict, tagged_union
from ema_cli.config.run import KEY_MARK

U_MIN = 1e-12
"""Uniforms are clipped to [U_MIN, 1 - U_MIN] before any quantile function [-]."""
Z_MAX = float(-stats.norm.ppf(U_MIN))
"""The largest normal score the sampler draws, Phi^-1(1 - U_MIN) = 7.034 [-]."""
MIN_MASS = 1e-6
"""A truncnormal interval must hold at least this share of its normal law [-]."""
DEFAULT_K = 3.0
"""Default half-width of the worst-case box in standard deviations of normal laws [-]."""
MAX_K = 7.0
"""Largest box half-width accepted: beyond Z_MAX the box leaves what the sampler draws [-]."""
MAX_TOLERANCES = 100
"""Tolerances in one file, at most (each path may appear once) [-]."""
MAX_UNITS = 2**30
"""Units in one sampled sequence, at most (the Sobol' sequence's 30 bits) [-]."""
METHODS = ("random", "sobol")

_STRICTLY_POSITIVE = ("m", "Jm", "JL", "L", "contact_pen", "T_ref", "T_amb", "Rth_wh", "Rth_ha",
                      "Cth_w", "Cth_h")
"""Plant parameters that must be > 0 (``params.resolve``), not only >= 0."""
_AT_MOST_ONE = ("contact_hc", "fb_motor", "notch_depth", "fric_heat")
"""Plant parameters that must lie in [0, 1] (``params.resolve``)."""
_NOT_TOLERANCED = {"Ts": "the controller sample time must stay a whole multiple of dt"}


def _at(key: str, message: str) -> ValueError:
    """A validation error at ``key`` below the failing model (folded into the key path)."""
    return ValueError(f"{KEY_MARK}{key}{KEY_MARK}{message}")


def _g(x: float) -> str:
    return f"{x:.6g}"


# ------------------------------------------------------------------------------------ laws


class _Law(Strict):
    """One law (an abstract base: every law defines the four methods below); ``ppf`` maps
    uniforms in (0, 1) to values in the path's unit."""

    FIELDS: ClassVar[tuple[str, ...]] = ()

    @abstractmethod
    def ppf(self, u: np.ndarray) -> np.ndarray:
        """Values [path unit] at the uniforms ``u``."""

    @abstractmethod
    def nominal(self) -> float:
        """The nominal value: mean, median, mode or midpoint."""

    @abstractmethod
    def extremes(self) -> list[tuple[str, float]]:
        """(label, value) of the smallest and largest values the sampler draws."""

    @abstractmethod
    def box(self, k: float) -> tuple[float, float]:
        """The worst-case search interval, before clipping to the parameter's range."""

    def describe(self) -> str:
        args = ", ".join(f"{f} {_g(getattr(self, f))}" for f in self.FIELDS)
        return f"{self.dist}, {args}"  # type: ignore[attr-defined]


class Normal(_Law):
    """Normal law N(mean, sd^2)."""

    FIELDS: ClassVar[tuple[str, ...]] = ("mean", "sd")
    dist: Literal["normal"]
    mean: FiniteFloat
    sd: PositiveFloat = Field(description="standard deviation, > 0, in the path's unit")

    def ppf(self, u: np.ndarray) -> np.ndarray:
        return self.mean + self.sd * stats.norm.ppf(u)

    def nominal(self) -> float:
        return self.mean

    def extremes(self) -> list[tuple[str, float]]:
        return [(f"mean - {Z_MAX:.3g} sd", self.mean - Z_MAX * self.sd),
                (f"mean + {Z_MAX:.3g} sd", self.mean + Z_MAX * self.sd)]

    def box(self, k: float) -> tuple[float, float]:
        return self.mean - k * self.sd, self.mean + k * self.sd


class TruncNormal(_Law):
    """Normal law N(mean, sd^2) truncated to [low, high]."""

    FIELDS: ClassVar[tuple[str, ...]] = ("mean", "sd", "low", "high")
    dist: Literal["truncnormal"]
    mean: FiniteFloat
    sd: PositiveFloat = Field(description="standard deviation of the untruncated law, > 0")
    low: FiniteFloat
    high: FiniteFloat

    @model_validator(mode="after")
    def _interval(self) -> TruncNormal:
        if not self.low < self.high:
            raise ValueError(f"low ({_g(self.low)}) must be below high ({_g(self.high)})")
        a, b = self._ab()
        mass = stats.norm.sf(a) - stats.norm.sf(b) if a > 0 else \
            stats.norm.cdf(b) - stats.norm.cdf(a)
        if not mass >= MIN_MASS:
            raise ValueError(f"[low, high] = [{_g(self.low)}, {_g(self.high)}] holds "
                             f"{mass:.2g} of the normal law (mean {_g(self.mean)}, sd "
                             f"{_g(self.sd)}), less than {MIN_MASS:g}: put the interval around "
                             "the mean or widen sd")
        return self

    def _ab(self) -> tuple[float, float]:
        return (self.low - self.mean) / self.sd, (self.high - self.mean) / self.sd

    def ppf(self, u: np.ndarray) -> np.ndarray:
        a, b = self._ab()
        x = stats.truncnorm.ppf(u, a, b, loc=self.mean, scale=self.sd)
        return np.clip(x, self.low, self.high)

    def nominal(self) -> float:
        return min(max(self.mean, self.low), self.high)

    def extremes(self) -> list[tuple[str, float]]:
        return [("low", self.low), ("high", self.high)]

    def box(self, k: float) -> tuple[float, float]:
        return max(self.mean - k * self.sd, self.low), min(self.mean + k * self.sd, self.high)


class Uniform(_Law):
    """Uniform law on [low, high]."""

    FIELDS: ClassVar[tuple[str, ...]] = ("low", "high")
    dist: Literal["uniform"]
    low: FiniteFloat
    high: FiniteFloat

    @model_validator(mode="after")
    def _interval(self) -> Uniform:
        if not self.low < self.high:
            raise ValueError(f"low ({_g(self.low)}) must be below high ({_g(self.high)})")
        return self

    def ppf(self, u: np.ndarray) -> np.ndarray:
        return np.clip(self.low + u * (self.high - self.low), self.low, self.high)

    def nominal(self) -> float:
        return 0.5 * (self.low + self.high)

    def extremes(self) -> list[tuple[str, float]]:
        return [("low", self.low), ("high", self.high)]

    def box(self, k: float) -> tuple[float, float]:
        return self.low, self.high


class LogNormal(_Law):
    """Log-normal law: ln(x) normal with mean ln(median) and standard deviation sigma."""

    FIELDS: ClassVar[tuple[str, ...]] = ("median", "sigma")
    dist: Literal["lognormal"]
    median: PositiveFloat = Field(description="median, > 0, in the path's unit")
    sigma: PositiveFloat = Field(description="standard deviation of ln(x), > 0 [-]")

    def ppf(self, u: np.ndarray) -> np.ndarray:
        return self.median * np.exp(self.sigma * stats.norm.ppf(u))

    def nominal(self) -> float:
        return self.median

    def extremes(self) -> list[tuple[str, float]]:
        return [(f"median*exp(-{Z_MAX:.3g} sigma)", self.median * math.exp(-Z_MAX * self.sigma)),
                (f"median*exp(+{Z_MAX:.3g} sigma)", self.median * math.exp(Z_MAX * self.sigma))]

    def box(self, k: float) -> tuple[float, float]:
        return self.median * math.exp(-k * self.sigma), self.median * math.exp(k * self.sigma)


class Triangular(_Law):
    """Triangular law on [low, high] with its peak at mode."""

    FIELDS: ClassVar[tuple[str, ...]] = ("low", "mode", "high")
    dist: Literal["triangular"]
    low: FiniteFloat
    mode: FiniteFloat
    high: FiniteFloat

    @model_validator(mode="after")
    def _interval(self) -> Triangular:
        if not self.low < self.high:
            raise ValueError(f"low ({_g(self.low)}) must be below high ({_g(self.high)})")
        if not self.low <= self.mode <= self.high:
            raise ValueError(f"mode ({_g(self.mode)}) must lie in [low, high] = "
                             f"[{_g(self.low)}, {_g(self.high)}]")
        return self

    def ppf(self, u: np.ndarray) -> np.ndarray:
        width = self.high - self.low
        x = stats.triang.ppf(u, (self.mode - self.low) / width, loc=self.low, scale=width)
        return np.clip(x, self.low, self.high)

    def nominal(self) -> float:
        return self.mode

    def extremes(self) -> list[tuple[str, float]]:
        return [("low", self.low), ("high", self.high)]

    def box(self, k: float) -> tuple[float, float]:
        return self.low, self.high


_LAWS: dict[str, type[_Law]] = {"normal": Normal, "truncnormal": TruncNormal,
                                "uniform": Uniform, "lognormal": LogNormal,
                                "triangular": Triangular}
DISTS = tuple(_LAWS)


Law = tagged_union("dist", _LAWS)


class WorstCase(Strict):
    """The worst-case search box."""

    k: PositiveFloat = Field(DEFAULT_K, le=MAX_K,
                             description="half-width in sd of normal laws (and sigma of "
                                         f"lognormal ones), at most {MAX_K:g}")


class ToleranceFile(Strict):
    """The schema of a tolerance file (paths, correlation and the box are checked after)."""

    tolerances: dict[str, Law] = Field(max_length=MAX_TOLERANCES)
    correlation: dict[str, FiniteFloat] = Field(default_factory=dict)
    worst_case: WorstCase = Field(default_factory=WorstCase)

    @model_validator(mode="before")
    @classmethod
    def _present(cls, data: Any) -> Any:
        if isinstance(data, dict) and "tolerances" not in data:
            raise _at("tolerances", "missing: give at least one PATH: {dist: LAW, ...} (e.g. "
                                    "plant.kL: {dist: normal, mean: 590, sd: 15})")
        return data

    @field_validator("tolerances", mode="before")
    @classmethod
    def _dists(cls, v: Any) -> Any:
        if isinstance(v, dict):
            if not v:
                raise ValueError("empty; give at least one PATH: {dist: LAW, ...} (e.g. "
                                 "plant.kL: {dist: normal, mean: 590, sd: 15})")
            for path, entry in v.items():
                if not isinstance(entry, dict):
                    raise _at(str(path), f"expected a mapping {{dist: LAW, ...}} with LAW one "
                                         f"of {', '.join(DISTS)}")
                if "dist" not in entry:
                    raise _at(f"{path}.dist", f"missing: the law, one of {', '.join(DISTS)}")
                if not isinstance(entry["dist"], str) or entry["dist"] not in _LAWS:
                    raise _at(f"{path}.dist", f"unknown law {entry['dist']!r}; expected one "
                                              f"of {', '.join(DISTS)}")
        elif v is None:
            raise ValueError("empty; give at least one PATH: {dist: LAW, ...}")
        return v

    @field_validator("correlation", mode="before")
    @classmethod
    def _pairs(cls, v: Any) -> Any:
        """``{"A, B": r}`` as it is; also ``{A: {B: r}}`` (nested) and ``[[A, B, r], ...]``
        (a list of triples), normalised to it; None: no correlation."""
        if v is None:
            return {}
        if isinstance(v, list):
            out = {}
            for k, item in enumerate(v):
                if not (isinstance(item, list | tuple) and len(item) == 3):
                    raise _at(str(k), "expected [PATH, PATH, coefficient]")
                out[f"{item[0]}, {item[1]}"] = item[2]
            return out
        if isinstance(v, dict) and any(isinstance(x, dict) for x in v.values()):
            out = {}
            for a, inner in v.items():
                if not isinstance(inner, dict):
                    raise _at(str(a), "expected {PATH: coefficient} when another "
                                                  "entry is nested")
                for b, r in inner.items():
                    out[f"{a}, {b}"] = r
            return out
        return v
