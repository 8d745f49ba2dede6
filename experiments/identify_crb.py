"""The information bound of the identification battery (issue 21): for each log, at its
truth, the Cramer-Rao standard deviation of kL, alpha, Fc and sigma2 for

- the whole log simulated from rest (single shooting: the most any estimator can get out of
  the log when the model is exact and its start known), and
- multiple shooting on segments of each length given (free segment states, the motor-angle
  tie; the states profiled out), the estimator ``ema identify --closed-loop`` uses;

with the probability that an unbiased Gaussian estimator with that covariance lands within
the issue's tolerances, and its sum over the logs (the expected count within tolerance).

    python -m experiments.identify_crb --battery DIR --out DIR [--set stated|unstated]
        [--only 0,6] [--lengths 0.4,0.8,1.6]

The weights are each channel's own noise at the truth (the RMS of its residual there), so a
log the model cannot follow from its start (the ratio well above 1: a multisine with the
jump law, impact timing) gets a meaningless, far too small bound: the ``ratios`` columns say
which. The Jacobians are the tool's own (finite differences at the fine step).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
import pandas as pd

from experiments.identify_battery import NAMES, TOL_STATED, TOL_UNSTATED, plan

DRAWS = 20_000  # Monte Carlo draws of the Gaussian estimator per log


def bounds(path: Path, plant: dict, truth: dict, lengths: list[float]) -> list[dict]:
    """The bound of one log: one row for the whole log, one per segment length."""
    from ema_cli.identify.closed_loop.ga_fit import build_problem
    from ema_cli.identify.closed_loop.problem import load_log
    from ema_cli.identify.closed_loop.shooting_quality import channel_ratios
    from ema_cli.identify.closed_loop.shooting_search import build
    from ema_cli.identify.closed_loop.shooting_seat import start_states
    from ema_cli.identify.closed_loop.whole_log import fd_jacobian
    from ema_cli.identify.log_settings import ClosedLoopSettings

    pb, _ = build_problem(ClosedLoopSettings(plant=plant), load_log(path))
    names, span = list(pb.names), pb.upper - pb.lower
    x = np.array([truth.get(n, 0.5 * (pb.lower[k] + pb.upper[k]))
                  for k, n in enumerate(names)])
    n = pb.log.n
    rows = []
    r, J = fd_jacobian(pb, x)
    q = np.array(list(channel_ratios(pb, r).values()))
    w = np.repeat(1.0 / np.maximum(q, 1e-3), n)
    cov = np.linalg.pinv((J * w[:, None]).T @ (J * w[:, None]))
    rows.append(("whole log", 1, q, cov))
    for length in lengths:
        sp = build(pb, length, x, tie=True)
        V = start_states(sp, x[None], pb.dt)[:1]
        r0, Jx, Js = (a[0] for a in sp.jacobian_many(V, pb.dt))
        qm = np.array(list(channel_ratios(pb, r0[:sp.n_data]).values()))
        wt = np.concatenate([np.repeat(1.0 / np.maximum(qm, 1e-3), n),
                             np.ones(r0.shape[0] - sp.n_data)])
        Jf = np.hstack([Jx, sp.full_state_jacobian(Js, V[0])]) * wt[:, None]
        cov_u = np.linalg.pinv(Jf.T @ Jf)[:sp.p, :sp.p]
        rows.append((f"{length:g} s", sp.seg.n, qm, cov_u * np.outer(span, span)))
    k4 = [names.index(m) for m in NAMES]
    out = []
    for label, n_seg, ratios, c in rows:
        out.append({"estimator": label, "segments": n_seg,
                    **{f"ratio_{ch}": float(v) for ch, v in zip(pb.channels, ratios,
                                                                strict=True)},
                    **{f"{m}_sd_pct": float(100.0 * np.sqrt(max(c[k, k], 0.0)) / abs(x[k]))
                       for k, m in zip(k4, NAMES, strict=True)},
                    "_cov_pct": c[np.ix_(k4, k4)] / np.outer(x[k4], x[k4]) * 1e4})
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--battery", type=Path, required=True)
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--set", dest="which", default="stated", choices=("stated", "unstated"))
    ap.add_argument("--only", default=None, help="comma-separated truth indices")
    ap.add_argument("--lengths", default="0.4,0.8,1.6", help="segment lengths [s]")
    a = ap.parse_args()
    manifest = json.loads((a.battery / "battery.json").read_text())
    meta = {e["file"]: e for e in manifest["logs"]}
    only = None if a.only is None else {int(k) for k in a.only.split(",")}
    lengths = [float(v) for v in a.lengths.split(",") if v.strip()]
    tol = np.array([(TOL_STATED if a.which == "stated" else TOL_UNSTATED)[m] for m in NAMES])
    rng = np.random.default_rng(0)
    table = []
    for f, _, plant in plan(manifest, a.which):
        if only is not None and meta[f]["index"] not in only:
            continue
        truth = json.loads((a.battery / f.replace(".csv", ".truth.json")).read_text())["truth"]
        for row in bounds(a.battery / f, plant, truth, lengths):
            c = row.pop("_cov_pct")
            draws = rng.multivariate_normal(np.zeros(len(NAMES)), 0.5 * (c + c.T), DRAWS,
                                            check_valid="ignore")
            row["p_within"] = float(np.mean(np.all(np.abs(draws) <= tol, axis=1)))
            table.append({"file": f, "excitation": meta[f]["excitation"],
                          "rate_hz": meta[f]["sample_rate_hz"],
                          "noise_pct": meta[f]["noise_pct"], **row})
            print(f"{f} {row['estimator']:>9} " + " ".join(
                f"{m} {row[f'{m}_sd_pct']:.3f}" for m in NAMES)
                + f"  P(within) {row['p_within']:.3f}", flush=True)
    df = pd.DataFrame(table)
    a.out.mkdir(parents=True, exist_ok=True)
    tmp = a.out / "crb.csv.tmp"
    df.to_csv(tmp, index=False)
    tmp.replace(a.out / "crb.csv")
    print("expected count within tolerance: " + ", ".join(
        f"{e} {g['p_within'].sum():.2f}" for e, g in df.groupby("estimator", sort=False)))


if __name__ == "__main__":
    main()
