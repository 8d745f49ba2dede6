"""The identification battery of issue 21: `ema identify --closed-loop` on logs made by an
independent simulator (experiments/loggen: scipy solve_ivp, the same documented equations),
at Latin-hypercube truths, three contact laws, three excitations, two sample rates.

    python experiments/identify_battery.py --battery DIR --out DIR [--set stated|unstated|all]
        [--only 0,3] [--starts 8] [--lengthen 0.1,0.2] [--no-tie]
        [--command linear|cubic]

Sets: ``stated`` = one log per truth with its contact law stated to the fit (even truths the
ramp law with its contact_tau, odd truths the jump law, contact_tau = 0; the damping ratio
zeta_t of the data); ``unstated`` = the Hunt-Crossley logs (a law ema does not have) fitted
with the defaults (the contact's zeta_t and contact_tau then free nuisance parameters). Every
fit runs in this process, one after the other (numba threads use the cores); results are
appended to ``results.csv`` as each fit ends (an interrupted run resumes), then ``summary.md``
tallies them against the issue's tolerances.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np
import pandas as pd

NAMES = ("kL", "alpha", "Fc", "sigma2")
TOL_STATED = {"kL": 0.5, "alpha": 0.5, "Fc": 2.0, "sigma2": 2.0}  # [%]
TOL_UNSTATED = {"kL": 2.0, "alpha": 2.0, "Fc": 5.0, "sigma2": 5.0}  # [%]


def plan(manifest: dict, which: str) -> list[tuple[str, str, dict]]:
    """(file, set, plant overrides) of every fit of the battery."""
    out = []
    by = {(e["index"], e["law"]): e for e in manifest["logs"] if e.get("status") == "ok"}
    for i in range(manifest["n_truths"]):
        if which in ("stated", "all"):
            law = "ramp" if i % 2 == 0 else "jump"
            e = by.get((i, law))
            if e is not None:
                tau = e["truth_full"].get("contact_tau", 1e-4 if law == "ramp" else 0.0)
                out.append((e["file"], "stated", {
                    "contact_tau": float(tau),
                    "zeta_t": float(e["truth_full"].get("zeta_t", 0.2))}))
        if which in ("unstated", "all"):
            e = by.get((i, "hunt_crossley"))
            if e is not None:
                out.append((e["file"], "unstated", {}))
    return out


def fit_one(path: Path, plant: dict, starts: int, lengthen: list[float] | None = None,
            tie: bool = True, command: str | None = None) -> dict:
    from ema_cli.identify.closed_loop.ga_fit import run_closed_loop
    from ema_cli.identify.closed_loop.problem import load_log
    from ema_cli.identify.log_settings import ClosedLoopSettings

    log = load_log(path)
    shooting: dict = {"starts": starts, "tie_motor_angle": tie}
    if lengthen is not None:
        shooting["lengthen_s"] = lengthen
    extra = {} if command is None else {"command": command}
    settings = ClosedLoopSettings(plant=plant, shooting=shooting, profile_points=5, **extra)
    from ema_cli.sim.runner import TALLY

    t0, steps0 = time.perf_counter(), TALLY["lane_steps"]
    fit = run_closed_loop(settings, log)
    wall = time.perf_counter() - t0
    lane_steps = TALLY["lane_steps"] - steps0
    js = fit.to_json()
    extra = {f"{n}_est": float(fit.x[j]) for j, n in enumerate(fit.names) if n not in NAMES}
    row: dict = {"wall_s": wall, "lane_steps": lane_steps,
                 "confirmed": js["optimum"]["confirmed"], **extra,
                 "J_over_N": fit.shooting.search.cost / fit.problem.measured.size,
                 "agree": fit.shooting.search.agree,
                 "max_ratio": max(js["fit_quality"]["rms_over_scale"].values()),
                 "reasons": " | ".join(js["optimum"]["not_confirmed_because"]),
                 # for diagnosis: the runner-up won on the longest segments, the LM
                 # iterations per stage, the intervals' widening terms for kL
                 "runner_up_won": js.get("shooting", {}).get(
                     "runner_up_won_on_longer_segments"),
                 "stage_iterations": json.dumps(js.get("shooting", {}).get(
                     "stage_iterations")),
                 "kL_step_shift": (js.get("shooting", {}).get("step_shift") or {}).get("kL"),
                 "kL_segment_shift": (js.get("shooting", {}).get("segment_shift")
                                      or {}).get("kL"),
                 "tie_rms_over_se": (js.get("shooting", {}).get("motor_angle_tie")
                                     or {}).get("rms_over_se"),
                 "tie_p_value": (js.get("shooting", {}).get("motor_angle_tie")
                                 or {}).get("p_value"),
                 "segments": js.get("shooting", {}).get("segments"),
                 "covariance_segments": js.get("shooting", {}).get("covariance_segments"),
                 "fell_back": js.get("shooting", {}).get("fell_back_from_longest_segments"),
                 "timings_s": json.dumps({k: round(v, 2) for k, v in {
                     **js.get("timings_s", {}),
                     **js.get("shooting", {}).get("timings_s", {})}.items()})}
    for j, n in enumerate(fit.names):
        if n not in NAMES:
            continue
        t = log.truth[n]
        lo, hi = js["parameters"][n]["ci95"]
        row[f"{n}_est"] = float(fit.x[j])
        row[f"{n}_truth"] = t
        row[f"{n}_err_pct"] = 100.0 * (float(fit.x[j]) / t - 1.0)
        row[f"{n}_covered"] = bool(lo <= t <= hi)
        row[f"{n}_halfwidth_pct"] = 100.0 * (hi - lo) / (2.0 * t)
        row[f"{n}_determined"] = bool(js["parameters"][n]["determined"])
    return row


STAGES = (("start_states_s", "start states"), ("joint_lm_s", "joint LM"),
          ("lengthen_s", "contact restart and lengthening"), ("refine_s", "refinement"),
          ("ms_uncertainty_s", "covariance"), ("polish_s", "whole-log polish"),
          ("uncertainty_profile_s", "alpha profile"))
"""The stages of a fit (``timings_s`` keys of identification.json) in the summary's medians."""


def stage_medians(d: pd.DataFrame) -> list[str]:
    """The line of median seconds per stage of the fits ``d`` (their ``timings_s``)."""
    if "timings_s" not in d:
        return []
    t = pd.DataFrame([json.loads(v) for v in d["timings_s"]])
    parts = [f"{label} {t[k].median():.1f}" for k, label in STAGES if k in t]
    return ["- median seconds per stage: " + ", ".join(parts)] if parts else []


def summarise(df: pd.DataFrame) -> str:
    lines = ["# Identification battery (experiments/identify_battery.py)", ""]
    for which, tol in (("stated", TOL_STATED), ("unstated", TOL_UNSTATED)):
        d = df[df["set"] == which]
        if d.empty:
            continue
        within = np.all([np.abs(d[f"{n}_err_pct"]) <= tol[n] for n in NAMES], axis=0)
        flagged = ~d["confirmed"].to_numpy(bool)
        misses = ~within
        cover = np.mean([d[f"{n}_covered"].to_numpy(bool) for n in NAMES])
        all_cov = np.all([d[f"{n}_covered"].to_numpy(bool) for n in NAMES], axis=0)
        conf = d["confirmed"].to_numpy(bool)
        # per fit: how many estimates miss their tolerance AND lie outside their interval
        wrong_and_sure = np.sum([(np.abs(d[f"{n}_err_pct"].to_numpy()) > tol[n])
                                 & ~d[f"{n}_covered"].to_numpy(bool) for n in NAMES], axis=0)
        cover_c = (np.mean([d[f"{n}_covered"].to_numpy(bool)[conf] for n in NAMES])
                   if conf.any() else float("nan"))
        lines += [f"## law {which} ({len(d)} logs; tolerances " + ", ".join(
            f"{n} {tol[n]:g} %" for n in NAMES) + ")", "",
            f"- within tolerance: {int(within.sum())} of {len(d)}",
            f"- misses flagged (optimum not confirmed): {int((misses & flagged).sum())} of "
            f"{int(misses.sum())}; hits flagged: {int((within & flagged).sum())}",
            f"- misses not flagged whose 95 % intervals all contain the truth: "
            f"{int((misses & ~flagged & all_cov).sum())}; with an interval that excludes it "
            f"(a confident wrong number): {int((misses & ~flagged & ~all_cov).sum())}",
            "- of those, estimates both out of tolerance and outside their own interval: "
            f"{int(wrong_and_sure[misses & ~flagged & ~all_cov].sum())}",
            *(["- median 95 % half-width: " + ", ".join(
                f"{n} {d[f'{n}_halfwidth_pct'].median():.2f} %" for n in NAMES)]
              if f"{NAMES[0]}_halfwidth_pct" in d else []),
            f"- 95 % intervals covering the truth: {100 * cover:.1f} % of "
            f"{len(d) * len(NAMES)} estimates; of the confirmed fits' estimates: "
            f"{100 * cover_c:.1f} % of {int(conf.sum()) * len(NAMES)}",
            f"- wall time per fit: median {d['wall_s'].median():.0f} s, max "
            f"{d['wall_s'].max():.0f} s", *stage_medians(d), "",
            "| log | excitation | rate Hz | noise % | " + " | ".join(
                f"{n} err %" for n in NAMES) + " | covered | confirmed | J/N | s |",
            "|---|---|---|---|" + "---|" * len(NAMES) + "---|---|---|---|"]
        for _, r in d.iterrows():
            cov = "".join("y" if r[f"{n}_covered"] else "n" for n in NAMES)
            lines.append(f"| {r['file']} | {r['excitation']} | {r['rate_hz']:g} | "
                         f"{r['noise_pct']:.2f} | " + " | ".join(
                             f"{r[f'{n}_err_pct']:+.3f}" for n in NAMES)
                         + f" | {cov} | {'yes' if r['confirmed'] else 'NO'} | "
                         f"{r['J_over_N']:.3f} | {r['wall_s']:.0f} |")
        lines.append("")
    return "\n".join(lines)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--battery", type=Path, required=True)
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--set", dest="which", default="all", choices=("stated", "unstated", "all"))
    ap.add_argument("--only", default=None, help="comma-separated truth indices")
    ap.add_argument("--starts", type=int, default=8)
    ap.add_argument("--lengthen", default=None,
                    help="comma-separated longer segment lengths [s] (default: the tool's)")
    ap.add_argument("--no-tie", action="store_true",
                    help="each segment's motor angle free (shooting.tie_motor_angle: false)")
    ap.add_argument("--command", default=None, choices=("linear", "cubic"),
                    help="the command between samples (default: the tool's)")
    a = ap.parse_args()
    manifest = json.loads((a.battery / "battery.json").read_text())
    a.out.mkdir(parents=True, exist_ok=True)
    res_path = a.out / "results.csv"
    done = pd.read_csv(res_path) if res_path.is_file() else pd.DataFrame()
    seen = set(zip(done["file"], done["set"], strict=True)) if len(done) else set()
    only = None if a.only is None else {int(k) for k in a.only.split(",")}
    lengthen = (None if a.lengthen is None
                else [float(v) for v in a.lengthen.split(",") if v.strip()])
    meta = {e["file"]: e for e in manifest["logs"]}
    todo = [(f, s, p) for f, s, p in plan(manifest, a.which)
            if (f, s) not in seen and (only is None or meta[f]["index"] in only)]
    for k, (f, s, plant) in enumerate(todo):
        e = meta[f]
        print(f"[{k + 1}/{len(todo)}] {f} ({s})", flush=True)
        row = {"file": f, "set": s, "law": e["law"], "excitation": e["excitation"],
               "rate_hz": e["sample_rate_hz"], "noise_pct": e["noise_pct"],
               **fit_one(a.battery / f, plant, a.starts, lengthen, not a.no_tie,
                        a.command)}
        print("   " + ", ".join(f"{n} {row[f'{n}_err_pct']:+.3f} %" for n in NAMES)
              + f"; confirmed {row['confirmed']}; {row['wall_s']:.0f} s", flush=True)
        frame = pd.DataFrame([row])
        tmp = res_path.with_suffix(".tmp")
        pd.concat([done, frame]).to_csv(tmp, index=False)
        tmp.replace(res_path)
        done = pd.read_csv(res_path)
    if len(done):
        (a.out / "summary.md").write_text(summarise(done))
        print((a.out / "summary.md").read_text())


if __name__ == "__main__":
    main()
