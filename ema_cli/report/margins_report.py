"""``ema margins``: open-loop Bode and Nichols plots of the linear limit, margins.json."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.figure import Figure

from ema_cli.analysis.linear import Margins
from ema_cli.report.figures import subplots
from ema_cli.report.rundir import manifest, write_columns, write_json, write_text
from ema_cli.vocab import margin_text

OUTPUT_FILES = ("config.resolved.yaml", "margins.json", "loops.csv", "margins.png",
                "manifest.json")


def margins_figure(f_hz: np.ndarray, loops: Mapping[str, np.ndarray],
                   result: Mapping[str, Margins], title: str) -> Figure:
    """Bode magnitude and phase of each open loop L(j w) (left), Nichols chart (right), with
    the crossovers and margins marked."""
    fig, axes = subplots(2, 2, figsize=(13, 7.5))
    mag_ax, nic_ax = axes[0, 0], axes[0, 1]
    ph_ax = axes[1, 0]
    text_ax = axes[1, 1]
    text_ax.axis("off")
    lines = ["Margins (loop broken at its feedback, the other closed)", ""]
    for loop, m in result.items():
        gm = (f"{margin_text(m.gm_db, 'gain_margin')} at {m.f_gm_hz:.3g} Hz"
              if math.isfinite(m.gm_db) else margin_text(m.gm_db, "gain_margin"))
        pm = (f"{margin_text(m.pm_deg, 'phase_margin')} at {m.f_pm_hz:.3g} Hz"
              if math.isfinite(m.pm_deg) else margin_text(m.pm_deg, "phase_margin"))
        lines += [f"{loop} loop", f"   gain margin   {gm}", f"   phase margin  {pm}", ""]
    text_ax.text(0.02, 0.95, "\n".join(lines), va="top", family="monospace", fontsize=10,
                 transform=text_ax.transAxes)
    for k, (loop, L) in enumerate(loops.items()):
        color = f"C{k}"
        mag = 20 * np.log10(np.abs(L))
        phase = np.degrees(np.unwrap(np.angle(L)))
        m = result[loop]
        label = (f"{loop} loop: GM {margin_text(m.gm_db, 'gain_margin')}, "
                 f"PM {margin_text(m.pm_deg, 'phase_margin')}")
        mag_ax.semilogx(f_hz, mag, color=color, label=label)
        ph_ax.semilogx(f_hz, phase, color=color)
        nic_ax.plot(phase, mag, color=color, label=f"{loop} loop")
        if math.isfinite(m.f_pm_hz):
            mag_ax.axvline(m.f_pm_hz, color=color, ls=":", lw=0.8)
            ph_ax.axvline(m.f_pm_hz, color=color, ls=":", lw=0.8)
        if math.isfinite(m.f_gm_hz):
            mag_ax.axvline(m.f_gm_hz, color=color, ls="--", lw=0.8)
            ph_ax.axvline(m.f_gm_hz, color=color, ls="--", lw=0.8)
    mag_ax.axhline(0, color="0.4", lw=0.8)
    ph_ax.axhline(-180, color="0.4", lw=0.8)
    nic_ax.plot([-180], [0], "kx", ms=8, label="critical point (-180 deg, 0 dB)")
    mag_ax.set_ylabel("|L| [dB]")
    mag_ax.set_title("Open-loop gain (dotted: gain crossover, dashed: phase crossover)")
    ph_ax.set_ylabel("phase of L [deg]")
    ph_ax.set_xlabel("frequency [Hz]")
    ph_ax.set_title("Open-loop phase")
    nic_ax.set_xlabel("phase of L [deg]")
    nic_ax.set_ylabel("|L| [dB]")
    nic_ax.set_title("Nichols chart")
    mag_ax.legend(fontsize=8, loc="lower left")
    nic_ax.legend(fontsize=8, loc="best")
    for a in (mag_ax, ph_ax, nic_ax):
        a.grid(True, alpha=0.3, which="both")
    fig.suptitle(title)
    fig.subplots_adjust(left=0.07, right=0.98, bottom=0.08, top=0.89, wspace=0.22, hspace=0.3)
    return fig


def write_margins(folder: Path, config_yaml: str, f_hz: np.ndarray,
                  loops: Mapping[str, np.ndarray], result: Mapping[str, Margins], title: str,
                  manifest_fields: Mapping[str, Any], notes: Sequence[str] = ()) -> list[str]:
    """Write the folder -> the names written."""
    from ema_cli.report.rundir import write_figure

    write_text(folder / "config.resolved.yaml", config_yaml)
    write_json(folder / "margins.json", {**{k: m.to_json() for k, m in result.items()},
                                         "notes": list(notes)})
    cols: dict[str, Any] = {"f_hz": f_hz}
    for loop, L in loops.items():
        cols[f"{loop}_gain_db"] = 20 * np.log10(np.abs(L))
        cols[f"{loop}_phase_deg"] = np.degrees(np.unwrap(np.angle(L)))
    write_columns(folder / "loops.csv", cols)
    write_figure(folder / "margins.png", margins_figure(f_hz, loops, result, title))
    write_json(folder / "manifest.json", manifest("margins", outputs=list(OUTPUT_FILES),
                                                  **manifest_fields))
    return list(OUTPUT_FILES)
