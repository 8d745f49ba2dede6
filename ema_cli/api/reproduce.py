"""``api.reproduce``: an experiment batch (the paper) run, its claims checked and REPORT.md
written, as ``ema reproduce`` does it."""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ema_cli.api._inputs import Overrides, folder_arg, override_pairs
from ema_cli.errors import EmaError
from ema_cli.files import shown

if TYPE_CHECKING:
    import pandas as pd
    from matplotlib.figure import Figure

    from ema_cli.analysis.reproduce import Reproduction
    from ema_cli.config.experiment import ExperimentConfig


@dataclass
class ReproduceResult:
    """A finished reproduction: ``reproduction`` is ``analysis.reproduce.Reproduction`` (the
    studies' sweeps, thresholds, identification, claims and their verdicts).

    folder    the run folder (studies/, identification/, REPORT.md, claims.csv, manifest)
    report    REPORT.md's path
    wall_s    wall seconds of the run
    """

    reproduction: Reproduction
    folder: Path
    report: Path
    wall_s: float
    overrides: list[tuple[str, Any]] = field(default_factory=list)

    @property
    def passed(self) -> bool:
        """True if every claim passed."""
        return not self.reproduction.failed

    @property
    def metrics(self) -> pd.DataFrame:
        """One row per claim: id, result, what was computed (claims.csv)."""
        from ema_cli.analysis.claims import verdicts_frame

        return verdicts_frame(self.reproduction.verdicts)

    def to_pandas(self, form: str = "wide") -> pd.DataFrame:
        """The claims: ``wide`` (claims.csv) or ``long`` (claim id, field, value)."""
        df = self.metrics
        if form == "wide":
            return df
        if form != "long":
            raise EmaError(f"form must be 'wide' or 'long', got {form!r}")
        key = df.columns[0]
        return df.melt(id_vars=key, var_name="field", value_name="value")

    def plot(self) -> list[Figure]:
        """Our version of every paper figure of the batch (every run of a study overlaid)."""
        from ema_cli.report.reproduce_report import study_figure

        rep = self.reproduction
        return [study_figure(rep, spec) for spec in rep.exp.studies]

    def save(self, folder: str | Path | None = None) -> Path:
        """Write REPORT.md, claims.csv, the figures and the manifest into ``folder`` (default:
        the run folder) -> REPORT.md's path. The studies' folders stay in the run folder."""
        from ema_cli.report.reproduce_report import write_reproduction

        target = folder_arg(folder)
        return write_reproduction(self.reproduction, target or self.folder, self.wall_s)


def _announce_tuning(cfg: Any, n_scenarios: int, tid: str) -> None:
    """Add a threshold's tuning to the command's estimate (``api.tune.tuning_seconds``, the
    cost model of ``ema tune``); before, the reproduction's estimate left the tuning out
    (``took 1 min 10 s (estimated ~14 s)`` in CI)."""
    from ema_cli.api.tune import tuning_seconds
    from ema_cli.limits import cores
    from ema_cli.progress import announce_estimate
    from ema_cli.tune.run import evaluations_for

    o = cfg.optimiser
    n_evals = o.runs * evaluations_for(o.method, o.budget, o.pop, len(cfg.variables), o.polish,
                                       o.local)
    steps = round(cfg.simulation.duration_s / cfg.simulation.dt_s)
    workers = cores()
    announce_estimate(tuning_seconds(n_evals, steps * n_scenarios, workers),
                      f"the tuning for threshold {tid}: {n_evals:,} evaluations of "
                      f"{n_scenarios} scenarios of {steps:,} steps on {workers} cores")


def run_threshold_tuning(path: Path, tid: str, rel: str, log: Any = print
                         ) -> tuple[dict[str, float], dict[str, Any]]:
    """Run the tuning config ``rel`` (relative to the experiment file ``path``) of threshold
    ``tid`` -> (tuned values, summary: cost, constraints met, evaluations, seconds)."""
    from ema_cli.config.loader import load_config
    from ema_cli.config.tune import TuneConfig
    from ema_cli.tune.problem import build_scenarios
    from ema_cli.tune.run import run_tuning

    cpath = (path.parent / rel).resolve()
    if not cpath.is_file():
        raise EmaError(f"{path}: threshold '{tid}': tuning '{rel}' is not a file")
    cfg = load_config(cpath, [], TuneConfig)
    log(f"tuning for threshold {tid}: {shown(cpath)} ({cfg.optimiser.method}, budget "
        f"{cfg.optimiser.budget})")
    scenarios, _ = build_scenarios(cfg, cpath.parent)
    _announce_tuning(cfg, len(scenarios), tid)
    o = run_tuning(cfg, scenarios)
    if not o.feasible:
        raise EmaError(f"{path}: threshold '{tid}': the tuning {rel} met no feasible "
                       "controller")
    values = {v: float(x) for v, x in zip(o.problem.variables, o.best.x, strict=True)}
    summary = {"config": rel, "cost": float(o.after.cost[0]), "feasible": o.feasible,
               "evaluations": int(o.timings["evaluations"]), "wall_s": o.wall_s,
               "method": o.method}
    return values, summary


def identification_summary(settings: Any, out: Path | None = None,
                           with_paper_mode: bool = True, with_mismatch: bool = True
                           ) -> dict[str, Any]:
    """``identify.torque.run.summarize_identification`` (its flat scalars are returned) and, when
    ``out`` is given, the identify folders written there (the paper-mode run's in
    ``out/ga-paper``, by ``report.identify_figures.write_identification_summary``)."""
    from ema_cli.identify.torque.run import summarize_identification
    from ema_cli.report.identify_figures import write_identification_summary

    summary = summarize_identification(settings, with_paper_mode, with_mismatch)
    if out is not None:
        write_identification_summary(summary, Path(out))
    return summary.scalars


def run_experiment(path: Path, out: Path, n_jobs: int | None = None,
                   progress: bool = True, log: Any = print,
                   experiment: ExperimentConfig | None = None,
                   write: bool = True) -> Reproduction:
    """Run the whole batch into ``out``; returns the computed Reproduction. ``experiment``: the
    validated experiment file (default: read from ``path``). ``write`` False: ``out`` holds the
    finished run of this batch; nothing is written into it (its studies are read).

    Each study's sweep folder goes to ``out/studies/<id>``, the identification's to
    ``out/identification``; ``report.reproduce_report.write_reproduction`` writes the report.
    """
    from ema_cli.analysis.reproduce import (
        Reproduction,
        add_identification,
        compute_thresholds,
        conclude,
        load_experiment,
        sensitivity_config,
        study_config,
    )
    from ema_cli.api.sensitivity import run_sensitivity
    from ema_cli.api.study import run_sweep
    from ema_cli.report.reproduce_report import under
    from ema_cli.report.sweep_report import default_cache_dir

    rep = Reproduction(experiment if experiment is not None else load_experiment(path), path)
    t0 = time.perf_counter()
    for s in rep.exp.studies:
        cfg, cpath = study_config(path, s.config)
        log(f"study {s.id}: {shown(cpath)}")
        res = run_sweep(cfg, under(out, "studies", s.id), n_jobs=n_jobs, progress=progress,
                        cache_dir=default_cache_dir(out),  # one cache for every study
                        base_dir=cpath.parent, source=str(cpath),
                        reuse_finished=True)  # a resumed run: finished studies are kept
        rep.studies[s.id] = res.metrics
        rep.sweeps[s.id] = res
    rep.timings["studies"] = time.perf_counter() - t0
    tuned = {}
    for t in rep.exp.thresholds:
        if t.tuning is not None:
            t1 = time.perf_counter()
            tuned[t.id] = run_threshold_tuning(path, t.id, t.tuning, log)
            rep.timings[f"tuning_{t.id}"] = time.perf_counter() - t1
    compute_thresholds(rep, log, tuned)
    if rep.exp.sensitivity is not None:
        t0 = time.perf_counter()
        spec = rep.exp.sensitivity
        cfg, cpath = sensitivity_config(path, spec)
        log(f"sensitivity: {shown(cpath)} ({spec.method}, n = {spec.n})")
        rep.sensitivity = run_sensitivity(
            cfg, under(out, "sensitivity"), spec.method, spec.n, n_jobs=n_jobs,
            progress=progress, cache_dir=default_cache_dir(out), base_dir=cpath.parent,
            source=str(cpath), reuse_finished=True)
        rep.timings["sensitivity"] = time.perf_counter() - t0
    if rep.exp.identification is not None:
        t0 = time.perf_counter()
        log("identification (paper §3.1)")
        add_identification(rep, identification_summary(
            rep.exp.identification.settings, out / "identification" if write else None))
        rep.timings["identification"] = time.perf_counter() - t0
    return conclude(rep)


def reproduce(experiment: str | Path, overrides: Overrides = None, *,
              out: str | Path | None = None, n_jobs: int | None = None,
              progress: bool = False, log: Callable[[str], None] | None = None
              ) -> ReproduceResult:
    """Run an experiment batch as ``ema reproduce EXPERIMENT --set ...`` does: every study,
    threshold, sensitivity study and identification, into ``out`` (default: a new folder under
    results/reproduce/; an unfinished run of the same experiment there is resumed, finished
    sweeps are not recomputed), then its claims, REPORT.md, claims.csv, figures and manifest.

    n_jobs    parallel workers for the sweeps (None: all cores)
    log       ``log(text)``: one line per stage as it starts (default: silent)
    """
    from ema_cli.analysis.reproduce import load_experiment
    from ema_cli.report.reproduce_report import write_reproduction
    from ema_cli.report.run_inputs import run_inputs
    from ema_cli.report.rundir import FINISHED, finish_output, prepare_output

    if not isinstance(experiment, str | Path):
        raise EmaError(f"experiment: expected the path of an experiment file, got "
                       f"{type(experiment).__name__}")
    path = Path(experiment)
    pairs = override_pairs(overrides)
    exp = load_experiment(path, pairs)
    folder, state = prepare_output("reproduce", exp.name, run_inputs(exp, sets=pairs),
                                   folder_arg(out))
    say = log or (lambda _text: None)  # a resumed or finished folder: prepare_output says so
    t0 = time.perf_counter()
    rep = run_experiment(path, folder, n_jobs=n_jobs, progress=progress, log=say, experiment=exp,
                         write=state != FINISHED)
    wall = time.perf_counter() - t0
    if state == FINISHED:  # the finished run of this batch: kept as it is
        report = folder / "REPORT.md"
    else:
        report = write_reproduction(rep, folder, wall)
        finish_output(folder)
    return ReproduceResult(rep, folder, report, wall, pairs)
