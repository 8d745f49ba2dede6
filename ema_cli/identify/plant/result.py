"""What a plant identification returns (``identify.plant.fit`` and ``.inverse`` build it): the
laws' terms, one law's fit with its verdicts, the whole identification, and the helpers both
paths share (the fitted samples, the record restricted to them, the law chosen)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from ema_cli.errors import EmaError
from ema_cli.identify.plant import adequacy as adq
from ema_cli.identify.plant import output_error as oe
from ema_cli.identify.plant.benchmark import BenchmarkErrors
from ema_cli.identify.plant.controller_check import ControllerCheck
from ema_cli.identify.plant.idim import BENCHMARK, IdimEstimate
from ema_cli.identify.plant.records import PlantRecord
from ema_cli.identify.plant.settings import PlantSettings
from ema_cli.identify.uncertainty import Uncertainty

LAW_TERMS = {"symmetric": ("M", "Fv", "Fc", "OF"), "per-direction": ("M", "Fv+", "Fc+", "Fv-",
                                                                    "Fc-")}


@dataclass
class LawFit:
    """One law fitted by output error: the IDIM-LS start, the fit, its uncertainty and
    adequacy, and the simulated channels at the estimate."""

    law: str
    start: IdimEstimate
    fit: oe.OutputErrorFit
    uncertainty: Uncertainty
    adequacy: adq.Adequacy
    clusters: int
    block_s: float
    F: np.ndarray
    q: np.ndarray
    v: np.ndarray
    a: np.ndarray
    on_bound: np.ndarray

    @property
    def estimate(self) -> dict[str, float]:
        """Term -> value (SI)."""
        return {n: float(v) for n, v in zip(self.fit.names, self.fit.x, strict=True)}

    def status(self, j: int) -> str:
        """Parameter j: ``determined``, ``zero within its interval`` (a force term of the law
        the data do not need), ``on its bound`` or ``NOT DETERMINED: why``."""
        u = self.uncertainty
        n = u.names[j]
        if n not in oe.TERM_PARAMS and self.on_bound[j]:
            return "NOT DETERMINED: on its bound"
        zero = bool(np.isfinite(u.se[j]) and u.ci_low[j] <= 0 <= u.ci_high[j])
        if zero and n in oe.TERM_PARAMS and n != "M":
            return "zero within its interval"
        if u.determined[j] and not zero:
            return "determined"
        why = list(u.reasons[j]) or ["its 95 % interval contains 0"]
        return "NOT DETERMINED: " + "; ".join(why)

    def determined(self) -> tuple[bool, list[str]]:
        """(every parameter determined or zero within its interval, the undetermined ones)."""
        u = self.uncertainty
        bad = [n for j, n in enumerate(u.names) if self.status(j).startswith("NOT")]
        return not bad, bad


@dataclass
class PlantFit:
    """The identification (module docstring). ``laws`` every law fitted, ``chosen`` the one
    reported, ``baseline`` IDIM-LS of the symmetric law (the benchmark's reference model),
    ``errors`` the benchmark's relative errors on the fitted samples (``output error`` and
    ``IDIM-LS``), ``split`` the time-split validation, ``t`` and the measured channels."""

    settings: PlantSettings
    record: PlantRecord
    extras: dict[str, Any]
    axis: str
    controller: ControllerCheck | None
    delay: int
    baseline: IdimEstimate
    laws: dict[str, LawFit]
    chosen: str
    choice: str
    errors: dict[str, BenchmarkErrors]
    baseline_sim: dict[str, np.ndarray]
    split: dict[str, Any] | None
    use: np.ndarray
    timings: dict[str, float]
    kernel: dict[str, float]
    mode: str = "closed-loop output error"

    @property
    def best(self) -> LawFit:
        """The chosen law's fit."""
        return self.laws[self.chosen]


def mask(record: PlantRecord, window: tuple[float, float] | None, first: int) -> np.ndarray:
    use = np.ones(record.n, dtype=bool)
    use[:first] = False
    if window is not None:
        t0, t1 = window
        if not (t0 < t1):
            raise EmaError(f"--window {t0:g},{t1:g}: expected T0 < T1 [s]")
        if t0 < record.t_s[0] or t1 > record.t_s[-1] + 1e-9:
            raise EmaError(f"--window {t0:g},{t1:g}: {record.source} spans 0 to "
                           f"{record.t_s[-1]:.6g} s; expected a window inside it")
        use &= (record.t_s >= t0) & (record.t_s <= t1)
    return use


def sliced(record: PlantRecord, use: np.ndarray) -> PlantRecord:
    """The record restricted to the contiguous span of ``use`` (for IDIM-LS on a window)."""
    idx = np.flatnonzero(use)
    a, b = int(idx[0]), int(idx[-1]) + 1
    a = max(a - BENCHMARK.first_sample, 0)  # IDIM drops its own border from the span's start
    return PlantRecord(record.t_s[a:b], record.q_m[a:b], record.force_n[a:b], record.h_s,
                       record.source, record.names, record.one_based,
                       None if record.reference_m is None else record.reference_m[a:b],
                       record.constants)


def choose_law(law: str, laws: dict[str, LawFit]) -> tuple[str, str]:
    """The law reported and why."""
    if law != "auto":
        return law, "asked for"
    if len(laws) == 1:
        return next(iter(laws)), "the description's LuGre law is symmetric"
    sym = laws["symmetric"]
    missed = [o for o in sym.adequacy.omitted if o.missed and o.name == "Fv asymmetry"]
    if missed:
        o = missed[0]
        return "per-direction", (f"the symmetric law misses the viscous asymmetry (t = "
                                 f"{o.t:.3g}; it lowers the force residual by "
                                 f"{100 * o.gain:.3g} %)")
    return "symmetric", "the per-direction terms are not called for (the symmetric law's " \
        "residual shows no significant viscous asymmetry)"
