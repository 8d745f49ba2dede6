"""`make emps-ci`: the EMPS benchmark's claims checked on a folder of `ema identify plant`
(results/emps-ci) and on the IDIM-LS pipeline, printed as a table; exit 1 when one fails.

    python -m experiments.emps_claims results/emps-ci

Claims (issue 38; published values: Janot, Gautier and Brunot 2019):
1. IDIM-LS reproduces M 95.1089 kg, Fv 203.5034 N*s/m, Fc 20.3935 N, OF -3.1648 N within
   0.01 % and its relative error 4.0834 %;
2. the output-error fit of the whole record runs in < 60 s (the folder's own timing);
3. its closed-loop force relative error on the estimation record is below the benchmark
   reference model's 5.848 % (and below 3.72 %, the asymmetric rigid model measured here);
4. every parameter is determined (cluster-robust 95 % intervals) and the adequacy report names
   where the model fails (a verdict, failing time ranges or missed terms);
5. on the samples a time-split fit did not use, the fit's force error is below IDIM-LS's.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
RECORD = ROOT / "experiments" / "data" / "emps" / "DATA_EMPS.mat"
PUBLISHED = {"M": 95.1089, "Fv": 203.5034, "Fc": 20.3935, "OF": -3.1648}
PUBLISHED_REL_ERR = 4.0834
REFERENCE_FORCE_PCT = 5.848
ASYMMETRIC_FORCE_PCT = 3.72
MAX_FIT_S = 60.0


def claims(folder: Path) -> list[tuple[str, bool, str]]:
    """(claim, holds, measured) for each claim of the module docstring."""
    from ema_cli.identify.plant.idim import idim_ls
    from ema_cli.identify.plant.records import read_plant_mat

    est = idim_ls(read_plant_mat(RECORD))
    dev = {k: abs(est.value(k) / v - 1) for k, v in PUBLISHED.items()}
    out = [("IDIM-LS reproduces the published M, Fv, Fc, OF within 0.01 %",
            max(dev.values()) <= 1e-4,
            ", ".join(f"{k} {est.value(k):.4f} ({100 * d:.1e} %)" for k, d in dev.items())),
           ("IDIM-LS relative error 4.0834 %", round(est.relative_error_pct, 4) ==
            PUBLISHED_REL_ERR, f"{est.relative_error_pct:.4f} %")]
    js = json.loads((folder / "plant.json").read_text())
    total = js["timings_s"]["total"]
    load = js["kernel"].get("load_s", 0.0)
    warm = total - load
    out.append((f"output-error fit of the whole record < {MAX_FIT_S:g} s", warm < MAX_FIT_S,
                f"{warm:.1f} s warm, both laws and the time-split refit included ({total:.1f} s "
                f"with {load:.1f} s compiling or loading the kernel)"))
    err = js["benchmark_errors_pct"]
    f_oe, f_idim = err["output error"]["force"], err["IDIM-LS"]["force"]
    out.append((f"force relative error < {REFERENCE_FORCE_PCT} % (benchmark reference model) "
                f"and < {ASYMMETRIC_FORCE_PCT} %", f_oe < ASYMMETRIC_FORCE_PCT,
                f"{f_oe:.3f} % (IDIM-LS in the same loop: {f_idim:.3f} %)"))
    law = js["laws"][js["chosen_law"]]
    ad = law["adequacy"]
    named = bool(ad["reasons"]) and (any(ad["failing_time_ranges_s"].values())
                                     or any(o["missed"] for o in ad["omitted_terms"].values())
                                     or ad["verdict"] == "ADEQUATE")
    out.append(("parameters determined with intervals; adequacy names where the model fails",
                law["determined"] and named,
                f"law {js['chosen_law']}, determined {law['determined']}, adequacy "
                f"{ad['verdict']}: {'; '.join(ad['reasons'])[:120]}"))
    sp = js["time_split_validation"]["errors_pct"]
    out.append(("time split: the fit beats IDIM-LS on samples it did not use",
                sp["output error"]["force"] < sp["IDIM-LS"]["force"],
                f"force {sp['output error']['force']:.3f} % vs {sp['IDIM-LS']['force']:.3f} %"))
    return out


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    folder = Path(argv[0]) if argv else ROOT / "results" / "emps-ci"
    rows = claims(folder)
    for claim, ok, measured in rows:
        print(f"{'PASS' if ok else 'FAIL'}  {claim}: {measured}")
    failed = sum(not ok for _, ok, _ in rows)
    print(f"{len(rows) - failed} of {len(rows)} claims hold")
    return 1 if failed else 0


if __name__ == "__main__":
    raise SystemExit(main())
