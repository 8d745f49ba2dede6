"""``ema acceptance``: acceptance.md (PASS/FAIL table), acceptance.csv, one figure per test."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.figure import Figure

from ema_cli.report.figures import subplots
from ema_cli.report.rundir import manifest, write_csv, write_figure, write_json, write_text
from ema_cli.units import DEG, ZERO_CELSIUS, from_si
from ema_cli.vocab import free_play


def _lines(ax: Any, title: str, xlabel: str, ylabel: str) -> None:
    ax.set_title(title)
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.grid(True, which="both", alpha=0.3)


def _limit_line(ax: Any, limit: Any, unit: str, horizontal: bool = True) -> None:
    """Dotted lines at a limit's min/max converted to ``unit``."""
    if limit is None:
        return
    lo, hi = limit.si()
    for v, word in ((lo, "min"), (hi, "max")):
        if math.isfinite(v):
            x = from_si(v, unit)
            (ax.axhline if horizontal else ax.axvline)(x, color="C3", ls=":", lw=1.2,
                                                       label=f"limit ({word}) {x:.4g} {unit}")


def figure_step(run: Any, test: Any, title: str) -> Figure:
    d = run.data
    fig, ax = subplots(1, 1, figsize=(9, 5))
    ax.plot(d["t"], d["ref"] / DEG, "k--", lw=1.2, label="command")
    ax.plot(d["t"], d["load"] / DEG, "C0", lw=1.4, label="load angle")
    a = d["amplitude_deg"]
    ax.axhspan(a * 0.98, a * 1.02, color="C2", alpha=0.15, label="2 % settling band")
    limits = getattr(test, "limits", {}) or {}
    for metric in ("rise_time", "settling_time"):  # time limits: where the step must be by
        lim = limits.get(metric)
        if lim is not None and lim.max is not None:
            t_max = lim.si()[1]
            ax.axvline(t_max, color="C3" if metric == "settling_time" else "C1", ls=":",
                       lw=1.2, label=f"{metric} limit {t_max:.4g} s")
    _lines(ax, f"{title}\n{run.name}: {a:g} deg step", "time [s]", "position [deg]")
    ax.legend(fontsize=8, loc="lower right")
    return fig


class _Bode:
    """The attributes :func:`freqresp_report.bode_figure` reads, from a test's data."""

    def __init__(self, data: Mapping[str, Any]) -> None:
        self.points = data["points"]
        self.amplitudes = data["amplitudes"]
        self.f_hz = data["f_hz"]
        self.linear = data["linear"]

    def block(self, a: float) -> list[Any]:
        return [p for p in self.points if p.amplitude_deg == a]


def figure_frequency_response(run: Any, test: Any, title: str) -> Figure:
    from ema_cli.report.freqresp_report import bode_figure

    fig = bode_figure(_Bode(run.data), f"{title}\n{run.name}: frequency response")
    fig.subplots_adjust(top=0.9)
    ax = fig.axes[0]
    if "bandwidth" in test.limits:
        _limit_line(ax, test.limits["bandwidth"], "Hz", horizontal=False)
        from ema_cli.report.figures import legend_outside

        legend_outside(ax, title="amplitude")
    return fig


def figure_margins(run: Any, test: Any, title: str) -> Figure:
    from ema_cli.report.margins_report import margins_figure

    d = run.data
    return margins_figure(d["f_hz"], d["loops"], d["margins"], f"{title}\n{run.name}: margins")


def figure_threshold(run: Any, test: Any, title: str) -> Figure:
    d = run.data
    amps = np.array(sorted(d["tried"]))
    frac = np.array([d["tried"][a] for a in amps])
    ok = frac >= d["fraction"]
    fig, ax = subplots(1, 1, figsize=(9, 5))
    ax.semilogx(amps / DEG, 100 * frac, "-", color="0.6", lw=0.8)
    ax.semilogx(amps[ok] / DEG, 100 * frac[ok], "o", color="C2", label="followed")
    ax.semilogx(amps[~ok] / DEG, 100 * frac[~ok], "x", color="C3", label="not followed")
    ax.axhline(100 * d["fraction"], color="0.3", ls="--", lw=1,
               label=f"criterion {100 * d['fraction']:g} % within {test.within_s:g} s")
    if math.isfinite(d["value"]):
        ax.axvline(d["value"] / DEG, color="C0", lw=1.2,
                   label=f"threshold {d['value'] / DEG:.4g} deg")
    if "threshold" in test.limits:
        _limit_line(ax, test.limits["threshold"], "deg", horizontal=False)
    _lines(ax, f"{title}\n{run.name}: smallest step followed (search)",
           "step size [deg]", "largest share of the step reached [%]")
    ax.legend(fontsize=8, loc="best")
    return fig


def figure_hysteresis(run: Any, test: Any, title: str) -> Figure:
    d = run.data
    up, down = d["rising"], d["falling"]
    fig, axes = subplots(1, 2, figsize=(13, 5.5))
    for mask, label, color in ((up, "rising command", "C0"), (down, "falling command", "C1")):
        axes[0].plot(d["ref"][mask] / DEG, (d["load"][mask] - d["ref"][mask]) / DEG, ".",
                     ms=1, color=color, label=label)
        axes[1].plot(d["load"][mask] / DEG, (d["motor"][mask] - d["load"][mask]) / DEG, ".",
                     ms=1, color=color, label=label)
    hyst = run.values("hysteresis")[0].value / DEG
    play = run.values("free_play")[0].value / DEG
    _lines(axes[0], f"command -> load loop (width {hyst:.4g} deg)", "command [deg]",
           "load angle - command [deg]")
    _lines(axes[1], f"motor -> load lost motion (free play {free_play(play)})",
           "load angle [deg]", "motor angle / m - load angle [deg]")
    for ax in axes:
        ax.legend(fontsize=8, loc="upper left", markerscale=8)
    fig.suptitle(f"{title}\n{run.name}: slow triangle, last period")
    fig.subplots_adjust(top=0.85, wspace=0.25)
    return fig


def figure_load_deflection(run: Any, test: Any, title: str) -> Figure:
    d = run.data
    fig, ax = subplots(1, 1, figsize=(9, 6))
    ax.plot(d["torque"], d["load"] / DEG, "C0", lw=3.5, alpha=0.45,
            label="load angle (motor locked)")
    T = np.linspace(-test.torque_nm, test.torque_nm, 3)
    for k, (b, side) in enumerate(((d["b_pos"], T >= 0), (d["b_neg"], T <= 0))):
        # drawn over the data, thin and dark: the fit lies on the measured curve
        ax.plot(T[side], (d["slope"] * T[side] + b) / DEG, color="C3", ls="--", lw=1.6,
                marker="o", ms=5, zorder=3, label="fitted lines" if k == 0 else None)
    k = run.values("stiffness")[0].value
    play = run.values("free_play")[0].value / DEG
    _lines(ax, f"{title}\n{run.name}: load deflection, stiffness {k:.4g} N*m/rad, free play "
               f"{free_play(play)}", "load torque [N*m]",
           "load angle [deg]")
    ax.legend(fontsize=8, loc="upper left")
    return fig


def figure_dynamic_stiffness(run: Any, test: Any, title: str) -> Figure:
    d = run.data
    pts = d["points"]
    f = d["f_hz"]
    fig, ax = subplots(1, 1, figsize=(9, 5.5))
    ax.loglog(f, [p.stiffness for p in pts], "o-", color="C0", ms=3, label="simulation")
    ax.loglog(f, 1.0 / np.abs(d["linear"]), "k--", lw=1, label="linear model")
    k = d["k_min"]
    ax.loglog([pts[k].f_hz], [pts[k].stiffness], "s", color="C3", ms=8,
              label=f"minimum {pts[k].stiffness:.4g} N*m/rad at {pts[k].f_hz:.4g} Hz")
    if "dynamic_stiffness" in test.limits:
        _limit_line(ax, test.limits["dynamic_stiffness"], "N*m/rad")
    _lines(ax, f"{title}\n{run.name}: dynamic stiffness |T_load / theta_L|, closed loop",
           "frequency [Hz]", "dynamic stiffness [N*m/rad]")
    ax.legend(fontsize=8, loc="best")
    return fig


def figure_no_load_rate(run: Any, test: Any, title: str) -> Figure:
    d = run.data
    fig, ax = subplots(1, 1, figsize=(9, 5))
    ax.plot(d["t"], d["rate"] / DEG, "C0", lw=1.3, label="load rate")
    if "rate" in test.limits:
        _limit_line(ax, test.limits["rate"], "deg/s")
    _lines(ax, f"{title}\n{run.name}: {d['amplitude_deg']:g} deg step, no load", "time [s]",
           "load rate [deg/s]")
    ax.legend(fontsize=8, loc="best")
    return fig


def figure_duty(run: Any, test: Any, title: str) -> Figure:
    d = run.data
    fig, ax = subplots(1, 1, figsize=(9, 5))
    t = np.asarray(d["t"])
    scale, unit = (3600.0, "h") if len(t) and t[-1] > 3 * 3600 else (
        (60.0, "min") if len(t) and t[-1] > 180 else (1.0, "s"))
    ax.plot(t / scale, np.asarray(d["peak"]) - ZERO_CELSIUS, "C3", lw=1.0,
            label="winding, peak")
    ax.plot(t / scale, np.asarray(d["t_w"]) - ZERO_CELSIUS, "C1", lw=1.4, label="winding")
    ax.plot(t / scale, np.asarray(d["t_h"]) - ZERO_CELSIUS, "C0", lw=1.4, label="housing")
    ax.plot(t / scale, np.asarray(d["ambient"]) - ZERO_CELSIUS, color="0.4", ls=":", lw=1.0,
            label="ambient")
    _limit_line(ax, test.limits.get("winding_temperature"), "degC")
    _lines(ax, f"{title}\n{run.name}: profile {d['profile']}", f"time [{unit}]",
           "temperature [degC]")
    ax.legend(fontsize=8, loc="best")
    return fig


VERDICT_COLORS = {"PASS": "C2", "FAIL": "C3", "INCONCLUSIVE": "C1"}
"""The colour of each result in the figures' verdict box."""


def test_figure(run: Any, test: Any, title: str, verdicts: Sequence[Any] = ()) -> Figure:
    """The figure of one test run (the kind's ``figure`` in :data:`acceptance.kinds.KINDS`),
    with its limits' verdicts (``verdicts``: the rows of this test) in a box at the top right:
    one line per limit, ``FAIL settling_time 0.42 s (<= 0.3 s)`` in red, PASS green,
    INCONCLUSIVE orange; a failed test says FAIL in its title."""
    from ema_cli.acceptance.kinds import KINDS

    rows = [v for v in verdicts if v.test == run.name]
    failed = any(v.result == "FAIL" for v in rows)
    fig = globals()[KINDS[run.kind].figure](run, test, ("FAIL - " if failed else "") + title)
    ax = fig.axes[0]
    lines = [(f"{v.result} {v.metric}" + (f" ({v.condition})" if v.condition else "")
              + f": {fmt_measured(v)} (limit {fmt_limit(v)} {v.unit})", v.result)
             for v in rows[:8]]
    if len(rows) > 8:
        lines.append((f"... {len(rows) - 8} more limits (acceptance.md)", ""))
    for k, (text, result) in enumerate(lines):
        ax.text(0.01, 0.98 - 0.06 * k, text, transform=ax.transAxes, ha="left", va="top",
                fontsize=8, color=VERDICT_COLORS.get(result, "k"), zorder=5,
                fontweight="bold" if result == "FAIL" else "normal",
                bbox={"fc": "white", "ec": "none", "alpha": 0.8, "pad": 1})
    return fig


def fmt_value(v: float | None) -> str:
    """A measured value or limit (4 significant digits; "not measured" for NaN, the infinity
    sign for an infinite value, e.g. a margin without crossover), without its unit."""
    from ema_cli.units import fmt_num

    if v is None:
        return ""
    return fmt_num(v, nan="not measured", inf="∞", neg_inf="-∞")


def fmt_limit(v: Any) -> str:
    parts = []
    if v.min is not None:
        parts.append(f">= {fmt_value(v.min)}")
    if v.max is not None:
        parts.append(f"<= {fmt_value(v.max)}")
    return " and ".join(parts)


def fmt_measured(v: Any, with_unit: bool = True) -> str:
    """A verdict's value in the one vocabulary (``ema_cli.vocab.quantity``): the number when
    measured, else the bound it is known by ("> 2 Hz", "<= 0.0001 s"; "not measured" when
    nothing is known), a margin without crossover in words ("no phase crossover (> 109.4 dB)");
    ``with_unit`` False: without the unit (a table whose column names it)."""
    from ema_cli.vocab import quantity

    return quantity(v.value, v.unit if with_unit else "", metric=v.metric, measured=v.measured,
                    lower=v.lower, upper=v.upper, note=v.note)


RESULT_MD = {"PASS": "PASS", "FAIL": "**FAIL**", "INCONCLUSIVE": "_INCONCLUSIVE_"}
"""The result column of acceptance.md: FAIL bold, INCONCLUSIVE italic."""


def verdict_line(res: Any) -> str:
    """The overall verdict in words (FAIL if any limit fails, else INCONCLUSIVE if any value
    could not be measured against its limit, else PASS)."""
    n = len(res.verdicts)
    if res.verdict == "PASS":
        return "PASS: every limit met"
    if res.verdict == "FAIL":
        more = (f", {len(res.inconclusive)} inconclusive" if res.inconclusive else "")
        return f"FAIL: {len(res.failed)} of {n} limits not met{more}"
    return (f"INCONCLUSIVE: {len(res.inconclusive)} of {n} limits not measured inside the "
            "test's range (see the reasons), none failed")


def acceptance_markdown(res: Any) -> str:
    """acceptance.md: the verdict, the PASS/FAIL/INCONCLUSIVE table, notes and figures."""
    lines = [f"# {res.title}", "", res.spec.description.strip(), "",
             f"Spec: `{res.source}`. **{res.verdict}**{verdict_line(res)[len(res.verdict):]} "
             f"({len(res.runs)} tests, "
             f"{res.wall_time_s:.1f} s).", "",
             "| test | metric | condition | value | limit | unit | result | note |",
             "|---|---|---|---|---|---|---|---|"]
    for v in res.verdicts:
        note = "; ".join(x for x in (v.reason, v.note) if x).replace("|", "\\|")
        shown = fmt_measured(v, with_unit=False)
        lines.append(f"| {v.test} | {v.metric} | {v.condition} | {shown} | "
                     f"{fmt_limit(v)} | {v.unit} | {RESULT_MD[v.result]} | {note} |")
    lines += ["", "A value measured inside the test's range is PASS or FAIL against its limit. "
              "Outside that range the test only bounds it (`> 2`: above 2): the row is PASS or "
              "FAIL when the whole bound lies on one side of the limit, otherwise "
              "INCONCLUSIVE with the setting that widens the range. Overall: FAIL if any row "
              "fails, else INCONCLUSIVE if any row is, else PASS."]
    notes = [(r.name, n) for r in res.runs for n in r.notes]
    if notes:
        lines += ["", "Notes:", ""] + [f"- {name}: {n}" for name, n in notes]
    lines += ["", "## Figures", ""]
    for r in res.runs:
        lines += [f"### {r.name} ({r.kind}, {r.wall_s:.2f} s)", "", f"![{r.name}]({r.name}.png)",
                  ""]
    return "\n".join(lines)


def write_acceptance(folder: Path, spec_yaml: str, res: Any,
                     manifest_fields: Mapping[str, Any]) -> list[str]:
    """Write the folder -> the names written."""
    names = ["spec.resolved.yaml", "acceptance.csv"]
    write_text(folder / "spec.resolved.yaml", spec_yaml)
    write_csv(folder / "acceptance.csv", res.to_pandas(), float_format="%.9g")
    for r in res.runs:
        write_figure(folder / f"{r.name}.png", test_figure(r, res.spec.tests[r.name],
                                                           res.title, res.verdicts))
        names.append(f"{r.name}.png")
    write_text(folder / "acceptance.md", acceptance_markdown(res))
    names += ["acceptance.md", "manifest.json"]
    write_json(folder / "manifest.json", manifest("acceptance", outputs=names,
                                                  **manifest_fields))
    return names
