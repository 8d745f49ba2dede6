"""The friction sweep's candidate laws (identify.friction.laws): per-direction terms recovered
when the data need them and at zero within their intervals when not, the BIC choice on
symmetric vs asymmetric data, an independent scipy curve_fit of the same law, the shape
verdict against the sweep's scatter, and sweep files as real maps come (unsorted, repeated,
magnitudes, zero rows, linear units, .mat)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import curve_fit

from ema_cli.errors import EmaError
from ema_cli.identify.friction.laws import fit_law
from ema_cli.identify.friction.sweep import SweepData, fit_friction_sweep, load_sweep

SPEEDS = np.geomspace(0.05, 100.0, 10)  # |speeds| [rad/s], each measured twice per direction
SYM = dict(Fc=0.02, Fs=0.03, vs=1.0, sigma2=1e-4)
ASYM = dict(SYM, Fc_neg=0.026, Fs_neg=0.034, vs_neg=1.5, sigma2_neg=1.3e-4)
NOISE = 2e-4  # [N*m], 1 % of Fc


def _side(u, fc, fs, vs, s2):
    """The Stribeck level written out (docs/model.md §2, delta = 1): independent of the code."""
    return fc + (fs - fc) * np.exp(-u / vs) + s2 * u


def _sweep(p: dict[str, float], seed: int, shuffle: bool = True) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    w = np.concatenate([SPEEDS, SPEEDS, -SPEEDS, -SPEEDS])
    if shuffle:
        rng.shuffle(w)
    neg = {k[:-4]: v for k, v in p.items() if k.endswith("_neg")}
    pos = {k: v for k, v in p.items() if not k.endswith("_neg")}
    negp = {**pos, **neg}
    u = np.abs(w)
    T = np.where(w > 0, _side(u, pos["Fc"], pos["Fs"], pos["vs"], pos["sigma2"]),
                 -_side(u, negp["Fc"], negp["Fs"], negp["vs"], negp["sigma2"]))
    return w, T + NOISE * rng.standard_normal(w.size)


def test_symmetric_data_choose_the_symmetric_law_and_differences_hold_zero():
    # 5 seeds: BIC picks a per-direction law on symmetric data with P(chi2_4 > 4 ln 40) = 0.5 %
    covered = 0
    for seed in range(5):
        w, T = _sweep(SYM, seed)
        fit = fit_friction_sweep(SweepData(w, T, "sym"))
        assert fit.chosen == "stribeck", (seed, fit.selection)
        # the per-direction law fitted anyway: every difference is zero within its interval
        diffs = fit.laws["stribeck-dir"].differences()
        assert len(diffs) == 4 and all(d["zero_inside"] for d in diffs.values()), diffs
        u = fit.law.uncertainty
        truth = np.array([SYM[n] for n in fit.law.names])
        covered += int(np.sum((u.ci_low <= truth) & (truth <= u.ci_high)))
        assert fit.adequacy.verdict == "fits", fit.adequacy.why
    # 95 % intervals, 20 of them: P(fewer than 17 cover) = 1.6 % for honest intervals
    assert covered >= 17, covered


def test_asymmetric_data_choose_per_direction_and_recover_every_term():
    for seed in range(3):
        w, T = _sweep(ASYM, seed)
        fit = fit_friction_sweep(SweepData(w, T, "asym"))
        assert fit.chosen == "stribeck-dir", fit.selection
        p = fit.selection["f_tests"]["symmetric -> per direction (Stribeck)"]["p"]
        assert p < 1e-6
        u = fit.law.uncertainty
        truth = np.array([ASYM[n] for n in fit.law.names])
        inside = (u.ci_low <= truth) & (truth <= u.ci_high)
        assert inside.sum() >= 7, dict(zip(fit.law.names, inside, strict=True))  # 95 % each
        diffs = fit.law.differences()
        assert not diffs["Fc_neg - Fc"]["zero_inside"]  # 0.006 N*m apart, SE ~1e-4
        assert not diffs["sigma2_neg - sigma2"]["zero_inside"]
        # the symmetric law's shape is wrong: the verdict says so, and where
        sym = fit.laws["stribeck"]
        from ema_cli.identify.friction.sweep import sweep_adequacy

        ad = sweep_adequacy(fit.data, sym)
        assert ad.verdict == "does not fit" and ad.ratio > 3 and ad.failing, ad.why
        assert fit.adequacy.verdict == "fits"


def test_per_direction_law_matches_scipy_curve_fit():
    # the - direction alone, fitted by scipy's curve_fit on the formula written out here
    w, T = _sweep(ASYM, 7, shuffle=False)
    fit = fit_law("stribeck-dir", w, T)
    neg = w < 0

    def f(u, fc, fs, vs, s2):
        return _side(u, fc, fs, vs, s2)

    popt, pcov = curve_fit(f, -w[neg], -T[neg], p0=[0.02, 0.03, 1.0, 1e-4])
    got = np.array([fit.params[n] for n in ("Fc_neg", "Fs_neg", "vs_neg", "sigma2_neg")])
    np.testing.assert_allclose(got, popt, rtol=1e-5)  # one optimum, two solvers
    # the joint fit pools the noise of both sides; each side's SE within 30 % of curve_fit's
    j = [fit.names.index(n) for n in ("Fc_neg", "Fs_neg", "vs_neg", "sigma2_neg")]
    se = fit.uncertainty.se[j]
    np.testing.assert_allclose(se, np.sqrt(np.diag(pcov)), rtol=0.3)


def test_coulomb_law_noise_free_is_exact():
    w = np.array([-3.0, -2.0, -1.0, -0.5, 0.5, 1.0, 2.0, 3.0])
    T = np.where(w > 0, 0.5 + 0.1 * w, -0.7 + 0.2 * w)  # Fc 0.5, 0.7; sigma2 0.1, 0.2
    fit = fit_law("coulomb-dir", w, T)
    np.testing.assert_allclose([fit.params[n] for n in ("Fc", "sigma2", "Fc_neg", "sigma2_neg")],
                               [0.5, 0.1, 0.7, 0.2], rtol=1e-12)


def test_shape_without_repeats_only_bounds_the_scatter():
    # one point per speed: the scatter comes from neighbours (an upper bound): never "fits"
    w = np.concatenate([SPEEDS, -SPEEDS])
    u = np.abs(w)
    T = np.sign(w) * _side(u, 0.02, 0.03, 1.0, 1e-4) + NOISE * np.random.default_rng(
        0).standard_normal(w.size)
    fit = fit_friction_sweep(SweepData(w, T, "no repeats"))
    assert fit.adequacy.verdict == "inconclusive" and "upper bound" in fit.adequacy.why


def test_real_map_shapes_load(tmp_path):
    # unsorted, repeated, magnitudes for both directions, a zero row, mm/s and N, extra columns
    w, T = _sweep(ASYM, 1)
    rows = ["speed,force,temp_C"] + [f"{1000 * a:.17g},{abs(b) / 1000:.17g},25" for a, b in
                                     zip(w, T, strict=True)] + ["0,0.5,25"]
    p = tmp_path / "screw.csv"
    p.write_text("\n".join(rows) + "\n")
    data = load_sweep(p, {"omega_rpm": "speed:mm/s", "torque_nm": "force:kN"})
    assert data.linear and data.speed_unit == "m/s" and data.force_unit == "N"
    assert data.n == w.size and len(data.notes) == 2
    np.testing.assert_allclose(data.omega, w, rtol=1e-9)
    np.testing.assert_allclose(data.torque, T, rtol=1e-9)  # |T|/1000 in kN: T in N, signed
    fit = fit_friction_sweep(data)
    assert fit.chosen == "stribeck-dir"
    assert fit.law_units()["sigma2"] == "N*s/m"


def test_sweep_from_a_mat_matrix(tmp_path):
    from scipy.io import savemat

    w, T = _sweep(SYM, 2)
    p = tmp_path / "map.mat"
    savemat(p, {"meas": {"map": np.column_stack([w / (2 * np.pi / 60), T]), "note": "x"}})
    data = load_sweep(p, {"omega_rpm": "meas.map[:, 0]", "torque_nm": "meas.map[:, 1]"})
    np.testing.assert_allclose(data.omega, w, rtol=1e-12)


@pytest.mark.parametrize("columns, expect", [
    ({"omega_rpm": "speed:furlong/s"}, "unknown unit 'furlong/s'; omega_rpm takes sweep speed "
                                       "units"),
    ({"omega_rpm": "speed:V"}, "'V' is a unit of voltage"),
    ({"torque_nm": "nope"}, "has no column 'nope'; it has speed, force"),
])
def test_bad_sweep_columns_one_line(tmp_path, columns, expect):
    p = tmp_path / "s.csv"
    p.write_text("speed,force\n" + "".join(f"{s}{v},{s}1\n" for s in "-+" for v in range(1, 6)))
    with pytest.raises(EmaError) as exc:
        load_sweep(p, columns)
    assert expect in exc.value.message and "\n" not in exc.value.message


def test_stribeck_shape_delta_freed_is_recovered():
    # a Gaussian Stribeck curve (delta = 2): fit_delta frees the shape; truth inside the
    # intervals and delta's within 5 %
    rng = np.random.default_rng(0)
    w = np.concatenate([SPEEDS, SPEEDS, -SPEEDS, -SPEEDS])
    u = np.abs(w)
    T = np.sign(w) * (0.02 + 0.01 * np.exp(-(u / 1.0) ** 2) + 1e-4 * u) \
        + NOISE * rng.standard_normal(w.size)
    fit = fit_friction_sweep(SweepData(w, T, "delta 2"), fit_delta=True)
    assert fit.chosen == "stribeck" and "delta" in fit.law.names
    u_ = fit.law.uncertainty
    truth = np.array([{"Fc": 0.02, "Fs": 0.03, "vs": 1.0, "sigma2": 1e-4, "delta": 2.0}[n]
                      for n in fit.law.names])
    assert np.sum((u_.ci_low <= truth) & (truth <= u_.ci_high)) >= 4
    assert abs(fit.law.params["delta"] / 2 - 1) < 0.05
