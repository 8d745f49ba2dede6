"""The torque-twist terms (identify.torque.terms): each term recovered within its interval on
data that need it and zero within its interval on data that do not, an independent scipy
curve_fit of the same law, the shape verdict (Eq. 8 on hysteresis data: "does not fit", and
where), a derived twist rate, bad terms one line."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.optimize import curve_fit

from ema_cli.errors import EmaError
from ema_cli.identify.torque.terms import check_terms, fit_terms

KL, ALPHA, C = 590.0, 0.003, 0.5  # [N*m/rad], [rad], [N*m*s/rad]
OFF = 0.001  # twist offset [rad]
NOISE = 0.05  # torque noise [N*m]
T_S = np.linspace(0.0, 2.0, 2001)  # 1 kHz, 2 s


def _twist() -> tuple[np.ndarray, np.ndarray]:
    """A growing chirp of twist [rad] and its exact rate [rad/s]."""
    t = T_S
    ph = 2 * np.pi * (0.5 * t + 0.8 * t**2)
    env = 0.01 + 0.005 * t
    return env * np.sin(ph), 0.005 * np.sin(ph) + env * np.cos(ph) * 2 * np.pi * (0.5 + 1.6 * t)


def _dz(d: np.ndarray, a: float) -> np.ndarray:
    return np.sign(d) * np.maximum(np.abs(d) - a, 0.0)


def _dahl(d: np.ndarray, fc: float, sigma: float) -> np.ndarray:
    """The Dahl element df/dx = sigma*(1 - f/fc*sign(dx)) integrated exactly per sample,
    written here from Dahl (1968), not from the code."""
    f, out = 0.0, np.zeros_like(d)
    for k in range(1, d.size):
        dx = d[k] - d[k - 1]
        s = math.copysign(1.0, dx) if dx else 0.0
        if s:
            f = s * fc + (f - s * fc) * math.exp(-sigma * abs(dx) / fc)
        out[k] = f
    return out


def _data(ft=0.0, preload=0.0, fc_t=0.0, sigma_t=400.0, seed=0):
    dth, dw = _twist()
    d = dth - OFF
    T = KL * _dz(d, ALPHA) + C * dw + ft * np.sign(dw) + preload * np.clip(d / ALPHA, -1, 1)
    if fc_t:
        T = T + _dahl(d, fc_t, sigma_t)
    return dth, dw, T + NOISE * np.random.default_rng(seed).standard_normal(T.size)


def _fit(dth, dw, T, terms):
    return fit_terms(T_S, dth, dw, T, "paper", 0.0, True, 0.0, terms, (0.0, 0.006))


def _check(fit, truth: dict[str, float]):
    iv = fit.intervals()
    for n, v in truth.items():
        lo, hi = iv[n]["ci95"]
        assert lo <= v <= hi, (n, v, iv[n])


@pytest.mark.parametrize("ft, preload", [(0.8, 1.5), (0.0, 0.0)])
def test_coulomb_friction_and_preload_needed_or_zero(ft, preload):
    dth, dw, T = _data(ft=ft, preload=preload)
    fit = _fit(dth, dw, T, ("offset", "friction", "preload"))
    _check(fit, {"kL": KL, "alpha": ALPHA, "c": C, "dth0": OFF, "Ft": ft, "preload": preload})
    iv = fit.intervals()
    needed = ft != 0.0
    assert iv["Ft"]["zero_inside"] is not needed and iv["preload"]["zero_inside"] is not needed
    assert fit.adequacy.verdict == "fits", fit.adequacy.why


@pytest.mark.parametrize("fc_t", [0.8, 0.0])
def test_dahl_friction_needed_or_zero(fc_t):
    dth, dw, T = _data(fc_t=fc_t, seed=1)
    fit = _fit(dth, dw, T, ("offset", "dahl"))
    truth = {"kL": KL, "alpha": ALPHA, "c": C, "dth0": OFF, "Fc_t": fc_t}
    if fc_t:
        truth["sigma_t"] = 400.0
    _check(fit, truth)
    assert fit.intervals()["Fc_t"]["zero_inside"] is (fc_t == 0.0)


def test_offset_zero_within_its_interval_when_absent():
    # 10 seeds: an honest 95 % interval holds 0 in >= 8 (P(fewer) = 1.2 %); measured over 30
    # seeds: z = dth0/SE has mean 0.02 and std 1.2 (the 19-dof jackknife), coverage 27/30
    dth, dw = _twist()
    zero, z = 0, []
    for seed in range(10):
        T = KL * _dz(dth, ALPHA) + C * dw + NOISE * np.random.default_rng(seed).standard_normal(
            dth.size)
        iv = _fit(dth, dw, T, ("offset",)).intervals()["dth0"]
        zero += iv["zero_inside"]
        z.append(iv["value"] / iv["standard_error"])
    assert zero >= 8 and abs(np.mean(z)) < 1.0, (zero, z)


def test_matches_scipy_curve_fit_on_the_same_law():
    dth, dw, T = _data(ft=0.8, preload=1.5, seed=3)
    fit = _fit(dth, dw, T, ("offset", "friction", "preload"))

    def f(_, k, a, c, off, ft, pre):
        d = dth - off
        return k * _dz(d, a) + c * dw + ft * np.sign(dw) + pre * np.clip(d / a, -1, 1)

    x0 = [600.0, 0.0025, 0.3, 0.0, 0.0, 0.0]
    popt, _ = curve_fit(f, None, T, p0=x0, method="trf", x_scale=[100, 1e-3, 0.1, 1e-3, 0.1, 0.1],
                        xtol=1e-14, ftol=1e-14, gtol=1e-14)
    got = [fit.params[n] for n in ("kL", "alpha", "c", "dth0", "Ft", "preload")]
    np.testing.assert_allclose(got, popt, rtol=1e-5, atol=1e-7)  # one optimum, two solvers


def test_eq8_on_hysteresis_data_does_not_fit_and_says_where():
    # a gearbox with friction: Eq. 8 lets c absorb the loop; its shape verdict catches it
    dth, dw, T = _data(ft=2.0, seed=4)
    plain = _fit(dth, dw, T, ())
    assert plain.adequacy.verdict == "does not fit", plain.adequacy.why
    assert plain.adequacy.failing and "twist rate" in plain.adequacy.where()
    with_f = _fit(dth, dw, T, ("offset", "friction"))
    assert with_f.adequacy.verdict == "fits"
    assert abs(with_f.params["kL"] / KL - 1) < 0.005  # the loaded branches' slope


def test_derived_twist_rate(tmp_path):
    from ema_cli.identify.torque.data import load_csv

    dth, dw = _twist()
    p = tmp_path / "loops.csv"
    rows = ["time,twist,torque"] + [f"{a:.17g},{b * 60 / math.pi * 180:.17g},{b:.17g}"
                                    for a, b in zip(T_S, dth, strict=True)]
    p.write_text("\n".join(rows) + "\n")
    data = load_csv(p, {"t_s": "time", "dtheta_rad": "twist:arcmin", "torque_nm": "torque"})
    np.testing.assert_allclose(data.dth, dth, rtol=1e-12)
    # central differences of a chirp at 1 kHz: error ~ (2 pi f dt)^2/6 of the rate, f <= 3.7 Hz
    inner = slice(1, -1)
    np.testing.assert_allclose(data.dw[inner], dw[inner], atol=1e-3 * np.max(np.abs(dw)))
    assert data.notes and "derived" in data.notes[0]


@pytest.mark.parametrize("terms, expect", [
    (("friction", "dahl"), "terms friction and dahl are two laws of one friction"),
    (("offset", "backlash"), "unknown term(s) backlash; expected any of offset, friction"),
])
def test_bad_terms_one_line(terms, expect):
    with pytest.raises(EmaError) as exc:
        check_terms(terms)
    assert expect in exc.value.message and "\n" not in exc.value.message
