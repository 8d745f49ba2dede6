"""`make bench`: kernel throughput vs the scalar baseline, the cost of running in time chunks,
same-accuracy comparisons with scipy, identification, sweeps.

Every figure is the median of several repeats measured in this one run (the machines are shared
and noisy); ratios are between numbers of the same run. Nothing here is asserted: tests check
correctness, this script measures speed.
"""

from __future__ import annotations

import importlib.util
import statistics
import sys
import time
import tracemalloc
from pathlib import Path

import numpy as np
import scipy.linalg
from scipy.integrate import solve_ivp

from ema_cli.model.params import resolve, to_row
from ema_cli.sim import runner
from ema_cli.sim.runner import plan_steps, simulate_batch
from ema_cli.sim.signals import InputSignal, sample
from ema_cli.timing import median_time
from ema_cli.units import DEG

REPEATS = 5
LINEAR = {"sat1": "off", "sat2": "off", "sat3": "off", "alpha": 0.0, "friction": 0}


BATCHES = (1, 64, 256, 1024)
KERNEL_CASES = {
    "defaults": {},
    "backlash 0.01 deg": {"alpha": 0.01 * DEG},
    "LuGre friction 0.01": {"friction": 1, "sigma2": 0.01},
}


def _baseline_kernel():
    """The first wave's scalar kernel (one configuration per loop iteration), kept verbatim in
    ``baseline_kernel.py`` beside this script so every run measures both."""
    path = Path(__file__).with_name("baseline_kernel.py")
    spec = importlib.util.spec_from_file_location("baseline_kernel", path)
    mod = importlib.util.module_from_spec(spec)  # type: ignore[arg-type]
    spec.loader.exec_module(mod)  # type: ignore[union-attr]
    return mod


def kernel_throughput() -> None:
    """System-steps/s (configurations x RK4 steps per second) of the v2 kernel (one-lane path
    for a batch of 1, SIMD lanes over the cores above) against the scalar baseline (serial for 1,
    prange over the cores above), 0.1 deg step, 1 s, dt 1e-5 s, metrics only. Both get the
    reference sampled beforehand (the v2 kernel in its time chunks, ``runner.TIME_CHUNK``);
    the wall time of ``simulate_batch`` is timed."""
    from ema_cli.sim.tables import N_METRICS, N_SIGNALS

    base = _baseline_kernel()
    dt = 1e-5
    n, _ = plan_steps(1.0, dt, None)
    ref = sample(InputSignal("step", 0.1 * DEG), dt, n)

    def run_base(P: np.ndarray) -> None:
        kernel = base.simulate_batch_nb if len(P) == 1 else base.simulate_batch_parallel_nb
        kernel(P, ref.pos_half[None], ref.vel[None], ref.step_info[None],
               np.zeros(len(P), np.int64), dt, n, 0, np.empty((len(P), 0, N_SIGNALS)),
               np.empty((len(P), N_METRICS)))

    print("\n== kernel throughput: 0.1 deg step, 1 s, dt 1e-5 s, metrics only "
          "[M system-steps/s]")
    print(f"  {'case':22s} {'batch':>5s} {'v2 kernel':>10s} {'baseline':>10s} {'ratio':>6s}")
    for label, over in KERNEL_CASES.items():
        for size in BATCHES:
            P = np.repeat(np.array([to_row(resolve(over))]), size, axis=0)
            reps = REPEATS if size <= 64 else 3
            t_new = median_time(lambda P=P: simulate_batch(P, [ref], None, dt, n, 0,
                                                           parallel=len(P) > 1), reps)
            t_old = median_time(lambda P=P: run_base(P), reps)
            print(f"  {label:22s} {size:5d} {size * n / t_new / 1e6:10.1f} "
                  f"{size * n / t_old / 1e6:10.1f} {t_old / t_new:6.2f}")


def _chunk_run(P: np.ndarray, sig: InputSignal, n: int, reps: int) -> tuple[float, float]:
    """Median (wall time of simulate_batch, its kernel_s) [s] for a metrics-only run of ``n``
    steps of 1e-5 s with the reference sampled per time chunk."""
    walls, kernels = [], []
    simulate_batch(P, [sig], None, 1e-5, n, 0, parallel=len(P) > 1)
    for _ in range(reps):
        t0 = time.perf_counter()
        res = simulate_batch(P, [sig], None, 1e-5, n, 0, parallel=len(P) > 1)
        walls.append(time.perf_counter() - t0)
        kernels.append(res.kernel_s)
    return statistics.median(walls), statistics.median(kernels)


def time_chunks() -> None:
    """What running in time chunks costs: the wall time of ``simulate_batch`` given the
    InputSignal (sampled per chunk) against the time inside the kernel calls (``kernel_s``), for
    chunks of 2**12 to 2**16 steps; and the peak of numpy's allocations (tracemalloc) for a
    metrics-only run, 1 s against 20 s (it does not grow with the duration)."""
    print("\n== time chunks: 1 s, dt 1e-5 s, metrics only; reference sampled per chunk "
          "[M system-steps/s; share of the wall time outside the kernel]")
    n, _ = plan_steps(1.0, 1e-5, None)
    default = runner.TIME_CHUNK
    print(f"  {'input':6s} {'batch':>5s} " + " ".join(f"{'2**' + str(e):>16s}"
                                                    for e in (12, 14, 16)))
    try:
        for sig in (InputSignal("step", 0.1 * DEG), InputSignal("sine", 0.1 * DEG, freq=5.0)):
            for size in (1, 1024):
                P = np.repeat(np.array([to_row(resolve())]), size, axis=0)
                cells = []
                for e in (12, 14, 16):
                    runner.TIME_CHUNK = 2**e
                    wall, kern = _chunk_run(P, sig, n, REPEATS if size == 1 else 3)
                    cells.append(f"{size * n / wall / 1e6:8.1f} ({(wall - kern) / wall:4.0%})")
                print(f"  {sig.kind:6s} {size:5d} " + " ".join(f"{c:>16s}" for c in cells))
    finally:
        runner.TIME_CHUNK = default
    P = np.array([to_row(resolve())])
    sig = InputSignal("sine", 0.1 * DEG, freq=5.0)
    for seconds in (1.0, 20.0):
        n, _ = plan_steps(seconds, 1e-5, None)
        tracemalloc.start()
        simulate_batch(P, [sig], None, 1e-5, n, 0)
        peak = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
        print(f"  {seconds:4g} s metrics only: numpy peak {peak / 2**20:6.2f} MiB "
              f"(the whole reference sampled at once: {(3 * n + 2) * 8 / 2**20:6.1f} MiB)")


def _kernel_step_run(p: dict[str, float], step: float, duration: float) -> tuple[float, np.ndarray]:
    """Median wall time [s] of one kernel run (step input, dt 1e-5 s) and its load angle every
    1e-3 s [rad]."""
    dt = 1e-5
    n, dec = plan_steps(duration, dt, 1e-3)
    ref = sample(InputSignal("step", step), dt, n)
    P = np.array([to_row(p)])
    t = median_time(lambda: simulate_batch(P, [ref], None, dt, n, dec))
    return t, simulate_batch(P, [ref], None, dt, n, dec).signals[0, :, 1]


def _linear_matrices(p: dict[str, float]) -> tuple[np.ndarray, np.ndarray]:
    m, kl, c = p["m"], p["kL"], p["c"]
    A = np.zeros((6, 6))
    B = np.zeros(6)
    A[0, 1] = 1
    A[1, :] = [-kl / m / m / p["Jm"], (-p["bm"] - c / m / m) / p["Jm"], p["Kt"] / p["Jm"],
               kl / m / p["Jm"], c / m / p["Jm"], 0]
    A[2, :] = [0, (-p["Kps"] - p["Ke"]) / p["L"], -p["R"] / p["L"],
               -p["Kps"] * m * p["Kpp"] / p["L"], 0, p["Kis"] / p["L"]]
    B[2] = p["Kps"] * m * p["Kpp"] / p["L"]
    A[3, 4] = 1
    A[4, :] = [kl / m / p["JL"], c / m / p["JL"], 0, -kl / p["JL"], (-c - p["bL"]) / p["JL"], 0]
    A[5, 1], A[5, 3], B[5] = -1, -m * p["Kpp"], m * p["Kpp"]
    return A, B


def same_accuracy_vs_scipy() -> None:
    """The linear loop (0.1 deg step, 0.2 s) against its exact solution (matrix exponential)."""
    print("\n== same accuracy: linear loop, 0.1 deg step, 0.2 s; error vs the exact solution")
    p = resolve(LINEAR)
    A, B = _linear_matrices(p)
    step = 0.1 * DEG
    t_eval = np.linspace(0, 0.2, 201)
    Ainv_B = np.linalg.solve(A, B)
    exact = np.array([(scipy.linalg.expm(A * t) @ Ainv_B - Ainv_B)[3] for t in t_eval]) * step

    t_ours, ours = _kernel_step_run(p, step, 0.2)
    err_ours = np.max(np.abs(ours - exact)) / step
    print(f"  ema kernel RK4 dt 1e-5 s    {t_ours * 1e3:8.2f} ms   max error {err_ours:.1e} "
          "of the step")

    def rhs(_t, x):
        return A @ x + B * step

    for method, rtol in (("RK45", 1e-10), ("DOP853", 1e-12)):
        def run(method=method, rtol=rtol):
            return solve_ivp(rhs, (0, 0.2), np.zeros(6), method=method, rtol=rtol,
                             atol=1e-14, t_eval=t_eval)
        t = median_time(run, 3)
        sol = run()
        err = np.max(np.abs(sol.y[3] - exact)) / step
        print(f"  scipy {method:6s} rtol {rtol:.0e}  {t * 1e3:8.2f} ms   max error {err:.1e} "
              f"of the step   ({sol.nfev} RHS calls) -> ema x{t / t_ours:.0f} faster")


def _python_rhs(p: dict[str, float], step: float):
    """docs/model.md §2 without friction, written independently in plain Python for solve_ivp."""
    m, alpha = p["m"], p["alpha"]

    def dz(u: float, d: float) -> float:
        return u - d if u > d else (u + d if u < -d else 0.0)

    def rhs(_t: float, x: np.ndarray) -> list[float]:
        th_m, w_m, i, th_l, w_l, x_i = x
        wl_star = min(max(p["Kpp"] * (step - th_l), -p["sat1"]), p["sat1"])
        e_w = m * wl_star - w_m
        u_un = p["Kps"] * e_w + p["Kis"] * x_i
        u = min(max(u_un, -p["sat2"]), p["sat2"])
        di = (u - p["R"] * i - p["Ke"] * w_m) / p["L"]
        if abs(i) >= p["sat3"] and di * i > 0:
            di = 0.0
        dxi = 0.0 if (abs(u_un) > p["sat2"] and e_w * u_un > 0) else e_w
        dth, dw = th_m / m - th_l, w_m / m - w_l
        t = p["kL"] * dz(dth, alpha) + p["c"] * dw
        if alpha > 0 and (abs(dth) <= alpha or dth * t < 0):  # in the gap, or pulling
            t = 0.0
        return [w_m, (p["Kt"] * i - p["bm"] * w_m - t / m) / p["Jm"], di, w_l,
                (t - p["bL"] * w_l) / p["JL"], dxi]

    return rhs


def nonlinear_vs_scipy() -> None:
    """20 deg step with the default saturations and a 0.01 deg dead band (contact), 0.3 s."""
    print("\n== nonlinear model: 20 deg step, saturations on, 0.01 deg dead band, 0.3 s")
    p = resolve({"alpha": 0.01 * DEG})
    step = 20 * DEG
    t_eval = np.linspace(0, 0.3, 301)
    rhs = _python_rhs(p, step)
    t0 = time.perf_counter()
    truth = solve_ivp(rhs, (0, 0.3), np.zeros(6), method="DOP853", rtol=1e-11, atol=1e-13,
                      t_eval=t_eval, max_step=1e-4)
    t_truth = time.perf_counter() - t0
    print(f"  reference: scipy DOP853 rtol 1e-11, max_step 1e-4 s: {t_truth:.1f} s, "
          f"{truth.nfev} RHS calls")
    t_ours, ours = _kernel_step_run(p, step, 0.3)
    n = round(0.3 / 1e-5)  # RK4 steps in the run
    err_ours = np.max(np.abs(ours - truth.y[3])) / step
    print(f"  ema kernel RK4 dt 1e-5 s   {t_ours * 1e3:9.2f} ms   max error {err_ours:.1e} of "
          f"the step   ({n / t_ours / 1e6:.1f} M steps/s)")
    for method, rtol in (("RK45", 1e-6), ("RK45", 1e-8), ("DOP853", 1e-9)):
        t0 = time.perf_counter()
        sol = solve_ivp(rhs, (0, 0.3), np.zeros(6), method=method, rtol=rtol, atol=1e-12,
                        t_eval=t_eval)
        t = time.perf_counter() - t0
        err = np.max(np.abs(sol.y[3] - truth.y[3])) / step
        print(f"  scipy {method:6s} rtol {rtol:.0e} {t * 1e3:9.2f} ms   max error {err:.1e} of "
              f"the step   ({sol.nfev} RHS calls) -> ema x{t / t_ours:.0f} faster")


def sweep_bench() -> None:
    path = Path(__file__).with_name("bench_sweep.py")
    if not path.exists():
        return
    spec = importlib.util.spec_from_file_location("bench_sweep", path)
    mod = importlib.util.module_from_spec(spec)  # type: ignore[arg-type]
    spec.loader.exec_module(mod)  # type: ignore[union-attr]
    print("\n== sweep: 1,000 jobs end to end")
    mod.main()


def main() -> int:
    from ema_cli.identify.torque.bench import bench_identify

    print(f"python {sys.version.split()[0]}, numpy {np.__version__}; medians of {REPEATS} repeats")
    kernel_throughput()
    time_chunks()
    same_accuracy_vs_scipy()
    nonlinear_vs_scipy()
    print("\n== identification")
    bench_identify()
    sweep_bench()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
