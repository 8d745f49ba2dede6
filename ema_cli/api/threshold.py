"""``api.threshold``: the threshold magnitude of one nonlinearity, as ``ema threshold`` finds it."""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ema_cli.api._inputs import ConfigSource, Overrides, base_dir, folder_arg, override_pairs
from ema_cli.config.support import check_command, checked
from ema_cli.errors import EmaError

if TYPE_CHECKING:
    import pandas as pd
    from matplotlib.figure import Figure

    from ema_cli.analysis.threshold import ThresholdResult
    from ema_cli.config.criteria import Criterion
    from ema_cli.config.study import StudyConfig


@dataclass
class Threshold:
    """A threshold search: ``value`` in the unit of ``ema locations`` (``unit``)."""

    config: StudyConfig
    vary: str
    unit: str
    criteria: list[Criterion]
    result: ThresholdResult
    input: str
    log: bool
    wall_time_s: float
    overrides: list[tuple[str, Any]] = field(default_factory=list)
    inputs: Any = None
    """What the folder's marker records (``report.run_inputs.RunInputs``)."""

    @property
    def value(self) -> float:
        """The threshold (last passing magnitude of the final bracket), or NaN."""
        return self.result.threshold

    @property
    def summary(self) -> dict[str, Any]:
        """threshold.json: status, threshold, bracket, width, simulations, requirements."""
        out = self.result.summary()
        out.update(vary=self.vary, unit=self.unit, requirements=[str(c) for c in self.criteria],
                   input=self.input)
        cfg = self.config
        if self.unit == "deg" and cfg.input.kind == "step" and cfg.input.amplitude_deg:
            out["threshold_percent_of_input"] = 100 * self.value / abs(cfg.input.amplitude_deg)
        return out

    @property
    def metrics(self) -> pd.DataFrame:
        """Every magnitude simulated (``value``), its metrics (edge units), pass/fail, round."""
        return self.result.history

    def to_pandas(self, form: str = "wide") -> pd.DataFrame:
        """The search history: ``wide`` (as history.csv) or ``long`` (``value``, ``round``,
        ``metric``, ``metric_value``)."""
        df = self.result.history
        if form == "wide":
            return df
        if form != "long":
            raise EmaError(f"form must be 'wide' or 'long', got {form!r}")
        return df.melt(id_vars=["value", "round", "passes"], var_name="metric",
                       value_name="metric_value")

    @property
    def title(self) -> str:
        """The figure title."""
        from ema_cli.model.nonlinearities import lookup

        pl = lookup(self.vary)
        return (f"{self.config.name} ({self.config.actuator_label()}): threshold of "
                f"{self.vary} ({pl.type} @ {pl.location}), "
                f"{self.input}")

    def plot(self) -> Figure:
        """Each requirement's metric vs the magnitude, with its limit and the threshold."""
        from ema_cli.report.threshold_figures import threshold_figure

        return threshold_figure(self.result, self.criteria, f"{self.vary} [{self.unit}]",
                                self.title, log=self.log)

    def save(self, folder: str | Path | None = None) -> Path:
        """Write the folder ``ema threshold`` writes -> the folder (new or empty if given)."""
        import yaml

        from ema_cli.report.run_inputs import run_inputs
        from ema_cli.report.rundir import write_run
        from ema_cli.report.threshold_report import write_threshold

        cfg_json = self.config.model_dump(mode="json")
        inputs = self.inputs or run_inputs(self.config, sets=self.overrides, options={
            "vary": self.vary, "require": [str(c) for c in self.criteria], "linear": not self.log})
        return write_run("threshold", self.config.name, inputs, folder_arg(folder),
                         lambda out: write_threshold(
                             out, yaml.safe_dump(cfg_json, sort_keys=False), self.result,
                             self.criteria, self.summary, f"{self.vary} [{self.unit}]",
                             self.title, self.log,
                             {"seed": self.config.seed, "wall_time_s": self.wall_time_s,
                              "overrides": [[k, v] for k, v in self.overrides]}))


def threshold(
    config: ConfigSource,
    vary: str,
    range: tuple[float, float],  # noqa: A002 (the option's name)
    *,
    metric: str | None = None,
    limit: float | None = None,
    require: Sequence[str] = (),
    direction: str = "max",
    log: bool = True,
    rtol: float | None = None,
    overrides: Overrides = None,
) -> Threshold:
    """Find the threshold magnitude of nonlinearity ``vary`` within ``range`` (LO, HI in the unit
    of ``ema locations``) at which every requirement holds, as ``ema threshold`` does.

    metric, limit  the main requirement ``metric <= limit`` (edge metric name, e.g.
                   ``ss_err_pos_deg``); require: further ``"METRIC<=VALUE"`` strings
    direction      max: largest passing value (small is benign); min: smallest passing value
    log            search a logarithmic grid (False: linear); rtol: relative bracket width
    """
    import math

    from ema_cli.analysis.threshold import find_threshold, simulation_evaluator
    from ema_cli.api._inputs import flag_arg, names_arg, number_arg
    from ema_cli.config.criteria import DEFAULT_RTOL, Criterion
    from ema_cli.config.loader import input_signal, load_config
    from ema_cli.config.study import StudyConfig
    from ema_cli.model.nonlinearities import lookup

    if not isinstance(vary, str) or not vary:
        raise EmaError(f"vary must be the name of a nonlinearity or parameter (str), got "
                       f"{vary!r}")
    raw = dict(vary=vary, range=range, metric=metric, limit=limit, require=require,
               direction=direction, log=log, rtol=rtol)
    criteria = [Criterion.parse(r) for r in names_arg(require, "require") or []]
    flag_arg(log, "log")
    if metric is not None and not isinstance(metric, str):
        raise EmaError(f"metric must be a metric name (str), got {metric!r}")
    if metric is not None or limit is not None:
        if metric is None or limit is None:
            raise EmaError("metric and limit go together")
        limit = float(number_arg(limit, "limit"))
        crit = Criterion(str(metric), "<=", limit)
        crit.check()
        criteria.insert(0, crit)
    if not criteria:
        raise EmaError("give at least one requirement: metric with limit, or require "
                       "METRIC<=VALUE")
    if direction not in ("max", "min"):
        raise EmaError(f"direction must be max or min, got {direction!r}")
    rtol = DEFAULT_RTOL if rtol is None else number_arg(rtol, "rtol")
    if not (math.isfinite(rtol) and 0 < rtol < 1):
        raise EmaError(f"rtol must be a number in (0, 1), got {rtol}")
    if isinstance(range, str | bytes) or not hasattr(range, "__len__") or len(range) != 2:
        raise EmaError(f"range must be two numbers (LO, HI), got {range!r}")
    lo, hi = (float(number_arg(x, "range", optional=False)) for x in range)
    if not lo < hi:
        raise EmaError(f"range (LO, HI) must have LO < HI, got {lo:g} {hi:g}")
    if log and lo <= 0:
        raise EmaError(f"range LO must be > 0 on a logarithmic grid (or a linear one), "
                       f"got {lo:g}")
    if lo < 0:
        raise EmaError(f"range LO must be >= 0 (a magnitude), got {lo:g}")
    pl = lookup(vary)
    pairs = override_pairs(overrides)
    cfg = load_config(config, pairs, StudyConfig)
    check_command(cfg, "threshold")
    inputs = _inputs(cfg, pairs, **raw)
    from ema_cli.model.nonlinearities import nonlinearity_updates
    from ema_cli.model.params import resolve

    both = sorted(set(nonlinearity_updates(vary, hi, resolve(), cfg.friction_reading))
                  & set(cfg.plant))
    if both:
        raise EmaError(f"vary {vary} and plant.{both[0]} set the same model parameter; "
                       "remove plant." + both[0])
    signal = input_signal(cfg.input, base_dir(config), cfg.load, cfg.axis)
    nls = {k: v for k, v in cfg.nonlinearities.items() if k != vary}
    ev = simulation_evaluator(vary, cfg.plant_overrides(), nls, signal, cfg.simulation.duration_s,
                              cfg.simulation.dt_s, cfg.friction_reading)
    from ema_cli.analysis.threshold import GRID_POINTS, expected_rounds
    from ema_cli.limits import cores
    from ema_cli.progress import announce_size
    from ema_cli.sim.runner import plan_steps

    rounds = expected_rounds(lo, hi, log, rtol)
    announce_size(rounds * GRID_POINTS, plan_steps(cfg.simulation.duration_s,
                                                   cfg.simulation.dt_s, None)[0], cores(),
                  f"{rounds} rounds of {GRID_POINTS} magnitudes to a bracket of {rtol:g}")
    t0 = time.perf_counter()
    res = find_threshold(ev, criteria, lo, hi, direction,  # type: ignore[arg-type]
                         log=log, rtol=rtol)
    return Threshold(cfg, vary, pl.unit, criteria, res, signal.describe(), log,
                     time.perf_counter() - t0, pairs, inputs)


def _inputs(cfg: StudyConfig, pairs: list[tuple[str, Any]], *, vary: str, range: Any,  # noqa: A002
            metric: str | None, limit: float | None, require: Sequence[str], direction: str,
            log: bool, rtol: float | None) -> Any:
    from ema_cli.report.run_inputs import run_inputs

    return run_inputs(cfg, sets=pairs, options={
        "vary": vary, "range": None if range is None else list(range), "metric": metric,
        "limit": limit, "require": list(require or ()), "direction": direction,
        "linear": not log, "rtol": rtol})


def threshold_inputs(config: ConfigSource, vary: str, range: tuple[float, float],  # noqa: A002
                     *, metric: str | None = None, limit: float | None = None,
                     require: Sequence[str] = (), direction: str = "max", log: bool = True,
                     rtol: float | None = None, overrides: Overrides = None) -> Any:
    """The inputs (``report.run_inputs.RunInputs``) a :func:`threshold` with these arguments
    records in its folder's marker: what ``ema threshold`` checks ``--out`` against first."""
    from ema_cli.config.loader import load_config
    from ema_cli.config.study import StudyConfig

    pairs = override_pairs(overrides)
    cfg = checked(load_config(config, pairs, StudyConfig), "threshold")
    return _inputs(cfg, pairs, vary=vary, range=range,
                   metric=metric, limit=limit, require=require, direction=direction, log=log,
                   rtol=rtol)
