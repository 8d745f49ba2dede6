"""``ema freqresp``: freqresp.csv, freqresp.json, bode.png and summary.md."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.figure import Figure

from ema_cli.analysis.freqresp import LIMIT_NAMES
from ema_cli.report.figures import subplots
from ema_cli.report.markdown import md_cell
from ema_cli.report.rundir import manifest, write_csv, write_figure, write_json, write_text

OUTPUT_FILES = ("config.resolved.yaml", "freqresp.csv", "freqresp.json", "bode.png",
                "summary.md", "manifest.json")


GAIN_TOL_DB = 0.05  # gain curves closer than this everywhere are reported as coinciding [dB]
PHASE_TOL_DEG = 0.5  # phase curves closer than this everywhere coincide [deg]


def bode_figure(res: Any, title: str) -> Figure:
    """Gain and phase of the load angle vs frequency, one curve per amplitude (distinct line
    styles and markers, so that curves lying on each other stay visible; circles where a limit
    was reached), the linear model in black; THD below. The legend, outside the axes, says
    which curves coincide (computed, within GAIN_TOL_DB / PHASE_TOL_DEG)."""
    from ema_cli.report.figures import coincidence_note, coinciding, curve_style, legend_outside

    fig, axes = subplots(3, 1, figsize=(11, 10), sharex=True)
    f = res.f_hz
    n_curves = len(res.amplitudes) + 1
    lin_g = 20 * np.log10(np.abs(res.linear))
    lin_ph = np.degrees(np.unwrap(np.angle(res.linear)))
    gains, phases = {}, {}
    for k, a in enumerate(res.amplitudes):
        blk = res.block(a)
        g = np.array([p.gain_db for p in blk])
        ph = np.array([p.phase_deg for p in blk])
        thd = np.array([p.thd_pct for p in blk])
        lim = np.array([bool(p.limits) for p in blk])
        style = curve_style(k, len(f), n_curves)
        label = f"{a:g} deg"
        gains[label], phases[label] = g, ph
        axes[0].semilogx(f, g, label=label, **style)
        axes[1].semilogx(f, ph, **style)
        axes[2].loglog(f, np.maximum(thd, 1e-6), **style)
        if lim.any():
            axes[0].semilogx(f[lim], g[lim], "o", color=style["color"], ms=9, mfc="none",
                             lw=0)
    gains["linear model"], phases["linear model"] = lin_g, lin_ph
    lin = {**curve_style(len(res.amplitudes), len(f), n_curves), "color": "k", "marker": "x",
           "ls": (0, (2, 2)), "lw": 1.0}
    axes[0].semilogx(f, lin_g, label="linear model", **lin)
    axes[1].semilogx(f, lin_ph, **lin)
    axes[0].axhline(-3, color="0.5", lw=0.8, ls=":")
    axes[1].axhline(-90, color="0.5", lw=0.8, ls=":")
    axes[0].set_ylabel("gain theta_L/theta_ref [dB]")
    axes[1].set_ylabel("phase [deg]")
    axes[2].set_ylabel("harmonic distortion [%]")
    axes[2].set_xlabel("frequency [Hz]")
    axes[0].set_title("Gain (large circles: a limit reached; dotted: -3 dB)")
    axes[1].set_title("Phase (dotted: -90 deg)")
    axes[2].set_title("Total harmonic distortion of the load angle (harmonics 2-10)")
    notes = [f"{what}: {n}" for what, n in (
        ("gain", coincidence_note(coinciding(gains, GAIN_TOL_DB), GAIN_TOL_DB, "dB")),
        ("phase", coincidence_note(coinciding(phases, PHASE_TOL_DEG), PHASE_TOL_DEG, "deg")))
        if n]
    legend_outside(axes[0], title="amplitude")
    if notes:
        import textwrap

        text = "curves on each other\n(markers staggered):\n" + "\n".join(
            textwrap.fill(n, 26) for n in notes)
        axes[1].text(1.01, 1.0, text, transform=axes[1].transAxes, va="top", ha="left",
                     fontsize=8, bbox={"boxstyle": "round", "fc": "0.95", "ec": "0.7"})
    for a in axes:
        a.grid(True, which="both", alpha=0.3)
    fig.suptitle(title)
    fig.subplots_adjust(left=0.08, right=0.79, bottom=0.06, top=0.92, hspace=0.3)
    return fig

def _onsets(onsets: Mapping[str, float]) -> str:
    return ", ".join(f"{k} ({v:.3g})" for k, v in onsets.items()) or "none"


def _limit(name: str | None) -> str:
    return "none (no limit reached up to the bandwidth)" if name is None else (
        f"{name}, {LIMIT_NAMES[name]}")


def summary_markdown(res: Any, summary: Mapping[str, Any]) -> str:
    """summary.md: the per-amplitude table and the bandwidth verdict."""
    lines = [f"# {res.title}", "", "| amplitude [deg] | -3 dB [Hz] | -90 deg [Hz] | peak [dB] | "
             "at [Hz] | max THD [%] | limits reached (from [Hz]) | binding limit |",
             "|---|---|---|---|---|---|---|---|"]
    for r in summary["amplitudes"]:
        lines.append(f"| {md_cell(r['amplitude_deg'])} | {md_cell(r['f_3db_hz'])} | "
                     f"{md_cell(r['f_minus90_hz'])} | {md_cell(r['peak_db'])} | "
                     f"{md_cell(r['f_peak_hz'])}"
                     f" | {md_cell(r['max_thd_pct'])} | {_onsets(r['limit_onset_hz'])} | "
                     f"{r['binding_limit'] or 'none'} |")
    lin = summary["linear"]
    lines += ["", f"Linear model: -3 dB at {md_cell(lin['f_3db_hz'])} Hz."]
    est = lin["limit_at_bandwidth"]
    if est is not None:
        amps = ", ".join(f"{LIMIT_NAMES[k]} from {md_cell(v)} deg"
                         for k, v in est["amplitude_deg"].items())
        lines.append(f"At that frequency the linear model reaches {amps}: "
                     f"{est['first_limit']} binds first.")
    lines.append("")
    drop = summary["bandwidth_drop"]
    if drop is None:
        lines.append("The bandwidth stays within 10 % of the smallest amplitude's at every "
                     "amplitude.")
    else:
        lines.append(f"The bandwidth first drops more than 10 % below the small-signal "
                     f"{md_cell(drop['small_signal_f_3db_hz'])} Hz at "
                     f"{md_cell(drop['amplitude_deg'])} deg ({md_cell(drop['f_3db_hz'])} Hz, "
                     f"{md_cell(drop['drop_pct'])} % lower); the "
                     f"binding limit is {_limit(drop['binding_limit'])}.")
    return "\n".join(lines) + "\n\n![Bode plot](bode.png)\n"


def write_freqresp(folder: Path, config_yaml: str, res: Any,
                   manifest_fields: Mapping[str, Any]) -> list[str]:
    """Write the folder -> the names written."""
    summary = res.summary
    write_text(folder / "config.resolved.yaml", config_yaml)
    write_csv(folder / "freqresp.csv", res.to_pandas(), float_format="%.9g")
    write_json(folder / "freqresp.json", summary)
    write_figure(folder / "bode.png", bode_figure(res, res.title))
    write_text(folder / "summary.md", summary_markdown(res, summary))
    write_json(folder / "manifest.json", manifest("freqresp", outputs=list(OUTPUT_FILES),
                                                  **manifest_fields))
    return list(OUTPUT_FILES)
