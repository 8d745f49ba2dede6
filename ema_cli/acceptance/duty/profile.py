"""A mission profile in SI: its segments as *blocks* (one period of motion repeated a number of
times), the order they run in, the position and load of each at any instant.

Each segment of ``config.duty.DutyProfile`` becomes a :class:`Block` (a sine: one period
repeated ``cycles`` times; a repeat block: its segments as one period repeated ``count`` times;
a move or a dwell: once), placed where the previous one ended. Blocks that are the same motion,
load and ambient are one *distinct* block: its mechanics is simulated once
(``duty.mechanics``). Checks that need the actuator (its axis for the units, its time step for
the fastest sine) are made here, before anything runs, each a one-line ``EmaError`` naming the
key.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ema_cli.config.duty import DutyProfile, Move, Repeat, Sine
from ema_cli.errors import EmaError
from ema_cli.units import AXIS_SI, parse_quantity, parse_temperature

SINE_PERIOD_STEPS = 88  # integration steps per period of a sine, at least (as freqresp) [-]
MAX_OCCURRENCES = 100_000  # blocks run in order (segments x the profile's repeat), at most [-]


@dataclass(frozen=True)
class Part:
    """One motion inside a block's period, from ``t0`` for ``dur`` seconds [SI]: ``sine``
    (``p0`` centre, ``amp``, ``freq``), ``move`` (``p0`` -> ``p1`` at ``speed``, ``accel``) or
    ``dwell`` (at ``p0``); its load ``force`` plus the ``table`` (t within the part's own cycle,
    force) repeated every ``cycle`` seconds; ``spring`` the hinge gradient."""

    kind: str
    t0: float
    dur: float
    p0: float
    p1: float = 0.0
    amp: float = 0.0
    freq: float = 0.0
    speed: float = 0.0
    accel: float = 0.0
    force: float = 0.0
    spring: float = 0.0
    table: tuple[tuple[float, ...], tuple[float, ...]] | None = None
    cycle: float = 0.0


@dataclass(frozen=True)
class Block:
    """One segment in SI: ``count`` repetitions of a period of ``parts``; ``key`` names it in
    messages (``segments.2.sine``), ``label`` in reports; ``ambient_k`` [K]."""

    key: str
    label: str
    kind: str
    parts: tuple[Part, ...]
    period: float
    count: int
    ambient_k: float
    start: float
    end: float

    @property
    def duration(self) -> float:
        """The block's whole duration [s]."""
        return self.period * self.count

    @property
    def spring(self) -> float:
        return self.parts[0].spring

    @property
    def pure_sine(self) -> bool:
        """One sine with a constant load: the kernel's own sine reference, no table."""
        p = self.parts[0]
        return len(self.parts) == 1 and p.kind == "sine" and p.table is None

    def signature(self) -> tuple:
        """What makes two blocks the same simulation (their motion, load, ambient)."""
        return (self.kind, round(self.period, 12), self.ambient_k,
                tuple((p.kind, round(p.t0, 12), round(p.dur, 12), p.p0, p.p1, p.amp, p.freq,
                       p.speed, p.accel, p.force, p.spring, p.table, p.cycle)
                      for p in self.parts))

    def position(self, t: np.ndarray) -> np.ndarray:
        """The reference position at times ``t`` [s] from the block's start (any number of
        periods) [rad or m]."""
        tau = np.mod(np.asarray(t, dtype=float), self.period)
        out = np.full(tau.shape, self.parts[0].p0)
        for p in self.parts:
            on = (tau >= p.t0) & (tau < p.t0 + p.dur + (1e-12 if p is self.parts[-1] else 0))
            out = np.where(on, _part_position(p, tau - p.t0), out)
        return out

    def load(self, t: np.ndarray) -> np.ndarray:
        """The external force (torque) at times ``t`` from the block's start, the spring's
        share aside [N or N*m]."""
        tau = np.mod(np.asarray(t, dtype=float), self.period)
        out = np.zeros(tau.shape)
        for p in self.parts:
            on = (tau >= p.t0) & (tau < p.t0 + p.dur + (1e-12 if p is self.parts[-1] else 0))
            f = np.full(tau.shape, p.force)
            if p.table is not None:
                f = f + np.interp(np.mod(tau - p.t0, p.cycle), p.table[0], p.table[1])
            out = np.where(on, f, out)
        return out

    @property
    def varying_load(self) -> bool:
        """Whether the load force changes within the period (a table or parts that differ)."""
        return any(p.table is not None for p in self.parts) or len(
            {p.force for p in self.parts}) > 1


def _part_position(p: Part, s: np.ndarray) -> np.ndarray:
    if p.kind == "sine":
        return p.p0 + p.amp * np.sin(2.0 * math.pi * p.freq * s)
    if p.kind == "dwell":
        return np.full(s.shape, p.p0)
    return p.p0 + math.copysign(1.0, p.p1 - p.p0) * trapezoid_travel(
        abs(p.p1 - p.p0), p.speed, p.accel, s)


def trapezoid_time(dist: float, speed: float, accel: float) -> float:
    """The duration of a trapezoidal move of ``dist`` (a triangle when it cannot reach
    ``speed``) [s]."""
    if dist <= 0.0:
        return 0.0
    if dist * accel <= speed * speed:  # triangle: peak speed sqrt(dist*accel)
        return 2.0 * math.sqrt(dist / accel)
    return dist / speed + speed / accel


def trapezoid_travel(dist: float, speed: float, accel: float, s: np.ndarray) -> np.ndarray:
    """The distance covered ``s`` seconds into a trapezoidal move of ``dist``."""
    s = np.clip(s, 0.0, trapezoid_time(dist, speed, accel))
    v = min(speed, math.sqrt(dist * accel)) if dist > 0 else 0.0
    ta = v / accel if accel > 0 else 0.0
    total = trapezoid_time(dist, speed, accel)
    up = 0.5 * accel * s * s
    cruise = 0.5 * accel * ta * ta + v * (s - ta)
    down = dist - 0.5 * accel * (total - s) ** 2
    return np.where(s < ta, up, np.where(s <= total - ta, cruise, down))


@dataclass
class Expanded:
    """A profile in SI: its distinct ``blocks`` and the ``order`` they run in (indices into
    ``blocks``, the profile's repeat included), the axis and the stroke."""

    blocks: list[Block]
    order: list[int]
    axis: str
    stroke: float | None
    notes: list[str] = field(default_factory=list)

    @property
    def duration(self) -> float:
        return sum(self.blocks[b].duration for b in self.order)


class _Units:
    """Reads a profile's values in SI for one axis (bare numbers: fractions of the stroke)."""

    def __init__(self, prof: DutyProfile, axis: str) -> None:
        self.axis = axis
        self.stroke = None
        if prof.stroke is not None:
            if isinstance(prof.stroke, int | float):
                raise EmaError(f"stroke: give it with a unit of the {axis} axis (e.g. "
                               f"'{'30 deg' if axis == 'rotary' else '50 mm'}'), got "
                               f"{prof.stroke!r}")
            self.stroke = self.q(prof.stroke, "position", "stroke")
            if not self.stroke > 0:
                raise EmaError(f"stroke: must be > 0, got {prof.stroke!r}")

    def q(self, v: Any, kind: str, key: str) -> float:
        if isinstance(v, int | float) and not isinstance(v, bool):
            if self.stroke is None and kind != "force" and kind != "stiffness":
                raise EmaError(f"{key}: a bare number is a fraction of the stroke; give the "
                               f"profile's stroke or a unit ({AXIS_SI[self.axis][kind]})")
            return float(v) * (self.stroke if kind not in ("force", "stiffness") else 1.0)
        try:
            return parse_quantity(v, kind, self.axis)
        except ValueError as exc:
            raise EmaError(f"{key}: {exc}") from None


def expand(prof: DutyProfile, axis: str, ambient_k: float, dt: float) -> Expanded:
    """The profile's blocks in SI, checked against the actuator (its ``axis``, its default
    ``ambient_k`` [K] and its step ``dt`` [s])."""
    u = _Units(prof, axis)
    amb0 = _temp(prof.ambient, "ambient") if prof.ambient is not None else ambient_k
    pos = u.q(prof.start, "position", "start")
    _check_travel(u, pos, "start")
    seq: list[Block] = []
    for k, seg in enumerate(prof.segments):  # the list once; the profile's repeat below
        blk = _block(seg, f"segments.{k}.{seg.kind}", pos, prof, u, amb0, dt)
        seq.append(blk)
        pos = blk.end
    first = seq[0].start
    order_one = list(range(len(seq)))
    blocks = list(seq)
    order = list(order_one)
    if prof.repeat > 1:
        if len(seq) * prof.repeat > MAX_OCCURRENCES:
            raise EmaError(f"repeat: {prof.repeat} x {len(seq)} segments is more than "
                           f"{MAX_OCCURRENCES:,} blocks in order; put the cycle in a repeat "
                           "segment (its count is unlimited)")
        if abs(pos - first) > 1e-12 * max(1.0, abs(first)):
            # the next pass starts where this one ended: its blocks are placed again
            pos2 = pos
            again = []
            for k, seg in enumerate(prof.segments):
                blk = _block(seg, f"segments.{k}.{seg.kind}", pos2, prof, u, amb0, dt)
                again.append(blk)
                pos2 = blk.end
            blocks += again
            order += [len(seq) + i for i in range(len(seq))] * (prof.repeat - 1)
        else:
            order = order_one * prof.repeat
    distinct: dict[tuple, int] = {}
    out_blocks: list[Block] = []
    remap = []
    for b in blocks:
        sig = (b.signature(), b.start)
        if sig not in distinct:
            distinct[sig] = len(out_blocks)
            out_blocks.append(b)
        remap.append(distinct[sig])
    return Expanded(out_blocks, [remap[i] for i in order], axis, u.stroke)


def _temp(v: Any, key: str) -> float:
    try:
        return parse_temperature(v)
    except ValueError as exc:
        raise EmaError(f"{key}: {exc}") from None


def _check_travel(u: _Units, p: float, key: str) -> None:
    if u.stroke is not None and abs(p) > u.stroke * (1.0 + 1e-9):
        raise EmaError(f"{key}: the position {p:g} {AXIS_SI[u.axis]['position']} lies beyond "
                       f"the stroke (+-{u.stroke:g})")


def _load(load: Any, u: _Units, key: str) -> tuple[float, float, Any]:
    force = u.q(load.force, "force", f"{key}.force")
    spring = u.q(load.spring, "stiffness", f"{key}.spring")
    table = None
    if load.profile is not None:
        table = (tuple(r[0] for r in load.profile), tuple(r[1] for r in load.profile))
    return force, spring, table


def _leaf(seg: Any, key: str, t0: float, pos: float, prof: DutyProfile, u: _Units,
          dt: float) -> Part:
    """One sine (one period), move or dwell as a :class:`Part` starting at ``pos``."""
    force, spring, table = _load(seg.load if seg.load is not None else prof.load, u,
                                 f"{key}.load" if seg.load is not None else "load")
    if isinstance(seg, Sine):
        centre = pos if seg.centre is None else u.q(seg.centre, "position", f"{key}.centre")
        amp = u.q(seg.amplitude, "position", f"{key}.amplitude")
        if not amp > 0:
            raise EmaError(f"{key}.amplitude: must be > 0, got {seg.amplitude!r}")
        for p in (centre + amp, centre - amp):
            _check_travel(u, p, f"{key}.amplitude")
        steps = 1.0 / (seg.frequency_hz * dt)
        if steps < SINE_PERIOD_STEPS:
            raise EmaError(f"{key}.frequency_hz: {seg.frequency_hz:g} Hz is {steps:.3g} "
                           f"integration steps per period at dt = {dt:g} s; the step resolves "
                           f"{SINE_PERIOD_STEPS} at least (lower the frequency, or "
                           "simulation.dt_s)")
        period = 1.0 / seg.frequency_hz
        return Part("sine", t0, period, centre, centre, amp, seg.frequency_hz, force=force,
                    spring=spring, table=table, cycle=period)
    if isinstance(seg, Move):
        to = u.q(seg.to, "position", f"{key}.to")
        _check_travel(u, to, f"{key}.to")
        v = u.q(seg.speed, "velocity", f"{key}.speed")
        a = u.q(seg.accel, "acceleration", f"{key}.accel")
        for name, x in (("speed", v), ("accel", a)):
            if not x > 0:
                raise EmaError(f"{key}.{name}: must be > 0, got {getattr(seg, name)!r}")
        dur = trapezoid_time(abs(to - pos), v, a)
        if dur <= 0.0:
            raise EmaError(f"{key}.to: the move goes nowhere (already at {to:g}); use a dwell")
        if dur < 10 * dt:
            raise EmaError(f"{key}: the move lasts {dur:.3g} s, under 10 integration steps of "
                           f"{dt:g} s")
        return Part("move", t0, dur, pos, to, speed=v, accel=a, force=force, spring=spring,
                    table=table, cycle=dur)
    return Part("dwell", t0, seg.duration_s, pos, pos, force=force, spring=spring, table=table,
                cycle=seg.duration_s)


def _describe(p: Part, u: _Units) -> str:
    unit = "deg" if u.axis == "rotary" else "mm"
    f = 180.0 / math.pi if u.axis == "rotary" else 1e3
    if p.kind == "sine":
        return f"sine {p.amp * f:.3g} {unit} {p.freq:g} Hz"
    if p.kind == "move":
        return f"move {p.p0 * f:.3g} -> {p.p1 * f:.3g} {unit}"
    return f"dwell {p.dur:g} s"


def _block(seg: Any, key: str, pos: float, prof: DutyProfile, u: _Units, amb0: float,
           dt: float) -> Block:
    amb = _temp(seg.ambient, f"{key}.ambient") if getattr(seg, "ambient", None) is not None \
        else amb0
    if isinstance(seg, Repeat):
        parts: list[Part] = []
        t0, p = 0.0, pos
        ambs = set()
        for j, sub in enumerate(seg.segments):
            sk = f"{key}.segments.{j}.{sub.kind}"
            part = _leaf(sub, sk, t0, p, prof, u, dt)
            if sub.kind == "sine":  # whole cycles of a sine inside a cycle
                part = Part(**{**part.__dict__, "dur": part.dur * sub.cycles})
            parts.append(part)
            ambs.add(_temp(sub.ambient, f"{sk}.ambient") if sub.ambient is not None else amb)
            t0 += part.dur
            p = part.p1 if part.kind == "move" else part.p0  # a sine ends at its centre
        if len({q.spring for q in parts}) > 1:
            raise EmaError(f"{key}: every segment of a repeat block needs the same load spring "
                           "(one hinge gradient per simulation)")
        if len(ambs) > 1:
            raise EmaError(f"{key}: every segment of a repeat block needs the same ambient")
        if abs(p - pos) > 1e-9 * max(1.0, abs(pos)):
            raise EmaError(f"{key}: a repeat block must end where it starts (a cycle); it "
                           f"ends {p - pos:+.4g} {AXIS_SI[u.axis]['position']} away")
        label = seg.label or f"repeat {seg.count} x [{', '.join(_describe(q, u) for q in parts)}]"
        return Block(key, label, "cycle", tuple(parts), t0, seg.count, next(iter(ambs)), pos,
                     pos)
    part = _leaf(seg, key, 0.0, pos, prof, u, dt)
    count = seg.cycles if seg.kind == "sine" else 1
    end = part.p1 if part.kind == "move" else part.p0  # a sine ends at its centre
    label = seg.label or _describe(part, u) + (f" x {count}" if count > 1 else "")
    return Block(key, label, part.kind, (part,), part.dur, count, amb, pos, end)
