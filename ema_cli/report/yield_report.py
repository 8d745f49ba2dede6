"""``ema yield``'s files: the checkpoint blocks (written as each block finishes, read back on
resume), and the report: yield.json, samples.parquet, yield.md, the figures (the yield's
convergence; per test, each limit's measured values against the limit), the spec and tolerance
snapshots and the manifest. Writes only; never simulates."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.figure import Figure

from ema_cli.report.figures import subplots
from ema_cli.report.markdown import md_cell, md_table
from ema_cli.report.rundir import manifest, write_figure, write_json, write_text

BLOCKS = "blocks"  # the checkpoint folder inside the output folder
MAX_ECDF_POINTS = 4000  # points of an ECDF drawn at most (evenly thinned) [-]


# ------------------------------------------------------------------------ checkpoints
def write_snapshots(folder: Path, plan: Any) -> None:
    """The run's inputs: the resolved spec and the tolerances (spec.resolved.yaml,
    tolerances.yaml)."""
    import yaml

    write_text(folder / "spec.resolved.yaml",
               yaml.safe_dump(plan.spec.model_dump(mode="json", by_alias=True),
                              sort_keys=False))
    write_text(folder / "tolerances.yaml", yaml.safe_dump(plan.tolerances.to_dict(),
                                                          sort_keys=False))


def write_plan(folder: Path, plan: Any, settings: dict[str, Any]) -> None:
    """The run's inputs, written before the first block: the snapshots and the settings."""
    write_snapshots(folder, plan)
    write_json(folder / BLOCKS / "settings.json", settings)


def write_block(folder: Path, start: int, df: Any, rows: list[Any]) -> None:
    """One finished block of units, atomically (``blocks/units_START.parquet``), and the
    battery's limit rows once."""
    import dataclasses

    from ema_cli.files import atomic_write

    (folder / BLOCKS).mkdir(exist_ok=True)
    if not (folder / BLOCKS / "rows.json").exists():
        write_json(folder / BLOCKS / "rows.json", [dataclasses.asdict(r) for r in rows])
    atomic_write(folder / BLOCKS / f"units_{start:09d}.parquet",
                 lambda p: df.to_parquet(p, index=False))


def read_blocks(folder: Path) -> tuple[Any, list[Any] | None]:
    """The finished blocks of an interrupted run -> (their units, in order, or None; the
    limit rows). Units must run 0..n-1 without a gap (else the blocks after the gap are
    ignored and run again)."""
    import json

    import pandas as pd

    from ema_cli.production.run import Row

    files = sorted((folder / BLOCKS).glob("units_*.parquet"))
    if not files:
        return None, None
    frames = []
    have = 0
    for f in files:
        df = pd.read_parquet(f)
        if len(df) == 0 or int(df["unit"].iloc[0]) != have:
            break
        frames.append(df)
        have += len(df)
    rows_file = folder / BLOCKS / "rows.json"
    rows = ([Row(**r) for r in json.loads(rows_file.read_text())] if rows_file.exists()
            else None)
    return (pd.concat(frames, ignore_index=True) if frames else None), rows


# ------------------------------------------------------------------------------ figures
def _band(results: Any, level: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(n, running yield, interval low, high) along the units, at most ~400 points."""
    from ema_cli.production.stats import clopper_pearson

    ok = np.asarray(results) == "PASS"
    k = np.cumsum(ok)
    n = np.arange(1, len(ok) + 1)
    pick = np.unique(np.round(np.geomspace(1, len(ok), min(len(ok), 400))).astype(int)) - 1
    lo, hi = zip(*(clopper_pearson(int(k[i]), int(n[i]), level) for i in pick), strict=True)
    return n[pick], k[pick] / n[pick], np.array(lo), np.array(hi)


def convergence_figure(res: Any) -> Figure:
    """The yield estimate and its Clopper-Pearson interval as the number of units grows."""
    n, y, lo, hi = _band(res.samples["result"], res.level)
    fig, ax = subplots(figsize=(8, 4.8))
    pct = 100 * res.level
    ax.fill_between(n, 100 * lo, 100 * hi, color="tab:blue", alpha=0.2,
                    label=f"{pct:g} % Clopper-Pearson interval")
    ax.plot(n, 100 * y, color="tab:blue", label="yield estimate (passing units / units)")
    r = res.overall
    ax.axhline(100 * r.value, color="k", lw=0.8, ls=":",
               label=f"final: {100 * r.value:.1f} % of {r.n}")
    ax.set_xscale("log")
    ax.set_xlabel("units sampled [-]")
    ax.set_ylabel("yield [%]")
    ax.set_ylim(-2, 102)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(loc="lower right", fontsize=8)
    ax.set_title(f"{res.title}: convergence ({res.plan.method} sampling, seed "
                 f"{res.plan.seed})", fontsize=10)
    return fig


def distribution_figure(res: Any, test: str) -> Figure:
    """Per limit of ``test``: the ECDF of the measured values across units, the limit drawn,
    the failing units in red, the yield of the limit in the title."""
    rows = [r for r in res.plan.rows if r.test == test]
    ncols = min(len(rows), 3) or 1
    nrows = max(1, math.ceil(len(rows) / ncols))
    fig, axes = subplots(nrows, ncols, figsize=(4.2 * ncols, 3.3 * nrows + 0.6), squeeze=False)
    limits = res.limits
    for ax, r in zip(axes.flat, rows, strict=False):
        v = res.samples[f"{r.label} [{r.unit}]"].to_numpy(dtype=float)
        verdict = res.samples[f"{r.label} result"].to_numpy()
        keep = np.isfinite(v) & (verdict != "INCONCLUSIVE")
        order = np.argsort(v[keep], kind="stable")
        x, fails = v[keep][order], (verdict[keep] == "FAIL")[order]
        p = np.arange(1, len(x) + 1) / max(len(x), 1)
        step = max(1, len(x) // MAX_ECDF_POINTS)
        ax.step(x[::step], p[::step], where="post", color="tab:blue", lw=1.2,
                label="measured (ECDF)")
        if fails.any():
            ax.plot(x[fails], p[fails], "o", ms=2.5, color="tab:red", label="failing units")
        for edge, name in ((r.lo, "min"), (r.hi, "max")):
            if edge is not None:
                ax.axvline(edge, color="tab:red", ls="--", lw=1.2,
                           label=f"limit {name} {edge:g} {r.unit}")
        rate = limits[r.label]
        lo, hi = rate.interval
        what = r.metric + (f" ({r.condition})" if r.condition else "")
        extra = f", {rate.n_inconclusive} inconclusive" if rate.n_inconclusive else ""
        ax.set_title(f"{what}\nyield {100 * rate.value:.1f} % [{100 * lo:.1f}, "
                     f"{100 * hi:.1f}]{extra}", fontsize=8)
        ax.set_xlabel(f"{r.metric} [{r.unit}]", fontsize=8)
        ax.set_ylabel("share of units [-]", fontsize=8)
        ax.tick_params(labelsize=7)
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=6, loc="lower right")
    for ax in list(axes.flat)[len(rows):]:
        ax.set_visible(False)
    fig.suptitle(f"{res.title}: {test} over {len(res.samples)} units", fontsize=10)
    fig.tight_layout()
    return fig


# ----------------------------------------------------------------------------- markdown
def _pct(x: float) -> str:
    return "n/a" if not math.isfinite(x) else f"{100 * x:.1f} %"


def headline(res: Any) -> str:
    """The answer, one sentence: the yield, its interval, the counts."""
    r = res.overall
    lo, hi = r.interval
    pct = f"{100 * res.level:g} %"
    text = (f"Yield {_pct(r.value)} ({pct} CI {_pct(lo)} to {_pct(hi)}): {r.n_pass} of {r.n} "
            f"units pass every limit of the battery; {r.n_fail} fail")
    if r.n_inconclusive:
        text += (f", {r.n_inconclusive} are INCONCLUSIVE (counted as not passing; if every one "
                 f"passed, the yield would be {_pct((r.n_pass + r.n_inconclusive) / r.n)})")
    return text + "."


def yield_markdown(res: Any) -> str:
    """yield.md: the answer first, then per test, per limit, why units fail, the worst case,
    the tolerances and the method."""
    pct = f"{100 * res.level:g} %"
    out = [f"# {res.title}", "", f"**{headline(res)}**", "",
           f"Stopped because {res.stop_reason}.", "", "## Per test", ""]
    rows = []
    for name, r in res.tests.items():
        lo, hi = r.interval
        rows.append([name, res.plan.spec.tests[name].test, _pct(r.value),
                     f"{_pct(lo)} to {_pct(hi)}", r.n_pass, r.n_fail, r.n_inconclusive])
    out += [md_table(rows, ["test", "kind", "yield", f"{pct} CI", "pass", "fail",
                            "inconclusive"]), "", "## Per limit", ""]
    rows = []
    for r in res.plan.rows:
        rate = res.limits[r.label]
        median, spread = measured_cells(res.samples, r.label, r.unit, r.metric)
        rows.append([r.label, r.limit_text, _pct(rate.value), rate.n_fail,
                     rate.n_inconclusive, median, spread])
    out += [md_table(rows, ["limit", "spec", "yield", "fail", "inconclusive",
                            "median", "range measured"]), ""]
    out += _drivers_md(res) + _worst_md(res)
    out += ["## Tolerances", ""] + [f"- {line}" for line in res.plan.tolerances.describe()]
    corr = getattr(res.plan.tolerances, "correlations", ())
    out += [f"- correlation {a} ~ {b}: {c:g} (Gaussian copula)" for a, b, c in corr]
    out += ["", "## Method", "", *_method_md(res)]
    return "\n".join(out) + "\n"


def measured_cells(samples: Any, label: str, unit: str, metric: str) -> tuple[str, str]:
    """The median and range of one limit's values over the units that measured it, in the one
    vocabulary (``ema_cli.vocab``): a value known only by a bound is not a measurement, so a
    limit no unit measured reads as its bound (``no phase crossover (> 109.5 dB)``), and the
    units known only by a bound are counted apart."""
    from ema_cli.vocab import NOT_MEASURED, number, quantity

    v = samples[f"{label} [{unit}]"].to_numpy(dtype=float)
    col = f"{label} measured"
    meas = (samples[col].to_numpy(dtype=bool) if col in samples.columns
            else np.ones(len(v), dtype=bool))
    fin = v[np.isfinite(v) & meas]
    n_bound = int((~meas).sum())
    if not fin.size:
        lows = samples.get(f"{label} lower")
        lows = np.array([]) if lows is None else lows.to_numpy(dtype=float)
        lows = lows[np.isfinite(lows)]
        lo = float(lows.min()) if lows.size and n_bound else float("nan")
        text = quantity(float("nan"), unit, metric=metric, measured=False, lower=lo,
                        upper=float("inf"))
        return (text if n_bound else NOT_MEASURED), "n/a"
    extra = f" ({n_bound} units: a bound only)" if n_bound else ""
    return (number(float(np.median(fin)), unit) + extra,
            f"{number(float(fin.min()))} to {number(float(fin.max()), unit)}")


def console_lines(res: Any, drivers: int = 3) -> list[str]:
    """The console's answer after the headline: the limits that fail most with their first
    ``drivers`` tolerances (SRRC), and the worst unit of the tolerance box (its smallest
    margin), as short lines (``yield.md`` has the tables)."""
    out = []
    failing = sorted((d for d in res.drivers if d["n_fail"] > 0), key=lambda d: -d["n_fail"])
    for d in failing[:3]:
        top = ", ".join(f"{p} {b:+.2f}" for p, b in d["drivers"][:drivers] if abs(b) >= 0.05)
        out.append(f"  drivers of {d['label']} ({d['n_fail']} fail): "
                   f"{top or 'none above 0.05 (SRRC)'}")
    w = res.worst
    if w is not None:
        found = [(label, v) for label, v in w.limits.items() if v["found"]]
        if found:
            label, v = min(found, key=lambda lv: lv[1]["margin"])
            out.append(f"  worst unit: {label} {md_cell(v['value'])} {v['unit']} against "
                       f"{v['limit']} (margin {v['margin']:+.3f}, {v['result']}), found by "
                       f"{v['stage']}")
        missing = [label for label, v in w.limits.items() if not v["found"]]
        if missing:
            out.append(f"  worst unit not found for {len(missing)} limit(s): "
                       f"{', '.join(missing[:3])}{' ...' if len(missing) > 3 else ''}")
    return out


def _drivers_md(res: Any) -> list[str]:
    failing = [d for d in res.drivers if d["n_fail"] > 0]
    out = ["## Why units fail", "",
           "Per limit that some units fail, the tolerances ranked by the standardised rank "
           "regression coefficient (SRRC) of the normalised margin to the limit on the sampled "
           "values (negative: a larger value eats the margin; R^2: the share of the margin's "
           "rank scatter the tolerances explain together).", ""]
    if not failing:
        return out + ["No unit fails any limit.", ""]
    rows = []
    for d in sorted(failing, key=lambda d: -d["n_fail"]):
        top = ", ".join(f"{p} {b:+.2f}" for p, b in d["drivers"][:3] if abs(b) >= 0.05)
        rows.append([d["label"], d["n_fail"], top or "none above 0.05", f"{d['r2']:.2f}"])
    return out + [md_table(rows, ["limit", "units failing", "drivers (SRRC)", "R^2"]), ""]


def _worst_md(res: Any) -> list[str]:
    w = res.worst
    if w is None:
        return []
    paths = list(res.plan.tolerances.paths)
    box = ", ".join(f"{p} {md_cell(float(a))}..{md_cell(float(b))}"
                    for p, a, b in zip(paths, w.lower, w.upper, strict=True))
    evals = ", ".join(f"{t} {n}" for t, n in w.evaluated.items())
    out = ["## Worst case", "",
           f"The unit inside the tolerance box (normal laws +-{w.k:g} sd; {box}) with the "
           "smallest normalised margin to each limit, among the box's corners and centre, a "
           "differential-evolution search per test and the sampled units inside the box "
           f"(units evaluated per test: {evals}). Its battery: the whole battery's verdict of "
           "that unit.", ""]
    rows = []
    for label, v in w.limits.items():
        if not v["found"]:
            rows.append([label, "not found", v["reason"], "", "", "", ""])
            continue
        vals = ", ".join(f"{p}={md_cell(v['values'][p])}" for p in paths)
        rows.append([label, v["limit"], f"{md_cell(v['value'])} {v['unit']}",
                     f"{v['margin']:+.3f}", v["result"], v.get("battery", "n/a"),
                     f"{v['stage']}: {vals}"])
    return out + [md_table(rows, ["limit", "spec", "worst value", "margin", "verdict",
                                  "its battery", "found by: the unit"]), ""]


def _method_md(res: Any) -> list[str]:
    s = res.settings
    return [
        f"- {len(res.samples)} units, {res.plan.method} sampling (seed {res.plan.seed}); unit "
        "i's values depend only on (seed, i, method, the tolerance file). Each unit is the "
        "spec's actuator with its values set as `--set actuator.PATH=VALUE`, through every "
        "test, batched across units (one kernel call per test, stage and memory block).",
        f"- Intervals: exact Clopper-Pearson at {100 * res.level:g} %"
        + (" (for scrambled Sobol points the interval assumes independent units: it is "
           "conservative when the quasi-random points reduce the variance)"
           if res.plan.method == "sobol" else "") + ". INCONCLUSIVE units are never passes.",
        f"- Target half width: {s['target_halfwidth']}; stop: {res.stop_reason}.",
        f"- Time: {res.timings.get('yield_s', math.nan):.1f} s for the units"
        + (f", {res.timings['worst_case_s']:.1f} s for the worst case"
           if "worst_case_s" in res.timings else "") + ".",
        "- Reproduce: `ema yield SPEC --tolerances tolerances.yaml --n "
        f"{len(res.samples)} --seed {res.plan.seed} --method {res.plan.method}` with the "
        "snapshots in this folder."]


# ------------------------------------------------------------------------------ the folder
def write_yield(folder: Path, res: Any) -> list[str]:
    """Write the report into ``folder`` -> the names written."""
    from ema_cli.files import atomic_write

    names = ["yield.json", "samples.parquet", "yield.md", "convergence.png",
             "spec.resolved.yaml", "tolerances.yaml"]
    if not (folder / "tolerances.yaml").exists():  # a checkpointed run wrote them first
        write_snapshots(folder, res.plan)
    atomic_write(folder / "samples.parquet", lambda p: res.samples.to_parquet(p, index=False))
    write_json(folder / "yield.json", res.to_json())
    write_figure(folder / "convergence.png", convergence_figure(res))
    for name in res.plan.names:
        write_figure(folder / f"dist_{name}.png", distribution_figure(res, name))
        names.append(f"dist_{name}.png")
    write_text(folder / "yield.md", yield_markdown(res))
    names.append("manifest.json")
    write_json(folder / "manifest.json", manifest(
        "yield", outputs=names, source=str(res.plan.spec_source), seed=res.plan.seed,
        settings=res.settings, timings_s=res.timings, resumed_units=res.resumed_units,
        execution=res.execution))
    return names
