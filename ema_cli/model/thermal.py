"""The drive's thermal element: a two-node network (winding, housing) and R(T) (numba, SI).

Two heat capacities joined by thermal resistances, the motor datasheets' two-body model::

    C_w dT_w/dt = P_cu - (T_w - T_h)/R_wh
    C_h dT_h/dt = (T_w - T_h)/R_wh - (T_h - T_a)/R_ha + P_h
    P_cu = i^2 R(T_w),   R(T) = R0 (1 + alpha (T - T_ref))          (alpha_Cu = 0.00393 1/K)
    P_h  = s_f (bm w_m + T_f) w_m + k_hyst |w_m| + k_eddy w_m^2     (friction and iron losses)

[K, W, J/K, K/W, ohm, rad/s]. Copper losses heat the winding; the motor's friction (its viscous
``bm`` and the friction law's torque ``T_f``, a share ``s_f``) and the iron losses (hysteresis and
eddy currents, heat only: their drag is the friction model's) heat the housing, which holds the
stator. R(T) is fed back into the armature's equation (``model.plant.current_rate_nb``).

In the kernel the states are the *rises above ambient* ``th_w = T_w - T_a``, ``th_h = T_h - T_a``
(their initial value 0 is a cold actuator at ambient; ``T_a`` is the lane's ``T_amb``), and the
derived constants ``th_r0 = R0 (1 + alpha (T_a - T_ref))`` and ``th_ra = R0 alpha`` give
``R = th_r0 + th_ra th_w``. The element is a structural flag of the variant (``thermal``): without
it the states' rates are 0 and the armature reads ``R`` as before, so the paper's EMA is
unchanged bit for bit. Numerics: the network's time constants (tens of seconds to hours) are far
slower than the mechanics, so RK4 at the mechanical step integrates it to rounding; ``ema duty``
integrates it exactly over hours instead (``duty.thermal``).
"""

from __future__ import annotations

import math
from collections.abc import Mapping

from ema_cli._numba import njit

ALPHA_CU = 0.00393  # temperature coefficient of copper's resistance near 20 degC [1/K]
T_REF_C = 25.0  # the temperature a datasheet's terminal resistance is given at [degC]
T_AMB_C = 40.0  # the reference EMA's ambient (IEC 60034-1's default for rating) [degC]
RTH_WH = 1.2  # reference EMA: winding-housing thermal resistance [K/W]
RTH_HA = 2.93  # reference EMA: housing-ambient thermal resistance [K/W]
CTH_W = 25.0  # reference EMA: winding heat capacity [J/K] (tau_w = R_wh*C_w = 30 s)
CTH_H = 400.0  # reference EMA: housing heat capacity [J/K] (R_ha*C_h = 1172 s)
"""The reference EMA's network: R_wh + R_ha = 4.13 K/W makes its continuous current at 40 degC
ambient and a class F limit (155 degC) 6.07 A, its rated current (:func:`continuous_current`)."""
INSULATION_CLASSES = {"A": 105.0, "E": 120.0, "B": 130.0, "F": 155.0, "H": 180.0, "N": 200.0,
                      "R": 220.0}
"""IEC 60085 thermal classes: the hot-spot temperature each insulation is rated for [degC]."""


@njit(cache=True, forceinline=True, error_model="numpy")
def resistance_nb(r0, alpha, temp, t_ref):
    """R(T) = R0 (1 + alpha (T - T_ref)) [ohm] (T, T_ref in K or both in degC)."""
    return r0 * (1.0 + alpha * (temp - t_ref))


@njit(cache=True, forceinline=True, error_model="numpy")
def housing_losses_nb(w_m, t_fric_m, bm, fric_heat, fe_hyst, fe_eddy):
    """The losses heating the housing [W]: the motor's friction ``fric_heat*(bm*w_m + T_f)*w_m``
    and the iron losses ``fe_hyst*|w_m| + fe_eddy*w_m^2`` (w_m [rad/s], torques [N*m])."""
    return (fric_heat * (bm * w_m + t_fric_m) * w_m + fe_hyst * abs(w_m)
            + fe_eddy * w_m * w_m)


# ---- the state equations (model.states.STATES: arguments bound by name) ---------------------

@njit(cache=True, forceinline=True, error_model="numpy")
def winding_rate_nb(i, th_w, th_h, t_drive, Kt, th_r0, th_ra, th_gwh, th_icw, amp, thermal):
    """d(th_w)/dt [K/s] = (i^2 R(T_w) - (th_w - th_h)/R_wh)/C_w; the current is the armature's,
    or the one an amplifier's torque stands for (``T_d/Kt``); 0 without the element."""
    if not thermal:
        return 0.0
    cur = (t_drive / Kt if Kt > 0.0 else 0.0) if amp else i
    return (cur * cur * (th_r0 + th_ra * th_w) - (th_w - th_h) * th_gwh) * th_icw


@njit(cache=True, forceinline=True, error_model="numpy")
def housing_rate_nb(th_w, th_h, w_m, t_fric_m, bm, fric_heat, fe_hyst, fe_eddy, th_gwh, th_gha,
                    th_ich, thermal):
    """d(th_h)/dt [K/s] = ((th_w - th_h)/R_wh - th_h/R_ha + P_h)/C_h (:func:`housing_losses_nb`);
    0 without the element."""
    if not thermal:
        return 0.0
    p_h = housing_losses_nb(w_m, t_fric_m, bm, fric_heat, fe_hyst, fe_eddy)
    return ((th_w - th_h) * th_gwh - th_h * th_gha + p_h) * th_ich


# ---- closed forms (Python) -------------------------------------------------------------------

def continuous_current(p: Mapping[str, float], limit_k: float,
                       ambient_k: float | None = None) -> float:
    """The largest constant current at standstill whose steady winding temperature is
    ``limit_k`` [A] (S1 at zero speed: no friction or iron losses): ``I^2 R(T_lim) (R_wh + R_ha)
    = T_lim - T_a``; ``ambient_k`` default the parameters' ``T_amb`` [K]. 0 when the ambient is
    at or above the limit."""
    t_a = p["T_amb"] if ambient_k is None else ambient_k
    rise = limit_k - t_a
    if rise <= 0.0:
        return 0.0
    r_hot = p["R"] * (1.0 + p["alpha_cu"] * (limit_k - p["T_ref"]))
    return math.sqrt(rise / (r_hot * (p["Rth_wh"] + p["Rth_ha"])))


def time_constants(p: Mapping[str, float]) -> tuple[float, float]:
    """The network's two time constants (fast, slow) [s] with constant losses: -1/eigenvalues
    of ``[[-1/(R_wh C_w), 1/(R_wh C_w)], [1/(R_wh C_h), -(1/R_wh + 1/R_ha)/C_h]]``."""
    a = -1.0 / (p["Rth_wh"] * p["Cth_w"])
    b = 1.0 / (p["Rth_wh"] * p["Cth_w"])
    c = 1.0 / (p["Rth_wh"] * p["Cth_h"])
    d = -(1.0 / p["Rth_wh"] + 1.0 / p["Rth_ha"]) / p["Cth_h"]
    tr, det = a + d, a * d - b * c
    disc = math.sqrt(max(tr * tr / 4.0 - det, 0.0))
    lam_fast, lam_slow = tr / 2.0 - disc, tr / 2.0 + disc
    return -1.0 / lam_fast, -1.0 / lam_slow


@njit(cache=True, error_model="numpy", entry=True)
def flow_nb(a11, a12, a21, a22, b1, b2, h):
    """The exact flow of ``dx/dt = A x + b`` over ``h`` [s] for a 2x2 ``A`` with real distinct
    eigenvalues (every two-node network: ``a12*a21 > 0``) -> ``(E, f)`` as six numbers
    ``e11, e12, e21, e22, f1, f2`` with ``x(h) = E x(0) + f``: ``E = expm(A h)``,
    ``f = (integral_0^h expm(A s) ds) b``, from Sylvester's formula
    ``F(A) = (F(l1) (A - l2 I) - F(l2) (A - l1 I)) / (l1 - l2)``. Caveat: the divided
    difference loses digits when the two time constants nearly coincide (never for a winding
    on a housing: their ratio is large)."""
    disc = math.sqrt((a11 - a22) * (a11 - a22) + 4.0 * a12 * a21)
    tr = a11 + a22
    l1 = 0.5 * (tr + disc)
    l2 = 0.5 * (tr - disc)
    e1 = math.exp(l1 * h)
    e2 = math.exp(l2 * h)
    z1 = l1 * h
    z2 = l2 * h
    g1 = h * (math.expm1(z1) / z1 if z1 != 0.0 else 1.0)
    g2 = h * (math.expm1(z2) / z2 if z2 != 0.0 else 1.0)
    inv = 1.0 / disc
    # F(A) = c1 (A - l2 I) - c2 (A - l1 I)
    e11 = (e1 * (a11 - l2) - e2 * (a11 - l1)) * inv
    e12 = (e1 - e2) * a12 * inv
    e21 = (e1 - e2) * a21 * inv
    e22 = (e1 * (a22 - l2) - e2 * (a22 - l1)) * inv
    f11 = (g1 * (a11 - l2) - g2 * (a11 - l1)) * inv
    f12 = (g1 - g2) * a12 * inv
    f21 = (g1 - g2) * a21 * inv
    f22 = (g1 * (a22 - l2) - g2 * (a22 - l1)) * inv
    return e11, e12, e21, e22, f11 * b1 + f12 * b2, f21 * b1 + f22 * b2
