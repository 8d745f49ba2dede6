"""The battery of independent closed-loop logs (issue 21): n truths by Latin hypercube, three
contact laws each, 4 s logs with their truths and a manifest.

Run: ``python -m experiments.loggen.battery --out DIR [--n 20] [--seed 2026] [--jobs 2]``.

Truth i (i = 0..n-1) is row i of a seeded Latin hypercube over kL 300-900 N*m/rad, alpha
0.0005-0.008 rad, Fc 0.005-0.08 N*m, sigma2 0.001-0.08 N*m*s/rad and noise 0-2 % (other
parameters at ema's defaults, derived ones re-derived); excitation chirp / multisine / steps
for i mod 3 = 0 / 1 / 2; 1 kHz for even i, 500 Hz for odd i. Each truth gives three logs,
``logNN_<law>.csv`` for law jump, ramp, hunt_crossley, with the same truth, excitation and noise
seed (``SeedSequence([seed, i])``). Logs already present are skipped (an interrupted run
resumes); every file is written atomically; ``battery.json`` lists every log (file, truths,
law, excitation, rate, noise, seed, generation time, status). Same seed, same files.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
import traceback
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor, as_completed
from pathlib import Path

import numpy as np
from scipy.stats import qmc

if __package__ in (None, ""):  # run as a script path: make the repository importable
    sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from experiments.loggen.excitations import KINDS  # noqa: E402
from experiments.loggen.logs import make_log, sidecar_path, write_json, write_log  # noqa: E402
from experiments.loggen.odemodel import LAWS  # noqa: E402

RANGES = {"kL": (300.0, 900.0), "alpha": (0.0005, 0.008), "Fc": (0.005, 0.08),
          "sigma2": (0.001, 0.08), "noise_pct": (0.0, 2.0)}
"""Latin-hypercube box of the truths (SI) and of the noise [% of each channel's RMS]."""
RATES_HZ = (1000.0, 500.0)  # sample rate, alternating with the truth index [Hz]
DURATION_S = 4.0  # length of every log [s]


def plan(n: int, seed: int) -> list[dict]:
    """The battery's logs: one dict per (truth, law) with everything that defines it."""
    lhs = qmc.LatinHypercube(d=len(RANGES), seed=np.random.default_rng([seed, 0x4C48]))
    lo = np.array([r[0] for r in RANGES.values()])
    hi = np.array([r[1] for r in RANGES.values()])
    X = qmc.scale(lhs.random(n), lo, hi)
    jobs = []
    for i in range(n):
        row = dict(zip(RANGES, map(float, X[i]), strict=True))
        noise = row.pop("noise_pct")
        log_seed = int(np.random.SeedSequence([seed, i]).generate_state(1)[0])
        for law in LAWS:
            jobs.append({"file": f"log{i:02d}_{law}.csv", "index": i, "truth": row, "law": law,
                         "excitation": KINDS[i % len(KINDS)],
                         "sample_rate_hz": RATES_HZ[i % len(RATES_HZ)],
                         "noise_pct": noise, "seed": log_seed, "duration_s": DURATION_S})
    return jobs


def run_one(job: dict, out: str) -> dict:
    """Generate and write one log (worker) -> its manifest entry."""
    path = Path(out) / job["file"]
    t0 = time.perf_counter()
    try:
        log = make_log(job["truth"], job["law"], job["excitation"], job["sample_rate_hz"],
                       job["noise_pct"], job["seed"], duration_s=job["duration_s"])
        write_log(path, log)
    except Exception as exc:  # a log that fails to integrate is reported, not fatal
        return {**job, "status": "failed", "error": f"{type(exc).__name__}: {exc}",
                "traceback": traceback.format_exc(limit=3),
                "generation_s": time.perf_counter() - t0}
    return entry(job, log.sidecar)


def entry(job: dict, sidecar: dict) -> dict:
    """A manifest entry from the job and the log's sidecar."""
    return {**job, "status": "ok", "truth_full": sidecar["truth"],
            "law_parameters": sidecar["law_parameters"],
            "excitation_detail": sidecar["excitation"],
            "limits_reached": sidecar["limits_reached"],
            "integration": sidecar["integration"], "generation_s": sidecar["generation_s"]}


def existing(job: dict, out: Path) -> dict | None:
    """The entry of a log already written with the same definition, else None."""
    csv, side = out / job["file"], sidecar_path(out / job["file"])
    if not (csv.is_file() and side.is_file()):
        return None
    try:
        sc = json.loads(side.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    same = (sc.get("law") == job["law"] and sc.get("seed") == job["seed"]
            and sc.get("excitation", {}).get("kind") == job["excitation"]
            and all(sc["truth"].get(k) == v for k, v in job["truth"].items()))
    return entry(job, sc) if same else None


def run_battery(out: Path, n: int, seed: int, jobs: int,
                log: Callable[[str], None] = print) -> dict:
    """Generate the battery into ``out`` (created) -> the manifest (also written there)."""
    out.mkdir(parents=True, exist_ok=True)
    todo, done = [], {}
    for job in plan(n, seed):
        e = existing(job, out)
        if e is None:
            todo.append(job)
        else:
            done[job["file"]] = {**e, "skipped": True}
    log(f"{len(done)} log(s) present, {len(todo)} to generate with {jobs} worker(s)")
    t0 = time.perf_counter()
    if todo:
        with ProcessPoolExecutor(max_workers=jobs) as ex:
            futs = [ex.submit(run_one, j, str(out)) for j in todo]
            for k, f in enumerate(as_completed(futs), 1):
                e = f.result()
                done[e["file"]] = e
                log(f"[{k}/{len(todo)}] {e['file']}: {e['status']} "
                    f"({e['generation_s']:.1f} s)" + (f" {e['error']}" if "error" in e else ""))
    entries = [done[j["file"]] for j in plan(n, seed)]
    gen = [e["generation_s"] for e in entries if e["status"] == "ok"]
    manifest = {
        "what": "independent closed-loop logs (experiments/loggen), issue 21's battery",
        "n_truths": n, "seed": seed, "laws": list(LAWS), "ranges": RANGES,
        "rates_hz": list(RATES_HZ), "duration_s": DURATION_S, "excitations": list(KINDS),
        "wall_s_this_run": time.perf_counter() - t0, "workers": jobs,
        "generation_s_median": float(np.median(gen)) if gen else None,
        "failed": [e["file"] for e in entries if e["status"] != "ok"],
        "logs": entries,
    }
    write_json(out / "battery.json", manifest)
    return manifest


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", required=True, type=Path, help="output folder (created)")
    ap.add_argument("--n", type=int, default=20, help="number of truths (3 logs each)")
    ap.add_argument("--seed", type=int, default=2026, help="battery seed")
    ap.add_argument("--jobs", type=int, default=2, help="worker processes")
    a = ap.parse_args(argv)
    if a.n < 1 or a.jobs < 1:
        ap.error("--n and --jobs must be >= 1")
    m = run_battery(a.out, a.n, a.seed, a.jobs)
    print(f"median generation time {m['generation_s_median']:.1f} s per log; failed: "
          f"{m['failed'] or 'none'}; manifest {a.out / 'battery.json'}")
    return 1 if m["failed"] else 0


if __name__ == "__main__":
    raise SystemExit(main())
