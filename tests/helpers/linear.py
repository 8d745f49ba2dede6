"""The EMA loop with every nonlinearity removed, written out by hand as a state-space model
(python-control): the independent reference of the linear checks."""

from __future__ import annotations

import control
import numpy as np


def linear_ss(p: dict[str, float]) -> control.StateSpace:
    """The loop of docs/model.md §2 with every nonlinearity removed, written out by hand.

    States [theta_m, w_m, i, theta_L, w_L, xI]; input theta_ref; output theta_L.
    """
    m, kl, c = p["m"], p["kL"], p["c"]
    kpp, kps, kis = p["Kpp"], p["Kps"], p["Kis"]
    R, L, kt, ke = p["R"], p["L"], p["Kt"], p["Ke"]
    jm, bm, jl, bl = p["Jm"], p["bm"], p["JL"], p["bL"]
    # e_w = m*Kpp*(r - thL) - w_m ;  u = Kps*e_w + Kis*xI
    # T = kL*(th_m/m - thL) + c*(w_m/m - w_L)
    A = np.zeros((6, 6))
    B = np.zeros((6, 1))
    A[0, 1] = 1.0
    A[1, 0] = -kl / m / m / jm
    A[1, 1] = (-bm - c / m / m) / jm
    A[1, 2] = kt / jm
    A[1, 3] = kl / m / jm
    A[1, 4] = c / m / jm
    A[2, 1] = (-kps - ke) / L
    A[2, 2] = -R / L
    A[2, 3] = -kps * m * kpp / L
    A[2, 5] = kis / L
    B[2, 0] = kps * m * kpp / L
    A[3, 4] = 1.0
    A[4, 0] = kl / m / jl
    A[4, 1] = c / m / jl
    A[4, 3] = -kl / jl
    A[4, 4] = (-c - bl) / jl
    A[5, 1] = -1.0
    A[5, 3] = -m * kpp
    B[5, 0] = m * kpp
    C = np.zeros((1, 6))
    C[0, 3] = 1.0
    return control.ss(A, B, C, np.zeros((1, 1)))
