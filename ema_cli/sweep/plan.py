"""Job planning: resolve every job of a sweep to SI parameters, a label and a content hash.

The content hash (the job's cache key) covers everything the kernel's output depends on: the
SI parameter row, the sampled input signal's definition, dt, the step count and a fingerprint
of the simulator source (kernel, signals, tables, parameter table). Two jobs with the same key
give bit-identical metrics, so a finished job is never computed twice.
"""

from __future__ import annotations

import dataclasses
import functools
import hashlib
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ema_cli import __version__
from ema_cli.config.loader import input_signal, resolve_params
from ema_cli.config.study import StudyConfig, SweepAxis
from ema_cli.errors import EmaError
from ema_cli.hashing import content_hash
from ema_cli.model.nonlinearities import OFF, lookup
from ema_cli.model.params import BY_NAME, to_row
from ema_cli.sim.runner import plan_steps, resolution_warnings, simulate_batch
from ema_cli.sim.signals import InputSignal, Sampler, sampler
from ema_cli.sim.tables import MET, SIG, SIGNALS
from ema_cli.sweep.expand import AxisPoint, JobSpec, expand, neutral_value
from ema_cli.units import DEG

KEY_LENGTH = 20  # hex digits of a job's content hash [-]
LOG_DECADES = 2.0  # numeric axes spanning at least this many decades (all > 0) plot on log axes
UNIT_SLUGS = {"deg/s": "deg_s", "%": "pct", "-": ""}
"""Column-name suffixes of units that the generic rule would spell badly."""
BASELINE_LABEL = "baseline"
TYPE_WORDS = {"deadzone": "dead zone", "saturation": "saturation", "compliance": "compliance",
              "friction": "friction"}


def unit_slug(unit: str) -> str:
    """A unit as a column-name suffix: ``N*m/rad`` -> ``nm_per_rad``, ``deg/s`` -> ``deg_s``."""
    if unit in UNIT_SLUGS:
        return UNIT_SLUGS[unit]
    return unit.lower().replace("*", "").replace("^", "").replace("/", "_per_")


def _column(name: str, unit: str) -> str:
    slug = unit_slug(unit)
    return f"{name}_{slug}" if slug else name


def fmt(value: float | str) -> str:
    """A magnitude as the reports print it (4 significant digits; words unchanged)."""
    return value if isinstance(value, str) else f"{value:.4g}"


@functools.cache
def simulator_fingerprint() -> str:
    """The ema version and the hash of the simulator's sources (``sim.runner.KERNEL_KEY``,
    the key of the compiled kernels too): part of every job key, so editing the model or the
    simulator makes the job cache miss."""
    from ema_cli.sim.runner import KERNEL_KEY

    return hashlib.sha256(f"{__version__}:{KERNEL_KEY}".encode()).hexdigest()[:16]


def signal_identity(sig: InputSignal) -> dict[str, Any]:
    """The input signal as hashable data (a CSV profile by the hash of its samples)."""
    data = dataclasses.asdict(sig)
    data.pop("path")
    data.pop("load_path")
    if data["load_sine"] is None:  # absent unless used: the job keys of older runs stay valid
        data.pop("load_sine")
    for key in ("table", "load_table"):
        table = data.pop(key)
        if table is not None:
            data[key] = content_hash([list(table[0]), list(table[1])], 16)
    return data


@dataclass(frozen=True)
class AxisInfo:
    """How one axis appears in metrics.csv and the figures.

    ``columns`` are its metrics.csv columns; ``x_column`` the one plotted on the x axis (percent
    for relative axes, the magnitude otherwise); ``group_column`` (placement axes) the column
    naming the nonlinearity of each row; ``unit`` the unit of ``x_column`` ('' if it differs
    between rows); ``log`` whether the values are logarithmic.
    """

    index: int
    name: str
    kind: str  # nonlinearity | parameter | placement
    targets: tuple[str, ...]
    columns: tuple[str, ...]
    x_column: str
    unit: str
    log: bool
    numeric: bool
    description: str
    group_column: str | None = None


@dataclass(frozen=True)
class Job:
    """One resolved job.

    ``values`` are its metrics.csv swept columns (paper units; 'off' where removed);
    ``params`` the SI parameter dict; ``key`` the content hash; ``point_index`` the index of
    its point on each axis (-1 for the baseline); ``parts`` the label of each axis's value.
    """

    index: int
    id: str
    label: str
    baseline: bool
    values: dict[str, float | str]
    params: dict[str, float]
    key: str
    point_index: tuple[int, ...]
    parts: tuple[str, ...] = ()


@dataclass
class Plan:
    """A sweep resolved to jobs, with its time grid and input signal (SI).

    ``reference`` is the input signal prepared for the grid once per run (a CSV profile read
    once): planning, the kernel warm-up and every chunk sample it.
    """

    cfg: StudyConfig
    jobs: list[Job]
    axes: list[AxisInfo]
    signal: InputSignal
    dt: float
    duration: float
    n_steps: int
    dec: int
    output_interval: float
    scales: dict[str, float] = field(default_factory=dict)
    warnings: list[str] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    reference: Sampler | None = None

    @property
    def key(self) -> str:
        """The sweep's identity: its config (parallel settings aside) and ordered job keys."""
        cfg = self.cfg.model_dump(mode="json", exclude={"parallel"})
        return content_hash([cfg, [[j.id, j.key] for j in self.jobs]], KEY_LENGTH)

    @property
    def n_signals(self) -> int:
        """The signals every job of the sweep records (``sim.runner.signal_count``: the paper's
        EMA's 17, or all of them when a job is another actuator)."""
        from ema_cli.sim.runner import signal_count

        return signal_count(self.P(self.jobs))

    @property
    def n_unique(self) -> int:
        """Distinct cache keys (jobs that are identical runs are computed once)."""
        return len({j.key for j in self.jobs})

    def P(self, jobs: list[Job] | None = None) -> np.ndarray:
        """The SI parameter matrix P[n_jobs, N_PARAMS] of ``jobs`` (default: all)."""
        return np.array([to_row(j.params) for j in (self.jobs if jobs is None else jobs)],
                        dtype=np.float64)


def _is_log(values: list[float | str], axis: SweepAxis) -> bool:
    if axis.logspace is not None:
        return True
    nums = [v for v in values if not isinstance(v, str)]
    if len(nums) < 2 or min(nums) <= 0:
        return False
    return math.log10(max(nums) / min(nums)) >= LOG_DECADES


def _where(pl: Any) -> str:
    """``dead zone @ speed sensor`` for a placement."""
    return f"{TYPE_WORDS.get(pl.type, pl.type)} @ {pl.location.replace('_', ' ')}"


def _axis_info(k: int, axis: SweepAxis) -> AxisInfo:
    name = axis.label
    values = [v for t in axis.targets for v in axis.value_list(t)]
    numeric = not any(isinstance(v, str) for v in values)
    log = _is_log(values, axis)
    if axis.parameter is not None:
        spec = BY_NAME[axis.parameter]
        col = _column(name, spec.unit)
        return AxisInfo(k, name, "parameter", axis.targets, (col,), col, spec.unit, log, numeric,
                        f"{axis.parameter}: {spec.description} [{spec.unit}]")
    if not axis.is_placement_axis:
        pl = lookup(axis.targets[0])
        col = _column(name, pl.unit)
        desc = f"{axis.targets[0]}: {_where(pl)}, {pl.meaning}"
        if axis.relative:
            pct = f"{name}_pct"
            return AxisInfo(k, name, "nonlinearity", axis.targets, (pct, col), pct, "%", log,
                            numeric, desc + " (in % of the baseline's peak signal)")
        return AxisInfo(k, name, "nonlinearity", axis.targets, (col,), col, pl.unit, log,
                        numeric, desc)
    units = {lookup(t).unit for t in axis.targets}
    cols = (name, f"{name}_magnitude", f"{name}_unit")
    what = ", ".join(axis.targets)
    if axis.relative:
        cols = (name, f"{name}_pct", *cols[1:])
        return AxisInfo(k, name, "placement", axis.targets, cols, f"{name}_pct", "%", log,
                        numeric, f"{name}: {what} (magnitude in % of the baseline's peak signal "
                                 "at each location)", group_column=name)
    unit = units.pop() if len(units) == 1 else ""
    return AxisInfo(k, name, "placement", axis.targets, cols, f"{name}_magnitude", unit, log,
                    numeric, f"{name}: {what}", group_column=name)


FIXED_COLUMNS = ("job", "label", "status", "key", "error", "diverged", "t_s")
"""metrics.csv's and signals.parquet's own columns besides the metrics and the signals."""
INTERNAL_COLUMNS = ("_index", "_baseline", "_category", "_others")
"""Columns the figures add to a copy of the metrics table."""


def check_columns(axes: list[AxisInfo], source: str = "config") -> None:
    """Refuse an axis whose column (metrics.csv, signals.parquet) is a fixed column, a metric,
    a signal or another axis's column, naming the axis and the column."""
    from ema_cli.sim.tables import METRICS

    fixed = {c: "a fixed column" for c in (*FIXED_COLUMNS, *INTERNAL_COLUMNS)}
    fixed.update((c.edge, "a metric column") for c in METRICS)
    fixed.update((c.edge, "a signal column") for c in SIGNALS)
    owner: dict[str, AxisInfo] = {}
    for info in axes:
        for c in info.columns:
            what = fixed.get(c)
            if what is None and c in owner and owner[c].index != info.index:
                what = f"a column of axis {owner[c].index} ('{owner[c].name}')"
            if what is not None:
                raise EmaError(f"{source}: sweep.axes.{info.index} ('{info.name}'): its column "
                               f"'{c}' clashes with {what}; give the axis another "
                               "sweep.axes.N.name")
            owner[c] = info


def check_parameters(cfg: StudyConfig, params: Mapping[str, float],
                     source: str = "config") -> None:
    """Refuse two axes that set the same model parameter (e.g. a ``deadzone2`` axis and a
    ``parameter: alpha`` axis), naming both."""
    from ema_cli.model.nonlinearities import nonlinearity_updates

    writer: dict[str, str] = {}
    for k, axis in enumerate(cfg.sweep.axes):
        for t in axis.targets:
            if axis.parameter is not None:
                names: set[str] = {t}
            else:
                values = axis.value_list(t)
                try:
                    names = set(nonlinearity_updates(t, values[0] if values else 0.0, params,
                                                     cfg.friction_reading))
                except EmaError:
                    continue  # the job that sets it reports the value
            for name in names:
                here = f"sweep.axes.{k} ('{t}')"
                if name in writer and not writer[name].startswith(f"sweep.axes.{k} "):
                    raise EmaError(f"{source}: {writer[name]} and {here} both set the model "
                                   f"parameter '{name}'; sweep it on one axis")
                writer.setdefault(name, here)


def _relative_scales(cfg: StudyConfig, base_params: dict[str, float], ref: Sampler,
                     dt: float, n_steps: int, dec: int) -> dict[str, float]:
    """Peak |signal| at each dead-zone location in the baseline run, in the location's unit.

    amplifier: peak voltage demand [V] (full-resolution metric); speed sensor: peak |motor
    speed| [rpm] (sampled every output interval); position sensor and transmission: peak
    |position reference| [deg] (the input signal, as the paper's "2 % of the input signal").
    """
    wanted = {f"{lookup(t).type}@{lookup(t).location}" for a in cfg.sweep.axes if a.relative
              for t in a.targets}
    if not wanted:
        return {}
    res = simulate_batch(np.array([to_row(base_params)]), [ref], None, dt, n_steps, dec)
    peak_ref = ref.max_abs_position() / DEG
    assert res.signals is not None
    w_motor = float(np.nanmax(np.abs(res.signals[0, :, SIG["omega_motor"]])))
    peaks = {
        "deadzone@amplifier": float(res.metrics[0, MET["peak_voltage"]]),
        "deadzone@speed_sensor": w_motor * SIGNALS[SIG["omega_motor"]].factor,
        "deadzone@position_sensor": peak_ref,
        "deadzone@transmission": peak_ref,
    }
    return {k: peaks[k] for k in sorted(wanted)}


def _apply_point(pt: AxisPoint, scales: Mapping[str, float]) -> tuple[float | str, float | None]:
    """(value applied in the placement's unit, percent if relative)."""
    if not pt.relative:
        return pt.value, None
    pl = lookup(pt.target)
    pct = float(pt.value)
    return pct / 100.0 * scales[f"{pl.type}@{pl.location}"], pct


def _values_and_label(spec: JobSpec, axes: list[AxisInfo], cfg: StudyConfig,
                      scales: Mapping[str, float], params: Mapping[str, float]
                      ) -> tuple[dict[str, float | str], dict[str, Any], dict[str, Any],
                                 tuple[str, ...]]:
    """The swept columns, the nonlinearity assignments, the plant overrides, label parts."""
    nls: dict[str, Any] = dict(cfg.nonlinearities)
    plant: dict[str, Any] = cfg.plant_overrides()
    values: dict[str, float | str] = {}
    parts: list[str] = []
    if spec.baseline:
        for info in axes:
            for t in info.targets:
                if info.kind == "parameter":
                    continue
                neutral = neutral_value(t)
                for other in [k for k in nls if lookup(k) is lookup(t)]:
                    del nls[other]
                if neutral is not None:
                    nls[t] = neutral
            if info.kind == "parameter":
                values[info.columns[0]] = plant.get(info.targets[0], params[info.targets[0]])
            elif info.kind == "placement":
                values.update({c: math.nan for c in info.columns})
                values[info.name] = "none"
                values[f"{info.name}_unit"] = ""
            else:
                neutral = neutral_value(info.targets[0])
                if neutral is None:  # compliance: the model's stiffness at the motor shaft
                    neutral = params["kL"] / params["m"] ** 2
                for c in info.columns:
                    values[c] = 0.0 if c.endswith("_pct") else neutral
        return values, nls, plant, ()
    for pt in spec.points:
        info = axes[pt.axis]
        if pt.is_parameter:
            plant[pt.target] = pt.value
            values[info.columns[0]] = pt.value
            parts.append(f"{pt.target} = {fmt(pt.value)} {BY_NAME[pt.target].unit}")
            continue
        applied, pct = _apply_point(pt, scales)
        pl = lookup(pt.target)
        for other in [k for k in nls if k != pt.target and lookup(k) is pl]:
            del nls[other]  # the axis replaces the study's fixed setting of the same placement
        nls[pt.target] = applied
        if info.kind == "placement":
            values[info.name] = pt.target
            if pct is not None:
                values[f"{info.name}_pct"] = pct
            values[f"{info.name}_magnitude"] = applied
            values[f"{info.name}_unit"] = pl.unit
        else:
            if pct is not None:
                values[f"{info.name}_pct"] = pct
            values[info.columns[-1]] = applied
        unit = "" if applied == OFF else f" {pl.unit}"
        text = f"{pt.target} = {fmt(applied)}{unit}"
        if pct is not None:
            text = f"{pt.target} = {fmt(pct)} % ({fmt(applied)}{unit})"
        parts.append(text)
    return values, nls, plant, tuple(parts)


def plan_sweep(cfg: StudyConfig, base_dir: Path | None = None, source: str = "config") -> Plan:
    """Expand and resolve a study config into jobs (SI parameters, labels, content hashes).

    Raises EmaError (naming ``source``) for an empty sweep, one past ``sweep.max_jobs``, or a
    job whose parameters cannot be resolved.
    """
    specs = expand(cfg, source)
    sim = cfg.simulation
    record = cfg.outputs.needs_signals
    n_steps, dec = plan_steps(sim.duration_s, sim.dt_s, sim.output_interval_s)
    sig = input_signal(cfg.input, base_dir, cfg.load, cfg.axis)
    ref = sampler(sig, sim.dt_s, n_steps)  # the one sampling of this run's reference
    axes = [_axis_info(k, a) for k, a in enumerate(cfg.sweep.axes)]
    check_columns(axes, source)

    base_spec = JobSpec((), baseline=True)
    try:
        plain = resolve_params(cfg.plant_overrides(), cfg.nonlinearities, cfg.friction_reading)
        _, base_nls, base_plant, _ = _values_and_label(base_spec, axes, cfg, {}, plain)
        base_params = resolve_params(base_plant, base_nls, cfg.friction_reading)
    except EmaError as exc:
        raise EmaError(f"{source}: the baseline cannot be resolved: {exc.message}") from None
    check_parameters(cfg, plain, source)
    scales = _relative_scales(cfg, base_params, ref, sim.dt_s, n_steps, dec)

    fixed = {"sim": simulator_fingerprint(), "signal": signal_identity(sig), "dt": sim.dt_s,
             "n_steps": n_steps}
    width = max(4, len(str(len(specs) - 1)))
    jobs: list[Job] = []
    warnings: set[str] = set()
    for n, spec in enumerate(specs):
        job_id = f"j{n:0{width}d}"
        values, nls, plant, parts = _values_and_label(spec, axes, cfg, scales, plain)
        label = ", ".join(parts) if parts else BASELINE_LABEL
        try:
            params = resolve_params(plant, nls, cfg.friction_reading)
        except EmaError as exc:
            raise EmaError(f"{source}: sweep job {job_id} ({label}): {exc.message}") from None
        warnings.update(resolution_warnings(params, sim.dt_s))
        key = content_hash({**fixed, "params": params}, KEY_LENGTH)
        point_index = tuple(-1 for _ in axes) if spec.baseline else tuple(
            p.index for p in spec.points)
        jobs.append(Job(n, job_id, label, spec.baseline, values, params, key, point_index,
                        parts))
    notes: list[str] = []
    if jobs and jobs[0].baseline and any(j.key == jobs[0].key for j in jobs[1:]):
        twin = next(j for j in jobs[1:] if j.key == jobs[0].key)
        notes.append(f"the baseline equals job {twin.label!r}; it is not run twice")
        jobs = [dataclasses.replace(j, index=i) for i, j in enumerate(jobs[1:])]
    return Plan(cfg, jobs, axes, sig, sim.dt_s, sim.duration_s, n_steps,
                dec if record else 0, sim.output_interval_s, scales, sorted(warnings), notes,
                ref)
