"""The computations of an experiment batch (the paper reproduction): thresholds, ranking, claims.

Compute only: the steps fill a :class:`Reproduction` with every table and number.
``api.reproduce.run_experiment`` runs the batch (the studies' sweeps and the identification
write their folders) and ``report.reproduce_report.write_reproduction`` writes REPORT.md,
claims.csv and the figures.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import pandas as pd

from ema_cli.analysis.claims import Verdict, evaluate_claims
from ema_cli.analysis.threshold import ThresholdResult, find_threshold, simulation_evaluator
from ema_cli.config.criteria import Criterion
from ema_cli.config.experiment import ExperimentConfig, SensitivitySpec, ThresholdSpec
from ema_cli.config.loader import input_signal, load_config, validate
from ema_cli.config.study import StudyConfig

if TYPE_CHECKING:
    from ema_cli.config.sensitivity import SensitivityConfig
from ema_cli.errors import EmaError
from ema_cli.identify.torque.settings import IdentifySettings
from ema_cli.model.nonlinearities import lookup


@dataclass
class ThresholdOutcome:
    """A computed threshold beside the paper's value."""

    spec: ThresholdSpec
    result: ThresholdResult
    criteria: list[Criterion]
    value: float
    unit: str
    input_desc: str
    tuned: dict[str, float] | None = None  # the tuned controller it ran with (SI)
    tuning: dict[str, Any] | None = None  # cost, constraints met, evaluations of that tuning


@dataclass
class Reproduction:
    """Everything a reproduction computed."""

    exp: ExperimentConfig
    path: Path
    studies: dict[str, pd.DataFrame] = field(default_factory=dict)
    sweeps: dict[str, Any] = field(default_factory=dict)
    thresholds: list[ThresholdOutcome] = field(default_factory=list)
    identification: dict[str, Any] | None = None
    ranking: pd.DataFrame | None = None
    sensitivity: Any = None  # sensitivity.run.SensitivityResult of the experiment's study
    sensitivity_ranking: pd.DataFrame | None = None
    scalars: dict[str, float] = field(default_factory=dict)
    verdicts: list[Verdict] = field(default_factory=list)
    timings: dict[str, float] = field(default_factory=dict)

    @property
    def failed(self) -> list[Verdict]:
        return [v for v in self.verdicts if not v.passed]


def load_experiment(path: Path, overrides: Sequence[tuple[str, Any]] = ()) -> ExperimentConfig:
    """Read and validate an experiment file with ``--set`` overrides (errors name the file and
    key), with the study and threshold configs it names and its identification settings."""
    exp = load_config(path, overrides, ExperimentConfig)
    if exp.identification is not None:
        validate(IdentifySettings, exp.identification.settings,
                 f"{path}: identification.settings")
    if exp.sensitivity is not None:
        sensitivity_config(path, exp.sensitivity)  # refused before anything is written
    checked: set[str] = set()
    for what, ident, rel in [*(("study", s.id, s.config) for s in exp.studies),
                             *(("threshold", t.id, t.config) for t in exp.thresholds)]:
        if not (path.parent / rel).is_file():
            raise EmaError(f"{path}: {what} '{ident}': config '{rel}' does not exist")
        if rel not in checked:  # every study config is valid before anything is written
            checked.add(rel)
            try:
                study_config(path, rel)
            except EmaError as exc:
                raise EmaError(f"{path}: {what} '{ident}': {exc.message}", exc.exit_code) from None
    return exp


def study_config(path: Path, rel: str) -> tuple[StudyConfig, Path]:
    """The study config ``rel`` (relative to the experiment file ``path``) and its path."""
    p = path.parent / rel
    return load_config(p, (), model=StudyConfig), p


def sensitivity_config(path: Path, spec: SensitivitySpec) -> tuple[SensitivityConfig, Path]:
    """The experiment's sensitivity config and its path; the input, metric and factors the spec
    names must be in it."""
    from ema_cli.config.sensitivity import SensitivityConfig

    p = path.parent / spec.config
    where = f"{path}: sensitivity"
    if not p.is_file():
        raise EmaError(f"{where}: config '{spec.config}' does not exist")
    try:
        cfg = load_config(p, (), SensitivityConfig)
    except EmaError as exc:
        raise EmaError(f"{where}: {exc.message}", exc.exit_code) from None
    inputs = [n for n, _ in cfg.input_list()]
    factors = [f.label for f in cfg.factors]
    if spec.input not in inputs:
        raise EmaError(f"{where}.input: '{spec.input}' is not an input of {spec.config} "
                       f"({', '.join(inputs)})")
    if spec.metric not in cfg.metrics:
        raise EmaError(f"{where}.metric: '{spec.metric}' is not a metric of {spec.config} "
                       f"({', '.join(cfg.metrics)})")
    for key, name in [("paper_first", spec.paper_first),
                      *((f"studies.{k}", v) for k, v in spec.studies.items())]:
        if name not in factors:
            raise EmaError(f"{where}.{key}: '{name}' is not a factor of {spec.config} "
                           f"({', '.join(factors)})")
    return cfg, p


def compute_sensitivity_ranking(rep: Reproduction) -> pd.DataFrame:
    """The factors ranked by Sobol ST (or Morris mu*) per input and metric, with the rank of the
    same nonlinearity in the one-at-a-time ranking (``oat_rank``, where a study varies it);
    fills the ``sensitivity.*`` scalars from the spec's input and metric."""
    from ema_cli.sensitivity.analyze import ranking

    spec = rep.exp.sensitivity
    res = rep.sensitivity
    assert spec is not None and res is not None
    oat: dict[str, int] = {}
    if rep.ranking is not None:
        for _, row in rep.ranking.iterrows():
            if str(row["study"]) in spec.studies:
                oat[spec.studies[str(row["study"])]] = int(row["rank"])
    frames = []
    ix = res.indices
    for _, t in ix.groupby(["input", "metric"], sort=False):
        r = ranking(t, res.method)
        r = r[["input", "metric", *[c for c in r.columns if c not in ("input", "metric")]]]
        r["oat_rank"] = [oat.get(str(f), math.nan) for f in r["factor"]]
        frames.append(r)
    out = pd.concat(frames, ignore_index=True)
    key = "ST" if res.method == "sobol" else "mu_star"
    mine = out[(out["input"] == spec.input) & (out["metric"] == spec.metric)]
    order = [str(f) for f in mine["factor"]]
    rep.scalars["sensitivity.paper_first_rank"] = float(order.index(spec.paper_first) + 1)
    rep.scalars["sensitivity.first_is_paper_first"] = float(order[0] == spec.paper_first)
    rep.scalars["sensitivity.paper_first_st"] = float(
        mine[mine["factor"] == spec.paper_first][key].iloc[0])
    rep.scalars["sensitivity.first_st"] = float(mine[key].iloc[0])
    for k, name in enumerate(order):
        rep.scalars[f"sensitivity.rank.{name}"] = float(k + 1)
    return out


def compute_threshold(path: Path, spec: ThresholdSpec,
                      plant: dict[str, float] | None = None) -> ThresholdOutcome:
    """Run one threshold search of the batch; ``plant``: SI overrides on top of its config
    (e.g. a tuned controller)."""
    cfg, cpath = study_config(path, spec.config)
    signal = input_signal(cfg.input, cpath.parent, cfg.load, cfg.axis)
    nls = {k: v for k, v in cfg.nonlinearities.items() if k != spec.vary}
    ev = simulation_evaluator(spec.vary, {**cfg.plant_overrides(), **(plant or {})}, nls,
                              signal,
                              cfg.simulation.duration_s, cfg.simulation.dt_s,
                              cfg.friction_reading)
    criteria = [Criterion.parse(r) for r in spec.require]
    if spec.require_relative:
        if spec.reference_value is None:
            raise EmaError(f"{path}: threshold '{spec.id}': require_relative needs "
                           "reference_value")
        ref = ev(np.array([spec.reference_value])).iloc[0]
        for rr in spec.require_relative:
            crit = Criterion(rr.metric, "<=", rr.factor * float(ref[rr.metric]) + rr.margin)
            crit.check()
            criteria.append(crit)
    res = find_threshold(ev, criteria, spec.range[0], spec.range[1], spec.direction,
                         rtol=spec.rtol)
    value, unit = res.threshold, spec.unit or lookup(spec.vary).unit
    if spec.percent_of_input:
        value, unit = 100 * res.threshold / abs(cfg.input.amplitude_deg), "% of the input"
    return ThresholdOutcome(spec, res, criteria, value, unit, signal.describe(),
                            dict(plant) if plant else None)


def compute_ranking(rep: Reproduction) -> pd.DataFrame:
    """Worst ratio of the ranking metric to the study's baseline, per study, sorted."""
    spec = rep.exp.ranking
    assert spec is not None
    rows = []
    for sid in spec.studies:
        df = rep.studies.get(sid)
        if df is None:
            raise EmaError(f"ranking: no study '{sid}'")
        base = df[df["label"].astype(str).str.startswith("baseline")]
        if base.empty:
            raise EmaError(f"ranking: study '{sid}' has no baseline run")
        b = float(base[spec.metric].iloc[0])
        others = df.drop(base.index)
        ratios = others[spec.metric].astype(float) / b
        k = int(np.nanargmax(ratios.to_numpy()))
        rows.append({"study": sid, "worst_run": str(others["label"].iloc[k]),
                     "baseline": b, "worst": float(others[spec.metric].iloc[k]),
                     "ratio": float(ratios.iloc[k])})
    out = pd.DataFrame(rows).sort_values("ratio", ascending=False, ignore_index=True)
    out.insert(0, "rank", np.arange(1, len(out) + 1))
    return out


def compute_thresholds(rep: Reproduction, log: Any = print,
                       tuned: dict[str, tuple[dict[str, float], dict[str, Any]]] | None = None
                       ) -> None:
    """Run every threshold search of the batch into ``rep`` (and its scalars); ``tuned``:
    threshold id -> (tuned controller values, tuning summary) for those with ``tuning``."""
    t0 = time.perf_counter()
    for t in rep.exp.thresholds:
        log(f"threshold {t.id}: {t.vary} over {t.range[0]:g}..{t.range[1]:g}")
        values, summary = (tuned or {}).get(t.id, (None, None))
        if t.tuning is not None and values is None:
            raise EmaError(f"{rep.path}: threshold '{t.id}' needs its tuning ({t.tuning}) run "
                           "first")
        outcome = compute_threshold(rep.path, t, values)
        outcome.tuning = summary
        rep.thresholds.append(outcome)
        rep.scalars[t.id] = outcome.value
        if summary is not None:
            rep.scalars[f"{t.id}.tuning_cost"] = float(summary["cost"])
        if t.compare_to is not None:
            rep.scalars[f"{t.id}_ratio"] = outcome.value / rep.scalars[t.compare_to]
    rep.timings["thresholds"] = time.perf_counter() - t0


def add_identification(rep: Reproduction, flat: dict[str, Any]) -> None:
    """Record the identification's flat scalars (``identification.<key>`` for the claims)."""
    rep.identification = flat
    for k, v in flat.items():
        if isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v):
            rep.scalars[f"identification.{k}"] = float(v)


def conclude(rep: Reproduction) -> Reproduction:
    """Rank the studies (if asked) and evaluate every claim; returns ``rep``."""
    exp = rep.exp
    if exp.ranking is not None:
        rep.ranking = compute_ranking(rep)
        order = [str(s) for s in rep.ranking["study"]]
        named = exp.ranking.paper_first
        rep.scalars["ranking.paper_first_rank"] = (
            float(order.index(named) + 1) if named in order else math.nan)
        rep.scalars["ranking.first_is_paper_first"] = float(order[0] == named)
    if exp.sensitivity is not None and rep.sensitivity is not None:
        rep.sensitivity_ranking = compute_sensitivity_ranking(rep)
    rep.verdicts = evaluate_claims(exp.claims, rep.studies, rep.scalars)
    return rep
