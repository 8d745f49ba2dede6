"""`ema freqresp`: sinestream frequency response at several amplitudes (nonlinear)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from ema_cli.cli.common import (
    as_options,
    check_number,
    console,
    handle_errors,
    out_help,
    parse_assignments,
)
from ema_cli.cli.output import print_table
from ema_cli.errors import EmaError
from ema_cli.progress import report as report_stage
from ema_cli.units import fmt_num


def parse_amplitudes(text: str | None) -> list[float]:
    """``--amplitudes 0.1,1,5`` (commas or spaces) -> degrees, each finite and > 0."""
    if text is None:
        return [0.1, 1.0, 5.0]
    items = [t for t in text.replace(",", " ").split() if t]
    try:
        values = [float(t) for t in items]
    except ValueError:
        raise EmaError(f"--amplitudes expects numbers in deg, e.g. 0.1,1,5; got {text!r}") from None
    if not values:
        raise EmaError("--amplitudes expects at least one amplitude [deg]")
    for v in values:
        check_number(v, "--amplitudes", low=0.0, low_open=True)
    return values


@handle_errors
def freqresp_cmd(
    config: Annotated[Path | None, typer.Argument(
        help="YAML study config (default: the bundled defaults).")] = None,
    amplitudes: Annotated[str | None, typer.Option(
        "--amplitudes", help="Reference amplitudes [deg], comma-separated (default 0.1,1,5).")
    ] = None,
    f_min: Annotated[float, typer.Option("--f-min", help="Lowest frequency [Hz].")] = 0.5,
    f_max: Annotated[float, typer.Option("--f-max", help="Highest frequency [Hz].")] = 50.0,
    n: Annotated[int, typer.Option("--n", help="Log-spaced frequencies.")] = 30,
    nl: Annotated[list[str] | None, typer.Option(
        "--nl", help="Nonlinearity NAME=VALUE in the units of `ema locations`; repeatable.")
    ] = None,
    set_: Annotated[list[str] | None, typer.Option(
        "--set", help="Override a config value by dotted path; repeatable.")] = None,
    out: Annotated[Path | None, typer.Option("--out", help=out_help())] = None,
) -> None:
    """Sinestream frequency response of the load angle at each amplitude: gain, phase, harmonic
    distortion and the limits reached, with the -3 dB bandwidth and -90 deg frequency per
    amplitude; writes freqresp.csv, freqresp.json, bode.png and summary.md."""
    from ema_cli.api.freqresp import freqresp
    from ema_cli.report.rundir import check_output

    amps = parse_amplitudes(amplitudes)
    check_number(f_min, "--f-min", low=0.0, low_open=True)
    check_number(f_max, "--f-max", low=0.0, low_open=True)
    check_number(n, "--n", low=2, high=2000)
    check_output(out, "freqresp")  # a file, a folder of another command: refused at once
    pairs, nls = parse_assignments(set_, "--set"), dict(parse_assignments(nl, "--nl"))
    if out is not None:  # its inputs against the folder's, before the sinestreams
        from ema_cli.api.freqresp import freqresp_inputs

        check_output(out, "freqresp", as_options(
            lambda: freqresp_inputs(config, pairs, amplitudes_deg=amps, f_min_hz=f_min,
                                    f_max_hz=f_max, n=n, nl=nls),
            f_min_hz="--f-min", f_max_hz="--f-max", amplitudes_deg="--amplitudes"))
    res = as_options(lambda: freqresp(config, pairs, amplitudes_deg=amps, f_min_hz=f_min,
                                      f_max_hz=f_max, n=n, nl=nls),
                     f_min_hz="--f-min", f_max_hz="--f-max", amplitudes_deg="--amplitudes")
    report_stage("writing files and figures")
    folder = res.save(out)
    summary = res.summary
    above = f"not reached below {f_max:g} Hz"
    rows = [(fmt_num(r["amplitude_deg"], "deg"), fmt_num(r["f_3db_hz"], "Hz", nan=above),
             fmt_num(r["f_minus90_hz"], "Hz", nan=above), fmt_num(r["peak_db"], "dB", 3),
             fmt_num(r["max_thd_pct"], "%", 3), ", ".join(r["limits"]) or "none",
             r["binding_limit"] or "none") for r in summary["amplitudes"]]
    print_table(res.title, ("amplitude", "-3 dB", "-90 deg", "peak gain", "max THD",
                            "limits reached", "binding limit"), rows,
                optional=("limits reached",), where="freqresp.json")
    drop = summary["bandwidth_drop"]
    if drop is not None:
        console.print(f"bandwidth drops > 10 % at {drop['amplitude_deg']:g} deg "
                      f"({fmt_num(drop['f_3db_hz'], 'Hz', nan=above)} vs "
                      f"{fmt_num(drop['small_signal_f_3db_hz'], 'Hz', nan=above)}); "
                      f"binding limit: {drop['binding_limit'] or 'none'}")
    est = summary["linear"]["limit_at_bandwidth"]
    if est is not None:
        console.print("linear estimate at the bandwidth ({:.4g} Hz): ".format(est["f_hz"])
                      + ", ".join(f"{k} from {v:.3g} deg"
                                  for k, v in est["amplitude_deg"].items()))
    console.print(f"{len(res.points)} simulations in {res.wall_time_s:.2f} s -> {folder}")
