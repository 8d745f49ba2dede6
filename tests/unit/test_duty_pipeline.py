"""`ema duty` through the API: the whole pipeline (profile, mechanics in the kernel, the exact
thermal integration) against closed forms, the acceptance battery's ``duty`` kind and thermal
tolerances in ``ema yield``."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from ema_cli.acceptance.duty.thermal import Network
from ema_cli.api.acceptance import acceptance
from ema_cli.api.duty import duty
from ema_cli.api.production import production_yield
from ema_cli.model.params import resolve
from tests.helpers.thermal import closed_form as _closed_form

ZERO_C = 273.15
LOAD = 9.6  # held on the output [N*m]: 9.6/(24*0.08) = 5 A in the reference EMA's winding


def _hold(plant: dict, duration: float = 12000.0) -> dict:
    return {"name": "hold", "stroke": "30 deg", "actuator": {"config": None, "plant": plant},
            "segments": [{"dwell": {"duration_s": duration,
                                    "load": {"force": f"{LOAD} N*m"}}}]}


def _current(p: dict) -> float:
    return LOAD / (p["m"] * p["Kt"])


def test_holding_a_load_matches_the_two_node_closed_form() -> None:
    """A dwell holding 9.6 N*m (5 A, 12.5 W at alpha 0, no friction heat) for 10 slow time
    constants: every trace row within 0.01 K of the two-node step response written out in
    tests/unit/test_duty_thermal.py (the current from the ratio and Kt, not the simulation)."""
    r = duty(_hold({"alpha_cu": 0.0, "fric_heat": 0.0}), hot=False)
    p = resolve()
    power = _current(p) ** 2 * p["R"]
    assert power == pytest.approx(12.5)
    tr = r.trace()
    want = _closed_form(Network.of({**p, "alpha_cu": 0.0}), power, tr.t_s.to_numpy(),
                        40.0 + ZERO_C) - ZERO_C
    assert np.abs(tr.winding_c.to_numpy() - want[0]).max() < 0.01
    assert np.abs(tr.housing_c.to_numpy() - want[1]).max() < 0.01
    assert r.run.thermal.peak_w - ZERO_C == pytest.approx(40.0 + 12.5 * 4.13, abs=0.05)


def test_resistance_rising_with_temperature_settles_where_the_closed_form_says() -> None:
    """R(T) fed back: the steady rise solves theta = i^2 R0 (1 + alpha (T_a + theta - T_ref))
    (R_wh + R_ha), i.e. theta = i^2 R0 (1 + alpha (T_a - T_ref)) R_sum / (1 - i^2 R0 alpha
    R_sum); after 10 slow time constants the winding is within 0.05 K of it (66.2 K, against
    51.6 K at the ambient's resistance)."""
    r = duty(_hold({"fric_heat": 0.0}), hot=False)
    p = resolve()
    i2, r0, a, r_sum = _current(p) ** 2, p["R"], p["alpha_cu"], p["Rth_wh"] + p["Rth_ha"]
    theta = i2 * r0 * (1 + a * (p["T_amb"] - p["T_ref"])) * r_sum / (1 - i2 * r0 * a * r_sum)
    assert theta > 60.0
    assert r.run.thermal.peak_w - p["T_amb"] == pytest.approx(theta, abs=0.05)


SHORT = {"name": "short", "stroke": "30 deg", "load": {"spring": "28 N*m/rad"},
         "segments": [{"sine": {"amplitude": 0.95, "frequency_hz": 0.3, "cycles": 400}},
                      {"sine": {"amplitude": 0.1, "frequency_hz": 2, "cycles": 200}}]}
"""A short sine profile (1433 s): the winding warms by tens of kelvin."""


def _spec(limit_c: float) -> dict:
    return {"name": "duty-spec", "actuator": {"config": None},
            "tests": {"mission": {"test": "duty", "profile": SHORT, "insulation": "F",
                                  "limits": {"winding_temperature": {"max": limit_c,
                                                                     "unit": "degC"}}}}}


def test_the_acceptance_duty_kind_judges_the_winding_as_ema_duty_measures_it() -> None:
    peak = duty(SHORT, hot=False).run.thermal.peak_w - ZERO_C
    assert 60.0 < peak < 150.0
    for limit, want in ((peak + 5.0, "PASS"), (peak - 5.0, "FAIL")):
        res = acceptance(_spec(limit))
        v = next(v for v in res.verdicts if v.metric == "winding_temperature")
        assert v.result == want, (limit, peak)
        # the same method; the hot simulation sits at the test's limit, not class F's: the
        # current's R dependence interpolated from another pair (1e-4 K here)
        assert v.value == pytest.approx(peak, abs=0.01)


@pytest.mark.slow
def test_thermal_tolerances_reach_each_unit_in_yield() -> None:
    """Only the ambient varies (sd 5 K): each unit's winding temperature is what the battery
    gives one actuator at that unit's ambient (to 1e-6 K: the units share the blocks' kernel
    batches), and a hotter bay makes a hotter winding."""
    tol = {"tolerances": {"plant.T_amb": {"dist": "normal", "mean": 313.15, "sd": 5.0}}}
    res = production_yield(_spec(150.0), tol, n=3, seed=1, worst_budget=None, drivers=False)
    s = res.samples
    col = "mission/winding_temperature [degC]"
    assert s["plant.T_amb"].std() > 1.0
    for _, row in s.iterrows():
        one = acceptance(_spec(150.0), {"actuator.plant.T_amb": float(row["plant.T_amb"])})
        v = next(v for v in one.verdicts if v.metric == "winding_temperature")
        assert row[col] == pytest.approx(v.value, abs=1e-6)
    order = np.argsort(s["plant.T_amb"].to_numpy())
    assert np.all(np.diff(s[col].to_numpy()[order]) > 0)


@pytest.mark.slow
def test_the_hot_actuator_is_the_battery_run_at_the_hot_resistance() -> None:
    """The hot check's resistance is R0 (1 + alpha (T_peak - T_ref)) (by hand here), and its
    bandwidth and no-load rate are what the acceptance battery measures on an actuator given
    that resistance; hot, the no-load rate is lower (less voltage left over R i)."""
    r = duty(SHORT, hot=True)
    h, p = r.run.hot, resolve()
    assert h is not None
    peak = r.run.thermal.peak_w
    r_hot = p["R"] * (1 + p["alpha_cu"] * (peak - p["T_ref"]))
    assert h.r_hot == pytest.approx(r_hot, rel=1e-12)
    assert h.r_hot > 1.15 * h.r_cold  # 89 degC against 40 degC
    spec = {"name": "hot", "actuator": {"config": None, "plant": {"R": r_hot}},
            "tests": {"bw": {"test": "frequency_response", "amplitudes_deg": [1.0],
                             "f_min_hz": 0.5, "f_max_hz": 50.0, "n": 16,
                             "limits": {"bandwidth": {"min": 0, "unit": "Hz"}}},
                      "rate": {"test": "no_load_rate", "amplitude_deg": 40.0, "duration_s": 1.0,
                               "limits": {"rate": {"min": 0, "unit": "deg/s"}}}}}
    acc = {v.metric: v.value for v in acceptance(spec).verdicts}
    assert h.bandwidth[1].value == pytest.approx(acc["bandwidth"], rel=1e-9)
    assert math.degrees(h.rate[1].value) == pytest.approx(acc["rate"], rel=1e-9)
    assert h.rate[1].value < h.rate[0].value


def _described(tmp_path, thermal: dict) -> Path:
    import yaml

    base = yaml.safe_load((Path(__file__).resolve().parents[2] / "configs" / "actuators"
                           / "paper_ema.yaml").read_text())
    base["drive"] = {**base["drive"], "thermal": thermal}
    f = tmp_path / "act.yaml"
    f.write_text(yaml.safe_dump(base))
    return f


def test_a_described_thermal_element_is_read_in_its_units(tmp_path) -> None:
    """drive.thermal in datasheet units: a time constant becomes a capacity (tau/R_th), the
    ambient in degC, class H's 180 degC the default limit; the held load settles at
    T_a + P (R_wh + R_ha) with P at the hot resistance (the closed form of the R(T) test)."""
    f = _described(tmp_path, {"rth_winding_housing": "1.0 K/W", "rth_housing_ambient": "3 K/W",
                              "tau_winding": "20 s", "cth_housing": "300 J/K",
                              "ambient": "25 degC", "insulation": "H", "friction_share": 0})
    r = duty(_hold({}, 15000.0), f, hot=False)  # 15 slow time constants (961 s)
    p = r.run.params
    assert (p["Cth_w"], p["Cth_h"], p["T_amb"]) == pytest.approx((20.0, 300.0, 298.15))
    assert r.limits.winding_k == pytest.approx(180.0 + ZERO_C)
    i2, r0, a = _current(p) ** 2, p["R"], p["alpha_cu"]
    theta = i2 * r0 * (1 + a * (p["T_amb"] - p["T_ref"])) * 4.0 / (1 - i2 * r0 * a * 4.0)
    assert r.run.thermal.peak_w - p["T_amb"] == pytest.approx(theta, abs=0.05)


@pytest.mark.parametrize(("thermal", "needle"), [
    ({"rth_winding_housing": "-1 K/W"}, "drive.thermal.rth_winding_housing: must be > 0"),
    ({"rth_winding_housing": "1 ohm"}, "drive.thermal.rth_winding_housing: unit 'ohm'"),
    ({"insulation": "Z"}, "drive.thermal.insulation: expected a class"),
    ({"tau_winding": "20 s", "cth_winding": 3}, "give cth_winding or tau_winding, not both"),
    ({"colour": 1}, "drive.thermal.colour: unknown key")])
def test_a_bad_thermal_element_is_one_line(tmp_path, thermal, needle) -> None:
    from ema_cli.errors import EmaError

    with pytest.raises(EmaError) as exc:
        duty(_hold({}), _described(tmp_path, thermal), hot=False)
    assert needle in str(exc.value) and "\n" not in str(exc.value)
