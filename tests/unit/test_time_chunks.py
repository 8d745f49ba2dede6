"""Time-chunked simulation: a run cut into kernel calls of a few steps is bit for bit the run done
in one call, the references are sampled per chunk exactly as for the whole run, memory does not
grow with the duration, the recording is checked against a budget, and the kernel time is
measured apart from loading the kernel."""

from __future__ import annotations

import itertools
import math
import os
import subprocess
import sys
import textwrap
import time
import tracemalloc

import numpy as np
import pytest

from ema_cli.errors import EmaError
from ema_cli.model.params import N_PARAMS, resolve, to_row
from ema_cli.sim import kernel, runner, signals
from ema_cli.sim.runner import load_kernel, plan_steps, simulate_batch
from ema_cli.sim.signals import InputSignal, Reference, sample, sampler
from ema_cli.sim.tables import MET, N_METRICS, PAPER_SIGNALS, SIG
from ema_cli.units import DEG

DT = 1e-5  # [s]
N_STEPS = 1200  # 12 ms: k_ss = 1080 (a multiple of neither 7 nor 64), k_osc = 960 (= 15*64)
DEC = 3  # recorded every 3 steps: chunk boundaries of 7 and 64 steps fall between samples
HUGE = 10**9  # a TIME_CHUNK that makes every run one kernel call
PROFILE = ((0.0, 0.003, 0.006, 0.0091, 0.012), (0.0, 2 * DEG, -1 * DEG, 0.5 * DEG, 0.5 * DEG))
LOAD = ((0.0, 0.004, 0.0093), (0.0, 1.5, -2.0))
SIGNALS = (
    InputSignal("step", 0.1 * DEG, start=0.00123),
    InputSignal("sine", 2 * DEG, freq=300.0, offset=0.1 * DEG, load_table=LOAD),
    InputSignal("chirp", 1 * DEG, freq=50.0, freq_end=800.0, start=0.002),
    InputSignal("ramp", 3 * DEG, rate=2000 * DEG, start=0.004),
    InputSignal("csv", path="profile.csv", table=PROFILE, load_table=LOAD),
)


def chunk_configs() -> list[dict[str, float]]:
    """Every kernel variant: plain, backlash, dead zone, friction (LuGre), digital controllers
    whose sample periods (3, 5, 7, 20 steps) cut across the chunks, position and speed
    quantisers, constant and position-dependent load torque, locked motors (one with friction),
    and one configuration that diverges after ~4.5 ms (saturations off, Kpp 1e5, Kps 2)."""
    over: list[dict[str, object]] = [
        {},
        {"alpha": 3e-3, "Kpp": 80},
        {"d1": 0.5, "T_load": 2.0},
        {"friction": 1, "sigma2": 1e-4},
        {"friction": 1, "sigma2": 2e-4, "alpha": 1e-3, "Ts": 5e-5},
        {"Ts": 3e-5, "q_pos": 2 * math.pi / 4096},
        {"Ts": 7e-5, "q_speed": 0.5, "T_load": -1.0, "k_h": 20.0},
        {"Ts": 2e-4, "Kpp": 35},
        {"locked": 1, "T_load": 2.0, "k_h": 30.0},
        {"locked": 1, "friction": 1},
        {"Kpp": 1e5, "Kps": 2.0, "sat1": "off", "sat2": "off", "sat3": "off"},  # diverges
        {"friction": 1, "sigma2": 3e-4, "q_pos": 2 * math.pi / 1024, "Kpp": 120},
    ]
    return [resolve(o) for o in over]


def batch(n_copies: int = 2) -> tuple[np.ndarray, np.ndarray]:
    """The configurations twice over (24 rows: a full chunk of 16 lanes and a partial one),
    each following one of the five references."""
    P = np.array([to_row(p) for p in chunk_configs()] * n_copies)
    return P, np.arange(len(P)) % len(SIGNALS)


def run(monkeypatch, chunk: int, refs=SIGNALS, P=None, q=None, dec=DEC, n_steps=N_STEPS, **kw):
    monkeypatch.setattr(runner, "TIME_CHUNK", chunk)
    if P is None:
        P, q = batch()
    return simulate_batch(P, list(refs), q, DT, n_steps, dec, **kw)


def same(a: np.ndarray | None, b: np.ndarray | None) -> bool:
    """Bit for bit (NaN payloads included)."""
    if a is None or b is None:
        return a is None and b is None
    return a.shape == b.shape and np.array_equal(a.view(np.int64), b.view(np.int64))


@pytest.fixture(scope="module")
def one_call():
    """The reference results: every variant in one kernel call."""
    mp = pytest.MonkeyPatch()
    try:
        out = {(lanes, par): run(mp, HUGE, lanes=lanes, parallel=par)
               for lanes in (1, kernel.LANES) for par in (False, True)}
    finally:
        mp.undo()
    return out


def test_reference_batch_is_meaningful(one_call):
    # exactly the intended row (and its copy) diverges; the others have finite metrics and
    # signals, step metrics exist for the step rows, the load profile reaches the record
    res = one_call[(1, False)]
    met = res.metrics
    assert np.flatnonzero(met[:, MET["diverged"]] == 1.0).tolist() == [10, 22]
    live = np.delete(np.arange(len(met)), [10, 22])
    assert np.all(np.isfinite(met[live][:, MET["iae_pos"]]))
    assert np.all(np.isfinite(res.signals[live]))
    step_rows = [r for r in live if r % len(SIGNALS) == 0]
    assert np.all(np.isfinite(met[step_rows, MET["overshoot"]]))
    assert np.ptp(res.signals[1, :, SIG["torque_load"]]) > 1.0  # the profile of row 1
    # the diverged row stops part-way: t_end before the duration, NaN samples after it
    t_end = met[10, MET["t_end"]]
    assert 0 < t_end < N_STEPS * DT
    assert np.all(np.isnan(res.signals[10, int(t_end / DT / DEC) + 1:]))
    # the four paths agree with each other (documented bit-identical)
    for key, other in one_call.items():
        assert same(other.metrics, met) and same(other.signals, res.signals), key


@pytest.mark.parametrize("lanes", [1, kernel.LANES])
@pytest.mark.parametrize("parallel", [False, True])
@pytest.mark.parametrize("chunk", [7, 64, N_STEPS])
def test_chunked_run_is_bit_identical_to_one_call(monkeypatch, one_call, lanes, parallel, chunk):
    # 7: boundaries off the recording grid (3), the controller periods and k_ss; 64: a boundary
    # on k_osc = 960; N_STEPS: a last call holding only the final step k = n_steps
    res = run(monkeypatch, chunk, lanes=lanes, parallel=parallel)
    ref = one_call[(lanes, parallel)]
    assert same(res.metrics, ref.metrics)
    assert same(res.signals, ref.signals)


def test_presampled_references_and_samplers_give_the_same_run(monkeypatch, one_call):
    refs = [sample(s, DT, N_STEPS) for s in SIGNALS]
    assert same(run(monkeypatch, 64, refs=refs).signals, one_call[(1, False)].signals)
    prepared = [sampler(s, DT, N_STEPS) for s in SIGNALS]
    assert same(run(monkeypatch, 7, refs=prepared).metrics, one_call[(1, False)].metrics)


def test_metrics_only_run_chunked(monkeypatch):
    P, q = batch(1)
    a = run(monkeypatch, HUGE, P=P, q=q, dec=0, lanes=kernel.LANES)
    b = run(monkeypatch, 5, P=P, q=q, dec=0, lanes=kernel.LANES)
    assert a.signals is None and b.signals is None
    assert same(a.metrics, b.metrics)


@pytest.mark.parametrize("lanes", [1, kernel.LANES])
def test_batch_that_diverges_everywhere_stops_early_with_the_same_results(monkeypatch, lanes):
    bad = np.repeat(np.array([to_row(chunk_configs()[10])]), 3, axis=0)
    n_steps, dec = plan_steps(0.2, DT, 1e-3)  # 20,000 steps; it diverges after ~4.4 ms
    whole = run(monkeypatch, HUGE, refs=SIGNALS[:1], P=bad, q=None, dec=dec, n_steps=n_steps,
                lanes=lanes)
    seen: list[float] = []
    cut = run(monkeypatch, 500, refs=SIGNALS[:1], P=bad, q=None, dec=dec, n_steps=n_steps,
              lanes=lanes, progress=seen.append)
    assert np.all(whole.metrics[:, MET["diverged"]] == 1.0)
    assert same(cut.metrics, whole.metrics) and same(cut.signals, whole.signals)
    # the runner stops calling the kernel once every row has diverged: far fewer than the 41
    # calls of the whole run, the last one reporting completion
    assert len(seen) < 15 and seen[-1] == 1.0


def test_progress_reports_the_fraction_after_each_chunk(monkeypatch):
    seen: list[float] = []
    P = np.array([to_row(resolve())])
    run(monkeypatch, 64, refs=SIGNALS[:1], P=P, q=None, dec=0, n_steps=300,
        progress=seen.append)
    assert seen == [64 / 301, 128 / 301, 192 / 301, 256 / 301, 1.0]


# --------------------------------------------------------------------------------------------
# references sampled per chunk
# --------------------------------------------------------------------------------------------

def chunked(s, n_steps: int, bounds: list[int]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Concatenate s.chunk over [b_i, b_i+1): each chunk's half steps overlap the next one's
    first sample, which is dropped."""
    pos, vel, load = [], [], []
    for k0, k1 in itertools.pairwise(bounds):
        p, v, ld = s.chunk(k0, k1)
        last = k1 == n_steps + 1
        assert len(p) == 2 * (k1 - k0) + (-1 if last else 1) and len(v) == k1 - k0
        pos.append(p if last else p[:-1])
        vel.append(v)
        load.append(ld if last or ld is None else ld[:-1])
    return (np.concatenate(pos), np.concatenate(vel),
            None if load[0] is None else np.concatenate(load))


@pytest.mark.parametrize("dt", [1e-3, 2.0**-10])  # steps of unequal / exactly equal length
@pytest.mark.parametrize("sig", SIGNALS, ids=lambda s: s.kind)
def test_chunks_of_a_reference_equal_the_whole_reference(sig, dt):
    n = 37
    whole = sample(sig, dt, n)
    pieces = chunked(sampler(sig, dt, n), n, [0, 1, 2, 9, 16, 17, 30, 36, 37, 38])
    assert same(pieces[0], whole.pos_half) and same(pieces[1], whole.vel)
    assert same(pieces[2], whole.load_half)


@pytest.mark.parametrize("dt", [1e-3, 2.0**-10])
def test_csv_velocity_is_numpys_gradient_of_the_whole_profile(dt):
    # the definition before time chunks: np.gradient over the whole run, whose formula depends
    # on whether every step of the grid has exactly the same length
    n = 41
    t = np.arange(n + 1) * dt
    uniform = bool(np.all(np.diff(t) == dt))
    assert uniform == (dt == 2.0**-10)
    sig = InputSignal("csv", table=((0.0, 0.013, 0.02, 0.05), (0.0, 1.0, -0.5, 0.25)))
    expected = np.gradient(np.interp(t, *sig.table), t)
    assert same(sample(sig, dt, n).vel, expected)
    assert same(chunked(sampler(sig, dt, n), n, [0, 3, 4, 40, 41, 42])[1], expected)


def test_grid_scan_in_blocks(monkeypatch):
    # the uniform-grid test and the peak reference are computed block by block
    monkeypatch.setattr(signals, "SCAN_STEPS", 4)
    assert signals._uniform_grid(2.0**-10, 50) and not signals._uniform_grid(1e-3, 50)
    sig = InputSignal("sine", 2.0, freq=3.0, offset=0.5)
    assert sampler(sig, 1e-2, 50).max_abs_position() == np.max(np.abs(sample(sig, 1e-2,
                                                                              50).pos_half))


def test_sampler_for_another_grid_and_short_reference_are_refused():
    with pytest.raises(ValueError, match="another time grid"):
        simulate_batch(np.array([to_row(resolve())]), [sampler(SIGNALS[0], DT, 10)], None, DT,
                       11)
    with pytest.raises(ValueError, match="different number of steps"):
        simulate_batch(np.array([to_row(resolve())]), [sample(SIGNALS[0], DT, 10)], None, DT,
                       11)


def test_reference_is_still_a_whole_run_sample():
    ref = sample(SIGNALS[1], DT, 100)
    assert isinstance(ref, Reference)
    assert ref.pos_half.shape == (201,) and ref.vel.shape == (101,)
    assert ref.load_half is not None and ref.load_half.shape == (201,)


# --------------------------------------------------------------------------------------------
# memory
# --------------------------------------------------------------------------------------------

def test_long_metrics_only_run_allocates_nothing_the_size_of_the_run(monkeypatch):
    # 200,000 steps in chunks of 64: the whole-run reference alone would be
    # (2n+1 + n+1) * 8 = 4.8 MB; the peak of all numpy allocations stays a small fraction of that
    n_steps = 200_000
    P = np.array([to_row(resolve())])
    monkeypatch.setattr(runner, "TIME_CHUNK", 64)
    simulate_batch(P, [SIGNALS[1]], None, DT, 200, 0)  # kernel loaded before measuring
    tracemalloc.start()
    try:
        res = simulate_batch(P, [SIGNALS[1]], None, DT, n_steps, 0)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert peak < 16 * n_steps / 50, peak  # < 64 kB
    assert res.metrics[0, MET["t_end"]] == pytest.approx(n_steps * DT)
    assert np.isfinite(res.metrics[0, MET["iae_pos"]])


def test_recording_over_the_budget_is_refused_before_allocating(monkeypatch):
    monkeypatch.setenv(runner.BUDGET_ENV, "1e9")
    P = np.array([to_row(resolve())])
    n_steps, dec = plan_steps(10_000.0, 1e-5, 1e-4)  # 1e8 + 1 samples of 17 signals
    need = ((10**8 + 1) * PAPER_SIGNALS + N_METRICS + N_PARAMS) * 8
    t0 = time.perf_counter()
    with pytest.raises(EmaError) as err:
        simulate_batch(P, [SIGNALS[0]], None, 1e-5, n_steps, dec)
    assert time.perf_counter() - t0 < 5.0  # refused up front, nothing was simulated
    msg = str(err.value)
    assert "\n" not in msg
    assert f"{need / 2**30:.3g} GiB" in msg and "12.7 GiB" in msg
    assert "1 run(s) x 100000001 samples x 17 signals x 8 bytes" in msg
    assert "0.931 GiB" in msg and runner.BUDGET_ENV in msg
    assert "simulation.output_interval_s" in msg and "simulation.duration_s" in msg
    # the same run without recording needs no more than its metrics: accepted (checked only)
    assert runner.check_memory(1, 0, 0) == (N_METRICS + N_PARAMS) * 8


def test_default_budget_is_half_the_available_memory(monkeypatch):
    monkeypatch.delenv(runner.BUDGET_ENV, raising=False)
    budget, source = runner.record_budget()
    if not hasattr(os, "sysconf"):
        assert budget is None
        return
    avail = os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    assert abs(budget - avail // 2) < 0.05 * avail  # available memory moves a little
    assert "half the available memory" in source


@pytest.mark.parametrize("value", ["lots", "-5", "0", "nan"])
def test_bad_budget_variable_names_it(monkeypatch, value):
    monkeypatch.setenv(runner.BUDGET_ENV, value)
    with pytest.raises(EmaError, match=f"{runner.BUDGET_ENV} must be a positive number"):
        runner.record_budget()


# --------------------------------------------------------------------------------------------
# timing: kernel time apart from loading the kernel
# --------------------------------------------------------------------------------------------

def test_kernel_time_excludes_loading_and_calls_compile_nothing_new(monkeypatch):
    P, q = batch(1)
    res = run(monkeypatch, 100, P=P, q=q, lanes=kernel.LANES)
    again = run(monkeypatch, 100, P=P, q=q, lanes=kernel.LANES)
    assert again.load_s == 0.0 and load_kernel(kernel.LANES) == 0.0
    for r in (res, again):
        assert r.kernel_s > 0.0
    # every compiled version of the entry point has a signature load_kernel prepares (one per
    # variant, literal variant arguments): no call compiled anything of its own inside the
    # timed region
    # (other tests in this process may have run other actuators' variants: any variant literal
    # counts, any other argument type would be a compile of its own)
    disp = kernel.KERNELS[True]
    for sig in disp.overloads:
        assert sig == runner.kernel_signature(sig[-1].literal_value)
    prepared = {runner.kernel_signature(v) for v in kernel.VARIANTS[kernel.LANES]}
    assert prepared & set(disp.overloads)
    assert runner.kernel_signature(kernel.variant_args(
        int(kernel.variant_codes(P)[0]), kernel.LANES)) in disp.overloads


def test_load_time_is_reported_on_first_use_in_a_process(monkeypatch):
    P = np.array([to_row(resolve())])
    run(monkeypatch, HUGE, refs=SIGNALS[:1], P=P, q=None, n_steps=10)  # compiled and cached
    code = textwrap.dedent("""
        import numpy as np
        from ema_cli.model.params import resolve, to_row
        from ema_cli.sim.runner import simulate_batch
        from ema_cli.sim.signals import InputSignal
        P = np.array([to_row(resolve())])
        for _ in range(2):
            r = simulate_batch(P, [InputSignal()], None, 1e-5, 10, 3, lanes=1)
            print(r.load_s, r.kernel_s)
    """)
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True, env={**os.environ, "NUMBA_NUM_THREADS": "1"})
    (load1, kern1), (load2, kern2) = (map(float, line.split()) for line in
                                      out.stdout.split("\n")[:2])
    assert load1 > 0.0 and load2 == 0.0
    assert 0.0 < kern1 < 1.0 and 0.0 < kern2 < 1.0


def test_batch_results_name_their_signals():
    from ema_cli.model.params import resolve
    from ema_cli.sim.runner import simulate
    from ema_cli.sim.signals import InputSignal
    from ema_cli.units import DEG

    res = simulate(resolve(), InputSignal(amplitude=2 * DEG), 0.01)
    k = res.signal_names.index("theta_load")
    np.testing.assert_array_equal(res.signal("theta_load"), res.signals[0, :, k])
    np.testing.assert_allclose(res.signal("theta_load_deg", edge=True),
                               res.signals[0, :, k] / DEG, rtol=1e-15)
    assert res.signal("theta_ref", edge=True)[-1] == pytest.approx(2.0, rel=1e-12)
    with pytest.raises(EmaError, match="unknown signal"):
        res.signal("nope")
