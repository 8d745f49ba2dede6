"""The thermal network over a whole profile, integrated exactly piece by piece (multirate).

The two-node network of ``model/thermal.py`` is linear in the temperatures once the copper
loss is written ``i^2 R0 (1 + alpha (T_w - T_ref))``: over any interval where ``i^2`` and the
housing losses are constant it is ``dx/dt = A x + b`` with constant ``A`` and ``b``, whose exact
flow is ``model.thermal.flow_nb`` (the 2x2 matrix exponential). The blocks' losses
(``duty.mechanics``) are integrated that way:

* a *transient* piece (a block's first moments, or a whole short block) bin by bin: each bin's
  exact flow, composed; R(T) is exact inside every bin;
* a steady *cycle* repeated ``n`` times either **averaged** (tier A) when its period ``P`` is at
  most :data:`CYCLE_RATIO` of the network's fast time constant: the cycle's mean losses over
  chunks of whole cycles (at most ``tau_fast/8`` each) with the flow of each chunk, the peak
  raised by the winding's ripple (the upward excursion of ``(1/C_w) integral (P_cu - mean)``,
  whose neglected conduction is at most ``P/tau_fast`` of it); or **cycle by cycle** (tier B)
  otherwise: the cycle's map ``x -> Phi x + gamma`` composed from its bins, applied per chunk
  (``Phi^m``), the peak read inside the first and last cycle of each chunk.

The current's own (small) dependence on R, through the mechanics, is interpolated between the
block's cold and hot simulations at the winding temperature where each piece or chunk starts:
the maps are linear in it to first order. Every quantity is SI inside (K, W, s); the trace is
returned in K.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np

from ema_cli._numba import njit
from ema_cli.acceptance.duty.mechanics import BlockRun, Piece
from ema_cli.acceptance.duty.profile import Expanded
from ema_cli.model.thermal import flow_nb, time_constants

CYCLE_RATIO = 0.05  # a cycle is averaged when its period is at most this share of tau_fast [-]
CHUNK_TAU = 0.125  # chunks of repeated cycles last at most this share of tau_fast [-]
MAX_CHUNKS = 20000  # chunks of one block's cycles, at most (longer chunks beyond) [-]
LIFE_STEP_K = 10.0  # insulation life halves every this many kelvin (the 10 K rule) [K]
STATS_POINTS = 128  # points of a cycle its peak, life and time above are read at, at most [-]


@dataclass(frozen=True)
class Network:
    """The network and resistance of one actuator (SI): conductances [W/K], capacities [J/K],
    R0 at ``t_ref`` [ohm, K], its temperature coefficient [1/K]."""

    g_wh: float
    g_ha: float
    c_w: float
    c_h: float
    r0: float
    alpha: float
    t_ref: float

    @classmethod
    def of(cls, p: Mapping[str, float]) -> Network:
        return cls(1.0 / p["Rth_wh"], 1.0 / p["Rth_ha"], p["Cth_w"], p["Cth_h"], p["R"],
                   p["alpha_cu"], p["T_ref"])

    @property
    def array(self) -> np.ndarray:
        return np.array([self.g_wh, self.g_ha, self.c_w, self.c_h, self.r0, self.alpha,
                         self.t_ref])

    def rho(self, temp: float) -> float:
        """R(T) [ohm]."""
        return self.r0 * (1.0 + self.alpha * (temp - self.t_ref))

    def tau_fast(self) -> float:
        return time_constants({"Rth_wh": 1 / self.g_wh, "Rth_ha": 1 / self.g_ha,
                               "Cth_w": self.c_w, "Cth_h": self.c_h})[0]


@njit(cache=True, error_model="numpy", entry=True)
def _coeffs_nb(i2, p_h, t_amb, net):
    g_wh, g_ha, c_w, c_h, r0, alpha, t_ref = net[0], net[1], net[2], net[3], net[4], net[5], \
        net[6]
    return ((-g_wh + i2 * r0 * alpha) / c_w, g_wh / c_w, g_wh / c_h, -(g_wh + g_ha) / c_h,
            i2 * r0 * (1.0 - alpha * t_ref) / c_w, (p_h + g_ha * t_amb) / c_h)


@njit(cache=True, error_model="numpy", entry=True)
def prefix_nb(i2, p_h, h, t_amb, net, scale):
    """The maps from a piece's start to the end of each bin: ``x_j = Psi[j] x + g[j]``, each
    bin's losses constant (``i2*scale`` [A^2], ``p_h`` [W]) over ``h`` [s]."""
    n = i2.shape[0]
    psi = np.empty((n, 2, 2))
    g = np.empty((n, 2))
    p11, p12, p21, p22, q1, q2 = 1.0, 0.0, 0.0, 1.0, 0.0, 0.0
    for j in range(n):
        a11, a12, a21, a22, b1, b2 = _coeffs_nb(i2[j] * scale, p_h[j], t_amb, net)
        e11, e12, e21, e22, f1, f2 = flow_nb(a11, a12, a21, a22, b1, b2, h)
        p11, p12, p21, p22 = (e11 * p11 + e12 * p21, e11 * p12 + e12 * p22,
                              e21 * p11 + e22 * p21, e21 * p12 + e22 * p22)
        q1, q2 = e11 * q1 + e12 * q2 + f1, e21 * q1 + e22 * q2 + f2
        psi[j, 0, 0], psi[j, 0, 1], psi[j, 1, 0], psi[j, 1, 1] = p11, p12, p21, p22
        g[j, 0], g[j, 1] = q1, q2
    return psi, g


def flow(net: Network, i2: float, p_h: float, t_amb: float, h: float
         ) -> tuple[np.ndarray, np.ndarray]:
    """The exact map over ``h`` [s] with constant losses -> (E[2, 2], f[2])."""
    e11, e12, e21, e22, f1, f2 = flow_nb(*_coeffs_nb(i2, p_h, t_amb, net.array), h)
    return np.array([[e11, e12], [e21, e22]]), np.array([f1, f2])


@dataclass
class Trace:
    """The temperatures over the profile, one row per interval (a bin of a transient, a chunk
    of cycles): its end time [s], the winding and housing temperature there [K], the winding's
    peak inside the interval [K], the ambient [K], the copper and housing losses' means [W],
    the block it belongs to."""

    t: list[float] = field(default_factory=list)
    t_w: list[float] = field(default_factory=list)
    t_h: list[float] = field(default_factory=list)
    peak: list[float] = field(default_factory=list)
    ambient: list[float] = field(default_factory=list)
    p_cu: list[float] = field(default_factory=list)
    p_h: list[float] = field(default_factory=list)
    block: list[int] = field(default_factory=list)

    def add(self, t: np.ndarray, x: np.ndarray, peak: np.ndarray, amb: float, p_cu: np.ndarray,
            p_h: np.ndarray, block: int) -> None:
        self.t += list(np.atleast_1d(t))
        self.t_w += list(np.atleast_1d(x[..., 0]))
        self.t_h += list(np.atleast_1d(x[..., 1]))
        self.peak += list(np.atleast_1d(peak))
        n = np.atleast_1d(t).size
        self.ambient += [amb] * n
        self.p_cu += list(np.broadcast_to(p_cu, (n,)))
        self.p_h += list(np.broadcast_to(p_h, (n,)))
        self.block += [block] * n


@dataclass
class Thermal:
    """The thermal result of one actuator over the profile (SI): the winding's and housing's
    peaks [K], the time above ``limit`` [s], the insulation's equivalent hours at its class
    temperature [h], the copper and housing loss energies [J], the trace, each block's method
    (``whole``, ``average``, ``cycle``) and the error estimate of the winding peak [K] by
    source."""

    peak_w: float
    peak_h: float
    time_above: float
    life_h: float
    copper_j: float
    housing_j: float
    trace: Trace
    methods: dict[int, str]
    errors: dict[str, float]
    end: np.ndarray

    @property
    def error_k(self) -> float:
        return float(sum(self.errors.values()))


class _Maps:
    """Each piece's bin maps (cold and hot), computed once per integration."""

    def __init__(self, net: Network, scale: float) -> None:
        self.net, self.scale, self.arr = net, scale, net.array
        self.cache: dict[tuple[int, str, int, float], tuple[np.ndarray, np.ndarray]] = {}

    def get(self, key: tuple[int, str, int, float], piece: Piece) -> tuple[np.ndarray,
                                                                            np.ndarray]:
        if key not in self.cache:
            self.cache[key] = prefix_nb(piece.i2, piece.p_h, piece.h, key[3], self.arr,
                                        self.scale)
        return self.cache[key]


def _weight(run: BlockRun, temp: float) -> float:
    """Where ``temp`` lies between the block's cold and hot simulation temperatures (the
    interpolation weight of their currents), kept within [-0.5, 2]."""
    t_c, t_h = run.temps
    return float(np.clip((temp - t_c) / (t_h - t_c), -0.5, 2.0)) if t_h != t_c else 0.0


def _mix(pair: Sequence[np.ndarray], w: float) -> np.ndarray:
    return (1.0 - w) * pair[0] + w * pair[1]


def integrate(exp: Expanded, runs: Sequence[BlockRun], net: Network, limit_k: float,
              class_k: float, scale: float = 1.0, initial_k: float | None = None) -> Thermal:
    """The network over the profile ``exp`` with each block's losses (``runs[block]``), the
    currents scaled by ``scale`` (``i^2 -> scale^2 i^2``: the current margin), from
    ``initial_k`` (default: the first block's ambient) [K]; ``limit_k`` the winding's limit,
    ``class_k`` its insulation class temperature [K]."""
    maps = _Maps(net, scale * scale)
    t0 = exp.blocks[exp.order[0]].ambient_k if initial_k is None else initial_k
    x = np.array([t0, t0])
    tr = Trace()
    st = {"t": 0.0, "peak_w": t0, "peak_h": t0, "above": 0.0, "life": 0.0, "cu": 0.0, "ph": 0.0}
    tau = net.tau_fast()
    methods: dict[int, str] = {}
    errors = {"ripple": 0.0, "periodicity": 0.0, "interpolation": 0.0}
    for bi in exp.order:
        run, amb = runs[bi], exp.blocks[bi].ambient_k
        x = _transient(run, bi, amb, x, maps, st, tr, limit_k, class_k)
        if run.cycle is None:
            methods[bi] = "whole"
            continue
        period = run.cycle[0].duration
        tier_a = period <= CYCLE_RATIO * tau
        methods[bi] = "average" if tier_a else "cycle"
        rise0 = x[0] - amb
        x = (_average if tier_a else _cycles)(run, bi, amb, x, maps, st, tr, limit_k, class_k,
                                              tau)
        rise = max(abs(x[0] - amb), abs(rise0))
        errors["periodicity"] = max(errors["periodicity"], run.cycle[0].change * rise)
        m_c, m_h = (float(np.mean(c.i2)) for c in run.cycle)
        if max(m_c, m_h) > 0:
            delta = abs(m_h - m_c) / max(m_c, m_h)
            errors["interpolation"] = max(errors["interpolation"], delta * rise / 8.0)
        if tier_a:
            up = max(_ripple(c) for c in run.cycle) * net.rho(x[0]) * scale * scale / net.c_w
            errors["ripple"] = max(errors["ripple"], up * period / tau)
    return Thermal(st["peak_w"], st["peak_h"], st["above"], st["life"] / 3600.0, st["cu"],
                   st["ph"], tr, methods, errors, x)


def _account(st: dict, t_w: np.ndarray, peak: np.ndarray, t_h: np.ndarray, dur: np.ndarray,
             p_cu: np.ndarray, p_h: np.ndarray, limit_k: float, class_k: float) -> None:
    """Add intervals (winding temperature, peak, housing, duration, losses) to the totals."""
    st["peak_w"] = max(st["peak_w"], float(np.max(peak)))
    st["peak_h"] = max(st["peak_h"], float(np.max(t_h)))
    st["above"] += float(np.sum(dur * (peak > limit_k)))
    st["life"] += float(np.sum(dur * np.exp2((t_w - class_k) / LIFE_STEP_K)))
    st["cu"] += float(np.sum(p_cu * dur))
    st["ph"] += float(np.sum(p_h * dur))
    st["t"] += float(np.sum(dur))


def _transient(run: BlockRun, bi: int, amb: float, x: np.ndarray, maps: _Maps, st: dict,
               tr: Trace, limit_k: float, class_k: float) -> np.ndarray:
    w = _weight(run, x[0])
    pc = [maps.get((bi, "tr", j, amb), run.transient[j]) for j in (0, 1)]
    psi, g = _mix([p[0] for p in pc], w), _mix([p[1] for p in pc], w)
    traj = psi @ x + g
    piece = run.transient[0]
    h = piece.h
    i2 = _mix([p.i2 for p in run.transient], w) * maps.scale
    p_h = _mix([p.p_h for p in run.transient], w)
    before = np.concatenate([[x[0]], traj[:-1, 0]])
    mid = 0.5 * (before + traj[:, 0])
    p_cu = i2 * (maps.net.r0 * (1.0 + maps.net.alpha * (mid - maps.net.t_ref)))
    peak = np.maximum(before, traj[:, 0])
    _account(st, mid, peak, traj[:, 1], np.full(len(i2), h), p_cu, p_h, limit_k, class_k)
    t = st["t"] - piece.duration + h * np.arange(1, len(i2) + 1)
    every = max(1, len(i2) // 64)  # the trace: every bin would be too fine
    sl = slice(every - 1, None, every)
    tr.add(t[sl], traj[sl], _window_max(peak, every), amb, _window_mean(p_cu, every),
           _window_mean(p_h, every), bi)
    return traj[-1].copy()


def _window_max(a: np.ndarray, k: int) -> np.ndarray:
    n = (len(a) // k) * k
    return a[:n].reshape(-1, k).max(axis=1)


def _window_mean(a: np.ndarray, k: int) -> np.ndarray:
    n = (len(a) // k) * k
    return a[:n].reshape(-1, k).mean(axis=1)


def _ripple(c: Piece) -> float:
    """The upward excursion of ``integral (i^2 - mean) dt`` over one cycle [A^2 s]: times
    ``R(T)/C_w`` the winding's ripple above its cycle mean."""
    e = np.cumsum((c.i2 - np.mean(c.i2)) * c.h)
    return float(np.max(e - np.mean(e))) if len(e) else 0.0


def _chunks(n: float, period: float, tau: float) -> list[float]:
    """The cycles of each chunk: whole cycles, at most ``CHUNK_TAU*tau`` long each (longer
    when that makes more than :data:`MAX_CHUNKS`); a fractional rest last."""
    m = max(1.0, math.floor(CHUNK_TAU * tau / period))
    m = max(m, math.ceil(n / MAX_CHUNKS))
    full = int(n // m)
    out = [m] * full
    rest = n - full * m
    if rest > 1e-9:
        out.append(rest)
    return out


@njit(cache=True, error_model="numpy", entry=True)
def average_nb(i2_c, i2_h, ph_c, ph_h, up_c, up_h, x0, x1, chunks, temps, net, amb, limit_k,
               class_k, period):
    """Tier A (:func:`_average`): chunks of ``chunks[k]`` cycles with the cycle's mean losses
    (cold and hot ``i2_*`` [A^2], ``ph_*`` [W], interpolated at each chunk's start), each
    chunk's exact flow; the peak is the chunk's larger end plus the ripple ``up_* R(T)/C_w``
    -> rows (duration, T_w, T_h, peak, copper W, housing W) and the totals (as
    :func:`cycles_nb`)."""
    rows = np.empty((chunks.shape[0], 6))
    tot = np.zeros(6)
    tot[0] = -1e300
    tot[1] = -1e300
    for k in range(chunks.shape[0]):
        w = 0.0
        if temps[1] != temps[0]:
            w = min(max((x0 - temps[0]) / (temps[1] - temps[0]), -0.5), 2.0)
        i2 = (1.0 - w) * i2_c + w * i2_h
        p_h = (1.0 - w) * ph_c + w * ph_h
        dur = chunks[k] * period
        a11, a12, a21, a22, b1, b2 = _coeffs_nb(i2, p_h, amb, net)
        e11, e12, e21, e22, f1, f2 = flow_nb(a11, a12, a21, a22, b1, b2, dur)
        y0 = e11 * x0 + e12 * x1 + f1
        y1 = e21 * x0 + e22 * x1 + f2
        hi = max(x0, y0)
        up = ((1.0 - w) * up_c + w * up_h) * net[4] * (1.0 + net[5] * (hi - net[6])) / net[2]
        peak = hi + up
        mid = 0.5 * (x0 + y0)
        cu = i2 * net[4] * (1.0 + net[5] * (mid - net[6]))
        # the share of the chunk above the limit: the (linear) mean plus the ripple
        a, b = x0 + up - limit_k, y0 + up - limit_k
        share = 1.0 if (a > 0.0 and b > 0.0) else 0.0
        if (a > 0.0) != (b > 0.0):
            share = max(a, b) / abs(b - a)
        rows[k, 0], rows[k, 1], rows[k, 2] = dur, y0, y1
        rows[k, 3], rows[k, 4], rows[k, 5] = peak, cu, p_h
        tot[0] = max(tot[0], peak)
        tot[1] = max(tot[1], max(x1, y1))
        tot[2] += dur * share
        tot[3] += dur * 0.5 * (2.0 ** ((x0 - class_k) / LIFE_STEP_K)
                               + 2.0 ** ((y0 - class_k) / LIFE_STEP_K))
        tot[4] += dur * cu
        tot[5] += dur * p_h
        x0, x1 = y0, y1
    return rows, tot


def _average(run: BlockRun, bi: int, amb: float, x: np.ndarray, maps: _Maps, st: dict,
             tr: Trace, limit_k: float, class_k: float, tau: float) -> np.ndarray:
    """Tier A: the cycle's mean losses over chunks of cycles, each chunk's exact flow."""
    cyc = run.cycle
    assert cyc is not None
    period = cyc[0].duration
    sc = maps.scale
    chunks = np.array(_chunks(run.n_rest, period, tau), dtype=float)
    rows, tot = average_nb(float(np.mean(cyc[0].i2)) * sc, float(np.mean(cyc[1].i2)) * sc,
                           float(np.mean(cyc[0].p_h)), float(np.mean(cyc[1].p_h)),
                           _ripple(cyc[0]) * sc, _ripple(cyc[1]) * sc, float(x[0]),
                           float(x[1]), chunks, np.array(run.temps, dtype=float), maps.arr,
                           amb, limit_k, class_k, period)
    return _totals(st, tr, rows, tot, amb, bi)


def _totals(st: dict, tr: Trace, rows: np.ndarray, tot: np.ndarray, amb: float,
            bi: int) -> np.ndarray:
    """Add a tier's rows and totals to the run's -> the state at its end."""
    st["peak_w"] = max(st["peak_w"], float(tot[0]))
    st["peak_h"] = max(st["peak_h"], float(tot[1]))
    st["above"] += float(tot[2])
    st["life"] += float(tot[3])
    st["cu"] += float(tot[4])
    st["ph"] += float(tot[5])
    t = st["t"] + np.cumsum(rows[:, 0])
    st["t"] = float(t[-1])
    tr.add(t, rows[:, 1:3], rows[:, 3], amb, rows[:, 4], rows[:, 5], bi)
    return rows[-1, 1:3].copy()


@njit(cache=True, error_model="numpy")
def _apply_nb(p, g, x0, x1):
    """``(p x + g)`` for a 2x2 ``p``, a 2-vector ``g`` and the state ``(x0, x1)``."""
    return p[0, 0] * x0 + p[0, 1] * x1 + g[0], p[1, 0] * x0 + p[1, 1] * x1 + g[1]


@njit(cache=True, error_model="numpy")
def _cycle_stats_nb(psi, g, dpsi, dg, w, x0, x1, i2, di2, net, limit_k, class_k, stride):
    """Inside one cycle from ``(x0, x1)``, the maps ``psi + w dpsi``, ``g + w dg`` read every
    ``stride`` bins (and at the end): (max T_w, mean 2^((T_w - class)/10), share above the
    limit, mean copper loss, max T_h)."""
    n = psi.shape[0]
    peak = -1e300
    peak_h = -1e300
    life = 0.0
    above = 0.0
    cu = 0.0
    count = 0
    j = stride - 1
    while True:
        if j > n - 1:
            j = n - 1
        tw = ((psi[j, 0, 0] + w * dpsi[j, 0, 0]) * x0 + (psi[j, 0, 1] + w * dpsi[j, 0, 1]) * x1
              + g[j, 0] + w * dg[j, 0])
        th = ((psi[j, 1, 0] + w * dpsi[j, 1, 0]) * x0 + (psi[j, 1, 1] + w * dpsi[j, 1, 1]) * x1
              + g[j, 1] + w * dg[j, 1])
        peak = max(peak, tw)
        peak_h = max(peak_h, th)
        life += math.exp((tw - class_k) * (math.log(2.0) / LIFE_STEP_K))
        above += 1.0 if tw > limit_k else 0.0
        cu += (i2[j] + w * di2[j]) * net[4] * (1.0 + net[5] * (tw - net[6]))
        count += 1
        if j == n - 1:
            break
        j += stride
    return peak, life / count, above / count, cu / count, peak_h


@njit(cache=True, error_model="numpy", entry=True)
def cycles_nb(psi_c, g_c, psi_h, g_h, i2_c, i2_h, ph_c, ph_h, x0, x1, chunks, temps, net,
              limit_k, class_k, period):
    """Tier B (:func:`_cycles`): chunks of ``chunks[k]`` whole cycles from ``(x0, x1)`` [K],
    the currents interpolated at each chunk's start between the cold and hot simulation
    ``temps`` -> rows (duration, T_w, T_h, peak, copper W, housing W) and the totals (peak
    T_w, peak T_h, time above, life integral, copper J, housing J). Inside a cycle the
    statistics read :data:`STATS_POINTS` points of it at most (the map itself composes every
    bin)."""
    n = psi_c.shape[0]
    stride = max(1, n // STATS_POINTS)
    rows = np.empty((chunks.shape[0], 6))
    tot = np.zeros(6)
    tot[0] = -1e300
    tot[1] = -1e300
    dpsi = psi_h - psi_c
    dg = g_h - g_c
    di2 = i2_h - i2_c
    for k in range(chunks.shape[0]):
        w = 0.0
        if temps[1] != temps[0]:
            w = min(max((x0 - temps[0]) / (temps[1] - temps[0]), -0.5), 2.0)
        p_h = (1.0 - w) * ph_c + w * ph_h
        m = int(chunks[k] + 0.5)
        phi = psi_c[n - 1] + w * dpsi[n - 1]
        gam = g_c[n - 1] + w * dg[n - 1]
        first = _cycle_stats_nb(psi_c, g_c, dpsi, dg, w, x0, x1, i2_c, di2, net, limit_k,
                                class_k, stride)
        # the state at the start of the chunk's last cycle: m - 1 applications of the map
        y0, y1 = x0, x1
        if m - 1 <= 64:
            for _ in range(m - 1):
                y0, y1 = _apply_nb(phi, gam, y0, y1)
        else:
            pm = np.eye(2)
            base = phi.copy()
            e = m - 1
            while e > 0:
                if e & 1:
                    pm = pm @ base
                base = base @ base
                e >>= 1
            s = np.linalg.solve(np.eye(2) - phi, (np.eye(2) - pm) @ gam)
            y0, y1 = (pm[0, 0] * x0 + pm[0, 1] * x1 + s[0], pm[1, 0] * x0 + pm[1, 1] * x1 + s[1])
        last = _cycle_stats_nb(psi_c, g_c, dpsi, dg, w, y0, y1, i2_c, di2, net, limit_k,
                               class_k, stride)
        e0, e1 = _apply_nb(phi, gam, y0, y1)
        dur = chunks[k] * period
        peak = max(first[0], last[0])
        cu = 0.5 * (first[3] + last[3])
        rows[k, 0], rows[k, 1], rows[k, 2] = dur, e0, e1
        rows[k, 3], rows[k, 4], rows[k, 5] = peak, cu, p_h
        tot[0] = max(tot[0], peak)
        tot[1] = max(tot[1], max(first[4], last[4]))
        tot[2] += dur * 0.5 * (first[2] + last[2])
        tot[3] += dur * 0.5 * (first[1] + last[1])
        tot[4] += dur * cu
        tot[5] += dur * p_h
        x0, x1 = e0, e1
    return rows, tot


def _cycles(run: BlockRun, bi: int, amb: float, x: np.ndarray, maps: _Maps, st: dict,
            tr: Trace, limit_k: float, class_k: float, tau: float) -> np.ndarray:
    """Tier B: the cycle's exact map (its bins composed), applied chunk by chunk; the peak,
    life and time above the limit read inside the first and last cycle of each chunk."""
    cyc = run.cycle
    assert cyc is not None
    period = cyc[0].duration
    pc = [maps.get((bi, "cy", j, amb), cyc[j]) for j in (0, 1)]
    chunks = np.array([round(m) for m in _chunks(run.n_rest, period, tau)], dtype=float)
    rows, tot = cycles_nb(pc[0][0], pc[0][1], pc[1][0], pc[1][1], cyc[0].i2 * maps.scale,
                          cyc[1].i2 * maps.scale, float(np.mean(cyc[0].p_h)),
                          float(np.mean(cyc[1].p_h)), float(x[0]), float(x[1]), chunks,
                          np.array(run.temps, dtype=float), maps.arr, limit_k, class_k, period)
    return _totals(st, tr, rows, tot, amb, bi)
