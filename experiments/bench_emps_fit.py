"""`make bench`: the EMPS output-error fit of the whole 24.8 s record (`ema identify plant`'s
computation through the API, time-split refit included), median of repeats, warm (the kernel
compiled before the first repeat).

    python -m experiments.bench_emps_fit [--repeats 3]
"""

from __future__ import annotations

import argparse
import statistics
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def main(argv: list[str] | None = None) -> int:
    from ema_cli.api import identify_plant

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args(argv)
    data = ROOT / "experiments" / "data" / "emps" / "DATA_EMPS.mat"
    desc = ROOT / "configs" / "actuators" / "emps.yaml"
    identify_plant(data, desc, split=0.0, max_iter=1)  # compile and warm
    times, fits = [], []
    for _ in range(max(args.repeats, 1)):
        t0 = time.perf_counter()
        fit = identify_plant(data, desc)
        times.append(time.perf_counter() - t0)
        fits.append(fit.result)
    r = fits[-1]
    each = ", ".join(f"{t:.1f}" for t in times)
    print(f"EMPS plant fit (whole record + time-split refit, law auto): median "
          f"{statistics.median(times):.1f} s of {len(times)} ({each} s); kernel "
          f"{r.kernel['kernel_s']:.1f} s in {r.kernel['calls']} calls of "
          f"{r.kernel['lanes']} simulations; force error {r.errors['output error'].force_pct:.3f}"
          f" % (IDIM-LS {r.errors['IDIM-LS'].force_pct:.3f} %)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
