"""A sensitivity study end to end (compute only): sample the factors, run every sample through
the sweep machinery, analyse each metric.

Each input's design is run as one sweep (``sweep.run.compute_sweep``): a ``zip`` sweep whose
axes are the factors with the design's values as explicit lists, no baseline, metrics only (no
time series recorded). So every sample is a cached, resumable job evaluated in batched kernel
calls on the sweep's backends (numba threads, loky processes, Dask): an interrupted study
rerun with the same inputs and the same job cache recomputes only the samples it had not
finished. Writes nothing but the job cache; ``report.sensitivity_report`` writes the folder.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from ema_cli.config.loader import validate
from ema_cli.config.run import InputConfig, RunConfig
from ema_cli.config.sensitivity import SensitivityConfig, check_sobol_n
from ema_cli.config.study import StudyConfig
from ema_cli.errors import EmaError
from ema_cli.progress import BIG_RUN, kernel_seconds, whole_estimate
from ema_cli.sensitivity.analyze import check_output, convergence, empty_table, indices
from ema_cli.sensitivity.sampling import Design, FactorRange, sample
from ema_cli.sweep.run import DIVERGED, OK, SweepResult, compute_sweep

RUN_KEYS = tuple(k for k in RunConfig.model_fields if k != "input")
"""The run settings every input's sweep shares (all of RunConfig but the input)."""


def factor_ranges(cfg: SensitivityConfig) -> list[FactorRange]:
    """The config's factors as sampling ranges (name, range, scale, unit)."""
    return [FactorRange(f.label, float(f.range[0]), float(f.range[1]), f.scale == "log", f.unit)
            for f in cfg.factors]


def resolve_method(cfg: SensitivityConfig, method: str | None, n: int | None) -> tuple[str, int]:
    """(method, n): the options (``--method``, ``--n``) over the config's settings; refuses a
    Sobol ``n`` that is not a power of two and a study past ``sensitivity.max_runs``."""
    method = method or cfg.sensitivity.method
    if method not in ("sobol", "morris"):
        raise EmaError(f"--method must be sobol or morris, got {method!r}")
    if n is None:
        n = cfg.sensitivity.n(method)
        where = f"sensitivity.n_{method}"
    else:
        where = "--n"
    if isinstance(n, bool) or not isinstance(n, int) or n < 1:
        raise EmaError(f"{where} must be an integer >= 1, got {n!r}")
    if method == "sobol":
        check_sobol_n(n, where)
    runs = cfg.runs(method, n)
    if runs > cfg.sensitivity.max_runs:
        raise EmaError(f"{where} = {n}: the study needs {runs:,} simulations, more than "
                       f"sensitivity.max_runs = {cfg.sensitivity.max_runs:,}; lower it or raise "
                       "sensitivity.max_runs")
    return method, n


def study_config(cfg: SensitivityConfig, inp: InputConfig, design: Design,
                 source: str = "config") -> StudyConfig:
    """The sweep that runs ``design`` on input ``inp``: a zip sweep over the factors with the
    design's values as explicit lists (row order = design order), no baseline, metrics only."""
    data: dict[str, Any] = cfg.model_dump(mode="json", include=set(RUN_KEYS))
    data["input"] = inp.model_dump(mode="json")
    x = design.values
    axes = []
    for k, f in enumerate(cfg.factors):
        axis: dict[str, Any] = {"name": f.label, "values": x[:, k].tolist()}
        axis["parameter" if f.parameter is not None else "nonlinearity"] = f.target
        axes.append(axis)
    data["sweep"] = {"mode": "zip", "baseline": False, "max_jobs": max(design.n_rows, 1),
                     "axes": axes}
    data["outputs"] = {"timeseries": False, "per_job_csv": False, "figures": [],
                       "metrics": list(cfg.metrics)}
    data["parallel"] = cfg.parallel.model_dump(mode="json")
    return validate(StudyConfig, data, source)


@dataclass
class InputRun:
    """One input's runs and indices.

    ``sweep``: the sweep that ran the design (its ``metrics`` has one row per design row, in
    order); ``indices``: one row per (metric, factor) with ``sensitivity.analyze``'s columns;
    ``convergence``: the same on nested prefixes (column ``n``); ``notes``: what could not be
    analysed and why.
    """

    name: str
    input: InputConfig
    sweep: SweepResult
    indices: pd.DataFrame = field(default_factory=pd.DataFrame)
    convergence: pd.DataFrame = field(default_factory=pd.DataFrame)
    notes: list[str] = field(default_factory=list)

    @property
    def complete(self) -> bool:
        """True when every sample finished (ok or diverged)."""
        return bool(self.sweep.metrics["status"].isin((OK, DIVERGED)).all())

    def values(self, metric: str) -> np.ndarray:
        """y[n_rows]: the metric of every design row, edge units."""
        return self.sweep.metrics[metric].to_numpy(dtype=np.float64)


@dataclass
class SensitivityResult:
    """A finished (or interrupted) sensitivity study: the design, one :class:`InputRun` per
    input run so far, timings [s]. ``folder``: the output folder (set by the report layer)."""

    cfg: SensitivityConfig
    method: str
    n: int
    design: Design
    inputs: list[InputRun]
    timings: dict[str, float] = field(default_factory=dict)
    interrupted: bool = False
    folder: Path | None = None
    source: str = "config"

    @property
    def n_runs(self) -> int:
        """Simulations of the whole study (every input)."""
        return self.design.n_rows * len(self.cfg.input_list())

    @property
    def computed(self) -> int:
        return sum(r.sweep.computed for r in self.inputs)

    @property
    def cached(self) -> int:
        return sum(r.sweep.cached for r in self.inputs)

    @property
    def complete(self) -> bool:
        """Every input ran every sample."""
        return (not self.interrupted and len(self.inputs) == len(self.cfg.input_list())
                and all(r.complete for r in self.inputs))

    @property
    def notes(self) -> list[str]:
        return [f"{r.name}: {n}" for r in self.inputs for n in r.notes]

    def _stack(self, attr: str) -> pd.DataFrame:
        frames = []
        for r in self.inputs:
            df = getattr(r, attr)
            if len(df):
                frames.append(df.assign(input=r.name)[["input", *df.columns]])
        return pd.concat(frames, ignore_index=True) if frames else pd.DataFrame()

    @property
    def indices(self) -> pd.DataFrame:
        """indices.csv: input, metric, factor, S1, S1_conf, ST, ST_conf, mu_star,
        mu_star_conf, sigma, mu (NaN where the method does not give it)."""
        return self._stack("indices")

    @property
    def convergence(self) -> pd.DataFrame:
        """The indices on nested prefixes: input, metric, n, factor and the indices columns."""
        return self._stack("convergence")

    @property
    def samples(self) -> pd.DataFrame:
        """One row per simulation: input, row (design order), job key, status, the factor
        values (factor names) and the metrics (edge units)."""
        x = self.design.values
        frames = []
        for r in self.inputs:
            m = r.sweep.metrics
            data: dict[str, Any] = {"input": r.name, "row": np.arange(len(m)),
                                    "key": m["key"].to_numpy(), "status": m["status"].to_numpy()}
            for k, f in enumerate(self.design.factors):
                data[f.name] = x[:, k]
            for metric in self.cfg.metrics:
                data[metric] = m[metric].to_numpy()
            frames.append(pd.DataFrame(data))
        return pd.concat(frames, ignore_index=True) if frames else pd.DataFrame()


def transformed(y: np.ndarray, transform: str) -> np.ndarray:
    """The values the indices apportion: ``y`` itself, or log10(y) (non-positive -> NaN)."""
    if transform == "none":
        return y
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(y > 0, np.log10(np.where(y > 0, y, 1.0)), np.nan)


def analyse(run: InputRun, design: Design, cfg: SensitivityConfig) -> None:
    """Fill ``run.indices`` and ``run.convergence`` for every metric (NaN indices and a note
    for a metric that cannot be analysed: unfinished runs, non-finite values)."""
    s = cfg.sensitivity
    frames, conv = [], []
    for metric in cfg.metrics:
        y = transformed(run.values(metric), s.transform)
        why = ("not every sample finished" if not run.complete else check_output(design, y))
        if why is not None and s.transform == "log10" and run.complete:
            why += " (log10 needs values > 0)"
        if why is None:
            table = indices(design, y, s.conf_level, s.num_resamples, cfg.seed)
            conv.append(convergence(design, y, s.conf_level, s.num_resamples, cfg.seed,
                                    full=table).assign(metric=metric))
        else:
            table = empty_table(design)
            run.notes.append(f"{metric}: not analysed: {why}")
        frames.append(table.assign(metric=metric, transform=s.transform))
    df = pd.concat(frames, ignore_index=True)
    run.indices = df[["metric", "transform", *[c for c in df.columns
                                               if c not in ("metric", "transform")]]]
    if conv:
        c = pd.concat(conv, ignore_index=True)
        run.convergence = c[["metric", *[k for k in c.columns if k != "metric"]]]
    diverged = int((run.sweep.metrics["status"] == DIVERGED).sum())
    if diverged:
        run.notes.append(f"{diverged} of {design.n_rows} runs diverged (their metrics are those "
                         "of the run up to the divergence)")


def compute_sensitivity(
    cfg: SensitivityConfig,
    method: str | None = None,
    n: int | None = None,
    *,
    n_jobs: int | None = None,
    backend: str | None = None,
    scheduler: str | None = None,
    force: bool = False,
    progress: bool = False,
    cache_dir: Path | None = None,
    base_dir: Path | None = None,
    source: str = "config",
    on_start: Callable[[SensitivityResult], None] | None = None,
    on_finish: Callable[[SensitivityResult, bool], None] | None = None,
    log: Callable[[str], None] | None = None,
) -> SensitivityResult:
    """Sample the factors, run every input's design as a sweep, analyse every metric.

    method, n     the options over ``cfg.sensitivity`` (:func:`resolve_method`)
    n_jobs, backend, scheduler, force, progress, cache_dir, base_dir, source
                  as ``sweep.run.compute_sweep`` (one job cache for every input)
    on_start      ``on_start(result)``: once the design is drawn and every input's sweep
                  config validated, before any simulation (the report layer creates the folder)
    on_finish     ``on_finish(result, aborted)``: when the study ends, also on Ctrl-C or an
                  error (``aborted`` True; the inputs finished so far are in the result)
    """
    t0 = time.perf_counter()
    method, n = resolve_method(cfg, method, n)
    s = cfg.sensitivity
    design = sample(factor_ranges(cfg), method, n, cfg.seed, s.morris_levels)
    studies = [(name, inp, study_config(cfg, inp, design, source))
               for name, inp in cfg.input_list()]
    result = SensitivityResult(cfg, method, n, design, [], {"sample": time.perf_counter() - t0},
                               source=source)
    if on_start is not None:
        on_start(result)
    total = design.n_rows * len(studies)
    from ema_cli.sweep.run import resolve_workers

    sim = studies[0][2].simulation
    workers = resolve_workers(n_jobs if n_jobs is not None else cfg.parallel.n_jobs)
    steps = round(sim.duration_s / sim.dt_s)
    whole = whole_estimate(kernel_seconds(total, steps, workers),
                           f"{total:,} simulations of {steps:,} steps on {workers} core"
                           f"{'s' if workers != 1 else ''} in all: {len(studies)} input(s) x "
                           f"{design.n_rows:,} ({method}, n = {n}; --n sets it; cached "
                           "samples are skipped)", force=total > BIG_RUN)
    aborted = True
    try:
        with whole:  # the sweeps' own estimates are inside this one
            for name, inp, study in studies:
                if log is not None:
                    log(f"input {name}: {design.n_rows:,} runs ({method}, n = {n})")
                t1 = time.perf_counter()
                sw = compute_sweep(study, n_jobs, backend, force, progress,
                                   scheduler=scheduler, cache_dir=cache_dir,
                                   base_dir=base_dir, source=source, keep_signals=False)
                t2 = time.perf_counter()
                run = InputRun(name, inp, sw)
                analyse(run, design, cfg)
                result.inputs.append(run)
                result.timings[f"{name}.sweep"] = t2 - t1
                result.timings[f"{name}.analysis"] = time.perf_counter() - t2
                for k in ("plan", "kernel", "execute", "lookup", "store"):
                    result.timings[f"{name}.{k}"] = sw.timings.get(k, 0.0)
        aborted = False
    except KeyboardInterrupt:
        result.interrupted = True
        raise
    finally:
        result.timings["total"] = time.perf_counter() - t0
        if on_finish is not None:
            on_finish(result, aborted)
    return result
