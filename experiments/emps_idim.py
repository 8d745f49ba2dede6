"""The EMPS benchmark's IDIM-LS reproduced (``ema_cli.identify.plant``), what each MATLAB detail
is worth, the per-direction law, and (``--closed-loop``) the benchmark's four relative errors of
a closed-loop simulation with the published estimate.

    python -m experiments.emps_idim [--closed-loop]

The closed-loop simulation is this script's own, from the benchmark README's description of
its Simulink model: the rigid axis with the published parameters, the 1 kHz controller
``u = kv*(kp*(qg - q) - (q[k] - q[k-2])/(2 Ts))`` saturated at +-10 V and applied one sample
late, the axis integrated over each sample by scipy's RK45 at the Simulink settings (RelTol
1e-3, MaxStep Ts/10) from rest at 0. It is not the Simulink model: where the axis rests, the
equilibrium is anywhere in the Coulomb band (+-Fc/(gtau kp kv) = +-15 um) and the solver's
chatter decides, so position and acceleration need not match the published figures; velocity
and force do (within 0.01 %, measured). About 15 s.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
from scipy import signal

from ema_cli.identify.plant import matlab
from ema_cli.identify.plant.benchmark import (
    EMPS_IDIM_PUBLISHED,
    EMPS_IDIM_RELATIVE_ERROR_PCT,
    EMPS_SIMULATION_PUBLISHED_PCT,
    benchmark_errors,
)
from ema_cli.identify.plant.idim import BENCHMARK, idim_ls
from ema_cli.identify.plant.records import PlantRecord, read_plant_mat
from ema_cli.identify.plant.terms import RIGID, RIGID_PER_DIRECTION, TERMS, Kinematics, regressors

DATA = Path(__file__).resolve().parent / "data" / "emps" / "DATA_EMPS.mat"
SATURATION_V = 10.0  # the controller's output limit [V]
RTOL, MAX_STEP_FRACTION = 1e-3, 0.1  # the Simulink solver settings (ode45, 'auto', Ts/10)


def _pct(x: float, ref: float) -> str:
    return f"{100 * (x - ref) / abs(ref):+.5f} %"


def reproduction(rec: PlantRecord) -> None:
    """The estimate with both noise rules against the published values."""
    for rule in ("unbiased", "benchmark"):
        est = idim_ls(rec, sigma_rule=rule)
        print(f"IDIM-LS, sigma rule '{rule}' ({est.regression.y.size} rows)")
        for n in est.names:
            v, s = est.value(n), est.std_of(n)
            pv, ps = EMPS_IDIM_PUBLISHED[n]
            print(f"  {n:3s} {v:12.6f} {est.units[n]:6s} published {pv:9.4f} ({_pct(v, pv)})"
                  f"   std {s:.6f} published {ps:.4f} ({_pct(s, ps)})")
        r = est.relative_error_pct
        print(f"  relative error {r:.6f} % published {EMPS_IDIM_RELATIVE_ERROR_PCT} % "
              f"({_pct(r, EMPS_IDIM_RELATIVE_ERROR_PCT)})")


def _variant(rec: PlantRecord, scipy_filtfilt: bool, first_of_each: bool, first: int
             ) -> np.ndarray:
    """M, Fv, Fc, OF and the relative error with one MATLAB detail replaced."""
    ff = signal.filtfilt if scipy_filtfilt else matlab.filtfilt
    b, a = BENCHMARK.butterworth(rec.h_s)
    q = ff(b, a, rec.q_m)
    dq = matlab.diffcent(q, rec.h_s)
    kin = Kinematics(q, dq, matlab.diffcent(dq, rec.h_s)).slice(first, rec.n)
    W0 = regressors([TERMS[n] for n in RIGID], kin)
    bd, ad = matlab.decimation_filter(10)

    def dec(x: np.ndarray) -> np.ndarray:
        z = ff(bd, ad, x)
        return z[::10] if first_of_each else z[matlab.decimation_indices(x.size, 10)]

    W = np.column_stack([dec(c) for c in W0.T])
    y = dec(rec.force_n[first:])
    th = np.linalg.lstsq(W, y, rcond=None)[0]
    return np.append(th, 100 * np.linalg.norm(y - W @ th) / np.linalg.norm(y))


def details(rec: PlantRecord) -> None:
    """The relative change of M, Fv, Fc, OF and the relative error per MATLAB detail."""
    ref = _variant(rec, False, False, 49)
    rows = {"scipy filtfilt padding (both filters)": (True, False, 49),
            "decimation keeps the first of each 10": (False, True, 49),
            "first sample 48 (0-based)": (False, False, 48),
            "first sample 50 (0-based)": (False, False, 50)}
    print("MATLAB details: relative change of M, Fv, Fc, OF, relative error [%]")
    for label, args in rows.items():
        d = 100 * (_variant(rec, *args) - ref) / np.abs(ref)
        print(f"  {label:40s} " + " ".join(f"{x:+9.5f}" for x in d))


def per_direction(rec: PlantRecord) -> None:
    """The per-direction law on the record."""
    est = idim_ls(rec, law=RIGID_PER_DIRECTION)
    print("per-direction law (Script_IDIM_LS_Asym_Fric.m)")
    for n in est.names:
        print(f"  {n:3s} {est.value(n):12.4f} +- {est.std_of(n):.4f} {est.units[n]}")
    d, sd = est.contrast({"Fc+": 1.0, "Fc-": -1.0})
    print(f"  Fc+ - Fc- = {d:.4f} +- {sd:.4f} N; relative error {est.relative_error_pct:.4f} %")


def closed_loop(rec: PlantRecord) -> None:
    """The benchmark's four relative errors of this script's closed-loop simulation."""
    from scipy.integrate import solve_ivp

    M, Fv, Fc, OF = (EMPS_IDIM_PUBLISHED[n][0] for n in RIGID)
    g, kp, kv = (rec.constants[c] for c in ("gtau", "kp", "kv"))
    ts, n, qg = rec.h_s, rec.n, rec.reference_m
    x, q_past, u_late = np.zeros(2), [0.0, 0.0], 0.0
    Q, V, A, F = (np.empty(n) for _ in range(4))
    for k in range(n):
        Q[k], V[k] = x
        u = float(np.clip(kv * (kp * (qg[k] - x[0]) - (x[0] - q_past[0]) / (2 * ts)),
                          -SATURATION_V, SATURATION_V))
        F[k], u_late = g * u_late, u
        f = F[k]

        def rhs(t, y, f=f):
            return [y[1], (f - Fv * y[1] - Fc * np.sign(y[1]) - OF) / M]

        A[k] = rhs(0.0, x)[1]
        sol = solve_ivp(rhs, (0.0, ts), x, method="RK45", rtol=RTOL,
                        max_step=MAX_STEP_FRACTION * ts)
        q_past, x = [q_past[1], x[0]], sol.y[:, -1]
    errs = benchmark_errors(rec, Q, V, A, F).as_dict()
    print("closed-loop simulation with the published estimate: relative errors [%]")
    for k, v in errs.items():
        p = EMPS_SIMULATION_PUBLISHED_PCT[k]
        print(f"  {k:12s} {v:10.6f} published {p:10.6f} ({_pct(v, p)})")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--closed-loop", action="store_true", help="also simulate the loop (~15 s)")
    args = ap.parse_args()
    rec = read_plant_mat(DATA)
    reproduction(rec)
    details(rec)
    per_direction(rec)
    if args.closed_loop:
        closed_loop(rec)


if __name__ == "__main__":
    main()
