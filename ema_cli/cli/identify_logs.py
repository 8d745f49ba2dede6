"""The log modes of `ema identify`: --closed-loop, --friction-sweep, --make-data (called by
``cli.identify.identify_cmd``; heavy imports inside the functions)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from ema_cli.cli.common import as_options, check_number, console, err_console, parse_assignments
from ema_cli.errors import EmaError
from ema_cli.progress import report as report_stage

MAKE_KINDS = ("closed-loop", "friction-sweep")


def _free_pairs(free: list[str] | None) -> list[tuple[str, Any]]:
    """``--free NAME=LO,HI`` -> (``free.NAME``, [LO, HI]) overrides; errors name the option."""
    import math

    pairs = []
    for name, text in parse_assignments(free, "--free"):
        parts = [x.strip() for x in text.split(",")]
        try:
            lo, hi = (float(parts[0]), float(parts[1]))
            if len(parts) != 2:
                raise ValueError
        except (ValueError, IndexError):
            raise EmaError(f"--free {name}: expected NAME=LO,HI (two numbers in SI), got "
                           f"{text!r}") from None
        if not (math.isfinite(lo) and math.isfinite(hi)):
            raise EmaError(f"--free {name}: bounds must be finite, got {text}")
        pairs.append((f"free.{name}", [lo, hi]))
    return pairs


def parse_window(text: str) -> list[float]:
    """``--window T0,T1`` -> [T0, T1] [s]; errors name the option and what is expected."""
    import math

    parts = [x.strip() for x in text.split(",")]
    try:
        if len(parts) != 2:
            raise ValueError
        lo, hi = float(parts[0]), float(parts[1])
    except ValueError:
        raise EmaError(f"--window: expected T0,T1 (two times in seconds, e.g. 0.5,2.5), got "
                       f"{text!r}") from None
    if not (math.isfinite(lo) and math.isfinite(hi)) or not lo < hi:
        raise EmaError(f"--window: expected T0 < T1, two finite times in seconds, got {text}")
    return [lo, hi]


def closed_loop_pairs(config: Path | None, pairs: list[tuple[str, Any]],
                      free: list[str] | None) -> list[tuple[str, Any]]:
    """``pairs`` + the ``--free`` options. ``--free`` adds to the free set: to the config's
    ``free:`` when it has one, else to the default set (kL, alpha, Fc, sigma2)."""
    extra = _free_pairs(free)
    if not extra:
        return pairs
    has_free = any(k == "free" for k, _ in pairs)
    if config is not None and not has_free:
        from ema_cli.config.loader import read_yaml

        has_free = "free" in read_yaml(config)
    if not has_free:
        from ema_cli.identify.closed_loop.problem import DEFAULT_FREE

        pairs = [("free", {k: list(v) for k, v in DEFAULT_FREE.items()}), *pairs]
    return [*pairs, *extra]


def _table(title: str, params: dict[str, dict], truth: dict[str, float] | None) -> None:
    """Print the identified parameters: value, SE and 95 % interval with units, whether the
    data determine each ("nuisance": the contact's parameters freed unless stated, reported
    but not judged), and the truth and error of synthetic data."""
    from ema_cli.cli.output import print_table
    from ema_cli.units import fmt_num

    cols = ["param", "value", "SE", "95 % interval", "determined"]
    if truth:
        cols += ["truth", "error"]
    rows = []
    for n, v in params.items():
        u = v["unit"]
        row = [n, fmt_num(v["value"], u, 6), fmt_num(v["standard_error"], u, 3),
               f"[{fmt_num(v['ci95'][0], '', 6)}, {fmt_num(v['ci95'][1], u, 6)}]",
               "nuisance" if v.get("role") == "nuisance"
               else "yes" if v["determined"] else "NOT DETERMINED"]
        if truth:
            t = truth.get(n)
            row += ["unknown" if t is None else fmt_num(t, u, 6),
                    "unknown" if not t else f"{100 * (v['value'] / t - 1):+.3g} %"]
        rows.append(row)
    # at 80 columns the estimate and its 95 % interval stay (what an identification is for):
    # the standard error goes first (the interval says more), then the truth columns
    optional = ("truth", "error", "SE") if truth else ("SE",)
    print_table(title, cols, rows, optional=optional, where="identification.json")


def run_log_mode(modes: list[str], *, config: Path | None, data: Path | None,
                 noise: float | None, seed: int | None, pop: int | None,
                 generations: int | None, set_: list[str] | None, out: Path | None,
                 free: list[str] | None, make_data: str | None,
                 method: str | None = None, starts: int | None = None,
                 torque_only: list[str], columns: list[str] | None = None,
                 window: str | None = None,
                 execution: tuple[str | None, int | None, str | None] = (None, None, None),
                 laws: str | None = None) -> None:
    """Check the options of a log mode (one mode; no torque-data options) and run it;
    ``execution``: --backend, --n-jobs, --scheduler (--closed-loop only); ``laws`` the
    friction-sweep's candidate laws."""
    from ema_cli.report.rundir import check_output

    if len(modes) > 1:
        raise EmaError(f"{' and '.join(modes)} cannot be combined; choose one mode")
    if not modes:
        raise EmaError("--free applies to --closed-loop only")
    mode = modes[0]
    if torque_only:
        raise EmaError(f"{', '.join(torque_only)} appl{'ies' if len(torque_only) == 1 else 'y'}"
                       f" to the torque-data identification, not to {mode}")
    if free and mode != "--closed-loop":
        raise EmaError(f"--free applies to --closed-loop, not to {mode}")
    if columns and mode not in ("--closed-loop", "--friction-sweep"):
        raise EmaError(f"--columns applies to --closed-loop, --friction-sweep and the "
                       f"torque-data identification, not to {mode}")
    if laws is not None and mode != "--friction-sweep":
        raise EmaError(f"--laws applies to --friction-sweep, not to {mode}")
    if window is not None and mode != "--closed-loop":
        raise EmaError(f"--window applies to --closed-loop, not to {mode}")
    if mode != "--make-data" and noise is not None:
        raise EmaError(f"--noise describes synthetic data (--make-data), not {mode}")
    if mode != "--closed-loop" and (pop is not None or generations is not None):
        raise EmaError(f"--pop and --generations set the GA of --closed-loop, not {mode}")
    if mode != "--closed-loop" and starts is not None:
        raise EmaError(f"--starts sets the search of --closed-loop, not {mode}")
    if mode != "--closed-loop" and (execution[0] is not None or execution[2] is not None):
        raise EmaError(f"--backend and --scheduler apply to --closed-loop (its starts), not "
                       f"to {mode}")
    check_number(noise, "--noise", low=0.0)
    check_output(out, "identify")
    pairs: list[tuple[str, Any]] = list(parse_assignments(set_, "--set"))
    if mode == "--make-data":
        if data is not None:
            raise EmaError("--make-data writes data; it takes no --data")
        if make_data not in MAKE_KINDS:
            raise EmaError(f"--make-data: expected {' or '.join(MAKE_KINDS)}, got {make_data!r}")
        pairs += [("kind", make_data)]
        if noise is not None:
            pairs.append(("noise_pct", noise))
        if seed is not None:
            pairs.append(("seed", seed))
        _make_data(config, pairs, out)
        return
    if data is not None:
        pairs.append(("data", str(data)))
    if seed is not None and mode == "--closed-loop":
        pairs.append(("seed", seed))
    elif seed is not None:
        raise EmaError("--seed has no use with --friction-sweep (the fit is deterministic)")
    if mode == "--closed-loop":
        if method is not None and method not in ("shooting", "ga"):
            raise EmaError(f"--method: --closed-loop searches by shooting or ga, got {method!r}")
        if method is None and (pop is not None or generations is not None):
            method = "ga"  # the GA's options keep their meaning: they select the GA
            err_console.print("note: --pop/--generations select the GA search (--method ga); "
                              "the default is multiple shooting (--starts)")
        if method == "ga" and starts is not None:
            raise EmaError("--starts sets the multiple-shooting search, not --method ga")
        if method == "shooting" and (pop is not None or generations is not None):
            raise EmaError("--pop and --generations set the GA, not --method shooting "
                           "(use --starts)")
        if method is not None:
            pairs.append(("search", method))
        if starts is not None:
            check_number(starts, "--starts", low=2)
            pairs.append(("shooting.starts", starts))
        if pop is not None:
            pairs.append(("ga.pop", pop))
        if generations is not None:
            pairs.append(("ga.generations", generations))
        pairs += [(f"columns.{ch}", spec) for ch, spec in parse_assignments(columns,
                                                                              "--columns")]
        if window is not None:
            pairs.append(("window", parse_window(window)))
        pairs = closed_loop_pairs(config, pairs, free)
        _closed_loop(config, pairs, out, execution)
    else:
        pairs += [(f"columns.{ch}", spec) for ch, spec in parse_assignments(columns,
                                                                              "--columns")]
        if laws is not None:
            pairs.append(("laws", [w.strip() for w in laws.split(",") if w.strip()]))
        _friction_sweep(config, pairs, out)


def _make_data(config: Path | None, pairs: list[tuple[str, Any]], out: Path | None) -> None:
    from ema_cli.api.identify_logs import make_data_inputs, make_identification_data
    from ema_cli.report.rundir import check_output

    if out is not None:  # its inputs against the folder's, before the data are made
        check_output(out, "identify", make_data_inputs(config, pairs))
    syn = make_identification_data(config, pairs)
    folder = syn.save(out)
    stem = syn.log.kind.replace("-", "_")
    console.print(f"{syn.log.description}")
    console.print("truth: " + ", ".join(f"{k} {v:.6g}" for k, v in syn.log.truth.items()))
    flag = "--closed-loop" if syn.log.kind == "closed-loop" else "--friction-sweep"
    keep = ""
    if syn.log.kind == "closed-loop":  # what the fit must hold fixed as the data had it
        from ema_cli.identify.closed_loop.problem import DEFAULT_FREE

        keep = "".join(f" --set plant.{k}={v}" for k, v in syn.settings.plant.items()
                       if k not in DEFAULT_FREE)
    console.print(f"-> {folder / (stem + '.csv')} (truths in {stem}.truth.json); fit it with "
                  f"`ema identify {flag} --data {folder / (stem + '.csv')}{keep}`")


def _closed_loop(config: Path | None, pairs: list[tuple[str, Any]], out: Path | None,
                 execution: tuple[str | None, int | None, str | None]) -> None:
    from ema_cli.api.identify_logs import closed_loop_inputs, identify_closed_loop
    from ema_cli.cli.common import BACKEND_OPTIONS, backend_options, print_retries
    from ema_cli.report.rundir import check_output

    backend, n_jobs, scheduler = execution
    n_jobs = backend_options(backend, n_jobs, scheduler)
    if out is not None:  # its inputs against the folder's, before the fit
        check_output(out, "identify", closed_loop_inputs(config, pairs))
    report_stage("reading the log, loading the kernel")
    ident = as_options(lambda: identify_closed_loop(config, pairs, backend=backend,
                                                    n_jobs=n_jobs, scheduler=scheduler),
                       **{"with window (T0, T1) [s]": "with --window T0,T1",
                          "data: out of memory": "--data: out of memory"}, **BACKEND_OPTIONS)
    print_retries(ident.execution)
    fit = ident.result
    report_stage("writing files and figures")
    folder = ident.save(out)
    js = fit.to_json()
    _table(f"ema identify --closed-loop · {fit.problem.log.source}", js["parameters"],
           fit.problem.log.truth)
    console.print("fit RMS: " + ", ".join(f"{c} {v:.4g}" for c, v in js["fit_rms"].items())
                  + f"; J = {fit.cost:.6g}")
    for w in fit.warnings:
        err_console.print(f"[yellow]warning:[/] {w}")
    t = fit.timings
    ms = fit.shooting
    if ms is not None:
        verdict = ("[green]optimum confirmed[/]" if ms.confirmed
                   else "[red]optimum NOT confirmed[/] (see the warning)")
        console.print(f"{verdict}: {ms.search.agree} of {len(ms.search.final_cost)} finishing "
                      f"starts agree; estimate from the {ms.source}")
        ad = js.get("adequacy")
        if ad is not None:
            fits = ", ".join(f"{c} {v['fit_percent']:.4g} %" for c, v in ad["channels"].items())
            console.print(("[green]model adequate[/]: residuals white and independent of the "
                           "command on every judged channel" if ad["adequate"] else
                           "[red]model NOT adequate[/] (see the warning)")
                          + f"; fit {fits}")
        first = (f"multiple shooting {t['search_s'] - t['polish_s']:.1f} s "
                 f"({fit.ga_throughput / 1e6:.1f} M steps/s)")
    else:
        first = f"GA {t['ga_s']:.1f} s ({fit.ga_throughput / 1e6:.1f} M steps/s)"
    console.print(f"{first}, polish {t['polish_s']:.1f} s, uncertainty and profile "
                  f"{t['uncertainty_profile_s']:.1f} s; total {t['total_s']:.1f} s -> {folder}")


def _friction_sweep(config: Path | None, pairs: list[tuple[str, Any]],
                    out: Path | None) -> None:
    from ema_cli.api.identify_logs import friction_sweep_inputs, identify_friction_sweep
    from ema_cli.report.rundir import check_output

    if out is not None:  # its inputs against the folder's, before the fit
        check_output(out, "identify", friction_sweep_inputs(config, pairs))
    report_stage("fitting the friction curve")
    ident = identify_friction_sweep(config, pairs)
    fit = ident.result
    report_stage("writing files and figures")
    folder = ident.save(out)
    js = fit.to_json()
    _table(f"ema identify --friction-sweep · {fit.data.source}", js["parameters"],
           fit.data.truth)
    for w in fit.warnings:
        err_console.print(f"[yellow]warning:[/] {w}")
    sel = js["selection"]
    console.print(f"law: {fit.chosen}: {sel['why']} ({sel['rule']})")
    for k, v in js["differences_neg_minus_pos"].items():
        console.print(f"  {k}: {v['value']:+.4g} [{v['ci95'][0]:+.4g}, {v['ci95'][1]:+.4g}]"
                      + ("  (0 inside)" if v["zero_inside"] else ""))
    if fit.adequacy is not None:
        console.print(fit.adequacy.line())
    console.print(f"speeds in {fit.data.speed_unit}, friction in {fit.data.force_unit}; "
                  f"symmetric LuGre residual std {js['cost']['residual_std_nm']:.4g}; sigma0 "
                  f"is not identifiable at constant speed; {fit.wall_time_s:.2f} s -> {folder}")
