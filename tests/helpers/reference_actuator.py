"""An independent reference simulator of the actuator description (tests only).

Written from the description of the model alone (docs of the actuator elements: rigid or
compliant transmission, armature or amplifier drive, static friction with stiction at the motor
and at the load, offset and external forces, the paper's continuous cascade, the described
discrete cascade, plant-only runs driven by the input signal), never from the kernel's code: it
integrates the equations with ``scipy.integrate.solve_ivp`` (DOP853, tight tolerances) piecewise
between every controller sample, every breakpoint of the inputs and every recorded instant, and
locates every mode switch with an event (a slipping body reaching zero speed, a stuck body's
other forces leaving the breakaway band, a limit engaging or releasing, the paper cascade's
anti-windup switching), restarting the integration there in the new mode. Within a segment every
input is one smooth piece (its right-hand limit at the segment's start), so no discontinuity is
ever integrated over.

Values are SI; load-side quantities in the axis's units (rad or m; N*m or N; kg*m^2 or kg).
Recorded values at an instant are its right-hand limits: the controller has sampled and its new
command is applied, and the friction modes are resolved for the inputs that hold from there on.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.integrate import solve_ivp

# state vector (one layout for every variant; unused states keep a zero derivative)
TH_M, W_M, CUR, TH_L, W_L, XI, F_AMP, F_T = range(8)
N_STATES = 8

CTRL_PAPER, CTRL_DISCRETE, CTRL_NONE = 0.0, 1.0, 2.0
DRIVE_ARMATURE, DRIVE_AMPLIFIER = 0.0, 1.0
INPUT_COMMAND, INPUT_FORCE, INPUT_CURRENT = 0.0, 1.0, 2.0
FRICTION_OFF, FRICTION_STATIC = 0.0, 2.0

SIGNALS = ("theta_load", "omega_load", "theta_motor", "omega_motor", "current", "drive_force",
           "voltage_cmd", "friction_load", "torque_friction", "friction_total", "theta_ref")
"""What :func:`simulate` records: load position and speed, motor angle over the ratio, motor
speed, armature current, drive force on the axis (load side), the command sent to the drive,
friction at the load site (load side), at the motor site (motor side), their sum on the axis
(load side: ``m*torque_friction + friction_load``) and the position reference."""


# ---------------------------------------------------------------- inputs, piece by piece


@dataclass(frozen=True)
class Piece:
    """A smooth function valid on one segment (the input's right limit at its start)."""

    a0: float = 0.0  # value at t = t0
    slope: float = 0.0
    t0: float = 0.0
    sine: tuple[float, float, float, float] | None = None  # (offset, amplitude, w, start)

    def __call__(self, t: float) -> float:
        if self.sine is not None:
            off, amp, w, start = self.sine
            return off + amp * math.sin(w * (t - start))
        return self.a0 + self.slope * (t - self.t0)


ZERO = Piece()


def _table_piece(tt: np.ndarray, vv: np.ndarray, hold: bool, mid: float) -> Piece:
    """The piece of a table (held or linear, end values held) around the instant ``mid``."""
    i = int(np.searchsorted(tt, mid, side="right")) - 1  # last sample at or before mid
    if i < 0:
        return Piece(float(vv[0]))
    if i >= len(tt) - 1 or hold:
        return Piece(float(vv[i]))
    slope = (float(vv[i + 1]) - float(vv[i])) / (float(tt[i + 1]) - float(tt[i]))
    return Piece(float(vv[i]), slope, float(tt[i]))


class Inputs:
    """The time-varying inputs of a run (position reference, input signal, load profile), read
    from an ``InputSignal``-like object (its documented fields only) and evaluated here."""

    def __init__(self, sig: Any):
        self.kind = sig.kind
        self.amplitude = float(sig.amplitude)
        self.start = float(sig.start)
        self.rate = float(sig.rate)
        self.freq = float(sig.freq)
        self.offset = float(sig.offset)
        if self.kind not in ("step", "ramp", "sine", "csv"):
            raise NotImplementedError(f"reference kind {self.kind!r}")
        self.table = None
        if self.kind == "csv":
            if sig.table is None:
                raise NotImplementedError("csv reference needs its table")
            self.table = (np.asarray(sig.table[0], float), np.asarray(sig.table[1], float))
        self.ext = None
        if sig.ext_table is not None:
            self.ext = (np.asarray(sig.ext_table[0], float), np.asarray(sig.ext_table[1], float))
        self.ext_hold = bool(sig.ext_hold)
        self.load = None
        if sig.load_table is not None:
            self.load = (np.asarray(sig.load_table[0], float),
                         np.asarray(sig.load_table[1], float))
        self.load_sine = sig.load_sine

    def breakpoints(self) -> list[float]:
        """Every instant where an input or its slope jumps."""
        bp = [self.start]
        if self.kind == "ramp" and self.amplitude != 0 and self.rate != 0:
            bp.append(self.start + abs(self.amplitude) / abs(self.rate))
        if self.table is not None:
            bp += list(self.table[0])
        if self.ext is not None:
            bp += list(self.ext[0])
        if self.load is not None:
            bp += list(self.load[0])
        return [float(b) for b in bp]

    def reference(self, mid: float) -> Piece:
        if self.kind == "csv":
            return _table_piece(self.table[0], self.table[1], False, mid)
        if mid < self.start:
            return ZERO
        if self.kind == "step":
            return Piece(self.amplitude)
        if self.kind == "ramp":
            if self.amplitude != 0 and abs(self.rate * (mid - self.start)) >= abs(self.amplitude):
                return Piece(math.copysign(abs(self.amplitude), self.rate))
            return Piece(0.0, self.rate, self.start)
        w = 2.0 * math.pi * self.freq
        return Piece(sine=(self.offset, self.amplitude, w, self.start))

    def ext_piece(self, mid: float) -> Piece:
        if self.ext is None:
            return ZERO
        return _table_piece(self.ext[0], self.ext[1], self.ext_hold, mid)

    def load_pieces(self, mid: float) -> tuple[Piece, Piece]:
        table = ZERO if self.load is None else _table_piece(self.load[0], self.load[1], False,
                                                            mid)
        sine = ZERO
        if self.load_sine is not None:
            amp, f = self.load_sine
            sine = Piece(sine=(0.0, float(amp), 2.0 * math.pi * float(f), 0.0))
        return table, sine


@dataclass
class Segment:
    """The inputs that hold on one segment between breakpoints."""

    r: Piece
    ext: Piece
    load: Piece
    load_sine: Piece
    u_held: float = 0.0  # the discrete cascade's zero-order-held command


# ---------------------------------------------------------------- modes


@dataclass
class Modes:
    """Discrete state of the hybrid system.

    body   friction body -> -1/+1 slipping in that direction, 0 stuck (only bodies that have a
           static friction law are listed): ``rigid`` or ``motor`` and ``load``
    clip   limit -> -1/+1 engaged at that side, 0 free: ``sat1``, ``sat2`` (paper cascade),
           ``amp`` (amplifier output)
    frozen the paper cascade's integrator is held (anti-windup)
    """

    body: dict[str, int]
    clip: dict[str, int]
    frozen: bool = False

    def copy(self) -> Modes:
        return Modes(dict(self.body), dict(self.clip), self.frozen)


class UnsupportedCase(NotImplementedError):
    """The description uses something this reference does not model."""


# ---------------------------------------------------------------- the model


class Reference:
    """The actuator of a resolved parameter dict ``p`` (SI, the names of ``model.params``)."""

    def __init__(self, p: Mapping[str, float]):
        self.p = dict(p)
        self.y_start = np.zeros(N_STATES)  # the state a run of the integrator starts from
        g = self.p.__getitem__
        self._check_supported()
        self.rigid = g("rigid") == 1.0
        self.drive = g("drive")
        self.ctrl = g("ctrl")
        self.plant_input = g("plant_input")
        self.dist_out = g("dist_out") == 1.0
        self.m = g("m")
        # static friction sites
        self.fm = g("friction") == FRICTION_STATIC
        self.fl = g("friction_L") == FRICTION_STATIC
        self.site_m = (g("Fc"), g("Fs"), g("sigma2"), g("Fc_neg"), g("Fs_neg"), g("sigma2_neg"),
                       g("vs"), g("delta"))
        self.site_l = (g("Fc_L"), g("Fs_L"), g("Fv_L"), g("Fc_L_neg"), g("Fs_L_neg"),
                       g("Fv_L_neg"), g("vs_L"), g("delta_L"))
        if self.rigid:
            self.M = g("JL") + self.m ** 2 * g("Jm")
            self.band_pos = (self.m * g("Fs") if self.fm else 0.0) + (g("Fs_L") if self.fl
                                                                      else 0.0)
            self.band_neg = (self.m * g("Fs_neg") if self.fm else 0.0) + (g("Fs_L_neg")
                                                                          if self.fl else 0.0)
        self.uses_drive = not (self.ctrl == CTRL_NONE and self.plant_input != INPUT_COMMAND)
        self.amp_clip = (self.uses_drive and self.drive == DRIVE_AMPLIFIER
                         and math.isfinite(g("amp_limit")))
        self.amp_dyn = self.drive == DRIVE_AMPLIFIER and g("amp_tau") > 0
        # discrete cascade
        if self.ctrl == CTRL_DISCRETE:
            self.Ts = g("Ts")
            self.fir = [g(f"dc_fir{i}") for i in range(8)]
            self.ndiff = int(g("dc_ndiff"))
            self.delay = int(g("dc_delay"))
            fc = g("dc_vfc")
            self.a_lp = math.exp(-2.0 * math.pi * fc * self.Ts) if fc > 0 else 0.0

    def _check_supported(self) -> None:
        g = self.p.__getitem__
        need = {"locked": 0.0, "d1": 0.0, "d3": 0.0, "d4": 0.0, "q_speed": 0.0,
                "fb_motor": 0.0, "dzi_v": 0.0, "ff_fc": 0.0, "ff_sigma0": 0.0, "notch_hz": 0.0}
        for k, v in need.items():
            if g(k) != v:
                raise UnsupportedCase(f"{k} = {g(k)} (the reference needs {v})")
        if g("rigid") != 1.0 and g("damping") != 1.0:
            raise UnsupportedCase("a compliant transmission needs damping = paper")
        if g("rigid") == 1.0 and g("alpha") != 0.0:
            raise UnsupportedCase("a rigid axis has no backlash")
        for site in ("friction", "friction_L"):
            if g(site) not in (FRICTION_OFF, FRICTION_STATIC):
                raise UnsupportedCase(f"{site} = {g(site)}: only off or static")
        if g("drive") == DRIVE_ARMATURE and math.isfinite(g("sat3")):
            raise UnsupportedCase("armature drive needs sat3 = off")
        if g("ctrl") == CTRL_PAPER and (g("Ts") != 0 or g("q_pos") != 0):
            raise UnsupportedCase("only the continuous paper cascade (Ts = 0, q_pos = 0)")

    # -------------------------------------------------------- algebra

    @staticmethod
    def _slip(site: tuple, d: int, v: float) -> float:
        """Friction of a static-law site slipping in direction ``d`` at speed ``v``
        (continued smoothly a little past v = 0 for the event search)."""
        fc, fs, fv, fcn, fsn, fvn, vs, delta = site
        if d < 0:
            fc, fs, fv = fcn, fsn, fvn
        g = fc
        if vs > 0:
            s = d * v / vs
            g = fc + (fs - fc) * math.exp(-math.copysign(abs(s) ** delta, s))
        return d * g + fv * v

    def evaluate(self, t: float, y: Sequence[float], seg: Segment, md: Modes) -> dict:
        """Every algebraic quantity at (t, y) in modes ``md``, and the derivative ``dy``."""
        p = self.p
        m = self.m
        thm, wm, cur, thl, wl, xi, famp, ft = y
        if self.rigid:
            thm, wm = m * thl, m * wl
        r = seg.r(t)
        ext = seg.ext(t)
        out: dict[str, Any] = {"r": r}
        dy = [0.0] * N_STATES
        # controller -> command u
        if self.ctrl == CTRL_PAPER:
            s1 = p["Kpp"] * (r - thl)
            c1 = md.clip.get("sat1", 0)
            ws = s1 if c1 == 0 else c1 * p["sat1"]
            ew = m * ws - wm
            s2 = p["Kps"] * ew + p["Kis"] * xi
            c2 = md.clip.get("sat2", 0)
            u = s2 if c2 == 0 else c2 * p["sat2"]
            dy[XI] = 0.0 if md.frozen else ew
            out.update(sat1=s1, sat2=s2, ew=ew)
        elif self.ctrl == CTRL_DISCRETE:
            u = seg.u_held
        else:
            u = ext if self.plant_input == INPUT_COMMAND else 0.0
        if self.dist_out:
            u += ext
        out["u"] = u
        # drive -> force on the axis fd (load side)
        current = cur
        if not self.uses_drive:
            if self.plant_input == INPUT_FORCE:
                fd = ext
            else:  # current
                current = ext
                fd = m * p["Kt"] * ext
        elif self.drive == DRIVE_ARMATURE:
            fd = m * p["Kt"] * cur
            dy[CUR] = (u - p["R"] * cur - p["Ke"] * wm) / p["L"]
        else:
            sa = p["amp_gain"] * u
            out["amp"] = sa
            ca = md.clip.get("amp", 0)
            fstar = sa if ca == 0 else ca * p["amp_limit"]
            if self.amp_dyn:
                fd = famp
                dy[F_AMP] = (fstar - famp) / p["amp_tau"]
            else:
                fd = fstar
        out["current"] = current if (self.drive == DRIVE_ARMATURE or not self.uses_drive) else 0.0
        out["fd"] = fd
        text = p["T_load"] - p["offset"] + seg.load(t) + seg.load_sine(t) - p["k_h"] * thl
        out["text"] = text
        # mechanics
        if self.rigid:
            fo = fd - (m * m * p["bm"] + p["bL"]) * wl + text
            d = md.body.get("rigid")
            ffm = ffl = 0.0
            if d is None:
                ffr = 0.0
            elif d == 0:
                ffr = fo
            else:
                if self.fm:
                    ffm = self._slip(self.site_m, d, m * wl)
                if self.fl:
                    ffl = self._slip(self.site_l, d, wl)
                ffr = m * ffm + ffl
            dy[TH_L] = wl
            dy[W_L] = 0.0 if d == 0 else (fo - ffr) / self.M
            out.update(fo_rigid=fo, ffr=ffr, ffm=ffm, ffl=ffl, wm=wm, thm=thm, thl=thl, wl=wl)
        else:
            # the shaft (paper Eq. 2 with its dead band), the anti-backlash preload bridging the
            # gap (linear from -preload to +preload across it), the Dahl friction in parallel
            dth, dw = thm / m - thl, wm / m - wl
            a = p["alpha"]
            spring = dth - a if dth > a else (dth + a if dth < -a else 0.0)
            T = p["kL"] * spring + p["c"] * dw
            if a > 0.0 and p["preload"] > 0.0:
                T += p["preload"] * max(-1.0, min(1.0, dth / a))
            if p["Fc_t"] > 0.0:
                T += ft
                dy[F_T] = p["sigma_t"] * (dw - abs(dw) * ft / p["Fc_t"])
            fo_m = fd / m - p["bm"] * wm - T / m
            fo_l = T - p["bL"] * wl + text
            dm, dl = md.body.get("motor"), md.body.get("load")
            ffm = 0.0 if dm is None else fo_m if dm == 0 else self._slip(self.site_m, dm, wm)
            ffl = 0.0 if dl is None else fo_l if dl == 0 else self._slip(self.site_l, dl, wl)
            dy[TH_M] = wm
            dy[W_M] = 0.0 if dm == 0 else (fo_m - ffm) / p["Jm"]
            dy[TH_L] = wl
            dy[W_L] = 0.0 if dl == 0 else (fo_l - ffl) / p["JL"]
            out.update(fo_motor=fo_m, fo_load=fo_l, ffm=ffm, ffl=ffl, ffr=m * ffm + ffl, wm=wm,
                       thm=thm, thl=thl, wl=wl, T=T)
        out["dy"] = dy
        return out

    # -------------------------------------------------------- modes and events

    def bodies(self) -> list[str]:
        if self.rigid:
            return ["rigid"] if (self.fm or self.fl) else []
        return (["motor"] if self.fm else []) + (["load"] if self.fl else [])

    def band(self, body: str) -> tuple[float, float]:
        """(Fs_+, Fs_-) of a friction body."""
        if body == "rigid":
            return self.band_pos, self.band_neg
        site = self.site_m if body == "motor" else self.site_l
        return site[1], site[4]

    def speed_index(self, body: str) -> int:
        return W_M if body == "motor" else W_L

    def clip_limits(self) -> dict[str, float]:
        lim = {}
        if self.ctrl == CTRL_PAPER:
            for k in ("sat1", "sat2"):
                if math.isfinite(self.p[k]):
                    lim[k] = self.p[k]
        if self.amp_clip:
            lim["amp"] = self.p["amp_limit"]
        return lim

    def resolve_modes(self, t: float, y: np.ndarray, seg: Segment, md: Modes) -> Modes:
        """Make the modes consistent with the state and the inputs that hold from ``t`` on (a
        segment's start, where inputs may jump): limits engaged as their arguments say (a value
        within 1e-12 of its limit keeps its mode), stuck bodies broken away when their other
        forces leave the band, in the order the quantities depend on each other."""
        md = md.copy()
        c2_old = md.clip.get("sat2", 0)
        for name, lim in self.clip_limits().items():  # sat1 before sat2 before amp
            val = self.evaluate(t, y, seg, md)[name]
            new = 1 if val > lim else -1 if val < -lim else 0
            if abs(abs(val) - lim) > 1e-12 * lim:
                md.clip[name] = new
        if "sat2" in md.clip:
            c2 = md.clip["sat2"]
            ew = self.evaluate(t, y, seg, md)["ew"]
            if c2 == 0:
                md.frozen = False
            elif c2 != c2_old or ew != 0.0:
                md.frozen = ew * c2 > 0
        for body in self.bodies():
            if md.body[body] == 0:
                fo = self.other_force(t, y, seg, md, body)
                bp, bn = self.band(body)
                if fo > bp:
                    md.body[body] = 1
                elif fo < -bn:
                    md.body[body] = -1
        return md

    def other_force(self, t, y, seg, md, body) -> float:
        return self.evaluate(t, y, seg, md)[f"fo_{body}"]

    def events(self, seg: Segment, md: Modes) -> list[tuple[Callable, str, Any]]:
        """(event function, kind, data) for every switch possible from modes ``md``."""
        evs: list[tuple[Callable, str, Any]] = []

        def make(fn: Callable[[float, np.ndarray], float], direction: int, kind: str, data):
            fn.terminal = True  # type: ignore[attr-defined]
            fn.direction = direction  # type: ignore[attr-defined]
            evs.append((fn, kind, data))

        for name, lim in self.clip_limits().items():
            c = md.clip[name]

            def arg(t, y, name=name):
                return self.evaluate(t, y, seg, md)[name]

            if c == 0:
                make(lambda t, y, arg=arg, lim=lim: arg(t, y) - lim, 1, "clip", (name, 1))
                make(lambda t, y, arg=arg, lim=lim: arg(t, y) + lim, -1, "clip", (name, -1))
            else:
                make(lambda t, y, arg=arg, lim=lim, c=c: arg(t, y) - c * lim, -c, "clip",
                     (name, 0))
        if md.clip.get("sat2", 0) != 0:
            c2 = md.clip["sat2"]
            make(lambda t, y: self.evaluate(t, y, seg, md)["ew"], -c2 if md.frozen else c2,
                 "frozen", None)
        if not self.rigid:  # kinks of the shaft's torque: restart the integration there
            y0 = self.y_start  # the run's start: each kink's function leaves its sign there

            def kink(fn: Callable[[float, np.ndarray], float], scale: float) -> None:
                v0 = fn(0.0, y0)
                if abs(v0) > 1e-12 * scale:  # (at a kink just located: the next run's start)
                    make(fn, -1 if v0 > 0 else 1, "kink", None)

            m, a = self.m, self.p["alpha"]
            if a > 0.0:
                kink(lambda t, y: y[TH_M] / m - y[TH_L] - a, a)
                kink(lambda t, y: y[TH_M] / m - y[TH_L] + a, a)
            if self.p["Fc_t"] > 0.0:
                kink(lambda t, y: y[W_M] / m - y[W_L], 1e-3)
        for body in self.bodies():
            d = md.body[body]
            if d != 0:
                k = self.speed_index(body)
                make(lambda t, y, k=k: y[k], -d, "stop", body)
            else:
                bp, bn = self.band(body)
                make(lambda t, y, body=body, bp=bp: self.other_force(t, y, seg, md, body) - bp,
                     1, "break", (body, 1))
                make(lambda t, y, body=body, bn=bn: self.other_force(t, y, seg, md, body) + bn,
                     -1, "break", (body, -1))
        return evs

    def apply_event(self, t, y, seg, md: Modes, kind: str, data) -> tuple[np.ndarray, Modes]:
        md = md.copy()
        y = y.copy()
        if kind == "clip":
            name, c = data
            md.clip[name] = c
            if name == "sat2":
                ew = self.evaluate(t, y, seg, md)["ew"]
                md.frozen = c != 0 and ew * c > 0
            elif name == "sat1" and md.clip.get("sat2", 0) != 0:
                ew = self.evaluate(t, y, seg, md)["ew"]
                md.frozen = ew * md.clip["sat2"] > 0
        elif kind == "frozen":
            md.frozen = not md.frozen
        elif kind == "break":
            body, d = data
            md.body[body] = d
        elif kind == "stop":
            body = data
            y[self.speed_index(body)] = 0.0
            md.body[body] = 0
            fo = self.other_force(t, y, seg, md, body)
            bp, bn = self.band(body)
            if fo > bp:
                md.body[body] = 1
            elif fo < -bn:
                md.body[body] = -1
        return y, md

    # -------------------------------------------------------- outputs

    def record(self, t, y, seg, md) -> dict[str, float]:
        q = self.evaluate(t, y, seg, md)
        m = self.m
        if self.rigid:
            ffm, ffl = q["ffm"], q["ffl"]
            if md.body.get("rigid") == 0:  # stuck: only the total is defined
                ffm = ffl = math.nan
        else:
            ffm, ffl = q["ffm"], q["ffl"]
        return {"theta_load": q["thl"], "omega_load": q["wl"], "theta_motor": q["thm"] / m,
                "omega_motor": q["wm"], "current": q["current"], "drive_force": q["fd"],
                "voltage_cmd": q["u"], "friction_load": ffl, "torque_friction": ffm,
                "friction_total": q["ffr"], "theta_ref": q["r"]}


# ---------------------------------------------------------------- the discrete cascade


class DiscreteCascade:
    """The described discrete cascade: one call per sample instant t_k = k*Ts."""

    def __init__(self, ref: Reference):
        self.ref = ref
        self.p = ref.p
        self.q: list[float] = []
        self.v_prev = 0.0
        self.xp = 0.0
        self.xv = 0.0
        self.u: list[float] = []

    def _q(self, j: int) -> float:
        return self.q[max(j, 0)]

    def _qf(self, j: int) -> float:
        return sum(b * self._q(j - i) for i, b in enumerate(self.ref.fir))

    def sample(self, k: int, r: float, theta_l: float, w_m: float) -> float:
        """Sample k: the command applied from t_k to t_{k+1} (u[k - delay])."""
        p = self.p
        Ts = p["Ts"]
        qp = p["q_pos"]
        q = qp * math.floor(theta_l / qp + 0.5) if qp > 0 else theta_l
        assert len(self.q) == k
        self.q.append(q)
        if p["dc_vsrc"] == 0.0:
            n = self.ref.ndiff
            ve = (self._qf(k) - self._qf(k - n)) / (n * Ts)
        else:
            ve = w_m / self.ref.m
        a = self.ref.a_lp
        v = a * self.v_prev + (1.0 - a) * ve
        self.v_prev = v
        e = r - q
        pre_p = p["dc_kp"] * e + p["dc_ki"] * self.xp
        vmax = p["dc_vmax"]
        vstar = min(max(pre_p, -vmax), vmax)
        ev = vstar - v
        pre_v = p["dc_kv"] * ev + p["dc_kvi"] * self.xv
        umax = p["dc_umax"]
        u = min(max(pre_v, -umax), umax)
        if not (abs(pre_p) > vmax and e * pre_p > 0):
            self.xp += Ts * e
        if not (abs(pre_v) > umax and ev * pre_v > 0):
            self.xv += Ts * ev
        self.u.append(u)
        d = self.ref.delay
        return self.u[k - d] if k - d >= 0 else 0.0


# ---------------------------------------------------------------- the run


@dataclass
class Result:
    t: np.ndarray
    signals: dict[str, np.ndarray]
    stuck: dict[str, np.ndarray]  # per friction body: stuck at each recorded instant
    n_events: int

    def __getitem__(self, name: str) -> np.ndarray:
        return self.signals[name]


def initial_state(p: Mapping[str, float]) -> np.ndarray:
    y = np.zeros(N_STATES)
    for k, name in ((TH_M, "theta_m"), (W_M, "w_m"), (CUR, "i"), (TH_L, "theta_L"),
                    (W_L, "w_L"), (XI, "xI"), (F_AMP, "f_amp"), (F_T, "f_t")):
        y[k] = p.get(f"x0_{name}", 0.0)
    if p["rigid"] == 1.0:
        y[TH_M] = y[W_M] = 0.0  # derived from the load's
    return y


def _merge_times(groups: dict[str, Sequence[float]], t_end: float, tol: float):
    """Sorted boundaries in [0, t_end], near-equal ones merged: [(t, {tag: index})]."""
    items = []
    for tag, times in groups.items():
        for i, t in enumerate(times):
            if -tol <= t <= t_end + tol:
                items.append((float(t), tag, i))
    items.sort()
    out: list[tuple[float, dict[str, int]]] = []
    for t, tag, i in items:
        if out and t - out[-1][0] <= tol:
            out[-1][1][tag] = i
        else:
            out.append((t, {tag: i}))
    return out


def simulate(p: Mapping[str, float], sig: Any, t_out: np.ndarray, *, rtol: float = 1e-12,
             atol: float = 1e-15, max_events: int = 100000) -> Result:
    """Simulate the actuator ``p`` (a resolved parameter dict) driven by ``sig`` (an
    ``InputSignal``: position reference, input signal ``ext_table``/``ext_hold``, load profile)
    and record every signal of :data:`SIGNALS` at the instants ``t_out`` (right-hand limits).

    The integration runs from 0 to ``t_out[-1]`` piecewise between the controller's samples
    and the inputs' breakpoints (and from every mode switch, located by its event), with DOP853
    at ``rtol``/``atol``; instants inside a piece are read from the integrator's dense output
    (``t_eval``), instants on a boundary are recorded there (after the controller's sample)."""
    ref = Reference(p)
    inputs = Inputs(sig)
    t_out = np.asarray(t_out, float)
    t_end = float(t_out[-1])
    tol = 1e-9 * max(float(np.min(np.diff(t_out))) if len(t_out) > 1 else 1.0, 1e-12)
    groups: dict[str, Sequence[float]] = {"input": inputs.breakpoints(), "end": [t_end]}
    cascade = None
    if ref.ctrl == CTRL_DISCRETE:
        n_samples = int(math.floor(t_end / ref.Ts + 1e-9)) + 1
        groups["sample"] = [k * ref.Ts for k in range(n_samples)]
        cascade = DiscreteCascade(ref)
    bounds = _merge_times(groups, t_end, tol)
    if bounds[0][0] > tol:
        bounds.insert(0, (0.0, {}))
    bounds[0] = (0.0, bounds[0][1])
    starts = np.array([b[0] for b in bounds])
    # each recorded instant: on a boundary (recorded there) or inside the piece that follows one
    seg_of = np.searchsorted(starts, t_out + tol, side="right") - 1
    on_bound = np.abs(t_out - starts[seg_of]) <= tol

    y = initial_state(p)
    md = Modes({}, {k: 0 for k in ref.clip_limits()})
    for body in ref.bodies():
        w = y[W_M] if body == "motor" else y[W_L]
        md.body[body] = 0 if w == 0 else (1 if w > 0 else -1)
    rec = {k: np.full(len(t_out), np.nan) for k in SIGNALS}
    stuck = {b: np.zeros(len(t_out), bool) for b in ref.bodies()}

    def record(i: int, t: float, y: np.ndarray, seg: Segment, md: Modes) -> None:
        for name, v in ref.record(t, y, seg, md).items():
            rec[name][i] = v
        for b in stuck:
            stuck[b][i] = md.body[b] == 0

    u_held = 0.0
    n_events = 0
    h = None
    for j, (ta, tags) in enumerate(bounds):
        tb = bounds[j + 1][0] if j + 1 < len(bounds) else None
        # the inputs' pieces on [ta, tb] (at the last instant: their right-hand limits there)
        mid = ta + 0.5 * (tb - ta) if tb is not None else ta + 1e-9 * max(abs(ta), 1.0)
        r_piece = inputs.reference(mid)
        load_p, sine_p = inputs.load_pieces(mid)
        seg = Segment(r_piece, inputs.ext_piece(mid), load_p, sine_p, u_held)
        if "sample" in tags and cascade is not None:
            w_m = ref.m * y[W_L] if ref.rigid else y[W_M]
            u_held = cascade.sample(tags["sample"], r_piece(ta), y[TH_L], w_m)
            seg.u_held = u_held
        md = ref.resolve_modes(ta, y, seg, md)
        for i in np.flatnonzero((seg_of == j) & on_bound):
            record(int(i), ta, y, seg, md)
        if tb is None:
            break
        inside = [int(i) for i in np.flatnonzero((seg_of == j) & ~on_bound)]
        t = ta
        stalled = 0
        while t < tb:
            ref.y_start = y
            evs = ref.events(seg, md)

            def rhs(tt, yy, seg=seg, md=md):
                return ref.evaluate(tt, yy, seg, md)["dy"]

            pending = [i for i in inside if t_out[i] > t]
            t_eval = np.array([t_out[i] for i in pending] + [tb])
            first = None if h is None else min(h, tb - t)
            sol = solve_ivp(rhs, (t, tb), y, method="DOP853", rtol=rtol, atol=atol,
                            events=[e[0] for e in evs] or None, t_eval=t_eval,
                            first_step=first)
            if sol.status < 0:
                raise RuntimeError(f"integration failed at t = {t}: {sol.message}")
            t_stop = float(sol.t[-1]) if len(sol.t) else t
            if sol.status == 1:
                t_stop = max(float(te[-1]) for te in sol.t_events if len(te))
            # the next run's first step: this one's mean step (DOP853: 12 evaluations a step)
            n_steps = (sol.nfev - (2 if first is None else 0)) / 12.0
            if t_stop > t and n_steps >= 1:
                h = (t_stop - t) / n_steps
            if len(sol.t):  # the recorded instants reached (up to an event)
                for i, tt, yy in zip(pending, sol.t, np.asarray(sol.y).T, strict=False):
                    record(i, float(tt), yy, seg, md)
            if sol.status == 1:
                # the terminal event that ended the run (the latest recorded one)
                idx = max((te[-1], k) for k, te in enumerate(sol.t_events) if len(te))[1]
                te = float(sol.t_events[idx][-1])
                ye = np.array(sol.y_events[idx][-1], float)
                _, kind, data = evs[idx]
                y, md = ref.apply_event(te, ye, seg, md, kind, data)
                stalled = stalled + 1 if te <= t else 0
                if stalled > 8:
                    raise RuntimeError(f"mode switches without progress at t = {te}: {md}")
                t = te
                n_events += 1
                if n_events > max_events:
                    raise RuntimeError(f"more than {max_events} mode switches (chattering?)")
            else:
                y = np.array(sol.y[:, -1], float)
                t = tb
        if ref.rigid:
            y[TH_M] = y[W_M] = 0.0
    return Result(t_out, rec, stuck, n_events)
