"""Issue 22: three verdicts. Every acceptance metric kind pushed outside its measurable range
gives INCONCLUSIVE with the reason naming the setting to change; a bound that lies wholly on
one side of the limit still decides; a spec that cannot measure is refused at load, naming the
key; the overall verdict and the exit codes."""

from __future__ import annotations

import math

import pytest

from ema_cli.acceptance.battery import (
    Measurement,
)
from ema_cli.acceptance.kinds import run_test
from ema_cli.acceptance.verdict import (
    EXIT_CODES,
    FAIL,
    INCONCLUSIVE,
    PASS,
    judge,
    overall,
    verdicts,
)
from ema_cli.api import acceptance
from ema_cli.config.acceptance import AcceptanceSpec
from ema_cli.config.loader import load_config
from ema_cli.errors import EmaError
from ema_cli.model.params import resolve

DT = 1e-5


def spec_test(entry: dict) -> object:
    return load_config({"name": "t", "tests": {"x": entry}}, [], AcceptanceSpec).tests["x"]


def rows(entry: dict, params: dict | None = None) -> dict[tuple[str, str], object]:
    """Run one test on the reference EMA (with ``params``) -> its verdicts by (metric,
    condition)."""
    test = spec_test(entry)
    run = run_test("x", test, resolve(params or {}), DT)
    return {(v.metric, v.condition): v for v in verdicts(run, test.limits)}


def only_row(entry: dict, metric: str, params: dict | None = None) -> object:
    (v,) = [v for (m, _), v in rows(entry, params).items() if m == metric]
    return v


# --------------------------------------------------------------- judging a value or a bound
def test_judge_measured_values_and_bounds():
    m = Measurement("bandwidth", "", 6.0, "Hz")
    assert judge(m, 5.0, math.inf) == (PASS, "") and judge(m, 7.0, math.inf) == (FAIL, "")
    nan = Measurement("bandwidth", "", math.nan, "Hz")
    assert judge(nan, 5.0, math.inf)[0] == INCONCLUSIVE  # a diverged run is not a measurement
    above = Measurement("bandwidth", "", 2.0, "Hz", lower=2.0, reason="widen f_max_hz")
    assert judge(above, 5.0, math.inf) == (INCONCLUSIVE, "widen f_max_hz")
    assert judge(above, 1.0, math.inf) == (PASS, "")  # > 2 Hz meets min 1 Hz whatever it is
    assert judge(above, 0.0, 1.5) == (FAIL, "")  # > 2 Hz breaks max 1.5 Hz
    assert judge(above, 1.0, 10.0) == (INCONCLUSIVE, "widen f_max_hz")


def test_overall_verdict_and_exit_codes():
    assert overall([PASS, PASS]) == PASS and overall([]) == PASS
    assert overall([PASS, INCONCLUSIVE]) == INCONCLUSIVE
    assert overall([INCONCLUSIVE, FAIL, PASS]) == FAIL
    assert EXIT_CODES == {PASS: 0, FAIL: 1, INCONCLUSIVE: 3}


# -------------------------------------------------- each metric kind outside its range
def test_step_shorter_than_its_settling_is_inconclusive():
    # 20 deg at ~810 deg/s takes ~25 ms: a 20 ms run ends mid-move
    got = rows({"test": "step", "amplitude_deg": 20, "duration_s": 0.02, "limits": {
        "rise_time": {"max": 80, "unit": "ms"}, "overshoot": {"max": 10, "unit": "%"},
        "settling_time": {"max": 0.35, "unit": "s"},
        "steady_state_error": {"max": 0.01, "unit": "deg"},
        "peak_current": {"max": 31, "unit": "A"}}})
    assert {v.metric: v.result for v in got.values()} == dict.fromkeys(
        ["rise_time", "overshoot", "settling_time", "steady_state_error", "peak_current"],
        INCONCLUSIVE)
    for v in got.values():
        assert not v.measured and "0.02 s: lengthen duration_s" in v.reason, v
    settle = got[("settling_time", "20 deg")]
    assert settle.lower == pytest.approx(0.02) and settle.upper == math.inf
    # the same bound decides a limit it lies wholly outside: not settled at 20 ms > 10 ms
    v = only_row({"test": "step", "amplitude_deg": 20, "duration_s": 0.02, "limits": {
        "settling_time": {"max": 10, "unit": "ms"}}}, "settling_time")
    assert v.result == FAIL and "decided on a bound" in v.note and not v.reason


def test_frequency_response_range_below_or_above_the_bandwidth_is_inconclusive():
    # the reference EMA's bandwidth: 6.2 Hz (bundled spec)
    # and its gain at 1 deg rises to 0.18 dB at 1 Hz (0.07 dB at 0.5 Hz, 0.11 dB at 2 Hz)
    low = rows({"test": "frequency_response", "amplitudes_deg": [1], "f_min_hz": 0.5,
                "f_max_hz": 0.8, "n": 2, "limits": {"bandwidth": {"min": 5, "unit": "Hz"},
                                                    "peak_gain": {"max": 2, "unit": "dB"}}})
    bw, peak = low[("bandwidth", "1 deg")], low[("peak_gain", "1 deg")]
    assert bw.result == INCONCLUSIVE and bw.lower == pytest.approx(0.8, rel=0.01)
    assert bw.reason == ("bandwidth above the highest frequency measured, 0.801 Hz: widen "
                         "f_max_hz")  # 0.8 Hz snapped to a whole number of samples
    assert peak.result == INCONCLUSIVE and peak.reason.endswith("widen f_max_hz")
    assert 0.05 < peak.lower < 0.2 and peak.upper == math.inf
    high = only_row({"test": "frequency_response", "amplitudes_deg": [1], "f_min_hz": 20,
                     "f_max_hz": 40, "n": 2, "limits": {"bandwidth": {"min": 5, "unit": "Hz"}}},
                    "bandwidth")
    assert high.result == INCONCLUSIVE and high.upper == pytest.approx(20.0, rel=0.01)
    assert "bandwidth below the lowest frequency measured, 20 Hz: lower f_min_hz" in high.reason


def test_margins_without_crossover_in_range_are_inconclusive():
    # position loop crossover near 8 Hz: a 1 Hz search range holds no crossover
    got = rows({"test": "margins", "loops": ["position"], "f_max_hz": 1.0, "limits": {
        "gain_margin": {"min": 6, "unit": "dB"}, "phase_margin": {"min": 45, "unit": "deg"}}})
    for metric in ("gain_margin", "phase_margin"):
        v = got[(metric, "position loop")]
        assert v.result == INCONCLUSIVE and "up to f_max_hz = 1 Hz (|L| = 16.6 dB" in v.reason
        assert v.reason.endswith("widen f_max_hz")
    # the speed loop has no phase crossover at all: the bound |L(1e5 Hz)| decides (> 100 dB)
    v = only_row({"test": "margins", "loops": ["speed"], "limits": {
        "gain_margin": {"min": 6, "unit": "dB"}}}, "gain_margin")
    assert v.result == PASS and not v.measured and v.lower > 100


def test_threshold_outside_the_search_range_is_inconclusive():
    below = only_row({"test": "threshold", "search_deg": [1e-3, 1.0], "within_s": 0.05,
                      "limits": {"threshold": {"min": 1e-5, "max": 1, "unit": "deg"}}},
                     "threshold")
    assert below.result == INCONCLUSIVE and below.upper == pytest.approx(1e-3)
    assert "search minimum 0.001 deg: lower search_deg" in below.reason
    # 0.17 deg of half backlash: no step up to 0.01 deg is followed
    above = only_row({"test": "threshold", "search_deg": [1e-4, 0.01], "within_s": 0.05,
                      "limits": {"threshold": {"max": 1, "unit": "deg"}}}, "threshold",
                     {"alpha": 0.003})
    assert above.result == INCONCLUSIVE and above.lower == pytest.approx(0.01)
    assert "search maximum 0.01 deg: raise search_deg" in above.reason


def test_hysteresis_where_the_load_does_not_move_is_inconclusive():
    # motor-angle loop, +-0.05 deg command inside a 0.34 deg dead band: the load never moves
    # and the loop width would read ~0 (a false PASS before issue 22)
    got = rows({"test": "hysteresis", "amplitude_deg": 0.05, "period_s": 0.4, "limits": {
        "hysteresis": {"max": 0.1, "unit": "deg"}, "free_play": {"max": 0.05, "unit": "deg"}}},
               {"alpha": 0.003, "fb_motor": 1.0})
    for v in got.values():
        assert v.result == INCONCLUSIVE and v.reason.endswith("raise amplitude_deg"), v
    # a limit cycle (load feedback, backlash): the free play is inconclusive, the loop is read
    lc = rows({"test": "hysteresis", "amplitude_deg": 2, "period_s": 2, "limits": {
        "hysteresis": {"max": 1, "unit": "deg"}, "free_play": {"max": 1, "unit": "deg"}}},
              {"alpha": 0.003})
    by = {v.metric: v for v in lc.values()}
    assert by["free_play"].result == INCONCLUSIVE and "limit cycle" in by["free_play"].reason
    assert by["hysteresis"].measured


def test_load_deflection_faster_than_the_load_follows_is_inconclusive():
    # a 4 ms torque triangle (250 Hz) against a 38 Hz load resonance: no static line
    got = rows({"test": "load_deflection", "torque_nm": 20, "period_s": 0.004, "limits": {
        "stiffness": {"min": 500, "unit": "N*m/rad"}, "free_play": {"max": 0.05, "unit": "deg"}}})
    for v in got.values():
        assert v.result == INCONCLUSIVE and "lengthen period_s" in v.reason, v
    # 50 ms with 0.17 deg of half backlash: a positive slope, but not one line per branch
    # (rms residual 12.8 % of the span; 0.3 s reads 578 N*m/rad within 2 % and passes)
    got = rows({"test": "load_deflection", "torque_nm": 20, "period_s": 0.05, "limits": {
        "stiffness": {"min": 500, "unit": "N*m/rad"}}}, {"alpha": 0.003})
    (v,) = got.values()
    assert v.result == INCONCLUSIVE and "not one line per branch" in v.reason
    assert v.reason.endswith("raise fit_fraction or lengthen period_s")


def test_dynamic_stiffness_minimum_at_the_range_edge_is_inconclusive():
    # the minimum lies at 36.5 Hz; 0.5-5 Hz puts it at the top edge
    v = only_row({"test": "dynamic_stiffness", "f_min_hz": 0.5, "f_max_hz": 5, "n": 3,
                  "limits": {"dynamic_stiffness": {"min": 100, "unit": "N*m/rad"}}},
                 "dynamic_stiffness")
    assert v.result == INCONCLUSIVE and v.lower == 0.0 and v.upper > 100
    assert "highest frequency measured" in v.reason and v.reason.endswith("widen f_max_hz")


def test_no_load_rate_still_accelerating_is_inconclusive():
    v = only_row({"test": "no_load_rate", "amplitude_deg": 40, "duration_s": 0.005,
                  "limits": {"rate": {"min": 700, "unit": "deg/s"}}}, "rate")
    assert v.result == INCONCLUSIVE and v.value < 700
    assert "still accelerating at the end of the run, 0.005 s: lengthen duration_s" in v.reason


# ----------------------------------------------------------- specs that cannot measure
@pytest.mark.parametrize(("entry", "message"), [
    ({"test": "step", "amplitude_deg": 1, "duration_s": 5e-5,
      "limits": {"overshoot": {"max": 10, "unit": "%"}}}, "tests.x.duration_s: 5e-05 gives 5"),
    ({"test": "hysteresis", "period_s": 1e-5,
      "limits": {"hysteresis": {"max": 1, "unit": "deg"}}}, "tests.x.period_s: 1e-05 gives"),
    ({"test": "load_deflection", "torque_nm": 1, "period_s": 1e-4,
      "limits": {"stiffness": {"min": 1, "unit": "N*m/rad"}}}, "tests.x.period_s"),
    ({"test": "threshold", "within_s": 1e-5,
      "limits": {"threshold": {"max": 1, "unit": "deg"}}}, "tests.x.within_s"),
    ({"test": "no_load_rate", "duration_s": 1e-5,
      "limits": {"rate": {"min": 1, "unit": "deg/s"}}}, "tests.x.duration_s"),
    ({"test": "frequency_response", "amplitudes_deg": [1], "f_min_hz": 1, "f_max_hz": 5000,
      "limits": {"bandwidth": {"min": 1, "unit": "Hz"}}}, "tests.x.f_max_hz: 5000 gives 20"),
    ({"test": "dynamic_stiffness", "f_min_hz": 1, "f_max_hz": 5000,
      "limits": {"dynamic_stiffness": {"min": 1, "unit": "N*m/rad"}}}, "tests.x.f_max_hz"),
])
def test_a_span_shorter_than_a_few_steps_is_refused_before_any_run(entry, message):
    with pytest.raises(EmaError) as exc:
        acceptance({"name": "t", "tests": {"x": entry}})
    text = str(exc.value)
    assert message in text and "dt_s = 1e-05 s" in text and "\n" not in text


def test_a_threshold_floor_above_the_limit_is_refused_at_load():
    with pytest.raises(EmaError, match=r"tests\.x\.search_deg: the search floor 0\.01 deg is "
                                       r"above the limit \(max 0\.005 deg\)"):
        spec_test({"test": "threshold", "search_deg": [0.01, 1],
                   "limits": {"threshold": {"max": 0.005, "unit": "deg"}}})
    with pytest.raises(EmaError, match=r"search ceiling 0\.1 deg is below the limit"):
        spec_test({"test": "threshold", "search_deg": [0.001, 0.1],
                   "limits": {"threshold": {"min": 12, "unit": "arcmin"}}})


def test_the_api_result_carries_the_three_verdicts():
    res = acceptance("configs/acceptance.yaml", {"tests.margins.f_max_hz": 1.0},
                     only=["margins"])
    assert res.verdict == INCONCLUSIVE and res.exit_code == 3 and not res.passed
    # |L| at 1 Hz: 16.6 dB (position loop), -17.8 dB and rising (speed loop): no margin known
    assert len(res.inconclusive) == 4 and not res.failed
    df = res.to_pandas()
    assert set(df.result) == {INCONCLUSIVE}
    assert (df.passed == (df.result == PASS)).all()
    assert df.loc[df.result == INCONCLUSIVE, "reason"].str.endswith("widen f_max_hz").all()
