"""Make the bundled log of `make design-ci`: experiments/logs/design_hc_1pct.csv (+ .truth.json).

The independent generator (experiments/loggen: scipy solve_ivp Radau of docs/model.md's
equations) with the FOREIGN contact law (Hunt-Crossley, which ema does not have), 1 % noise on
every measured channel, 500 Hz, a 2 s chirp (5 deg, 0.5 -> 8 Hz), a default-ish truth (kL,
alpha, Fc, sigma2 near the middle of the identification bounds, not ema's defaults). 2 s keeps
the file under 150 KB (1001 rows) and the CI fit short.

    python -m experiments.logs.make_design_log [--out experiments/logs/design_hc_1pct.csv]
"""

from __future__ import annotations

import argparse
from pathlib import Path

from experiments.loggen.logs import make_log, write_log

TRUTH = {"kL": 520.0, "alpha": 0.0025, "Fc": 0.03, "sigma2": 0.02}
"""SI: N*m/rad, rad (0.143 deg half backlash), N*m, N*m*s/rad."""
LAW = "hunt_crossley"
EXCITATION = "chirp"
SAMPLE_RATE_HZ = 500.0
NOISE_PCT = 1.0
DURATION_S = 2.0
SEED = 2121


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=Path(__file__).with_name("design_hc_1pct.csv"))
    a = ap.parse_args(argv)
    log = make_log(TRUTH, LAW, EXCITATION, SAMPLE_RATE_HZ, NOISE_PCT, SEED,
                   duration_s=DURATION_S)
    write_log(a.out, log)
    print(f"{a.out}: {a.out.stat().st_size / 1e3:.1f} kB, generated in "
          f"{log.sidecar['generation_s']:.1f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
