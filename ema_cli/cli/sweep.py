"""`ema sweep`, `ema validate` and `ema show`: run, check and inspect a study config."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any

import typer

from ema_cli.cli.common import (
    check_jobs,
    console,
    err_console,
    handle_errors,
    out_help,
    parse_assignments,
)
from ema_cli.errors import EmaError
from ema_cli.units import fmt_num

if TYPE_CHECKING:
    from ema_cli.api.study import Sweep

MAX_TABLE_ROWS = 40  # rows of the terminal summary table (metrics.csv has every job)
MAX_TABLE_METRICS = 4  # metric columns of the terminal summary table
MAX_SHOW_JOBS = 50  # jobs listed by `ema show` unless --all
ConfigArg = Annotated[Path, typer.Argument(help="YAML study config, e.g. configs/deadzone2.yaml.")]
SetOpt = Annotated[list[str] | None, typer.Option(
    "--set", help="Override a config value by dotted path (list items by index), e.g. "
                  "plant.Kpp=60, sweep.axes.0.values=[0.01,0.1], outputs.timeseries=false; "
                  "repeatable.")]


def _load(config: Path, set_: list[str] | None) -> tuple[Any, list[tuple[str, str]]]:
    from ema_cli.config.loader import load_config
    from ema_cli.config.study import StudyConfig

    overrides = parse_assignments(set_, "--set")
    return load_config(config, overrides, StudyConfig), overrides


def print_summary(sweep: Sweep) -> None:
    """The closing terminal table: one row per job (capped), key metrics in edge units; at a
    narrow console the last metric columns are dropped (all are in metrics.csv), then rows
    become key/value blocks."""
    from ema_cli.cli.output import print_table
    from ema_cli.report.sweep_tables import metric_label

    result = sweep.result
    cfg = result.plan.cfg
    metrics = list(cfg.outputs.metrics)[:MAX_TABLE_METRICS]
    labels = [metric_label(m) for m in metrics]
    df = result.metrics
    counts = result.counts()
    shown = df if len(df) <= MAX_TABLE_ROWS else df.head(MAX_TABLE_ROWS)
    rows, styles = [], []
    for _, row in shown.iterrows():
        styles.append("red" if row["status"] == "failed" else None)  # sweep.run.FAILED
        rows.append((row["job"], str(row["label"]), row["status"],
                     *[fmt_num(float(row[m]), nan="n/a") for m in metrics]))
    caption = (f"first {MAX_TABLE_ROWS} of {len(df)} jobs; all in metrics.csv"
               if len(df) > MAX_TABLE_ROWS else None)
    print_table(f"{cfg.name}: {len(df)} jobs ({counts['ok']} ok, {counts['diverged']} "
                f"diverged, {counts['failed']} failed, {counts['pending']} not run)",
                ("job", "swept values", "status", *labels), rows,
                justify=["left", "left", "left"] + ["right"] * len(labels),
                optional=labels[1:], caption=caption, where="metrics.csv", styles=styles)


@handle_errors
def sweep_cmd(
    config: ConfigArg,
    set_: SetOpt = None,
    n_jobs: Annotated[int | None, typer.Option(
        "--n-jobs", "-j", help="Workers (processes or threads); -1: all cores "
                               "(default: parallel.n_jobs, else all cores).")] = None,
    backend: Annotated[str | None, typer.Option(
        "--backend", help="auto | loky (processes) | threads (in this process) | dask "
                          "(default: parallel.backend).")] = None,
    scheduler: Annotated[str | None, typer.Option(
        "--scheduler", help="Dask scheduler address for --backend dask, e.g. "
                            "tcp://10.0.0.5:8786.")] = None,
    out: Annotated[Path | None, typer.Option("--out", help=out_help(
        "an unfinished run of the same sweep there is resumed"))] = None,
    force: Annotated[bool, typer.Option(
        "--force", help="Recompute every job, even those in the cache.")] = False,
    cache_dir: Annotated[Path | None, typer.Option(
        "--cache-dir", help="Job cache folder (default: results/.cache/sweep, or OUT/.cache "
                            "when --out is outside results/).")] = None,
    progress: Annotated[bool, typer.Option(
        "--progress/--no-progress", help="Show a progress bar with ETA (stderr).")] = True,
    no_figures: Annotated[bool, typer.Option(
        "--no-figures", help="Draw no figures (they can cost more than a small sweep's "
                             "simulations); metrics.csv and signals.parquet hold the data.")
    ] = False,
) -> None:
    """Run a sweep: every job of CONFIG, in parallel, cached and resumable; writes metrics.csv,
    time series, figures, summary.md and manifest.json."""
    from ema_cli.api.study import sweep
    from ema_cli.limits import BACKENDS

    n_jobs = check_jobs(n_jobs, "--n-jobs", scheduler)
    if backend is not None and backend not in BACKENDS:
        raise EmaError(f"--backend must be one of {', '.join(BACKENDS)}; got {backend!r}")
    overrides = parse_assignments(set_, "--set")
    try:
        run = sweep(config, overrides, n_jobs=n_jobs, backend=backend, force=force,
                    progress=progress, scheduler=scheduler, cache_dir=cache_dir, out=out,
                    write=True, figures="none" if no_figures else "background")
        result = run.result
        for w in result.warnings:
            err_console.print(f"[yellow]warning:[/] {w}")
        for n in result.plan.notes:
            console.print(f"note: {n}")
        print_summary(run)
        if result.pending is not None:
            err_console.print(f"drawing {len(result.plan.cfg.outputs.figures)} kinds of "
                              "figures (--no-figures skips them) ...")
            run.finish()
    except BaseException:  # Ctrl-C while the figures are drawn: none left half-written
        from ema_cli.report.sweep_report import stop_drawing

        stop_drawing()
        raise
    counts = result.counts()
    t = result.timings
    figs = (f"; {len(result.figures)} figures {t['figures']:.1f} s" if "figures" in t
            else "; no figures" if no_figures else "")
    console.print(f"{result.computed} runs computed, {result.cached} cached; backend "
                  f"{result.backend} x{result.workers}; {t.get('total', 0.0):.2f} s "
                  f"(kernel {t.get('kernel', 0.0):.2f} s){figs} -> {result.folder}")
    if counts["failed"]:
        raise EmaError(f"{counts['failed']} job(s) failed (errors in {result.folder}/"
                       "manifest.json); re-run the same command to retry them, finished jobs "
                       "are cached", 1)


KINDS = ("auto", "study", "experiment", "identify", "acceptance", "sensitivity", "tune",
         "design", "tolerances")
"""What `ema validate` can check: a study config, an experiment batch, identification settings,
an acceptance spec, a sensitivity study, a tuning or design config, a tolerance file."""


def detect_kind(config: Path) -> str:
    """The kind of a config file from its top-level keys (``study`` when unsure)."""
    from ema_cli.config.loader import read_yaml

    keys = set(read_yaml(config))
    if "tolerances" in keys:
        return "tolerances"
    if keys & {"identify", "tune"}:
        return "design"
    if keys & {"scenarios", "variables", "optimiser"}:
        return "tune"
    if "tests" in keys or ("actuator" in keys and not keys & {"input", "simulation", "plant",
                                                               "sweep", "nonlinearities"}):
        return "acceptance"  # (a run config's actuator is a description beside its input)
    if keys & {"studies", "claims", "thresholds", "ranking", "identification", "paper"}:
        return "experiment"
    if keys & {"k_range", "alpha_range", "c_range", "ga", "synthetic", "method", "fit_c",
               "columns", "data", "runs"}:
        return "identify"
    if keys & {"factors", "sensitivity", "inputs"}:
        return "sensitivity"
    return "study"


@handle_errors
def validate_cmd(
    config: ConfigArg,
    set_: SetOpt = None,
    kind: Annotated[str, typer.Option(
        "--kind", help="What CONFIG is: study (`ema sweep`/`simulate`), experiment "
                       "(`ema reproduce`), identify (`ema identify`), acceptance (`ema "
                       "acceptance`), sensitivity (`ema sensitivity`), tune (`ema tune`), "
                       "design (`ema design`), tolerances (`ema yield --tolerances`) or auto "
                       "(from its keys).")
    ] = "auto",
) -> None:
    """Check CONFIG against its schema (fast: nothing is simulated); for a study, count its
    jobs."""
    if kind not in KINDS:
        raise EmaError(f"--kind must be one of {', '.join(KINDS)}; got {kind!r}")
    if kind == "auto":
        kind = detect_kind(config)
    overrides = parse_assignments(set_, "--set")
    if kind == "tolerances":
        from ema_cli.production.tolerances import load_tolerances

        if overrides:
            raise EmaError("--set: a tolerance file takes no overrides (edit the file)")
        tol = load_tolerances(config)
        console.print(f"{config}: valid tolerance file; {len(tol.paths)} laws "
                      f"({', '.join(tol.paths)}), {len(tol.correlations)} "
                      f"correlation{'' if len(tol.correlations) == 1 else 's'}, "
                      f"worst-case box +-{tol.k:g} sd")
        return
    if kind == "experiment":
        from ema_cli.analysis.reproduce import load_experiment

        exp = load_experiment(config, overrides)
        console.print(f"{config}: valid experiment; {len(exp.studies)} studies, "
                      f"{len(exp.thresholds)} thresholds, {len(exp.claims)} claims"
                      + (", an identification" if exp.identification else ""))
        return
    if kind == "acceptance":
        from ema_cli.config.acceptance import AcceptanceSpec
        from ema_cli.config.loader import load_config

        spec = load_config(config, overrides, AcceptanceSpec)
        _check_actuator(spec.actuator, config)
        n_limits = sum(len(t.limits) for t in spec.tests.values())
        console.print(f"{config}: valid acceptance spec; {len(spec.tests)} tests, {n_limits} "
                      "limits")
        return
    if kind == "design":
        from ema_cli.config.design import DesignConfig
        from ema_cli.config.loader import load_config

        d = load_config(config, overrides, DesignConfig)
        _check_design_sections(d)
        console.print(f"{config}: valid design config ({d.name}); its identify section "
                      "checked against `ema identify --closed-loop`, its tune overrides "
                      "against configs/tune.yaml (`ema design --tune-config` may name another)")
        return
    if kind == "tune":
        from ema_cli.config.loader import load_config
        from ema_cli.config.tune import TuneConfig

        t = load_config(config, overrides, TuneConfig)
        _check_actuator(t.actuator, config)
        n_cons = len(t.constraints)
        console.print(f"{config}: valid tuning config; {len(t.scenarios)} scenarios, "
                      f"{len(t.variables)} variables ({', '.join(t.variables)}), {n_cons} "
                      f"constraints, {t.optimiser.method} budget {t.optimiser.budget} x "
                      f"{t.optimiser.runs} run(s)")
        return
    if kind == "identify":
        from ema_cli.config.loader import load_config
        from ema_cli.identify.torque.settings import IdentifySettings

        s = load_config(config, overrides, IdentifySettings)
        console.print(f"{config}: valid identification settings; method {s.method}, "
                      f"{s.runs} run(s), data {s.data or 'synthetic'}")
        return
    if kind == "sensitivity":
        from ema_cli.config.loader import load_config
        from ema_cli.config.sensitivity import SensitivityConfig
        from ema_cli.sensitivity.run import resolve_method

        c = load_config(config, overrides, SensitivityConfig)
        method, n = resolve_method(c, None, None)
        console.print(f"{config}: valid sensitivity study; {len(c.factors)} factors, "
                      f"{len(c.input_list())} input(s), {method} n = {n} -> "
                      f"{c.runs(method, n):,} runs")
        return
    from ema_cli.sweep.expand import check_size

    cfg, _ = _load(config, set_)
    from ema_cli.config.loader import inert_input_warnings, input_signal

    # the files it refers to (input and load profiles) are read and checked too
    signal = input_signal(cfg.input, config.parent, cfg.load, cfg.axis)
    for w in inert_input_warnings(signal, cfg.simulation.duration_s):
        err_console.print(f"warning: {w}", highlight=False)
    if not cfg.sweep.axes:  # a run config (`ema simulate`), or a study still without axes
        console.print(f"{config}: valid run config (no sweep axes: `ema simulate` runs it; "
                      "`ema sweep` needs sweep.axes)")
        return
    n = check_size(cfg.sweep, str(config))
    axes = "; ".join(f"{a.label} ({a.n_points()} values)" for a in cfg.sweep.axes)
    console.print(f"{config}: valid; {cfg.sweep.mode} over {axes} -> {n} jobs"
                  + (" (baseline included)" if cfg.sweep.baseline else ""))


def _check_design_sections(d: Any) -> None:
    """A design config's ``identify:`` settings against the closed-loop schema and its
    ``tune:`` overrides on the bundled tuning config (an unknown key named, never dropped)."""
    from ema_cli.api.design import DEFAULT_TUNE_CONFIG
    from ema_cli.config.loader import dotted_pairs, load_config
    from ema_cli.config.tune import TuneConfig
    from ema_cli.identify.log_settings import ClosedLoopSettings

    for key, check in (("identify", lambda: load_config(
            {**d.identify, "name": d.identify.get("name", d.name)}, [], ClosedLoopSettings)),
                       ("tune", lambda: load_config(DEFAULT_TUNE_CONFIG, dotted_pairs(d.tune),
                                                    TuneConfig))):
        try:
            check()
        except EmaError as exc:
            raise EmaError(f"{key}: {exc.message}") from None


def _check_actuator(actuator: Any, config: Path) -> None:
    """The run config an acceptance spec or a tuning config names (``actuator.config``): it
    exists, passes the run-config schema and its profiles can be read."""
    from ema_cli.config.loader import input_signal, load_config
    from ema_cli.config.study import StudyConfig

    src, here = actuator.source(config.parent, "config")
    if src is None:
        return
    try:
        run = load_config(src, [], StudyConfig)
        input_signal(run.input, here, run.load, run.axis)
    except EmaError as exc:
        raise EmaError(f"actuator.config: {exc}") from None


@handle_errors
def show_cmd(
    config: ConfigArg,
    set_: SetOpt = None,
    all_: Annotated[bool, typer.Option("--all", help="List every job (default: the first "
                                                     f"{MAX_SHOW_JOBS}).")] = False,
) -> None:
    """Print the resolved config (every default filled in) and the jobs it expands to."""
    import yaml

    from ema_cli.api.study import plan as plan_study

    plan = plan_study(config, parse_assignments(set_, "--set"))
    cfg = plan.cfg
    console.print(yaml.safe_dump(cfg.model_dump(mode="json"), sort_keys=False).rstrip(),
                  markup=False)
    from ema_cli.cli.output import print_table

    jobs = plan.jobs if all_ else plan.jobs[:MAX_SHOW_JOBS]
    print_table(f"{len(plan.jobs)} jobs ({plan.n_unique} distinct runs); input "
                f"{plan.signal.describe()}, {plan.duration:g} s at dt {plan.dt:g} s",
                ("job", "swept values", "key"), [(j.id, j.label, j.key) for j in jobs],
                justify=["left"] * 3, optional=("key",), where="the job cache keys",
                caption=(f"first {len(jobs)} of {len(plan.jobs)}; --all lists every job"
                         if len(jobs) < len(plan.jobs) else None))
    for info in plan.axes:
        console.print(f"axis {info.name}: {info.description}; columns "
                      f"{', '.join(info.columns)}", markup=False)
    for key, v in plan.scales.items():
        console.print(f"relative scale {key}: {v:.6g} (baseline peak)")
    for n in plan.notes:
        console.print(f"note: {n}")
    for w in plan.warnings:
        err_console.print(f"[yellow]warning:[/] {w}")
