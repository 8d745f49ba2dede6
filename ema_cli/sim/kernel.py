"""The batched fixed-step kernel (numba): RK4 across SIMD lanes, exact LuGre bristle update.

The model's equations live in ``ema_cli.model`` (plant, controller, transmission, LuGre,
elements); this module only integrates them, records the signals and accumulates the metrics.

Layout
------
A batch ``P[n_cases, N_PARAMS]`` (columns: ``model.params.PARAMS``) is cut into chunks of up to
``lanes`` configurations. A chunk is advanced *together*: its parameters, states and metric
accumulators are held as ``[quantity, lane]`` work arrays laid out by name (``sim.layout``:
structure of arrays, the lane axis innermost) and every time step is one loop over the lanes
whose body is branch-free (selects, ``min``/``max``, the ``model.vmath`` functions), so the
compiler vectorises it (AVX2 or AVX-512: 4 or 8 lanes per instruction). Blocks of chunks
are spread over threads (``sim.runner``). The time loop of a chunk is compiled once per kernel
*variant*: the actuator's structure as a whole number (``model.actuator``: friction at the
motor and at the load, the extras of the paper cascade, a rigid axis, an amplifier drive and
its bandwidth, the controller, an input signal; the locked motor is a select in all), each a
function of its own that carries only what its lanes need. Variants with a static friction
law (stick-slip) or a sampled controller run one lane at a time: their switching does not
vectorise. The variant is a compile-time argument of the entry points, so a variant is compiled
(or loaded from the cache) only when a batch first needs it; the runner sorts a batch's rows
by variant (``sim.variants``) and calls each variant's entry point for its rows. A lane's step
is ``sim.step``, its integration (RK4, the switches of static friction) ``sim.integrate``.
One configuration is a chunk of one lane: the same code, so a batch equals its single runs bit
for bit, and a serial and a threaded run give identical results (no fast-math, no
reassociation).

Numerics
--------
* RK4 for ``theta_m, w_m, i, theta_L, w_L, xI`` with the reference and the load-torque profile
  sampled at the stage times (half steps).
* The LuGre bristle state is advanced with the exact solution for the motor speed frozen over
  the step and its torque (exact step averages) held over the RK4 stages; the viscous part
  ``sigma2*w_m`` is evaluated at every stage (``model.lugre``).
* Current limit: ``di/dt = 0`` while ``|i| >= sat3`` and pushing outward; ``i`` is clamped to
  ``+-sat3`` after each step. Clamping anti-windup on the speed PI while SAT2 is active.
* Digital controller (``Ts > 0``, a whole number ``Ts/dt`` of steps): the cascade is evaluated
  at the sample instants from the state there, the voltage demand is held until the next one and
  the integral advances by forward Euler; between samples the integral has no rate. The
  described discrete cascade (``model.discrete``) is sampled the same way.
* Static friction (``model.friction``): a site sticks with its speed exactly 0 and breaks away
  when the other forces on its body leave the breakaway band; a slipping site whose speed
  reaches 0 sticks or reverses. The instants of these switches are located inside the step
  (:func:`_hybrid_advance`: regula falsi on RK4 sub-steps, inputs interpolated quadratically
  through the step's three samples), so the integration stays fourth order across them.
* Rigid axis: one body in load coordinates (``model.plant``); the motor's angle and speed are
  set to ``m`` times the load's after every step.
* Locked motor: ``theta_m, w_m, i, xI`` keep their initial 0 (controller and armature off).
* A non-finite state or one past the runaway bounds marks the lane diverged: its metrics are NaN
  except ``diverged = 1`` and ``t_end``; its later samples are NaN. Other lanes are unaffected.

Time chunks
-----------
An entry point advances steps ``k0 <= k < k1`` of a run of ``n_steps`` steps (``k`` runs to
``n_steps`` inclusive: the last step only records and accumulates). Everything that must persist
between calls lives in the caller's state array ``S`` (one work array per chunk of lanes):
the first call (``k0 == 0``) fills it from ``P``, later calls resume from it, and only the call
that reaches the end (``k1 == n_steps + 1``) finishes the metrics. The inputs are given for the
steps of the call only (``ref_pos[:, 2*(k-k0)]`` is the reference at ``t_k``). Every step index
the numerics use (the trapezoid end weights, the steady-state and oscillation windows, the
recording instants, the divergence checks) is absolute, so a run cut into any chunks is bit for
bit the run done in one call. A run done in one call may pass an empty ``S``.
"""

from __future__ import annotations

import numpy as np

from ema_cli._numba import literally, njit
from ema_cli.model.actuator import (
    CTRL_DISCRETE,
    flags_nb,
)
from ema_cli.model.params import N_PARAMS
from ema_cli.sim import layout
from ema_cli.sim.layout import (
    START,
    R,
    lane_params,
    load_acc,
    load_mem,
    load_x,
    record,
    store_acc,
    store_mem,
    store_x,
)
from ema_cli.sim.step import advance_nb, discrete_sample, finish_metrics_nb, init_nb, step_nb
from ema_cli.sim.variants import (  # noqa: F401 (re-exported: the kernel's variant API)
    LANES,
    VARIANTS,
    one_lane_only,
    variant_args,
    variant_codes,
    variant_keys,
    variant_order,
)

N_ROWS = layout.N_ROWS  # rows of a work array (S of the entry points has this many)
ALIVE_ROW = R.alive  # the row of S that is 0 once a lane has diverged
_P0 = START["param"]
_REC0 = START["rec"]
SS_FRACTION = 0.9  # steady-state error: mean over t >= 0.9*T
OSC_FRACTION = 0.8  # residual oscillation: peak-to-peak over t >= 0.8*T
ALIVE_CHECK = 1024  # steps between checks whether a chunk has any running lane left [steps]
_NAN = np.nan


@njit(cache=True, error_model="numpy")
def _steps(W, n_real, ref_pos, ref_vel, load_half, ext_half, qidx, dt, n_steps, k0, k1, dec,
           sig, rows, variant):
    """Advance the lanes of ``W`` over steps ``k0..k1-1`` (see :func:`_run`) in kernel variant
    ``variant``: compiled once per variant, each a function of its own, so the optimiser sees
    (and lays out) one variant at a time."""
    literally(variant)
    nl = W.shape[1]
    k_ss = int(np.ceil(SS_FRACTION * n_steps - 1e-9))
    k_osc = int(np.ceil(OSC_FRACTION * n_steps - 1e-9))
    has_load = load_half.shape[1] > 0
    has_ext = ext_half.shape[1] > 0
    countdown = (dec - k0 % dec) % dec if dec > 0 else 0  # steps until the next recorded sample
    n_alive = n_real
    if k0 > 0:  # resumed: nothing to do once every lane has diverged
        n_alive = 0
        for j in range(n_real):
            n_alive += W[R.alive, j] != 0.0
    for k in range(k0, k1 if n_alive > 0 else k0):
        # this step's inputs per lane (lanes may follow different references)
        cur = 2 * (k - k0)
        nxt = cur + 1 if k < n_steps else cur
        nxt2 = nxt + 1 if k < n_steps else nxt
        for j in range(nl):  # (inline: an array argument costs reference counting per call)
            q = qidx[j if j < n_real else 0]
            W[R.r0, j] = ref_pos[q, cur]
            W[R.r1, j] = ref_pos[q, nxt]
            W[R.r2, j] = ref_pos[q, nxt2]
            W[R.rv, j] = ref_vel[q, k - k0]
            if has_load:
                W[R.l0, j] = load_half[q, cur]
                W[R.l1, j] = load_half[q, nxt]
                W[R.l2, j] = load_half[q, nxt2]
            if has_ext:
                W[R.e0, j] = ext_half[q, cur]
                W[R.e1, j] = ext_half[q, nxt]
                W[R.e2, j] = ext_half[q, nxt2]
        record_now = dec > 0 and countdown == 0
        advance_nb(W, k, dt, n_steps, k >= k_ss, k >= k_osc, record_now, variant)
        if record_now:
            countdown = dec
            row = k // dec
            for j in range(n_real):
                dead = k >= W[R.kend, j]
                for s in range(sig.shape[2]):
                    sig[rows[j], row, s] = _NAN if dead else W[_REC0 + s, j]
        countdown -= 1
        if k % ALIVE_CHECK == ALIVE_CHECK - 1:
            n_alive = 0
            for j in range(n_real):
                n_alive += W[R.alive, j] != 0.0
            if n_alive == 0:
                break  # every lane diverged: the rest of the record stays NaN


@njit(cache=True, forceinline=True, error_model="numpy")
def _run(W, n_real, ref_pos, ref_vel, load_half, ext_half, step_info, qidx, dt, n_steps, k0, k1,
         dec, sig, rows, met, variant):
    """Advance the lanes of the work array ``W`` together over steps ``k0..k1-1`` in the kernel
    variant the caller chose for them (the first ``n_real`` lanes are real, the rest padding
    copies of lane 0): initialise ``W`` when ``k0`` is 0, record the signals of lane ``j`` into
    ``sig[rows[j]]`` and, when the run ends here, write its metrics into ``met[rows[j]]``."""
    if k0 == 0:
        init_nb(W, n_real, step_info, qidx, dt, n_steps)
    _steps(W, n_real, ref_pos, ref_vel, load_half, ext_half, qidx, dt, n_steps, k0, k1, dec, sig,
           rows, variant)
    if k1 > n_steps:
        finish_metrics_nb(W, n_real, dt, n_steps, int(np.ceil(SS_FRACTION * n_steps - 1e-9)), met,
                        rows)


@njit(cache=True, forceinline=True, error_model="numpy")
def _run_one(W, ref_pos, ref_vel, load_half, ext_half, q, dt, n_steps, k0, k1, dec, sig, o, met,
             rows, variant):
    """:func:`_run` for a single lane (row ``o`` of ``sig``) with its states held in registers
    (the same arithmetic, :func:`_step`, without the round trips through W)."""
    literally(variant)
    k_ss = int(np.ceil(SS_FRACTION * n_steps - 1e-9))
    k_osc = int(np.ceil(OSC_FRACTION * n_steps - 1e-9))
    has_load = load_half.shape[1] > 0
    has_ext = ext_half.shape[1] > 0
    x = load_x(W, 0)
    acc = load_acc(W, 0)
    mem = load_mem(W, 0)
    lp = lane_params(W, 0)
    countdown = (dec - k0 % dec) % dec if dec > 0 else 0
    # a lane that diverged in an earlier call stays where it stopped (the rest stays NaN)
    for k in range(k0, k1 if mem.alive != 0.0 else k0):
        cur = 2 * (k - k0)
        nxt = cur + 1 if k < n_steps else cur
        nxt2 = nxt + 1 if k < n_steps else nxt
        # (the arrays indexed here, not in a function: an array argument costs reference
        # counting at every step)
        l0 = load_half[q, cur] if has_load else 0.0
        l1 = load_half[q, nxt] if has_load else 0.0
        l2 = load_half[q, nxt2] if has_load else 0.0
        e0 = ext_half[q, cur] if has_ext else 0.0
        e1 = ext_half[q, nxt] if has_ext else 0.0
        e2 = ext_half[q, nxt2] if has_ext else 0.0
        inp = layout.Inp(ref_pos[q, cur], ref_pos[q, nxt], ref_pos[q, nxt2], ref_vel[q, k - k0],
                         l0, l1, l2, e0, e1, e2)
        dsc = 0.0
        if flags_nb(variant).ctrl == CTRL_DISCRETE:
            dsc = discrete_sample(W, 0, x, inp, mem, lp, variant)
        xn, acc, mem, out = step_nb(x, acc, mem, inp, lp, k, dt, n_steps, k >= k_ss, k >= k_osc,
                                  variant, dsc)
        if dec > 0 and countdown == 0:
            countdown = dec
            record(W, 0, x, inp, out, lp)
            for s in range(sig.shape[2]):
                sig[o, k // dec, s] = W[_REC0 + s, 0]
        countdown -= 1
        x = xn
        if mem.alive == 0.0:
            break  # diverged: the rest of the record stays NaN
    store_x(W, 0, x)
    store_acc(W, 0, acc)
    store_mem(W, 0, mem)
    if k1 > n_steps:
        finish_metrics_nb(W, 1, dt, n_steps, k_ss, met, rows)




# ---- entry points ------------------------------------------------------------------------------
@njit(cache=True, error_model="numpy")
def simulate_chunk_nb(P, a, b, S, g, ref_pos, ref_vel, load_half, ext_half, step_info,
                      ref_index, out_row, dt, n_steps, k0, k1, dec, sig, met, variant):
    """Advance rows ``a..b-1`` of ``P[n_cases, N_PARAMS]`` together in one chunk of
    :data:`LANES` lanes (``b - a <= LANES``; the spare lanes repeat row ``a`` and are dropped)
    over steps ``k0..k1-1``, their work array kept in ``S[g]`` between calls, in kernel variant
    ``variant`` (a compile-time constant, :func:`variant_codes`).

    ref_pos[n_refs, 2*(k1-k0)+1, or 2*(k1-k0)-1 when k1 == n_steps+1] the reference at the half
    steps t = j*dt/2, j = 2*k0, 2*k0+1, ... (rad or m); ref_vel[n_refs, k1-k0] its velocity at
    the steps; load_half and ext_half [n_refs, like ref_pos, or 0 columns: none] the load profile
    (N*m or N) and the input signal (the disturbance or actuation it stands for);
    step_info[n_refs, 3] (is_step, final value, step time s); ref_index[n_cases] the reference
    of each row; out_row[n_cases] the row of sig and met each row of P writes.
    Writes, if ``dec`` > 0, the signals of the steps k0..k1-1 that are multiples of ``dec`` into
    sig[n_cases, n_out, n_sig] (the first ``n_sig`` of ``sim.tables.SIGNALS``) and, if
    k1 == n_steps + 1, the metrics into met[n_cases, N_METRICS].
    """
    W = np.zeros((N_ROWS, LANES))
    if k0 == 0:
        for j in range(b - a):
            for c in range(N_PARAMS):
                W[_P0 + c, j] = P[a + j, c]
    else:
        for r in range(N_ROWS):
            for j in range(LANES):
                W[r, j] = S[g, r, j]
    _run(W, b - a, ref_pos, ref_vel, load_half, ext_half, step_info, ref_index[a:b], dt,
         n_steps, k0, k1, dec, sig, out_row[a:b], met, variant)
    if k1 <= n_steps:
        for r in range(N_ROWS):
            for j in range(LANES):
                S[g, r, j] = W[r, j]


@njit(cache=True, error_model="numpy")
def simulate_one_nb(P, a, S, ref_pos, ref_vel, load_half, ext_half, step_info, ref_index,
                    out_row, dt, n_steps, k0, k1, dec, sig, met, variant):
    """The same as :func:`simulate_chunk_nb` for the single row ``a`` (its work array kept in
    ``S[a]``): a chunk of one lane, its states kept in registers (the fastest path for a few
    configurations; identical results)."""
    W = np.empty((N_ROWS, 1))
    if k0 == 0:
        for r in range(N_ROWS):
            W[r, 0] = P[a, r - _P0] if _P0 <= r < _P0 + N_PARAMS else 0.0
        init_nb(W, 1, step_info, ref_index[a:a + 1], dt, n_steps)
    else:
        for r in range(N_ROWS):
            W[r, 0] = S[a, r, 0]
    rows = out_row[a:a + 1]
    _run_one(W, ref_pos, ref_vel, load_half, ext_half, ref_index[a], dt, n_steps, k0, k1, dec,
             sig, out_row[a], met, rows, variant)
    if k1 <= n_steps:
        for r in range(N_ROWS):
            S[a, r, 0] = W[r, 0]


@njit(cache=True, nogil=True, error_model="numpy", entry=True)
def simulate_rows_nb(P, S, ref_pos, ref_vel, load_half, ext_half, step_info, ref_index, out_row,
                     dt, n_steps, k0, k1, dec, sig, met, variant):
    """Every row of P alone (:func:`simulate_one_nb`, state ``S[n_cases, N_ROWS, 1]``),
    serially; releases the GIL, safe in any thread (the runner spreads blocks of rows over
    threads: ``sim.runner.simulate_batch``)."""
    literally(variant)
    for a in range(P.shape[0]):
        simulate_one_nb(P, a, S, ref_pos, ref_vel, load_half, ext_half, step_info, ref_index,
                        out_row, dt, n_steps, k0, k1, dec, sig, met, variant)


@njit(cache=True, nogil=True, error_model="numpy", entry=True)
def simulate_lanes_nb(P, S, ref_pos, ref_vel, load_half, ext_half, step_info, ref_index, out_row,
                      dt, n_steps, k0, k1, dec, sig, met, variant):
    """Chunks of :data:`LANES` rows of P advanced together (:func:`simulate_chunk_nb`, state
    ``S[n_chunks, N_ROWS, LANES]``), serially; releases the GIL, safe in any thread (the runner
    spreads blocks of whole chunks over threads)."""
    literally(variant)
    n = P.shape[0]
    for ch in range((n + LANES - 1) // LANES):
        a = ch * LANES
        simulate_chunk_nb(P, a, min(a + LANES, n), S, ch, ref_pos, ref_vel, load_half, ext_half,
                          step_info, ref_index, out_row, dt, n_steps, k0, k1, dec, sig, met,
                          variant)


KERNELS = {False: simulate_rows_nb, True: simulate_lanes_nb}
"""Entry points by whether they run in lanes; both take (P, S, ref_pos, ref_vel, load_half,
ext_half, step_info, ref_index, out_row, dt, n_steps, k0, k1, dec, sig, met, variant), see
:func:`simulate_chunk_nb`; ``variant`` is a compile-time constant: each variant is compiled (or
loaded from the cache) the first time it is asked for. Parallel runs call them from threads on
blocks of rows (one compiled entry point serves serial and parallel runs: half the compiling of
separate ``prange`` entry points, same speed on one thread, bit-identical results)."""
