"""`ema duty`'s outputs: the metrics and trace tables, the temperature and torque-speed
figures, duty.md and duty.json, trace.parquet. Takes a result and writes; never simulates."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.figure import Figure

from ema_cli.report.figures import legend_outside, subplots
from ema_cli.report.markdown import md_table
from ema_cli.report.rundir import manifest, write_figure, write_json, write_text
from ema_cli.units import RPM, ZERO_CELSIUS, fmt_num, from_si

EDGE = {"winding_temperature": "degC", "housing_temperature": "degC",
        "time_above_limit": "s", "peak_current": "A", "rms_current": "A",
        "peak_torque": "N*m", "rms_torque": "N*m", "envelope_use": "%", "l10_life": "h",
        "insulation_life_used": "%", "energy": "Wh"}
"""The unit each duty metric is shown in (``units.UNITS``)."""
LABELLED_SEGMENTS = 12  # segments named on the temperature figure, at most [-]
METHOD_WORDS = {"whole": "simulated whole", "average": "cycle average",
                "cycle": "cycle by cycle"}


def _edge(metric: str, si: float) -> float:
    return from_si(si, EDGE[metric]) if math.isfinite(si) else si


def metrics_frame(res: Any) -> Any:
    """One row per duty metric: its value in the edge unit, the SI value, whether measured or
    only bounded (lower, upper), its limit and result (when it has a limit), note, reason."""
    import pandas as pd

    judged = {v.metric: v for v in res.verdicts}
    rows = []
    for m in res.run.measurements:
        v = judged.get(m.metric)
        lo, hi = (m.value, m.value) if m.measured else (m.lower, m.upper)
        rows.append({"metric": m.metric, "value": _edge(m.metric, m.value),
                     "unit": EDGE[m.metric], "value_si": m.value, "si_unit": m.si_unit,
                     "measured": m.measured, "lower": _edge(m.metric, lo),
                     "upper": _edge(m.metric, hi),
                     "min": None if v is None else v.min, "max": None if v is None else v.max,
                     "limit_unit": None if v is None else v.unit,
                     "result": "" if v is None else v.result, "note": m.note,
                     "reason": m.reason})
    return pd.DataFrame(rows)


def trace_frame(res: Any) -> Any:
    """The thermal trace in edge units (degC, W), one row per interval."""
    import pandas as pd

    tr = res.run.thermal.trace
    labels = [res.expanded.blocks[b].label for b in tr.block]
    return pd.DataFrame({
        "t_s": np.asarray(tr.t), "winding_c": np.asarray(tr.t_w) - ZERO_CELSIUS,
        "winding_peak_c": np.asarray(tr.peak) - ZERO_CELSIUS,
        "housing_c": np.asarray(tr.t_h) - ZERO_CELSIUS,
        "ambient_c": np.asarray(tr.ambient) - ZERO_CELSIUS,
        "copper_w": np.asarray(tr.p_cu), "housing_loss_w": np.asarray(tr.p_h),
        "segment": labels})


def _time_axis(t_end: float) -> tuple[float, str]:
    if t_end > 3 * 3600:
        return 3600.0, "h"
    if t_end > 180:
        return 60.0, "min"
    return 1.0, "s"


def temperature_figure(res: Any) -> Figure:
    """Winding (its cycle mean and peak) and housing temperature over the profile, the ambient
    and the winding's limit; the segments shaded; the full-resolution reference when run."""
    df = trace_frame(res)
    scale, unit = _time_axis(float(df["t_s"].iloc[-1]) if len(df) else 1.0)
    fig, ax = subplots(figsize=(9.5, 5.2))
    t = np.concatenate([[0.0], df["t_s"].to_numpy()]) / scale
    t0 = res.run.thermal.trace
    first = res.expanded.blocks[res.expanded.order[0]].ambient_k - ZERO_CELSIUS
    ax.plot(t, np.concatenate([[first], df["winding_peak_c"]]), color="C3", lw=1.0,
            label="winding, peak")
    ax.plot(t, np.concatenate([[first], df["winding_c"]]), color="C1", lw=1.4,
            label="winding")
    ax.plot(t, np.concatenate([[first], df["housing_c"]]), color="C0", lw=1.4, label="housing")
    ax.plot(t, np.concatenate([[first], df["ambient_c"]]), color="0.4", lw=1.0, ls=":",
            label="ambient")
    lim = res.limits.winding_k - ZERO_CELSIUS
    ax.axhline(lim, color="k", ls="--", lw=1.2,
               label=f"winding limit {lim:g} degC ({res.limits.class_name})"
               if abs(res.limits.winding_k - res.limits.class_k) < 1e-9
               else f"winding limit {lim:g} degC")
    if res.reference is not None:
        r = res.reference
        ax.plot(r.t / scale, r.t_w - ZERO_CELSIUS, color="k", lw=0.6, alpha=0.6,
                label="winding, full resolution")
    start = 0.0
    labels = len(res.expanded.order) <= LABELLED_SEGMENTS
    for k, bi in enumerate(res.expanded.order):
        b = res.expanded.blocks[bi]
        if k % 2 == 1:
            ax.axvspan(start / scale, (start + b.duration) / scale, color="0.93", lw=0)
        if labels:
            ax.text(start / scale, 0.98, f" {b.label}", transform=ax.get_xaxis_transform(),
                    rotation=90, va="top", ha="left", fontsize=7, color="0.35")
        start += b.duration
    del t0
    ax.set_xlabel(f"time [{unit}]")
    ax.set_ylabel("temperature [degC]")
    ax.set_title(f"{res.title}: winding and housing temperature "
                 f"(peak {res.run.thermal.peak_w - ZERO_CELSIUS:.1f} degC)")
    ax.grid(True, alpha=0.3)
    legend_outside(ax)
    fig.tight_layout()
    return fig


def envelope_figure(res: Any) -> Figure:
    """The operating points (motor speed, motor torque) of every block against the drive's
    torque-speed envelope at the cold and the hot winding resistance, and the continuous
    (thermal) torque at the profile's ambient and the winding limit: the whole envelope on the
    left, the operating points' region on the right."""
    from ema_cli.model.drive import torque_envelope
    from ema_cli.model.thermal import resistance_nb

    p = res.run.params
    fig, axes = subplots(1, 2, figsize=(12.5, 5.4))
    pts = []
    for run in res.run.runs:
        xy = [run.transient[0].points] + ([run.cycle[0].points] if run.cycle is not None
                                          else [])
        pts.append(np.vstack(xy))
    w_pts = max((float(np.max(np.abs(xy[:, 0]))) for xy in pts if len(xy)), default=0.0)
    t_pts = max((float(np.max(np.abs(xy[:, 1]))) for xy in pts if len(xy)), default=0.0)
    tc = p["Kt"] * res.run.continuous_current
    amb = res.expanded.blocks[res.expanded.order[0]].ambient_k
    armature = p["drive"] == 0.0
    w_full = 1.1 * max(w_pts, p["sat2"] / p["Ke"] if armature and math.isfinite(p["sat2"])
                       else w_pts, 1e-9)
    t_full = 1.1 * max(t_pts, tc, p["Kt"] * p["sat3"] if armature and math.isfinite(p["sat3"])
                       else p["amp_limit"] / p["m"] if math.isfinite(p["amp_limit"]) else 0.0)
    zoom = (1.3 * max(w_pts, 1e-9), 1.3 * max(t_pts, tc, 1e-9))
    for ax, (w_top, t_top) in zip(axes, ((w_full, t_full), zoom), strict=True):
        for k, (run, xy) in enumerate(zip(res.run.runs, pts, strict=True)):
            ax.plot(xy[:, 0] / RPM, xy[:, 1], ".", ms=2, color=f"C{k % 10}",
                    label=res.expanded.blocks[run.block].label)
        w = np.linspace(-w_top, w_top, 801)
        for temp, ls, word in ((amb, "-", "cold"), (res.run.thermal.peak_w, "--", "hot")):
            q = dict(p)
            q["R"] = resistance_nb.py_func(p["R"], p["alpha_cu"], temp, p["T_ref"])
            for sign in (1.0, -1.0):  # upper and lower halves: motoring and braking quadrants
                env = torque_envelope(q, w, np.full(w.shape, sign))
                ax.plot(w / RPM, sign * env, color="k", ls=ls, lw=1.1,
                        label=f"drive envelope, {word} winding ({temp - ZERO_CELSIUS:.0f} degC)"
                        if sign > 0 else None)
        ax.axhline(tc, color="C3", ls=":", lw=1.2,
                   label=f"continuous torque {tc:.3g} N*m ({res.run.continuous_current:.3g} A)")
        ax.axhline(-tc, color="C3", ls=":", lw=1.2)
        ax.set_xlim(-w_top / RPM, w_top / RPM)
        ax.set_ylim(-t_top, t_top)
        ax.set_xlabel("motor speed [rpm]")
        ax.set_ylabel("motor torque [N*m]")
        ax.grid(True, alpha=0.3)
    axes[0].set_title("the whole envelope")
    axes[1].set_title("the operating points")
    use = 100.0 * res.run.stats.envelope_use
    fig.suptitle(f"{res.title}: operating points against the drive's torque-speed "
                 f"envelope (at most {use:.3g} % of it used)")
    legend_outside(axes[1])
    fig.tight_layout()
    return fig


def summary(res: Any) -> dict[str, Any]:
    """duty.json's body (edge units, named)."""
    from ema_cli.acceptance.duty.hot import as_dict
    from ema_cli.acceptance.duty.run import describe

    th, st = res.run.thermal, res.run.stats
    out: dict[str, Any] = {
        "profile": res.profile.name, "verdict": res.verdict, "exit_code": res.exit_code,
        "axis": res.axis, "dt_s": res.dt, "duration_s": res.expanded.duration,
        "thermal_element": res.thermal_source,
        "winding_limit_c": res.limits.winding_k - ZERO_CELSIUS,
        "insulation": res.limits.class_name,
        "peak_winding_c": th.peak_w - ZERO_CELSIUS, "peak_housing_c": th.peak_h - ZERO_CELSIUS,
        "error_estimate_k": {**th.errors, "total": th.error_k},
        "continuous_current_a": res.run.continuous_current,
        "current_margin": st.margin,
        "equivalent_load": st.equivalent_load, "revolutions_per_pass": st.revolutions,
        "l10_revolutions": st.l10_revs,
        "energy_wh": {"electrical": st.energy / 3600, "copper": st.copper_j / 3600,
                      "housing_losses": st.housing_j / 3600,
                      "motor_mechanical": st.mechanical_j / 3600},
        "metrics": metrics_frame(res).to_dict(orient="records"),
        "blocks": [{**d, **{k: v for k, v in row.items() if k not in d}}
                   for d, row in zip(describe(res.expanded), _block_rows(res), strict=True)],
        "timings_s": {**res.run.timings, "total": res.wall_time_s},
        "notes": res.run.notes,
    }
    if res.run.hot is not None:
        out["hot_actuator"] = as_dict(res.run.hot)
    if res.reference is not None:
        r = res.reference
        out["full_resolution"] = {"peak_winding_c": r.peak_w - ZERO_CELSIUS,
                                  "multirate_minus_reference_k": th.peak_w - r.peak_w,
                                  "kernel_wall_s": r.wall_s, "steps": r.steps}
    return out


def _block_rows(res: Any) -> list[dict[str, Any]]:
    by = {row["block"]: row for row in res.run.stats.per_block}
    out = []
    for bi in range(len(res.expanded.blocks)):
        row = by.get(bi, {})
        out.append({"method": METHOD_WORDS.get(res.run.thermal.methods.get(bi, "whole"), ""),
                    "rms_current_a": row.get("rms_current"),
                    "peak_current_a": row.get("peak_cur"),
                    "cycle_change": row.get("change")})
    return out


def duty_markdown(res: Any) -> str:
    """duty.md: the verdict first, then every metric, the blocks, the hot actuator, the
    method and its error estimate."""
    th, st = res.run.thermal, res.run.stats
    lines = [f"# {res.title}", "", f"**{res.verdict}** - {res.profile.description.strip()}",
             "", f"Profile: {res.expanded.duration:,.0f} s ({res.expanded.duration / 3600:.2f} h) "
             f"in {len(res.expanded.order)} segment(s), {len(res.expanded.blocks)} distinct; "
             f"{res.axis} axis; thermal element: {res.thermal_source}.", "",
             "## Metrics", ""]
    df = metrics_frame(res)
    rows = [{"metric": r.metric, "value": fmt_num(r.value, r.unit),
             "limit": _limit_text(r), "result": r.result or "-",
             "note": "; ".join(x for x in (r.note, r.reason) if x)} for r in df.itertuples()]
    lines += [_md(rows), ""]
    lines += [f"Continuous current at {_amb(res):g} degC ambient and the winding limit "
              f"({res.limits.winding_k - ZERO_CELSIUS:g} degC): "
              f"{res.run.continuous_current:.4g} A. Current margin: every current could be "
              f"{st.margin:.3g} times larger (the motion unchanged) before the winding reaches "
              "its limit.", "",
              f"Equivalent load (mean cubic over the travel): {st.equivalent_load:.4g} "
              f"{'N*m' if res.axis == 'rotary' else 'N'}; {st.revolutions:.4g} revolutions "
              f"per pass; L10 {st.l10_revs:.4g} revolutions = "
              f"{st.l10_s / 3600:.4g} h of this profile.", "",
              f"Energy per pass: {st.energy / 3600:.4g} Wh drawn (copper "
              f"{st.copper_j / 3600:.4g} Wh, friction and iron {st.housing_j / 3600:.4g} Wh, "
              f"motor shaft {st.mechanical_j / 3600:.4g} Wh).", "", "## Segments", ""]
    brows = []
    for d, extra in zip(res.run.stats.per_block, _block_rows(res), strict=False):
        brows.append({"segment": d["label"], "runs": d["runs"],
                      "duration": fmt_num(d["duration_s"], "s"),
                      "method": METHOD_WORDS.get(res.run.thermal.methods.get(d["block"], ""), ""),
                      "rms current": fmt_num(d["rms_current"], "A"),
                      "peak current": fmt_num(d["peak_cur"], "A"),
                      "cycle change": fmt_num(d["change"])})
        del extra
    lines += [_md(brows), ""]
    if res.run.hot is not None:
        from ema_cli.acceptance.duty.hot import as_dict

        h = as_dict(res.run.hot)
        bw, rt = h["bandwidth_hz"], h["no_load_rate_deg_s"]
        lines += ["## The hot actuator", "",
                  f"Winding resistance {h['resistance_ohm']['cold']:.4g} ohm at "
                  f"{h['temperature_c']['cold']:.1f} degC, {h['resistance_ohm']['hot']:.4g} "
                  f"ohm at the peak {h['temperature_c']['hot']:.1f} degC.", "",
                  _md([{"": "bandwidth (1 deg) [Hz]", "cold": fmt_num(bw["cold"]["value"]),
                             "hot": fmt_num(bw["hot"]["value"])},
                            {"": "no-load rate (40 deg step) [deg/s]",
                             "cold": fmt_num(rt["cold"]["value"]),
                             "hot": fmt_num(rt["hot"]["value"])}]), ""]
    lines += ["## Method", "",
              "Each distinct segment's mechanics is simulated once (from rest at its start, "
              "settling, then two periods), at the winding resistance of the ambient and of the "
              "limit; the thermal network is integrated exactly over the profile (matrix "
              "exponential per bin or chunk), a cycle averaged when its period is at most "
              "5 % of the winding's time constant, else cycle by cycle "
              "(docs/duty.md). Error estimate of the winding peak: "
              + ", ".join(f"{k} {v:.2g} K" for k, v in th.errors.items()) + ".", ""]
    if res.reference is not None:
        r = res.reference
        lines += [f"Full-resolution reference: peak {r.peak_w - ZERO_CELSIUS:.3f} degC "
                  f"(multirate - reference {th.peak_w - r.peak_w:+.3f} K), {r.steps:,} steps "
                  f"in {r.wall_s:.1f} s.", ""]
    for n in res.run.notes:
        lines.append(f"- note: {n}")
    return "\n".join(lines) + "\n"


def _md(rows: list[dict[str, Any]]) -> str:
    import pandas as pd

    return md_table(pd.DataFrame(rows))


def _amb(res: Any) -> float:
    return res.expanded.blocks[res.expanded.order[0]].ambient_k - ZERO_CELSIUS


def _limit_text(r: Any) -> str:
    if not isinstance(r.limit_unit, str) or not r.limit_unit:
        return "-"
    parts = []
    if r.min is not None and not (isinstance(r.min, float) and math.isnan(r.min)):
        parts.append(f">= {r.min:g}")
    if r.max is not None and not (isinstance(r.max, float) and math.isnan(r.max)):
        parts.append(f"<= {r.max:g}")
    return " and ".join(parts) + f" {r.limit_unit}"


def write_duty(folder: Path, res: Any) -> list[str]:
    """Write the folder -> the names written."""
    import yaml

    from ema_cli.files import atomic_write

    names = ["profile.resolved.yaml", "duty.json", "duty.md", "temperature.png",
             "envelope.png", "trace.parquet"]
    prof = res.profile.model_dump(mode="json", exclude={"segments"})
    prof["segments"] = [_segment_doc(s) for s in res.profile.segments]
    write_text(folder / "profile.resolved.yaml", yaml.safe_dump(prof, sort_keys=False))
    write_json(folder / "duty.json", summary(res))
    write_text(folder / "duty.md", duty_markdown(res))
    write_figure(folder / "temperature.png", temperature_figure(res))
    write_figure(folder / "envelope.png", envelope_figure(res))
    df = trace_frame(res)
    atomic_write(folder / "trace.parquet", lambda p: df.to_parquet(p, index=False))
    if res.reference is not None:
        import pandas as pd

        r = res.reference
        ref = pd.DataFrame({"t_s": r.t, "winding_c": r.t_w - ZERO_CELSIUS,
                            "housing_c": r.t_h - ZERO_CELSIUS, "current_a": r.current})
        atomic_write(folder / "reference.parquet", lambda p: ref.to_parquet(p, index=False))
        names.append("reference.parquet")
    names.append("manifest.json")
    write_json(folder / "manifest.json", manifest(
        "duty", outputs=names, source=res.source, seed=None,
        deterministic="no random numbers: the same inputs give the same results",
        verdict=res.verdict, exit_code=res.exit_code, parameters_si=res.run.params,
        overrides=[[k, v] for k, v in res.overrides], dt_s=res.dt,
        timings_s={**res.run.timings, "total": res.wall_time_s}))
    return names


def _segment_doc(s: Any) -> dict[str, Any]:
    """A validated segment back in the profile's ``{kind: {...}}`` form."""
    body = s.model_dump(mode="json", exclude={"kind"})
    if s.kind == "repeat":
        body["segments"] = [_segment_doc(x) for x in s.segments]
    return {s.kind: body}
