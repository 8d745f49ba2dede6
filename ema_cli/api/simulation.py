"""``api.simulate``: one run of the EMA model, as ``ema simulate`` runs it, as a result object."""

from __future__ import annotations

import time
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ema_cli.api._inputs import ConfigSource, Overrides, base_dir, folder_arg, override_pairs
from ema_cli.errors import EmaError
from ema_cli.sim.tables import MET, METRICS, SIGNALS

if TYPE_CHECKING:
    import numpy as np
    import pandas as pd
    from matplotlib.figure import Figure

    from ema_cli.config.study import StudyConfig
    from ema_cli.sim.runner import BatchResult
    from ema_cli.sim.signals import InputSignal

_SIGNAL_BY_NAME = {**{c.name: c for c in SIGNALS}, **{c.edge: c for c in SIGNALS}}
_METRIC_BY_NAME = {**{c.name: c for c in METRICS}, **{c.edge: c for c in METRICS}}


def signal_column(name: str):  # -> tables.Column
    """The recorded signal called ``name`` (kernel name ``theta_load`` or edge column
    ``theta_load_deg``); an unknown name is an EmaError listing the valid ones."""
    try:
        return _SIGNAL_BY_NAME[name]
    except KeyError:
        raise EmaError(f"unknown signal {name!r}; expected one of "
                       f"{', '.join(c.edge for c in SIGNALS)}") from None


@dataclass
class Simulation:
    """One simulated run. Values are in edge units (deg, deg/s, rpm, A, V, N*m) with the unit
    in every column name, as in the CSV files; ``params`` and ``batch`` are SI.

    config      the validated config (every default filled in)
    params      the complete SI parameter set that was simulated
    input       the reference input (SI)
    batch       the simulator's raw output (``sim.runner.BatchResult``, SI)
    overrides   the (path, value) overrides applied to the config
    timings     wall seconds: config, kernel_load, simulation (the kernel alone), total
    warnings    resolution warnings (dt too coarse for a fast mode)
    """

    config: StudyConfig
    params: dict[str, float]
    input: InputSignal
    batch: BatchResult
    overrides: list[tuple[str, Any]] = field(default_factory=list)
    timings: dict[str, float] = field(default_factory=dict)
    warnings: list[str] = field(default_factory=list)

    # ------------------------------------------------------------------ values
    @property
    def t(self) -> np.ndarray:
        """The recorded times [s]."""
        return self.batch.t_out

    @property
    def diverged(self) -> bool:
        """True if the run diverged (non-finite or runaway state)."""
        return bool(self.batch.diverged[0])

    @property
    def axis(self) -> str:
        """The actuator's axis: rotary (deg, rpm, N*m) or translational (mm, mm/s, N)."""
        return self.config.axis

    @property
    def shown(self) -> frozenset[str]:
        """The kernel names of the signals and metrics this actuator has (``tables.shown``)."""
        from ema_cli.sim.tables import shown

        a = self.config.actuator
        motor = a is None or a.axis == "rotary" or a.ratio is not None
        return shown(self.params, motor)

    @property
    def metric_columns(self) -> tuple:
        """The metrics of this actuator, named and scaled for its axis."""
        from ema_cli.sim.tables import for_axis

        return tuple(c for c in for_axis(METRICS, self.axis) if c.name in self.shown)

    @property
    def signal_columns(self) -> tuple:
        """The recorded signals of this actuator, named and scaled for its axis."""
        from ema_cli.sim.tables import for_axis

        return tuple(c for c in for_axis(self.batch.columns, self.axis) if c.name in self.shown)

    @property
    def summary(self) -> dict[str, float]:
        """Every metric in edge units, by edge column name (``overshoot_pct``, ...)."""
        cols = self.metric_columns
        return {c.edge: float(self.batch.metrics[0, MET[c.name]] * c.factor) for c in cols}

    @property
    def metrics(self) -> pd.DataFrame:
        """The metrics as a one-row table (edge units, unit in each column name)."""
        import pandas as pd

        row = self.summary
        row["diverged"] = bool(row["diverged"])
        return pd.DataFrame([row])

    def signal(self, name: str) -> np.ndarray:
        """One recorded signal in its edge unit, by kernel or edge name (``theta_load`` or
        ``theta_load_deg``); sampled at :attr:`t`."""
        if self.batch.signals is None:
            raise EmaError("no signals were recorded (simulation.output_interval_s is null)")
        for c in self.signal_columns:
            if name in (c.name, c.edge):
                return self.batch.signals[0, :, SIGNALS.index(signal_column(c.name))] * c.factor
        raise EmaError(f"unknown signal {name!r} for this actuator; expected one of "
                       f"{', '.join(c.edge for c in self.signal_columns)}")

    def table(self) -> dict[str, np.ndarray]:
        """``t_s`` and every recorded signal in edge units (the columns of timeseries.csv)."""
        if self.batch.signals is None:
            raise EmaError("no signals were recorded (simulation.output_interval_s is null)")
        out = {"t_s": self.t}
        for c in self.signal_columns:
            out[c.edge] = self.batch.signals[0, :, SIGNALS.index(signal_column(c.name))] * c.factor
        return out

    def to_pandas(self, form: str = "wide") -> pd.DataFrame:
        """The recorded signals: ``wide`` (``t_s`` + one column per signal, as timeseries.csv)
        or ``long`` (columns ``t_s``, ``signal``, ``unit``, ``value``; one row per sample)."""
        import pandas as pd

        wide = pd.DataFrame(self.table())
        if form == "wide":
            return wide
        if form != "long":
            raise EmaError(f"form must be 'wide' or 'long', got {form!r}")
        long = wide.melt(id_vars="t_s", var_name="signal", value_name="value")
        long.insert(2, "unit", long["signal"].map(_edge_units(self.signal_columns)))
        return long

    # ------------------------------------------------------------------ pictures and files
    @property
    def title(self) -> str:
        """The title of the figure and the terminal table."""
        from ema_cli.report.simulate_report import simulation_title

        return simulation_title(self.config.name, self.input.describe(),
                                self.config.nonlinearities, self.config.describe_options())

    def plot(self) -> Figure:
        """Position and velocity tracking and their errors vs time (a matplotlib Figure)."""
        from ema_cli.report.figures import tracking_figure

        return tracking_figure(self.table(), self.title, self.axis)

    def save(self, folder: str | Path | None = None, worker: Any = None) -> Path:
        """Write the run's folder as ``ema simulate`` does (timeseries.csv, metrics.csv,
        tracking.png, config.resolved.yaml, manifest.json) -> the folder. ``folder`` None: a new
        folder under ``results/simulate/<name>/``; a given folder must be new or empty.
        ``worker``: a ``report.figure_worker.FigureWorker`` to draw the figure in (the CLI's
        start-up path)."""
        import yaml

        from ema_cli.report.run_inputs import run_inputs
        from ema_cli.report.rundir import FINISHED, finish_output, prepare_output
        from ema_cli.report.simulate_report import write_simulation

        cfg_json = self.config.model_dump(mode="json")
        out, state = prepare_output("simulate", self.config.name,
                                    run_inputs(self.config, sets=self.overrides),
                                    folder_arg(folder))
        if state == FINISHED:  # the finished run of these inputs: kept as it is
            if worker is not None:
                worker.cancel()
            return out
        timings = dict(self.timings)
        table = self.table() if self.batch.signals is not None else None
        if worker is not None:
            fig: Any = (worker, self.title)
        else:
            t0 = time.perf_counter()
            fig = self.plot() if self.batch.signals is not None else None
            timings["figure_draw"] = time.perf_counter() - t0
        write_simulation(out, yaml.safe_dump(cfg_json, sort_keys=False), table, self.summary,
                         fig, self.manifest_fields(), timings)
        finish_output(out)
        return out

    def manifest_fields(self) -> dict[str, Any]:
        """What the manifest records about this run besides the common fields."""
        b = self.batch
        kernel = self.timings.get("simulation", 0.0)
        return dict(
            seed=self.config.seed, dt_s=b.dt, duration_s=b.n_steps * b.dt,
            output_interval_s=self.config.simulation.output_interval_s, n_steps=b.n_steps,
            steps_per_s=b.n_steps / kernel if kernel > 0 else None,
            diverged=self.diverged, input=self.input.describe(),
            nonlinearities=dict(self.config.nonlinearities),
            overrides=[[k, v] for k, v in self.overrides], parameters_si=self.params,
            warnings=self.warnings)


def _edge_units(columns: tuple) -> dict[str, str]:
    """Edge column name -> its unit (``sim.tables.edge_unit``)."""
    from ema_cli.sim.tables import edge_unit

    return {c.edge: edge_unit(c) for c in columns}


def simulate(
    config: ConfigSource = None,
    overrides: Overrides = None,
    *,
    nl: Mapping[str, Any] | None = None,
    step_deg: float | None = None,
    duration_s: float | None = None,
    dt_s: float | None = None,
) -> Simulation:
    """Simulate one configuration, as ``ema simulate CONFIG --set ... --nl ...`` does.

    config      a YAML file, a dict (the YAML document), a config model, or None (defaults)
    overrides   dotted paths -> values, e.g. ``{"plant.kL": 600, "input.kind": "sine"}``
    nl          nonlinearities -> magnitude in the units of ``ema locations``, or "off"
    step_deg, duration_s, dt_s   shortcuts for input.amplitude_deg (with input.kind step),
                simulation.duration_s and simulation.dt_s
    """
    import numpy as np

    from ema_cli.config.loader import resolve_run
    from ema_cli.model.params import to_row
    from ema_cli.sim.grid import plan_steps, resolution_warnings
    from ema_cli.sim.runner import simulate_batch

    t0 = time.perf_counter()
    cfg, pairs = _resolve(config, overrides, nl, step_deg, duration_s, dt_s)
    run = resolve_run(cfg, base_dir(config))
    from ema_cli.config.loader import check_input_start

    check_input_start(run.signal, run.duration)
    n_steps, dec = plan_steps(run.duration, run.dt, run.output_interval)
    from ema_cli.limits import estimate

    estimate(n_steps, f"one run of {n_steps:,} steps", workers=1)
    timings = {"config": time.perf_counter() - t0}
    res = simulate_batch(np.array([to_row(run.params)]), [run.signal], None, run.dt, n_steps,
                         dec)
    timings["kernel_load"] = res.load_s
    timings["simulation"] = res.kernel_s
    timings["total"] = time.perf_counter() - t0
    return Simulation(cfg, run.params, run.signal, res, pairs, timings,
                      resolution_warnings(run.params, run.dt))


def _resolve(config: ConfigSource, overrides: Overrides, nl: Mapping[str, Any] | None,
             step_deg: float | None, duration_s: float | None, dt_s: float | None
             ) -> tuple[StudyConfig, list[tuple[str, Any]]]:
    """The validated config of a run of :func:`simulate` and the overrides applied."""
    from ema_cli.api._inputs import number_arg
    from ema_cli.config.loader import load_config
    from ema_cli.config.study import StudyConfig

    number_arg(step_deg, "step_deg")
    number_arg(duration_s, "duration_s", low=0.0, low_open=True)
    number_arg(dt_s, "dt_s", low=0.0, low_open=True)
    pairs = override_pairs(overrides)
    if step_deg is not None:
        pairs += [("input.kind", "step"), ("input.amplitude_deg", step_deg)]
    if duration_s is not None:
        pairs.append(("simulation.duration_s", duration_s))
    if dt_s is not None:
        pairs.append(("simulation.dt_s", dt_s))
    pairs += override_pairs(None, nl)
    return load_config(config, pairs, StudyConfig), pairs


def simulation_inputs(config: ConfigSource = None, overrides: Overrides = None, *,
                      nl: Mapping[str, Any] | None = None, step_deg: float | None = None,
                      duration_s: float | None = None, dt_s: float | None = None) -> Any:
    """The inputs (``report.run_inputs.RunInputs``) a run of :func:`simulate` with these
    arguments records in its folder's marker: what ``ema simulate`` checks ``--out`` against
    before it simulates."""
    from ema_cli.report.run_inputs import run_inputs

    cfg, pairs = _resolve(config, overrides, nl, step_deg, duration_s, dt_s)
    return run_inputs(cfg, sets=pairs)
