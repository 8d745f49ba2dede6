"""The two-node thermal network's step response written out by hand (the independent reference
of tests/unit/test_duty_thermal.py and test_duty_pipeline.py)."""

from __future__ import annotations

import math

import numpy as np

from ema_cli.acceptance.duty.thermal import Network


def closed_form(net: Network, p_w: float, t: np.ndarray, amb: float) -> np.ndarray:
    """The two-node network's response to a step of ``p_w`` [W] into the winding from ambient,
    by hand: the steady state ``theta_inf = [P (R_wh + R_ha), P R_ha]`` plus two modes
    ``v_k exp(lambda_k t)`` fitted to theta(0) = 0 (eigenvalues of the 2x2 matrix from the
    quadratic formula). Returns (T_w, T_h) [K], shape (2, len(t))."""
    r_wh, r_ha = 1.0 / net.g_wh, 1.0 / net.g_ha
    a11, a12 = -1.0 / (r_wh * net.c_w), 1.0 / (r_wh * net.c_w)
    a21, a22 = 1.0 / (r_wh * net.c_h), -(1.0 / r_wh + 1.0 / r_ha) / net.c_h
    tr, det = a11 + a22, a11 * a22 - a12 * a21
    lam = np.array([tr / 2 + math.sqrt(tr * tr / 4 - det), tr / 2 - math.sqrt(tr * tr / 4 - det)])
    vecs = np.array([[a12, a12], [lam[0] - a11, lam[1] - a11]])  # columns: eigenvectors
    th_inf = np.array([p_w * (r_wh + r_ha), p_w * r_ha])
    c = np.linalg.solve(vecs, -th_inf)
    theta = th_inf[:, None] + vecs @ (c[:, None] * np.exp(lam[:, None] * t[None, :]))
    return amb + theta
