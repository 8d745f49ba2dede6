"""``api.duty``: a mission profile through an actuator (``ema duty PROFILE [ACTUATOR]``)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ema_cli.api._inputs import ConfigSource, Overrides, base_dir, folder_arg, override_pairs
from ema_cli.errors import EmaError

if TYPE_CHECKING:
    import pandas as pd
    from matplotlib.figure import Figure

    from ema_cli.acceptance.duty.profile import Expanded
    from ema_cli.acceptance.duty.reference import Reference
    from ema_cli.acceptance.duty.run import DutyRun, Limits
    from ema_cli.acceptance.verdict import Verdict
    from ema_cli.config.duty import DutyProfile

ACTUATOR_KEYS = {"axis", "ratio", "transmission", "motor", "drive", "friction", "sensors",
                 "disturbance"}
"""Top-level keys that make a YAML file an actuator description (not a run config)."""


@dataclass
class DutyResult:
    """A duty run: the profile, its blocks (``expanded``), the actuator's run (thermal
    history, figures of merit, measurements: ``run``), the verdict rows (each measurement with
    a limit, in the limit's unit), the limits used, the full-resolution reference when asked,
    where the thermal element came from."""

    profile: DutyProfile
    source: str
    expanded: Expanded
    run: DutyRun
    verdicts: list[Verdict]
    limits: Limits
    axis: str
    dt: float
    thermal_source: str
    reference: Reference | None = None
    wall_time_s: float = 0.0
    overrides: list[tuple[str, Any]] = field(default_factory=list)
    inputs: Any = None
    """What the folder's marker records (``report.run_inputs.RunInputs``)."""

    @property
    def verdict(self) -> str:
        """FAIL if a limit fails, else INCONCLUSIVE if a value is only known as a bound that
        straddles its limit, else PASS (the acceptance battery's rule)."""
        from ema_cli.acceptance.verdict import overall

        return overall([v.result for v in self.verdicts])

    @property
    def exit_code(self) -> int:
        """``ema duty``'s exit code: 0 PASS, 1 FAIL, 3 INCONCLUSIVE."""
        from ema_cli.acceptance.verdict import EXIT_CODES

        return EXIT_CODES[self.verdict]

    def hot_summary(self) -> dict[str, Any] | None:
        """The hot check in edge units (degC, Hz, deg/s), cold beside hot; None when skipped."""
        if self.run.hot is None:
            return None
        from ema_cli.acceptance.duty.hot import as_dict

        return as_dict(self.run.hot)

    @property
    def title(self) -> str:
        return f"{self.profile.name}: duty ({self.profile.actuator.label()})"

    @property
    def metrics(self) -> pd.DataFrame:
        """Every duty metric: metric, value and unit at the edge (degC, h, Wh, ...), the SI
        value, its limit and result when it has one, and how it was measured."""
        return self.to_pandas()

    def to_pandas(self, form: str = "wide") -> pd.DataFrame:
        """:attr:`metrics` (``wide``), or ``long`` (metric, quantity, value)."""
        from ema_cli.report.duty_report import metrics_frame

        df = metrics_frame(self)
        if form == "wide":
            return df
        if form != "long":
            raise EmaError(f"form must be 'wide' or 'long', got {form!r}")
        return df.melt(id_vars=["metric"], var_name="quantity", value_name="value")

    def trace(self) -> pd.DataFrame:
        """The temperatures over the profile (edge units): ``t_s``, ``winding_c``,
        ``winding_peak_c``, ``housing_c``, ``ambient_c``, ``copper_w``, ``housing_loss_w``,
        ``segment``."""
        from ema_cli.report.duty_report import trace_frame

        return trace_frame(self)

    def plot(self, which: str = "temperature") -> Figure:
        """``temperature`` (over the profile, with the limit) or ``envelope`` (the operating
        points against the drive's torque-speed envelope)."""
        from ema_cli.report.duty_report import envelope_figure, temperature_figure

        if which == "temperature":
            return temperature_figure(self)
        if which == "envelope":
            return envelope_figure(self)
        raise EmaError(f"which must be 'temperature' or 'envelope', got {which!r}")

    def save(self, folder: str | Path | None = None) -> Path:
        """Write duty.json, duty.md, temperature.png, envelope.png, trace.parquet, the
        profile and a manifest (``ema duty --out FOLDER``)."""
        from ema_cli.report.duty_report import write_duty
        from ema_cli.report.rundir import write_run

        inputs = self.inputs or _inputs(self.profile, self.overrides, None, False, True)
        return write_run("duty", self.profile.name, inputs, folder_arg(folder),
                         lambda out: write_duty(out, self))


def _inputs(prof: Any, pairs: list[tuple[str, Any]], actuator: Any, full: bool,
            hot: bool) -> Any:
    from ema_cli.report.run_inputs import run_inputs

    return run_inputs(prof, sets=pairs,
                      options={"actuator": str(actuator) if actuator is not None else None,
                               "full_resolution": bool(full), "hot": bool(hot)},
                      files={"actuator": actuator} if actuator is not None else None)


def _load(profile: ConfigSource, actuator: str | Path | None,
          overrides: Overrides) -> tuple[Any, list[tuple[str, Any]]]:
    from ema_cli.config.duty import DutyProfile
    from ema_cli.config.loader import load_config

    if profile is None:
        raise EmaError("duty needs a profile (a YAML file such as configs/duty/tvc.yaml)")
    pairs = override_pairs(overrides)
    prof = load_config(profile, pairs, DutyProfile)
    if actuator is not None:
        if not isinstance(actuator, str | Path):
            raise EmaError(f"actuator: expected a path, got {type(actuator).__name__}")
        if not Path(actuator).is_file():
            raise EmaError(f"actuator: '{actuator}' is not a file (a run config or an actuator "
                           "description, e.g. configs/actuators/paper_ema.yaml)")
    return prof, pairs


def duty_inputs(profile: ConfigSource, actuator: str | Path | None = None,
                overrides: Overrides = None, *, full_resolution: bool = False,
                hot: bool = True) -> Any:
    """The inputs (``report.run_inputs.RunInputs``) a :func:`duty` with these arguments
    records in its folder's marker: what ``ema duty`` checks ``--out`` against first."""
    prof, pairs = _load(profile, actuator, overrides)
    return _inputs(prof, pairs, actuator, full_resolution, hot)


def _actuator(prof: Any, profile: ConfigSource, actuator: str | Path | None
              ) -> tuple[Any, dict[str, float], float]:
    """The run config, its SI parameters and step: ``actuator`` (a run config or an
    actuator description file) or the profile's ``actuator`` section."""
    from ema_cli.config.loader import load_config, read_yaml, resolve_run
    from ema_cli.config.study import StudyConfig
    from ema_cli.config.support import check_command

    pairs = prof.actuator.pairs()
    if actuator is not None:
        doc = read_yaml(actuator)
        if isinstance(doc, dict) and (set(doc) == {"actuator"} or (
                set(doc) & ACTUATOR_KEYS and not set(doc) & {"plant", "simulation", "input"})):
            source: Any = {"actuator": str(Path(actuator).resolve())}
            folder = Path(actuator).parent
        else:
            source, folder = Path(actuator), Path(actuator).parent
    else:
        source, folder = prof.actuator.source(base_dir(profile), "profile")
    try:
        cfg = load_config(source, pairs, StudyConfig)
        check_command(cfg, "duty")
    except EmaError as exc:
        raise EmaError(f"actuator: {exc}") from None
    run = resolve_run(cfg, folder)
    dt = prof.simulation.dt_s or run.dt
    return cfg, run.params, dt


def limits_of(prof: Any, cfg: Any) -> tuple[Limits, str]:
    """The winding limit, class temperature and insulation life of ``prof`` on the actuator
    of run config ``cfg`` -> (limits, where the thermal element came from)."""
    from ema_cli.acceptance.duty.run import Limits, winding_limit
    from ema_cli.config.thermal import DEFAULT_CLASS, thermal_of
    from ema_cli.model.thermal import INSULATION_CLASSES
    from ema_cli.units import ZERO_CELSIUS

    th = thermal_of(cfg)
    if th is None:
        class_k = INSULATION_CLASSES[DEFAULT_CLASS] + ZERO_CELSIUS
        name, source = f"class {DEFAULT_CLASS}", (
            "the reference EMA's thermal element (`ema params`; describe yours in "
            "actuator.drive.thermal)")
    else:
        class_k = th.limit_k()
        ins = str(th.insulation).strip()
        name = f"class {ins.upper()}" if ins.upper() in INSULATION_CLASSES else ins
        source = "the actuator's drive.thermal"
    lim = Limits(winding_limit(prof, class_k), class_k, prof.life.insulation_life_h, name)
    return lim, source


def verdict_rows(prof: Any, run: Any, limits: Limits) -> list[Verdict]:
    """Each measurement with a limit (the profile's, the winding's insulation limit when it
    gives none) judged as the acceptance battery judges."""
    from ema_cli.acceptance.measurement import TestRun
    from ema_cli.acceptance.verdict import verdicts
    from ema_cli.config.acceptance import Limit
    from ema_cli.units import ZERO_CELSIUS

    lims = dict(prof.limits)
    if "winding_temperature" not in lims:
        lims["winding_temperature"] = Limit(max=round(limits.class_k - ZERO_CELSIUS, 6),
                                            unit="degC")
    return verdicts(TestRun(prof.name, "duty", run.measurements), lims)


def duty(profile: ConfigSource, actuator: str | Path | None = None,
         overrides: Overrides = None, *, full_resolution: bool = False, hot: bool = True,
         progress: Callable[[str, int, int], None] | None = None) -> DutyResult:
    """Run the mission ``profile`` (a YAML file, a dict or a :class:`DutyProfile`) on its
    actuator, or on ``actuator`` (a run config or an actuator description file);
    ``overrides`` are dotted paths of the profile (``ambient``, ``actuator.plant.R``,
    ``segments.0.sine.cycles``...). ``hot``: the hot actuator's bandwidth and no-load rate
    beside the cold one's; ``full_resolution``: also the brute-force reference (the whole
    profile at the mechanical step: minutes per hour of profile)."""
    import time

    from ema_cli.acceptance.duty.run import run_units
    from ema_cli.api._inputs import callable_arg, flag_arg

    full_resolution = flag_arg(full_resolution, "full_resolution")
    hot = flag_arg(hot, "hot")
    callable_arg(progress, "progress")
    t0 = time.perf_counter()
    prof, pairs = _load(profile, actuator, overrides)
    cfg, params, dt = _actuator(prof, profile, actuator)
    limits, th_source = limits_of(prof, cfg)
    exp, runs = run_units(prof, [params], dt, limits, cfg.axis, hot=hot, progress=progress)
    run = runs[0]
    ref = None
    if full_resolution:
        from ema_cli.acceptance.duty.reference import full_resolution as brute

        ref = brute(exp, params, dt,
                    None if progress is None else lambda f: progress("full resolution",
                                                                     int(100 * f), 100))
    res = DutyResult(prof, str(profile) if isinstance(profile, str | Path) else "dict", exp,
                     run, verdict_rows(prof, run, limits), limits, cfg.axis, dt, th_source,
                     ref, time.perf_counter() - t0, pairs,
                     _inputs(prof, pairs, actuator, full_resolution, hot))
    return res
