"""``api.identify_closed_loop``, ``api.identify_friction_sweep``, ``api.make_identification_data``:
the log identifications as ``ema identify --closed-loop / --friction-sweep / --make-data`` run
them."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ema_cli.api._inputs import ConfigSource, Overrides, folder_arg, override_pairs
from ema_cli.api.result import long_form

if TYPE_CHECKING:
    import pandas as pd
    from matplotlib.figure import Figure

    from ema_cli.identify.closed_loop.ga_fit import ClosedLoopFit
    from ema_cli.identify.friction.sweep import FrictionFit
    from ema_cli.identify.make_data import SyntheticLog


def _parameters_frame(js: dict[str, Any]) -> pd.DataFrame:
    """One row per identified parameter of a fit's JSON: value, unit, standard error, 95 %
    interval, determined."""
    import pandas as pd

    return pd.DataFrame([{"parameter": n, "value": v["value"], "unit": v["unit"],
                          "standard_error": v["standard_error"], "ci95_low": v["ci95"][0],
                          "ci95_high": v["ci95"][1], "determined": v["determined"]}
                         for n, v in js["parameters"].items()])


def _save(command: str, name: str, settings: Any, folder: str | Path | None,
          write: Any) -> Path:
    from ema_cli.report.rundir import write_run

    return write_run(command, name, log_inputs(settings), folder_arg(folder), write)


def log_inputs(settings: Any) -> Any:
    """The inputs (``report.run_inputs.RunInputs``) a log identification or synthetic log
    with the validated ``settings`` records in its folder's marker: every setting, and the data
    file's SHA-256 (what ``ema identify`` checks ``--out`` against first)."""
    from ema_cli.report.run_inputs import run_inputs

    return run_inputs(settings, files={"data": getattr(settings, "data", None)})


def closed_loop_inputs(config: ConfigSource = None, overrides: Overrides = None,
                       **settings: Any) -> Any:
    """:func:`log_inputs` of :func:`identify_closed_loop` with these arguments."""
    from ema_cli.config.loader import load_config
    from ema_cli.identify.log_settings import ClosedLoopSettings

    pairs = override_pairs(overrides) + list(settings.items())
    return log_inputs(load_config(config, pairs, ClosedLoopSettings))


def friction_sweep_inputs(config: ConfigSource = None, overrides: Overrides = None,
                          **settings: Any) -> Any:
    """:func:`log_inputs` of :func:`identify_friction_sweep` with these arguments."""
    from ema_cli.config.loader import load_config
    from ema_cli.identify.log_settings import FrictionSweepSettings

    pairs = override_pairs(overrides) + list(settings.items())
    return log_inputs(load_config(config, pairs, FrictionSweepSettings))


def make_data_inputs(config: ConfigSource = None, overrides: Overrides = None,
                     **settings: Any) -> Any:
    """:func:`log_inputs` of :func:`make_identification_data` with these arguments."""
    from ema_cli.config.loader import load_config
    from ema_cli.identify.log_settings import MakeDataSettings

    pairs = override_pairs(overrides) + list(settings.items())
    return log_inputs(load_config(config, pairs, MakeDataSettings))


@dataclass
class ClosedLoopIdentification:
    """A closed-loop identification: ``result`` is ``identify.closed_loop.ga_fit.ClosedLoopFit``;
    ``execution`` where its starts ran (``sweep.executor.Executor.describe``)."""

    result: ClosedLoopFit
    execution: dict[str, Any] = field(default_factory=dict)

    @property
    def parameters(self) -> dict[str, float]:
        """The identified free parameters, SI (names of ``ema params``)."""
        return {n: float(v) for n, v in zip(self.result.names, self.result.x, strict=True)}

    @property
    def metrics(self) -> pd.DataFrame:
        """One row per free parameter: value, unit, SE, 95 % interval, determined."""
        return _parameters_frame(self.result.to_json())

    def to_pandas(self, form: str = "wide") -> pd.DataFrame:
        """fit.csv: ``t_s``, each fitted channel measured and simulated at the fit (edge
        units); ``long``: one row per sample and column."""
        import pandas as pd

        from ema_cli.report.log_identify_report import closed_loop_fit_columns

        return long_form(pd.DataFrame(closed_loop_fit_columns(self.result)), form, ["t_s"])

    def plot(self, channel: str | None = None) -> Figure:
        """Measured and fitted ``channel`` (default: the first fitted one) vs time."""
        from ema_cli.errors import EmaError
        from ema_cli.report.log_identify_report import channel_figure

        channels = list(self.result.problem.channels)
        if channel is not None and channel not in channels:
            raise EmaError(f"channel: {channel!r} was not fitted; expected one of "
                           f"{', '.join(channels)}")
        return channel_figure(self.result, channel or channels[0])

    def save(self, folder: str | Path | None = None) -> Path:
        """Write the folder ``ema identify --closed-loop`` writes -> the folder."""
        from ema_cli.report.log_identify_report import write_closed_loop

        s = self.result.settings
        return _save("identify", s.name, s, folder,
                     lambda out: write_closed_loop(self.result, out,
                                                   execution=self.execution))


@dataclass
class FrictionSweepIdentification:
    """A friction-sweep identification: ``result`` is ``identify.friction.sweep.FrictionFit``."""

    result: FrictionFit
    settings: Any

    @property
    def parameters(self) -> dict[str, float]:
        """Fc [N*m], Fs [N*m], vs [rad/s], sigma2 [N*m*s/rad]."""
        return self.result.params

    @property
    def metrics(self) -> pd.DataFrame:
        """One row per parameter: value, unit, SE, 95 % interval, determined."""
        return _parameters_frame(self.result.to_json())

    def to_pandas(self, form: str = "wide") -> pd.DataFrame:
        """fit.csv: ``omega_rpm``, measured ``torque_nm``, fitted ``torque_model_nm``;
        ``long``: one row per speed and column."""
        import pandas as pd

        from ema_cli.report.log_identify_report import friction_fit_columns

        return long_form(pd.DataFrame(friction_fit_columns(self.result)), form, ["omega_rpm"])

    def plot(self) -> Figure:
        """The measured and fitted static friction curve, and the residuals."""
        from ema_cli.report.log_identify_report import friction_figure

        return friction_figure(self.result)

    def save(self, folder: str | Path | None = None) -> Path:
        """Write the folder ``ema identify --friction-sweep`` writes -> the folder."""
        from ema_cli.report.log_identify_report import write_friction_sweep

        js = self.settings.model_dump(mode="json")
        return _save("identify", self.settings.name, self.settings, folder,
                     lambda out: write_friction_sweep(self.result, out, js))


@dataclass
class SyntheticData:
    """Synthetic identification data: ``log`` is ``identify.make_data.SyntheticLog``."""

    log: SyntheticLog
    settings: Any

    @property
    def metrics(self) -> pd.DataFrame:
        """The stated truths: one row per parameter (SI value, as ``ema params``)."""
        import pandas as pd

        return pd.DataFrame([{"parameter": n, "value": float(v)}
                             for n, v in self.log.truth.items()])

    def to_pandas(self, form: str = "wide") -> pd.DataFrame:
        """The data table (``<kind>.csv``, edge units); ``long``: one row per sample and
        column."""
        import pandas as pd

        wide = pd.DataFrame(self.log.columns)
        return long_form(wide, form, [wide.columns[0]])

    def plot(self) -> Figure:
        """Every column of the data against the first (time, or motor speed)."""
        from ema_cli.report.log_identify_report import synthetic_figure

        return synthetic_figure(self.log)

    def save(self, folder: str | Path | None = None) -> Path:
        """Write ``<kind>.csv``, ``<kind>.truth.json`` and the manifest -> the folder."""
        from ema_cli.report.log_identify_report import write_synthetic

        js = self.settings.model_dump(mode="json")
        return _save("identify", f"data-{self.log.kind}", self.settings, folder,
                     lambda out: write_synthetic(self.log, out, js))


def identify_closed_loop(config: ConfigSource = None, overrides: Overrides = None, *,
                         backend: str | None = None, n_jobs: int | None = None,
                         scheduler: str | None = None,
                         **settings: Any) -> ClosedLoopIdentification:
    """Fit the simulator to a closed-loop log (``data=`` the file: CSV, Parquet or MATLAB .mat;
    ``columns=`` a column map, ``window=`` (T0, T1) [s]), as ``ema identify --closed-loop``
    does; settings: ``identify.log_settings.ClosedLoopSettings``. ``backend`` (threads, loky,
    dask; None: this process's threads), ``n_jobs`` and ``scheduler`` say where the
    multiple-shooting starts run (``sweep.executor``; the same bits on every backend)."""
    from ema_cli.api._inputs import backend_args

    n_jobs = backend_args(backend, n_jobs, scheduler)
    from ema_cli.config.loader import load_config
    from ema_cli.identify.closed_loop.ga_fit import run_closed_loop
    from ema_cli.identify.closed_loop.problem import load_log
    from ema_cli.identify.log_settings import ClosedLoopSettings

    pairs = override_pairs(overrides) + list(settings.items())
    cfg = load_config(config, pairs, ClosedLoopSettings)
    from ema_cli.errors import EmaError

    log = None
    if cfg.data is not None:  # read here: the column map and the window belong to the reading
        try:
            log = load_log(cfg.data, columns=cfg.columns, window=cfg.window)
        except MemoryError:
            size = Path(cfg.data).stat().st_size if Path(cfg.data).is_file() else 0
            raise EmaError(f"data: out of memory reading the log '{cfg.data}' ({size:,} "
                           "bytes); read a part of it with window (T0, T1) [s]") from None
        check_log_steps(cfg, log.duration, str(cfg.data))
        check_log_span(cfg, log, str(cfg.data))
        from ema_cli.progress import announce_estimate

        announce_estimate(*fit_estimate(cfg, log.duration))
    from ema_cli.sweep.executor import executing

    try:
        with executing(backend, n_jobs, scheduler) as ex:
            return ClosedLoopIdentification(run_closed_loop(cfg, log), ex.describe())
    except MemoryError:
        what = (f"the {log.n:,}-row, {log.duration:.4g} s log '{cfg.data}'" if log is not None
                else "the log")
        raise EmaError(f"out of memory fitting {what} at dt_s = {cfg.dt_s:g} s: fit a part "
                       "of it with window (T0, T1) [s], or raise dt_s") from None


FIT_PASSES_FIXED = 1580.0
"""Kernel work of a multiple-shooting fit that does not grow with the starts, in passes over
the whole log at ``dt_s``: the finishing candidates' lengthening, the refinement at the fine
step, the contact restart, the polish, the intervals and the profile."""
FIT_PASSES_PER_START = 61.0
"""Kernel work per multiple-shooting start, in passes over the log at ``dt_s`` (the start
states and the joint search). Both from the kernel's lane-step tally of the README's 4 s
example (`ema identify --make-data closed-loop --noise 1`, then the fit) at 2, 4 and 8
starts: 6.63e8, 7.58e8 and 8.18e8 lane-steps of 400,000-step passes, 2026-11-27, after the
LM's creeping stop, its Broyden-carried Jacobian and the start states' pruning after one
iteration (before them: 1.046e9, 1.138e9 and 1.422e9, 2300 passes plus 157 per start; the
earlier model, 440 passes per start and nothing fixed, put 2 starts at 12 s for 45 s)."""
FIT_OVERHEAD = 3.5
"""A fit's wall time over its kernel time at ``progress.CPU_S_PER_STEP`` on 2 cores (the
least-squares algebra of the segments, the verdict's checks, the kernel's own speed on these
variants): the README's 4 s example took 26.8, 29.6 and 30.3 s at 2, 4 and 8 starts for
26, 28 and 32 s estimated, 2026-11-27 (44.8, 46.5 and 55.8 s before the changes above)."""


def fit_estimate(cfg: Any, duration: float, workers: int | None = None) -> tuple[float, str]:
    """The estimated time [s] of a closed-loop fit of a ``duration`` [s] log with settings
    ``cfg`` (``ClosedLoopSettings``) and what it counts: the kernel work at
    ``progress.CPU_S_PER_STEP`` (:data:`FIT_PASSES_FIXED` passes over the log, plus
    :data:`FIT_PASSES_PER_START` per shooting start; the GA search: its population times
    generations at ``ga_dt_s``, then the fixed passes), times :data:`FIT_OVERHEAD`."""
    from ema_cli.limits import cores
    from ema_cli.progress import kernel_seconds

    workers = cores() if workers is None else workers
    steps = duration / cfg.dt_s
    if cfg.search == "shooting":
        passes = FIT_PASSES_FIXED + FIT_PASSES_PER_START * cfg.shooting.starts
        lane_steps, first = passes * steps, f"{cfg.shooting.starts} starts,"
    else:
        ga_steps = duration / (cfg.ga_dt_s or cfg.dt_s)
        n_ga = cfg.ga.pop * cfg.ga.generations
        passes = FIT_PASSES_FIXED
        lane_steps = n_ga * ga_steps + passes * steps
        first = f"GA {n_ga:,} simulations of {ga_steps:,.0f} steps, then"
    what = (f"a closed-loop fit of the {duration:.3g} s log: {first} about {passes:,.0f} "
            f"passes of {steps:,.0f} steps on {workers} core{'s' if workers != 1 else ''}")
    return FIT_OVERHEAD * kernel_seconds(lane_steps, 1, workers), what


def check_log_steps(cfg: Any, duration: float, source: str) -> None:
    """Refuse a closed-loop fit whose one pass over the log (``duration`` [s]) at its finest
    step (``dt_s``, ``ga_dt_s``) exceeds :data:`ema_cli.limits.MAX_RUN_STEPS`: every evaluation
    of the fit is such a pass (hundreds to thousands of them)."""
    from ema_cli.errors import EmaError
    from ema_cli.limits import MAX_RUN_STEPS

    for key in ("dt_s", "ga_dt_s"):
        dt = getattr(cfg, key, None)
        if dt is None:
            continue
        steps = duration / dt
        if steps > MAX_RUN_STEPS:
            raise EmaError(f"{key}: one pass over the {duration:.4g} s log '{source}' at "
                           f"{key} = {dt:g} s is {steps:.3g} integration steps, more than "
                           f"{MAX_RUN_STEPS:.0e} per pass (each evaluation of the fit is one); "
                           f"raise {key} or cut the log with window (T0, T1) [s]")


def check_log_span(cfg: Any, log: Any, source: str) -> None:
    """Refuse a closed-loop log (or its ``window``) shorter than the slowest time constant to
    identify: that of the closed loop's slowest mode, ``1/min |Re(lambda)|`` of the linear
    limit (:func:`ema_cli.analysis.linear.slowest_time_constant`: no backlash, friction as its
    viscous part) at the start of the fit, the middle of every free parameter's bounds (the
    contact's nuisance parameters included). A response shorter than that has not shown its
    slowest mode's decay, and the parameters it depends on are not in the log. No refusal
    when that linear loop is not stable (nothing to measure the decay by)."""
    from ema_cli.analysis.linear import slowest_time_constant
    from ema_cli.errors import EmaError
    from ema_cli.identify.closed_loop.ga_fit import build_problem

    problem, _ = build_problem(cfg, log)
    try:
        tau = slowest_time_constant(problem.params(0.5 * (problem.lower + problem.upper)))
    except EmaError:  # a plant the linear limit cannot describe (e.g. JL = 0): no claim
        return
    if tau is not None and log.duration < tau:
        span = (f"--window {cfg.window[0]:g},{cfg.window[1]:g} of data file '{source}' keeps"
                if cfg.window is not None else f"data file '{source}' spans")
        raise EmaError(f"{span} {log.duration:.4g} s, shorter than the {tau:.4g} s it needs: "
                       "the closed loop's slowest time constant at the middle of the free "
                       f"bounds ({', '.join(problem.names)}); expected a log or --window at "
                       f"least {tau:.4g} s long")


def identify_friction_sweep(config: ConfigSource = None, overrides: Overrides = None,
                            **settings: Any) -> FrictionSweepIdentification:
    """Fit the static LuGre curve and the candidate laws (symmetric or per direction,
    Coulomb or Stribeck; the lowest BIC chosen) to a friction sweep (``data=`` the file), as
    ``ema identify --friction-sweep`` does; settings:
    ``identify.log_settings.FrictionSweepSettings``."""
    from ema_cli.config.loader import load_config
    from ema_cli.errors import EmaError
    from ema_cli.identify.friction.sweep import fit_friction_sweep, load_sweep
    from ema_cli.identify.log_settings import FrictionSweepSettings

    pairs = override_pairs(overrides) + list(settings.items())
    cfg = load_config(config, pairs, FrictionSweepSettings)
    if cfg.data is None:
        raise EmaError("--friction-sweep needs --data SWEEP.csv (columns omega_rpm, torque_nm)")
    fit = fit_friction_sweep(load_sweep(cfg.data, cfg.columns), cfg.delta, cfg.vs_range,
                             tuple(cfg.laws), cfg.fit_delta)
    return FrictionSweepIdentification(fit, cfg)


def make_identification_data(config: ConfigSource = None, overrides: Overrides = None,
                             **settings: Any) -> SyntheticData:
    """Synthetic data with stated truths, as ``ema identify --make-data KIND`` makes them;
    settings: ``identify.log_settings.MakeDataSettings`` (``kind``, ``noise_pct``, ``seed``,
    ``plant``, ...)."""
    from ema_cli.config.loader import load_config
    from ema_cli.identify.log_settings import MakeDataSettings
    from ema_cli.identify.make_data import closed_loop_log, friction_sweep_log

    pairs = override_pairs(overrides) + list(settings.items())
    cfg = load_config(config, pairs, MakeDataSettings)
    if cfg.kind == "closed-loop":
        log = closed_loop_log(cfg.plant, cfg.noise_pct, cfg.seed, amplitude_deg=cfg.amplitude_deg,
                              freq_hz=cfg.freq_hz, freq_end_hz=cfg.freq_end_hz,
                              duration_s=cfg.duration_s,
                              sample_interval_s=cfg.sample_interval_s, dt_s=cfg.dt_s)
    else:
        log = friction_sweep_log(cfg.plant, cfg.noise_pct, cfg.seed,
                                 speeds_rpm=cfg.speeds_rpm)
    return SyntheticData(log, cfg)
