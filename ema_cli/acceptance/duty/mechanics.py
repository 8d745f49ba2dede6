"""The mechanics of each distinct block, simulated once per actuator, reduced to its losses.

For every distinct block (``duty.profile``) the kernel runs a *window* from rest at the block's
start (the static equilibrium under its load: the load angle at the position, the shaft wound
up, the current and the speed PI's integral holding it): a sine or a repeat block runs
``ceil(settle/P)`` periods to settle and two more, a dwell ``settle`` and two averaging windows,
a move its whole duration (and any block shorter than its window whole). The window's first
part is the block's *transient* piece, counted once as it was simulated; the last period is
its steady *cycle*, repeated for the rest of the block. Whether the cycle is steady is checked:
the losses of the last two periods must agree within :data:`PERIODIC_TOL`.

Each block runs at two winding resistances in the same kernel batch: ``R(T_amb)`` (cold) and
``R(T_limit)`` (hot), so the thermal integration can interpolate the current's (small) own
dependence on R between them (``duty.thermal``); every actuator of ``units`` shares the batch
(``ema yield``: the kernel's lanes are independent, each unit's result is its result alone).
The thermal element is off in these runs (R is a parameter): its states are integrated
exactly over hours by ``duty.thermal`` instead.

Every piece is reduced at once to what the rest needs (so memory does not grow with the units):
its losses in at most :data:`MAX_BINS` bins (copper ``i^2``, housing ``P_h``, electromagnetic
``T_m w_m``), integrals for the RMS values, the equivalent load and the energy, peaks, and
at most :data:`MAX_POINTS` operating points for the torque-speed figure.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np

from ema_cli.acceptance.duty.profile import Block, Expanded
from ema_cli.errors import EmaError

RECORD_S = 1e-4  # recording interval of the block simulations [s]
PERIODIC_TOL = 0.01  # the last two periods' losses agree within this share: a steady cycle [-]
DWELL_AVG_S = 0.1  # a long dwell's constant losses: the mean over this window [s]
MAX_BINS = {"transient": 2048, "cycle": 512}  # bins of a piece's loss waveform, at most [-]
MAX_POINTS = 1500  # operating points kept per block for the figure [-]
CHUNK_BYTES = 192 * 2**20  # recorded signals of one kernel call, at most [bytes]
SIGNALS = ("current", "omega_motor", "torque_friction", "torque_shaft", "omega_load",
           "theta_load", "drive_force", "voltage_cmd")
"""The recorded signals the reduction reads (``sim.tables.SIGNALS``)."""


@dataclass
class Piece:
    """One piece of a block on one actuator at one resistance, reduced (SI).

    ``duration`` [s]; the loss waveform in ``n`` equal bins of ``h = duration/n``: ``i2``
    [A^2], ``p_h`` (housing: friction and iron) [W], ``p_em`` (electromagnetic, T_m w_m) [W];
    ``sums``: integrals over the piece (``i2`` A^2 s, ``tm2`` (N*m)^2 s, ``travel`` load-side
    distance, ``fpv`` |F|^p |v| dt, ``p_em`` J); ``peaks``: max |i|, |T_m|, |w_m|, |F| and
    the largest share of the drive's torque-speed envelope used (``model.drive``);
    ``points``: (w_m, T_m) operating points; ``change``: the relative change of the losses
    between the last two periods (NaN: not checked)."""

    duration: float
    i2: np.ndarray
    p_h: np.ndarray
    p_em: np.ndarray
    sums: dict[str, float]
    peaks: dict[str, float]
    points: np.ndarray
    change: float = math.nan

    @property
    def h(self) -> float:
        return self.duration / len(self.i2)


@dataclass
class BlockRun:
    """A distinct block on one actuator: its transient piece and steady cycle at the cold and
    hot resistance (``[cold, hot]``), the periods of the cycle left after the transient
    (``n_rest``, fractional for a dwell's constant window), the two simulation temperatures
    [K] and whether a run diverged."""

    block: int
    transient: list[Piece]
    cycle: list[Piece] | None
    n_rest: float
    temps: tuple[float, float]
    diverged: bool = False
    notes: list[str] = field(default_factory=list)


@dataclass(frozen=True)
class Window:
    """How a block is simulated: ``length`` [s]; the transient piece ``[0, t_tr)``; the cycle
    ``[t_tr, t_tr + cycle)`` (``cycle`` 0: none) compared with the one before it; the cycle's
    repetitions after the transient ``n_rest``."""

    length: float
    t_tr: float
    cycle: float
    n_rest: float


def window(b: Block, settle: float) -> Window:
    """The simulated window of block ``b`` (module docstring)."""
    if b.kind == "move":
        return Window(b.duration, b.duration, 0.0, 0.0)
    if b.kind == "dwell":
        if b.duration <= settle + 2.0 * DWELL_AVG_S:
            return Window(b.duration, b.duration, 0.0, 0.0)
        t_tr = settle + DWELL_AVG_S
        return Window(t_tr + DWELL_AVG_S, t_tr, DWELL_AVG_S,
                      (b.duration - t_tr) / DWELL_AVG_S)
    n_s = max(1, math.ceil(settle / b.period - 1e-9))
    if b.count <= n_s + 2:
        return Window(b.duration, b.duration, 0.0, 0.0)
    return Window((n_s + 2) * b.period, (n_s + 1) * b.period, b.period,
                  float(b.count - n_s - 1))


def rest_state(p: Mapping[str, float], pos: float, force: float) -> dict[str, float]:
    """The initial state holding the load at ``pos`` against the external force ``force``
    (SI): the paper cascade on a compliant armature-driven axis is put in its static
    equilibrium (shaft wound up ``dth``, ``i = T/(m Kt)``, speed-PI integral ``R i/Kis``); any
    other actuator starts at rest at the position (its first moments settle in the transient
    piece)."""
    t_ext = force - p["offset"] - p["k_h"] * pos
    out = {"x0_theta_L": pos, "x0_theta_m": p["m"] * pos}
    if p["rigid"] or p["ctrl"] != 0.0 or p["locked"]:
        return out
    t_sh = -t_ext  # the shaft holds the load
    dth = t_sh / p["kL"] + math.copysign(p["alpha"], t_sh) if t_sh else 0.0
    b = p["fb_motor"]
    th_l = pos - b * dth  # the position fed back sits at the reference
    out.update({"x0_theta_L": th_l, "x0_theta_m": p["m"] * (th_l + dth)})
    if p["drive"] == 0.0:
        i = t_sh / (p["m"] * p["Kt"])
        out["x0_i"] = i
        if p["Kis"] > 0.0:
            out["x0_xI"] = p["R"] * i / p["Kis"]
    return out


def _case_params(p: Mapping[str, float], b: Block, r_ohm: float) -> dict[str, float]:
    from ema_cli.model.params import resolve

    q = dict(p)
    q.update({"thermal": 0.0, "R": r_ohm, "k_h": b.spring,
              "T_load": 0.0 if b.varying_load else b.parts[0].force})
    q.update(rest_state(q, b.start, float(b.load(np.zeros(1))[0])))
    return resolve(q)


def _signal(b: Block, length: float, dt: float) -> object:
    from ema_cli.sim.signals import InputSignal

    load = None
    if b.varying_load:
        n = max(2, int(math.ceil(length / min(1e-3, b.period / 1000.0))) + 1)
        t = np.linspace(0.0, length, n)
        load = (tuple(t), tuple(b.load(t)))
    if b.pure_sine and load is None:
        p = b.parts[0]
        return InputSignal(kind="sine", amplitude=p.amp, freq=p.freq, offset=p.p0)
    h = max(dt, min(1e-3, b.period / 2000.0))
    n = int(math.ceil(length / h)) + 1
    t = np.arange(n) * h
    return InputSignal(kind="csv", table=(tuple(t), tuple(b.position(t))), load_table=load,
                       path=b.key)


def simulate_blocks(exps: Sequence[Expanded], units: Sequence[Mapping[str, float]], dt: float,
                    settle: float, limit_k: float, life_exp: float = 3.0,
                    progress: Callable[[str, int, int], None] | None = None
                    ) -> list[list[BlockRun]]:
    """Every distinct block of the profile on every actuator of ``units`` (SI parameters), the
    profile expanded for each (``exps[u]``: the same motion, each unit's own ambient) ->
    ``runs[unit][block]``; ``limit_k`` the hot simulation's winding temperature [K];
    ``life_exp`` the exponent of the equivalent load (``sum |F|^p |v| dt``)."""
    from ema_cli.limits import check_steps

    exp = exps[0]
    if any(len(e.blocks) != len(exp.blocks) or any(
            b.signature()[3:] != c.signature()[3:] or b.start != c.start
            for b, c in zip(e.blocks, exp.blocks, strict=True)) for e in exps):
        raise EmaError("duty: the units' profiles differ in more than their ambient")
    wins = [window(b, settle) for b in exp.blocks]
    two = [2 if p["drive"] == 0.0 else 1 for p in units]
    check_steps(sum(w.length for w in wins) / dt * sum(two), "the profile's block simulations",
                "shorten the settling (simulation.settle_s) or raise simulation.dt_s")
    from ema_cli.progress import report

    out: list[list[BlockRun]] = [[] for _ in units]
    for k, (b, w) in enumerate(zip(exp.blocks, wins, strict=True)):
        report(f"segment {k + 1}/{len(exp.blocks)} {b.label}")
        if progress is not None:
            progress(f"segment {k + 1}/{len(exp.blocks)} {b.label}", k, len(exp.blocks))
        amb = [e.blocks[k].ambient_k for e in exps]
        for u, run in enumerate(_block_runs(b, k, w, units, amb, two, dt, limit_k, life_exp)):
            out[u].append(run)
    return out


def _block_runs(b: Block, k: int, w: Window, units: Sequence[Mapping[str, float]],
                ambients: list[float], two: list[int], dt: float, limit_k: float,
                life_exp: float) -> list[BlockRun]:
    from ema_cli.model.params import to_row
    from ema_cli.model.thermal import resistance_nb
    from ema_cli.sim.runner import simulate_batch
    from ema_cli.sim.tables import SIG

    dec = max(1, round(RECORD_S / dt))
    n_steps = max(dec, math.ceil(w.length / dt - 1e-6))  # the window, whole steps
    n_out = n_steps // dec + 1
    n_sig = max(SIG[s] for s in SIGNALS) + 1
    rows, owner = [], []
    for u, p in enumerate(units):
        temps = (ambients[u], limit_k)
        for j in range(two[u]):
            r = resistance_nb.py_func(p["R"], p["alpha_cu"], temps[j], p["T_ref"])
            rows.append(to_row(_case_params(p, b, r)))
            owner.append((u, j))
    sig = _signal(b, w.length, dt)
    per = max(1, CHUNK_BYTES // (n_out * n_sig * 8))
    pieces: dict[tuple[int, int], tuple[Piece, Piece | None, bool]] = {}
    for a in range(0, len(rows), per):
        P = np.array(rows[a:a + per])
        res = simulate_batch(P, [sig], None, dt, n_steps, dec, parallel=len(P) > 1,
                             n_signals=n_sig)
        for c in range(len(P)):
            pieces[owner[a + c]] = _reduce(res, c, units[owner[a + c][0]], b, w, dec * dt,
                                           life_exp)
    out = []
    for u in range(len(units)):
        tr = [pieces[(u, j)][0] for j in range(two[u])]
        cy = [pieces[(u, j)][1] for j in range(two[u])]
        div = any(pieces[(u, j)][2] for j in range(two[u]))
        if two[u] == 1:  # an amplifier: R does not enter the mechanics
            tr, cy = tr * 2, cy * 2
        run = BlockRun(k, tr, None if cy[0] is None else cy, w.n_rest,  # type: ignore[arg-type]
                       (ambients[u], limit_k), div)
        if div:
            run.notes.append(f"{b.key}: the simulation diverged (check the actuator, or lower "
                             "simulation.dt_s)")
        out.append(run)
    return out


def _reduce(res: object, c: int, p: Mapping[str, float], b: Block, w: Window, h: float,
            life_exp: float) -> tuple[Piece, Piece | None, bool]:
    """Case ``c`` of a block's batch -> (transient piece, steady cycle or None, diverged)."""
    from ema_cli.model.drive import torque_envelope
    from ema_cli.sim.tables import SIG

    s = res.signals[c]  # type: ignore[attr-defined]
    div = bool(res.diverged[c])  # type: ignore[attr-defined]
    cur = s[:, SIG["current"]]
    w_m = s[:, SIG["omega_motor"]]
    t_f = s[:, SIG["torque_friction"]]
    t_m = p["Kt"] * cur
    f_out = (s[:, SIG["drive_force"]] - p["m"] * (p["bm"] * w_m + t_f) if p["rigid"]
             else s[:, SIG["torque_shaft"]])
    v_l = s[:, SIG["omega_load"]]
    p_h = (p["fric_heat"] * (p["bm"] * w_m + t_f) * w_m + p["fe_hyst"] * np.abs(w_m)
           + p["fe_eddy"] * w_m * w_m)
    with np.errstate(divide="ignore", invalid="ignore"):
        env = np.abs(t_m) / torque_envelope(p, w_m, t_m)
    data = {"i2": cur * cur, "p_h": p_h, "p_em": t_m * w_m, "cur": cur, "t_m": t_m, "w_m": w_m,
            "f": f_out, "v": v_l, "env": np.where(np.isfinite(env), env, np.inf),
            "p": np.array([life_exp])}
    if div:
        data = {k: np.nan_to_num(v, nan=0.0) for k, v in data.items()}

    def idx(t: float) -> int:
        return min(int(round(t / h)), len(cur) - 1)

    k_tr = max(1, idx(w.t_tr)) if w.cycle else len(cur) - 1
    tr = _piece(data, 0, k_tr, w.t_tr if w.cycle else w.length, "transient")
    if not w.cycle:
        return tr, None, div
    k_end = max(k_tr + 1, idx(w.t_tr + w.cycle))
    cyc = _piece(data, k_tr, k_end, w.cycle, "cycle")
    k_prev = max(0, k_tr - (k_end - k_tr))
    before = _piece(data, k_prev, k_tr, w.cycle, "cycle")
    now = float(np.mean(cyc.i2)) * p["R"] + float(np.mean(cyc.p_h))
    then = float(np.mean(before.i2)) * p["R"] + float(np.mean(before.p_h))
    cyc.change = abs(now - then) / max(abs(now), abs(then), 1e-12)
    return tr, cyc, div


def _piece(d: Mapping[str, np.ndarray], a: int, b: int, duration: float, kind: str) -> Piece:
    """Samples ``[a, b)`` of a case as a :class:`Piece` lasting ``duration`` [s]."""
    n = b - a
    if n <= 0:
        raise EmaError("a block's window holds no recorded sample (internal: window too short)")
    bins = min(n, MAX_BINS[kind])
    edges = np.linspace(0, n, bins + 1).round().astype(int)[:-1] + a
    counts = np.diff(np.append(edges, b))

    def binned(x: np.ndarray) -> np.ndarray:
        return np.add.reduceat(x[a:b], edges - a) / counts

    hs = duration / n  # each sample's share of the piece's true duration
    v = np.abs(d["v"][a:b])
    f = np.abs(d["f"][a:b])
    sums = {"i2": float(np.sum(d["i2"][a:b]) * hs),
            "tm2": float(np.sum(d["t_m"][a:b] ** 2) * hs),
            "travel": float(np.sum(v) * hs),
            "fpv": float(np.sum(f ** d["p"][0] * v) * hs),
            "p_em": float(np.sum(d["p_em"][a:b]) * hs)}
    peaks = {"cur": float(np.max(np.abs(d["cur"][a:b]))),
             "t_m": float(np.max(np.abs(d["t_m"][a:b]))),
             "w_m": float(np.max(np.abs(d["w_m"][a:b]))), "f": float(np.max(f)),
             "env": float(np.max(d["env"][a:b]))}
    step = max(1, n // (MAX_POINTS // 2))
    pts = np.column_stack([d["w_m"][a:b:step], d["t_m"][a:b:step]])
    return Piece(duration, binned(d["i2"]), binned(d["p_h"]), binned(d["p_em"]), sums, peaks,
                 pts)
