"""Claim evaluation on synthetic result tables: passing, failing and not evaluable."""

from __future__ import annotations

import math

import pandas as pd
import pytest

from ema_cli.analysis.claims import Claim, evaluate_claim, verdicts_frame

STUDIES = {
    "dz2": pd.DataFrame({
        "label": ["baseline", "0.001", "0.01", "0.1"],
        "deadzone2_deg": [math.nan, 0.001, 0.01, 0.1],
        "p2p_err_pos_deg": [1e-6, 0.003, 0.03, 0.3],
        "t50_s": [0.0169, 0.0193, 0.0193, 0.0447],
    }),
    "sat2": pd.DataFrame({"saturation2_v": ["40", "off"], "peak_voltage_cmd_v": [40.0, 50.3]}),
}
SCALARS = {"kL_error_pct": 0.004, "alpha_error_pct": 5.0}


def claim(check: dict) -> Claim:
    return Claim.model_validate({"id": "c", "paper": "p", "statement": "s", "check": check})


@pytest.mark.parametrize(("check", "passed", "measured"), [
    ({"kind": "value", "study": "dz2", "where": {"deadzone2_deg": 0.1},
      "metric": "p2p_err_pos_deg", "op": ">", "value": 0.002}, True, "p2p_err_pos_deg = 0.3"),
    ({"kind": "value", "study": "dz2", "where": {"label": "baseline"},
      "metric": "p2p_err_pos_deg", "op": ">", "value": 0.002}, False, "= 1e-06"),
    ({"kind": "compare", "study": "sat2", "a": {"saturation2_v": "off"},
      "b": {"saturation2_v": "40"}, "metric": "peak_voltage_cmd_v", "op": ">", "factor": 1.2},
     True, "50.3 > 1.2 x 40"),
    ({"kind": "compare", "study": "sat2", "a": {"saturation2_v": "off"},
      "b": {"saturation2_v": "40"}, "metric": "peak_voltage_cmd_v", "op": ">", "factor": 1.3},
     False, "50.3 > 1.3 x 40"),
    ({"kind": "monotonic", "study": "dz2", "axis": "deadzone2_deg", "metric": "t50_s",
      "direction": "increasing", "strict": True}, False, "0.01: 0.0193"),  # 0.0193 twice
    ({"kind": "monotonic", "study": "dz2", "axis": "deadzone2_deg", "metric": "t50_s",
      "direction": "increasing", "strict": False}, True, "0.1: 0.0447"),
    ({"kind": "scalar", "name": "kL_error_pct", "op": "<", "value": 0.85}, True, "0.004"),
    ({"kind": "scalar", "name": "alpha_error_pct", "op": "<", "value": 3.7}, False, "= 5"),
])
def test_checks_pass_and_fail(check, passed, measured):
    v = evaluate_claim(claim(check), STUDIES, SCALARS)
    assert v.passed is passed
    assert measured in v.measured


@pytest.mark.parametrize(("check", "reason"), [
    ({"kind": "value", "study": "nope", "metric": "x", "op": "<", "value": 1}, "no study 'nope'"),
    ({"kind": "value", "study": "dz2", "where": {"deadzone2_deg": 0.5},
      "metric": "t50_s", "op": "<", "value": 1}, "selects 0 rows"),
    ({"kind": "value", "study": "dz2", "where": {"bogus": 1},
      "metric": "t50_s", "op": "<", "value": 1}, "no column 'bogus'"),
    ({"kind": "scalar", "name": "missing", "op": "<", "value": 1}, "no result named 'missing'"),
])
def test_unevaluable_claims_fail_with_the_reason(check, reason):
    v = evaluate_claim(claim(check), STUDIES, SCALARS)
    assert not v.passed and reason in v.error


def test_nan_metric_fails_and_frame_lists_results():
    df = {"s": pd.DataFrame({"x": [1.0], "m": [math.nan]})}
    v = evaluate_claim(claim({"kind": "value", "study": "s", "where": {"x": 1.0}, "metric": "m",
                              "op": "<", "value": 1.0}), df, {})
    assert not v.passed
    frame = verdicts_frame([v])
    assert frame["result"].tolist() == ["FAIL"]
    assert frame["measured"][0] == "m = n/a (< 1 required)"  # units.fmt_num: NaN reads n/a
