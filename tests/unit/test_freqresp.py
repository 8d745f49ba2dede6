"""Sinestream frequency response against the linear model (issue 10's first check), and the
nonlinear indicators: the rate limit at a large amplitude, distortion growing with a dead band."""

from __future__ import annotations

import numpy as np
import pytest

from ema_cli.analysis.freqresp import crossing, sinestream, snap_frequency
from ema_cli.analysis.linear import linear_model
from ema_cli.errors import EmaError
from ema_cli.model.params import resolve
from ema_cli.units import DEG
from tests.conftest import LINEAR_OVERRIDES


def test_linear_limit_matches_the_linear_model():
    # every nonlinearity off: gain within 0.1 dB, phase within 0.5 deg at 0.1, 1 and 5 deg
    # from 0.5 to 50 Hz, and the -3 dB bandwidth within 1 % (issue 10)
    p = resolve(LINEAR_OVERRIDES)
    f = np.geomspace(0.5, 50, 12)
    pts = sinestream(p, [0.1, 1.0, 5.0], f)
    fs = np.array([q.f_hz for q in pts[:12]])
    H = linear_model(p).response(fs)
    gain_lin = 20 * np.log10(np.abs(H))
    phase_lin = np.degrees(np.unwrap(np.angle(H)))
    bw_lin = crossing(np.geomspace(0.5, 50, 400),
                      20 * np.log10(np.abs(linear_model(p).response(np.geomspace(0.5, 50, 400)))),
                      -3.0)
    for k in range(3):
        block = pts[12 * k:12 * k + 12]
        gain = np.array([q.gain_db for q in block])
        phase = np.array([q.phase_deg for q in block])
        assert np.max(np.abs(gain - gain_lin)) < 0.1
        assert np.max(np.abs(phase - phase_lin)) < 0.5
        assert crossing(fs, gain, -3.0) == pytest.approx(bw_lin, rel=0.01)
        assert all(q.limits == () and not q.diverged for q in block)


def test_the_rate_limit_binds_at_a_large_amplitude():
    # 20 deg at 10 Hz asks for 2*pi*10*20 = 1257 deg/s > sat1 = 800 deg/s: SAT1 is reached
    p = resolve()
    small, large = sinestream(p, [0.5, 20.0], [10.0])
    assert small.limits == () and "sat1" in large.limits
    assert large.gain_db < small.gain_db - 0.3 and large.phase_deg < small.phase_deg
    assert 2 * np.pi * large.f_hz * 20.0 > p["sat1"] / DEG


def test_distortion_grows_with_the_dead_band():
    thd = []
    for alpha_deg in (0.0, 0.01, 0.05):
        p = resolve({**LINEAR_OVERRIDES, "alpha": alpha_deg * DEG})
        (pt,) = sinestream(p, [0.2], [2.0])
        thd.append(pt.thd_pct)
    assert thd[0] < 0.1 < thd[1] < thd[2]


def test_frequencies_are_snapped_to_whole_samples():
    for f_req in (0.5, 7.3, 45.0, 50.0):
        f, dec, spp = snap_frequency(f_req, 1e-5)
        assert abs(f - f_req) / f_req < 0.0025 and 200 <= spp < 400
        assert dec * spp * 1e-5 * f == pytest.approx(1.0, rel=1e-12)
    with pytest.raises(EmaError, match="amplitudes"):
        sinestream(resolve(), [float("nan")], [1.0])
    with pytest.raises(EmaError, match="frequencies"):
        sinestream(resolve(), [1.0], [0.0])
