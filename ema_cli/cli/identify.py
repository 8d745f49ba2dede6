"""`ema identify`: its subcommands (``torque``: the gear stiffness kL and half backlash alpha,
paper §3.1, with a GA; ``closed-loop``, ``friction-sweep``, ``make-data``: the log modes, run by
cli/identify_logs.py) and the default command holding the earlier spelling, `ema identify
[CONFIG] --closed-loop ...` (registered in cli/main.py, IDENTIFY_COMMANDS; cli/groups.py)."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any

import typer

from ema_cli.cli.common import (
    BackendOpt,
    NJobsOpt,
    SchedulerOpt,
    check_number,
    console,
    err_console,
    handle_errors,
    out_help,
    parse_assignments,
)
from ema_cli.errors import EmaError
from ema_cli.progress import report as report_stage

if TYPE_CHECKING:
    from ema_cli.api.identification import Identification
    from ema_cli.identify.torque.run import IdentificationResult

Range = tuple[float, float]


def identify_errors(fn: Callable[..., None]) -> Callable[..., None]:
    """:func:`handle_errors` with the progress lines of every spelling labelled `identify`."""
    return handle_errors(fn, label="identify")


def result_table(res: IdentificationResult) -> None:
    """Print identified (median over runs), truth, |error| % (median / worst), LS optimum ± SE
    and the runs' |distance| to it, with units."""
    from ema_cli.cli.output import print_table
    from ema_cli.identify.torque.problem import PARAM_UNITS
    from ema_cli.units import fmt_num

    summ = res.summary()
    n_runs = len(res.runs)
    many = n_runs > 1
    caption = (
        ("identified: median over the runs; error and Δopt: median/worst over the runs. "
         if many else "") + "error = |identified − truth|/truth; Δopt = |identified − LS "
        "optimum|/optimum; SE: standard error of the LS optimum")
    rows = []
    for n, s in summ.items():
        u = PARAM_UNITS[n]
        if s["error_pct_median"] is None:
            e = "unknown"
        elif many:
            e = f"{s['error_pct_median']:.2g}/{s['error_pct_worst']:.2g} %"
        else:
            e = f"{s['error_pct_worst']:.2g} %"
        d = (f"{s['dist_opt_pct_median']:.2g}/{s['dist_opt_pct_worst']:.2g} %" if many
             else f"{s['dist_opt_pct_worst']:.2g} %")
        rows.append((n, fmt_num(s["median"], u, 6), fmt_num(s["truth"], u, 6, none="unknown"),
                     e, fmt_num(s["optimum"], u, 6), fmt_num(s["optimum_se"], u, 2), d))
    print_table(f"ema identify · {res.settings.method} · model {res.settings.model} · "
                f"{n_runs} run(s)",
                ("param", "identified", "truth", "error", "LS optimum", "SE", "Δopt"), rows,
                caption=caption, optional=("SE", "Δopt"), where="identification.json")


ColumnsOpt = Annotated[list[str] | None, typer.Option(
    "--columns", help="Map a column, repeatable. Torque data: NAME=FILE_COLUMN, e.g. "
                      "torque_nm=T_meas. --closed-loop: CHANNEL=COLUMN[:UNIT], e.g. "
                      "theta_load_deg=pos:rad, t_s=time:ms; units: time s|ms|us, angle "
                      "deg|rad|mrad, speed rpm|rad/s|deg/s, current A|mA, voltage V|mV "
                      "(default: the channel's own).")]
WindowOpt = Annotated[str | None, typer.Option(
    "--window", metavar="T0,T1",
    help="--closed-loop: fit only the samples with T0 <= t <= T1, in seconds of the log's "
         "own time (e.g. 0.5,2.5); it must lie within the log.")]
ClosedLoopOpt = Annotated[bool, typer.Option(
    "--closed-loop", help="Fit the whole simulator to a closed-loop log (--data LOG: .csv, "
                          ".parquet or .mat (MATLAB v5/v7.3) with t_s, theta_ref_deg, "
                          "theta_load_deg [, omega_motor_rpm, current_a, voltage_cmd_v], or "
                          "mapped by --columns); output error by multiple shooting (--method "
                          "shooting, default) or GA then least squares (--method ga)."
)]
FrictionSweepOpt = Annotated[bool, typer.Option(
    "--friction-sweep", help="Fit the static LuGre curve (Fc, Fs, vs, sigma2) to a "
                             "constant-speed sweep (--data SWEEP.csv: omega_rpm, torque_nm)."
)]
MakeDataOpt = Annotated[str | None, typer.Option(
    "--make-data", help="Write synthetic data with stated truths: closed-loop (a 4 s chirp "
                        "log) or friction-sweep; with --noise, --seed, --set plant.NAME=VALUE."
)]
FreeOpt = Annotated[list[str] | None, typer.Option(
    "--free", help="--closed-loop: free a parameter with bounds, NAME=LO,HI in SI (e.g. "
                   "Fs=0,0.2); repeatable; added to the default set kL, alpha, Fc, sigma2 "
                   "(a config's free: replaces it).")]
StartsBackendOpt = Annotated[str | None, typer.Option(
    "--backend", help="--closed-loop: where the starts run: threads (this process; the "
                      "default) | loky (worker processes) | dask (a cluster: --scheduler); the "
                      "same results bit for bit.")]
StartsOpt = Annotated[int | None, typer.Option(
    "--starts", help="--closed-loop: starts of the multiple-shooting search (8).")]
AnyJobsOpt = Annotated[int | None, typer.Option(
    "--n-jobs", help="Parallel processes for the runs (joblib; -1 all cores; default 1); "
                     "with --closed-loop the workers of --backend (default all cores).")]


def torque_pairs(options: dict[str, Any], set_: list[str] | None,
                 columns: list[str] | None) -> list[tuple[str, Any]]:
    """The settings overrides of a torque-data identification: ``--set``, then the options
    given (by settings path), then ``--columns``; the numbers checked against their ranges
    (errors name the option)."""
    for path, option in (("k_range", "--k-range"), ("alpha_range", "--alpha-range"),
                         ("c_range", "--c-range")):
        for v in options[path] or ():
            check_number(v, option, low=0.0)
    check_number(options["synthetic.noise_pct"], "--noise", low=0.0)
    check_number(options["c"], "--c", low=0.0)
    check_number(options["ga.pc"], "--pc", low=0.0, high=1.0)
    check_number(options["ga.pm"], "--pm", low=0.0, high=1.0)
    pairs: list[tuple[str, Any]] = list(parse_assignments(set_, "--set"))
    pairs += [(path, list(v) if isinstance(v, tuple) else v) for path, v in options.items()
              if v is not None]
    for name, col in parse_assignments(columns, "--columns"):
        pairs.append((f"columns.{name}", col))
    if options["c"] is not None and options["fit_c"] is None:
        pairs.append(("fit_c", False))  # --c fixes c even if the config asked to fit it
    return pairs


ConfigArg = Annotated[Path | None, typer.Argument(
    help="YAML settings (e.g. configs/identify.yaml); options below override it.")]
KRangeOpt = Annotated[Range | None, typer.Option(
    "--k-range", metavar="LO HI", help="kL search range LO HI [N*m/rad] (default 500 700).")]
AlphaRangeOpt = Annotated[Range | None, typer.Option(
    "--alpha-range", metavar="LO HI",
    help="alpha search range LO HI in rad (default 0.002 0.004).")]
CRangeOpt = Annotated[Range | None, typer.Option(
    "--c-range", metavar="LO HI",
    help="c search range LO HI when fitted [N*m*s/rad] (default 0 5).")]
RunsOpt = Annotated[int | None, typer.Option(
    "--runs", help="GA runs with seeds SeedSequence(seed).spawn(N) (default 1).")]
JobsOpt = Annotated[int | None, typer.Option(
    "--n-jobs", help="Parallel processes for the runs (joblib; -1 all cores; default 1).")]
TorqueDataOpt = Annotated[Path | None, typer.Option(
    "--data", help="CSV with columns t_s, dtheta_rad, domega_rad_s, torque_nm "
                   "(default: synthetic data from the simulator).")]
NoiseOpt = Annotated[float | None, typer.Option(
    "--noise", help="Synthetic data: Gaussian noise, % of the torque RMS (seeded).")]
DampingOpt = Annotated[str | None, typer.Option(
    "--damping", help="Synthetic data: damping form of the simulator, contact or paper.")]
ModelOpt = Annotated[str | None, typer.Option(
    "--model", help="Torque form fitted: contact (default) or paper (Eq. 2).")]
COpt = Annotated[float | None, typer.Option(
    "--c", help="Fix the damping c [N*m*s/rad] (default: the simulator's for synthetic "
                "data; fitted for --data).")]
FitCOpt = Annotated[bool | None, typer.Option(
    "--fit-c/--no-fit-c", help="Identify c too (default: yes for --data, no otherwise).")]
SeedOpt = Annotated[int | None, typer.Option("--seed", help="Seed of GA and noise.")]
PopOpt = Annotated[int | None, typer.Option("--pop", help="Population size (100).")]
GenerationsOpt = Annotated[int | None, typer.Option(
    "--generations", help="Evaluated generations incl. the initial one (200).")]
PcOpt = Annotated[float | None, typer.Option(
    "--pc", help="Crossover probability per pair of parents (0.85).")]
PmOpt = Annotated[float | None, typer.Option(
    "--pm", help="Mutation probability (0.05): per bit for ga-paper, per gene (parameter) "
                 "for ga.")]
BitsOpt = Annotated[int | None, typer.Option(
    "--bits", help="Bits per parameter, ga-paper binary coding (20).")]
SetOpt = Annotated[list[str] | None, typer.Option(
    "--set", help="Override a setting by dotted path, e.g. ga.pop=50, synthetic.noise_pct=1; "
                  "repeatable (the options above win).")]
OutOpt = Annotated[Path | None, typer.Option("--out", help=out_help())]


@identify_errors
def identify_cmd(
    config: ConfigArg = None,
    k_range: KRangeOpt = None,
    alpha_range: AlphaRangeOpt = None,
    c_range: CRangeOpt = None,
    method: Annotated[str | None, typer.Option(
        "--method", help="ga (improved GA, default), ga-paper (the paper's binary GA) or "
                         "exact (least squares only); --closed-loop: shooting (default) or "
                         "ga.")] = None,
    runs: RunsOpt = None,
    n_jobs: AnyJobsOpt = None,
    data: TorqueDataOpt = None,
    columns: ColumnsOpt = None,
    window: WindowOpt = None,
    noise: NoiseOpt = None,
    damping: DampingOpt = None,
    model: ModelOpt = None,
    c: COpt = None,
    fit_c: FitCOpt = None,
    seed: SeedOpt = None,
    pop: PopOpt = None,
    generations: GenerationsOpt = None,
    pc: PcOpt = None,
    pm: PmOpt = None,
    bits: BitsOpt = None,
    set_: SetOpt = None,
    out: OutOpt = None,
    closed_loop: ClosedLoopOpt = False,
    friction_sweep: FrictionSweepOpt = False,
    make_data: MakeDataOpt = None,
    starts: StartsOpt = None,
    free: FreeOpt = None,
    backend: StartsBackendOpt = None,
    scheduler: SchedulerOpt = None,
) -> None:
    """The torque-data identification (as `ema identify torque`), or with --closed-loop,
    --friction-sweep or --make-data KIND the log modes (as `ema identify closed-loop`,
    `friction-sweep`, `make-data KIND`): the spelling of earlier versions, every option of
    every mode (docs/identification.md)."""
    modes = [m for m, on in (("--closed-loop", closed_loop), ("--friction-sweep", friction_sweep),
                             ("--make-data", make_data is not None)) if on]
    if modes or free:
        from ema_cli.cli.identify_logs import run_log_mode

        torque_only = {"--k-range": k_range, "--alpha-range": alpha_range, "--c-range": c_range,
                       "--method": method if not closed_loop else None, "--runs": runs,
                       "--n-jobs": n_jobs if not closed_loop else None,
                       "--damping": damping, "--model": model, "--c": c,
                       "--fit-c/--no-fit-c": fit_c, "--pc": pc, "--pm": pm, "--bits": bits}
        run_log_mode(modes, config=config, data=data, noise=noise, seed=seed, pop=pop,
                     generations=generations, set_=set_, out=out, free=free,
                     make_data=make_data, columns=columns, window=window,
                     method=method if closed_loop else None, starts=starts,
                     torque_only=[k for k, v in torque_only.items() if v is not None],
                     execution=(backend, n_jobs if closed_loop else None, scheduler))
        return
    if backend is not None or scheduler is not None:
        raise EmaError("--backend and --scheduler apply to --closed-loop; the torque-data "
                       "identification runs its GA runs in processes (--n-jobs)")
    if window is not None:
        raise EmaError("--window applies to --closed-loop, not to the torque-data "
                       "identification")
    run_torque(config, k_range=k_range, alpha_range=alpha_range, c_range=c_range,
               method=method, runs=runs, n_jobs=n_jobs, data=data, columns=columns,
               noise=noise, damping=damping, model=model, c=c, fit_c=fit_c, seed=seed,
               pop=pop, generations=generations, pc=pc, pm=pm, bits=bits, set_=set_, out=out)


@identify_errors
def torque_cmd(
    config: ConfigArg = None,
    k_range: KRangeOpt = None,
    alpha_range: AlphaRangeOpt = None,
    c_range: CRangeOpt = None,
    method: Annotated[str | None, typer.Option(
        "--method", help="ga (improved GA, default), ga-paper (the paper's binary GA) or "
                         "exact (least squares only).")] = None,
    runs: RunsOpt = None,
    n_jobs: JobsOpt = None,
    data: TorqueDataOpt = None,
    columns: Annotated[list[str] | None, typer.Option(
        "--columns", help="Map a column of --data, repeatable: NAME=FILE_COLUMN, e.g. "
                          "torque_nm=T_meas.")] = None,
    noise: NoiseOpt = None,
    damping: DampingOpt = None,
    model: ModelOpt = None,
    c: COpt = None,
    fit_c: FitCOpt = None,
    seed: SeedOpt = None,
    pop: PopOpt = None,
    generations: GenerationsOpt = None,
    pc: PcOpt = None,
    pm: PmOpt = None,
    bits: BitsOpt = None,
    set_: SetOpt = None,
    out: OutOpt = None,
) -> None:
    """Gear stiffness kL and half backlash alpha (and damping c) from transmission torque data
    (paper §3.1, Eq. 8) with a GA, beside the exact least-squares optimum; synthetic data or
    --data FILE.csv.

    Minimises J = sum (T_meas - T_model)^2. Writes identification.json, runs.csv,
    history.csv, convergence.png, fit.png and manifest.json."""
    run_torque(config, k_range=k_range, alpha_range=alpha_range, c_range=c_range,
               method=method, runs=runs, n_jobs=n_jobs, data=data, columns=columns,
               noise=noise, damping=damping, model=model, c=c, fit_c=fit_c, seed=seed,
               pop=pop, generations=generations, pc=pc, pm=pm, bits=bits, set_=set_, out=out)


def run_torque(config: Path | None, *, k_range: Range | None, alpha_range: Range | None,
               c_range: Range | None, method: str | None, runs: int | None,
               n_jobs: int | None, data: Path | None, columns: list[str] | None,
               noise: float | None, damping: str | None, model: str | None, c: float | None,
               fit_c: bool | None, seed: int | None, pop: int | None,
               generations: int | None, pc: float | None, pm: float | None,
               bits: int | None, set_: list[str] | None, out: Path | None) -> None:
    """Check the options of the torque-data identification, run it, write its folder and
    print its table (both spellings: `ema identify torque` and `ema identify [CONFIG]`)."""
    from ema_cli.api.identification import identification_inputs, identify, load_settings
    from ema_cli.report.rundir import check_output

    check_output(out, "identify")  # a file, a folder of another command: refused at once
    from ema_cli.cli.common import check_jobs

    n_jobs = check_jobs(n_jobs, "--n-jobs")  # capped at the cores available, with a note
    pairs = torque_pairs({
        "k_range": k_range, "alpha_range": alpha_range, "c_range": c_range, "method": method,
        "runs": runs, "n_jobs": n_jobs, "data": str(data) if data is not None else None,
        "synthetic.noise_pct": noise, "synthetic.damping": damping, "model": model, "c": c,
        "fit_c": fit_c, "seed": seed, "ga.pop": pop, "ga.generations": generations,
        "ga.pc": pc, "ga.pm": pm, "ga.bits": bits}, set_, columns)
    settings = load_settings(config, pairs)
    if settings.data is not None and (noise is not None or damping is not None):
        raise EmaError("--noise and --damping describe synthetic data; they cannot be used "
                       "with --data")
    if out is not None:  # its inputs against the folder's, before the identification
        check_output(out, "identify", identification_inputs(settings))
    report_stage(f"identification ({settings.method}, {settings.runs} run(s))")
    ident = identify(settings)
    report_stage("writing files and figures")
    folder = ident.save(out)

    print_identification(ident, folder)


LogDataOpt = Annotated[Path | None, typer.Option(
    "--data", help="The closed-loop log: .csv, .parquet or .mat (MATLAB v5/v7.3) with t_s, "
                   "theta_ref_deg, theta_load_deg [, omega_motor_rpm, current_a, "
                   "voltage_cmd_v], or mapped by --columns.")]
LogSetOpt = Annotated[list[str] | None, typer.Option(
    "--set", help="Override a setting by dotted path, e.g. plant.contact_tau=1e-4, "
                  "shooting.starts=4; repeatable (the options above win).")]


@identify_errors
def closed_loop_cmd(
    config: Annotated[Path | None, typer.Argument(
        help="YAML settings of the closed-loop fit; options below override it.")] = None,
    data: LogDataOpt = None,
    columns: Annotated[list[str] | None, typer.Option(
        "--columns", help="Map a log column, repeatable: CHANNEL=COLUMN[:UNIT], e.g. "
                          "theta_load_deg=pos:rad, t_s=time:ms; units: time s|ms|us, angle "
                          "deg|rad|mrad, speed rpm|rad/s|deg/s, current A|mA, voltage V|mV "
                          "(default: the channel's own).")] = None,
    window: Annotated[str | None, typer.Option(
        "--window", metavar="T0,T1",
        help="Fit only the samples with T0 <= t <= T1, in seconds of the log's own time "
             "(e.g. 0.5,2.5); it must lie within the log.")] = None,
    method: Annotated[str | None, typer.Option(
        "--method", help="shooting (multiple shooting from Sobol starts, default) or ga (GA "
                         "then least squares).")] = None,
    starts: Annotated[int | None, typer.Option(
        "--starts", help="Starts of the multiple-shooting search (8).")] = None,
    free: Annotated[list[str] | None, typer.Option(
        "--free", help="Free a parameter with bounds, NAME=LO,HI in SI (e.g. Fs=0,0.2); "
                       "repeatable; added to the default set kL, alpha, Fc, sigma2 (a "
                       "config's free: replaces it).")] = None,
    seed: Annotated[int | None, typer.Option(
        "--seed", help="Seed of the search's starts.")] = None,
    pop: Annotated[int | None, typer.Option(
        "--pop", help="--method ga: population size (selects the GA).")] = None,
    generations: Annotated[int | None, typer.Option(
        "--generations", help="--method ga: evaluated generations (selects the GA).")] = None,
    set_: LogSetOpt = None,
    out: OutOpt = None,
    backend: BackendOpt = None,
    n_jobs: NJobsOpt = None,
    scheduler: SchedulerOpt = None,
) -> None:
    """Output-error fit of the whole simulator to a closed-loop log (--data LOG) by multiple
    shooting: kL, alpha, Fc, sigma2 (and --free more), 95 % intervals and a verdict.

    Writes identification.json, fit_<channel>.png, alpha_profile.png, fitted.yaml (runs with
    `ema simulate`), summary.md and manifest.json (docs/identification.md)."""
    from ema_cli.cli.identify_logs import run_log_mode

    run_log_mode(["--closed-loop"], config=config, data=data, noise=None, seed=seed, pop=pop,
                 generations=generations, set_=set_, out=out, free=free, make_data=None,
                 columns=columns, window=window, method=method, starts=starts, torque_only=[],
                 execution=(backend, n_jobs, scheduler))


@identify_errors
def friction_sweep_cmd(
    config: Annotated[Path | None, typer.Argument(
        help="YAML settings of the friction fit; options below override it.")] = None,
    data: Annotated[Path | None, typer.Option(
        "--data", help="The sweep: CSV with omega_rpm, torque_nm (steady friction torque at "
                       "constant motor speeds).")] = None,
    set_: Annotated[list[str] | None, typer.Option(
        "--set", help="Override a setting by dotted path; repeatable.")] = None,
    out: OutOpt = None,
) -> None:
    """Fit the static LuGre curve (Fc, Fs, vs, sigma2) to a constant-speed friction sweep
    (--data SWEEP.csv) by variable projection, with standard errors.

    Writes identification.json, friction_fit.png, summary.md and manifest.json."""
    from ema_cli.cli.identify_logs import run_log_mode

    run_log_mode(["--friction-sweep"], config=config, data=data, noise=None, seed=None,
                 pop=None, generations=None, set_=set_, out=out, free=None, make_data=None,
                 torque_only=[])


@identify_errors
def make_data_cmd(
    kind: Annotated[str, typer.Argument(
        help="closed-loop (a 4 s chirp log) or friction-sweep.")],
    config: Annotated[Path | None, typer.Argument(
        help="YAML settings of the synthetic data; options below override it.")] = None,
    noise: Annotated[float | None, typer.Option(
        "--noise", help="Gaussian noise on every channel, % of its RMS (seeded).")] = None,
    seed: Annotated[int | None, typer.Option("--seed", help="Seed of the noise.")] = None,
    set_: Annotated[list[str] | None, typer.Option(
        "--set", help="Override a setting by dotted path, e.g. plant.kL=600, duration_s=2; "
                      "repeatable.")] = None,
    out: OutOpt = None,
) -> None:
    """Write a synthetic log with stated truths (KIND: closed-loop or friction-sweep), to try
    `ema identify closed-loop` or `friction-sweep` on.

    Writes closed_loop.csv or friction_sweep.csv, <stem>.truth.json and manifest.json."""
    from ema_cli.cli.identify_logs import MAKE_KINDS, run_log_mode

    if kind not in MAKE_KINDS:
        raise EmaError(f"make-data KIND: expected {' or '.join(MAKE_KINDS)}, got {kind!r}")
    run_log_mode(["--make-data"], config=config, data=None, noise=noise, seed=seed, pop=None,
                 generations=None, set_=set_, out=out, free=None, make_data=kind,
                 torque_only=[])


def print_identification(ident: Identification, folder: Path) -> None:
    """The closing lines of a torque-data identification: the result table, warnings, units,
    the data, the cost and the timings."""
    from ema_cli.identify.torque.problem import PARAM_UNITS

    res = ident.result
    result_table(res)
    for w in res.warnings:
        err_console.print(f"[yellow]warning:[/] {w}")
    console.print("units: " + ", ".join(f"{n} {PARAM_UNITS[n]}" for n in res.names))
    js = res.to_json()
    opt = res.optimum
    costs = [r.cost for r in res.runs]
    console.print(f"data: {res.data.source} ({res.data.n_samples:,} samples); {js['experiment']}")
    console.print(
        f"J: best {min(costs):.6g}, LS optimum {opt.cost:.6g} N²·m²; kL–alpha correlation "
        f"{opt.corr_k_alpha:.3f}; "
        + ("c fitted" if res.problem.fit_c else f"c fixed at {res.problem.c_fixed:.6g} N·m·s/rad"))
    evals = res.runs[0].evaluations
    per_run = sum(r.wall_time_s for r in res.runs) / len(res.runs)
    console.print(
        f"{len(res.runs)} run(s) × {evals:,} evaluations, {per_run:.3f} s per run; exact "
        f"solver {opt.wall_time_s * 1e3:.1f} ms; total {res.wall_time_s:.2f} s -> {folder}")
