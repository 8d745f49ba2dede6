"""One result contract: every result class of ``api.__all__`` honours ``api.Result``
(``.metrics``, ``.to_pandas(form)``, ``.plot()``, ``.save(folder)``), every API function
returns one, and the markdown of every report formats a cell one way (NaN reads ``n/a``)."""

from __future__ import annotations

import inspect
import math
from collections.abc import Callable

import numpy as np
import pandas as pd
import pytest
from matplotlib.figure import Figure

from ema_cli import api
from ema_cli.api.result import Result
from ema_cli.errors import EmaError
from ema_cli.report.markdown import md_cell, md_table

NOT_RESULTS = {"EmaError", "Result"}


def _result_classes() -> list[type]:
    return [getattr(api, n) for n in api.__all__
            if inspect.isclass(getattr(api, n)) and n not in NOT_RESULTS]


def _functions() -> list[Callable]:
    return [getattr(api, n) for n in api.__all__ if inspect.isfunction(getattr(api, n))]


def contract_problems(cls: type) -> list[str]:
    """What ``cls`` lacks of the contract, read from its definition (nothing runs)."""
    problems = []
    if not isinstance(inspect.getattr_static(cls, "metrics", None), property):
        problems.append("metrics is not a property")
    for name in ("to_pandas", "plot", "save"):
        if not callable(inspect.getattr_static(cls, name, None)):
            problems.append(f"no {name}()")
    if problems:
        return problems
    form = list(inspect.signature(cls.to_pandas).parameters.values())[1:]
    if not form or form[0].name != "form" or form[0].default not in ("wide", "long"):
        problems.append("to_pandas's first argument is not form='wide'|'long'")
    plot = list(inspect.signature(cls.plot).parameters.values())[1:]
    if any(p.default is inspect.Parameter.empty and p.kind not in (p.VAR_POSITIONAL,
                                                                 p.VAR_KEYWORD) for p in plot):
        problems.append("plot() has an argument without a default")
    save = list(inspect.signature(cls.save).parameters.values())[1:]
    if not save or save[0].name != "folder" or save[0].default is not None:
        problems.append("save's first argument is not folder=None")
    return problems


@pytest.mark.parametrize("cls", _result_classes(), ids=lambda c: c.__name__)
def test_every_result_class_honours_the_contract(cls):
    assert contract_problems(cls) == []


@pytest.mark.parametrize("fn", _functions(), ids=lambda f: f.__name__)
def test_every_api_function_returns_a_result(fn):
    returned = inspect.signature(fn).return_annotation  # a string: postponed annotations
    assert getattr(api, str(returned), None) in _result_classes(), \
        f"{fn.__name__} returns {returned}"


def test_the_check_finds_a_broken_result():
    class Broken:
        def save(self, path):  # no metrics, no to_pandas, no plot
            return path

    assert contract_problems(Broken) == ["metrics is not a property", "no to_pandas()",
                                         "no plot()"]


# ------------------------------------------------------------------ the ones that broke it
def test_synthetic_data_and_friction_fit_honour_it_at_run_time(tmp_path):
    data = api.make_identification_data(kind="friction-sweep", noise_pct=0.0, seed=1)
    assert isinstance(data, Result)
    truth = data.metrics.set_index("parameter")["value"]
    wide = data.to_pandas()
    assert list(wide.columns[:2]) == ["omega_rpm", "torque_nm"]
    long = data.to_pandas("long")
    assert len(long) == len(wide) * (len(wide.columns) - 1)
    assert isinstance(data.plot(), Figure)
    folder = data.save(tmp_path / "data")
    fit = api.identify_friction_sweep(data=str(folder / "friction_sweep.csv"))
    assert isinstance(fit, Result)
    m = fit.metrics.set_index("parameter")
    # noise-free data of the static curve: the fit recovers the stated Fc within 0.1 %
    assert m.loc["Fc", "value"] == pytest.approx(truth["Fc"], rel=1e-3)
    table = fit.to_pandas()
    np.testing.assert_allclose(table["torque_model_nm"], table["torque_nm"], rtol=1e-3)
    assert isinstance(fit.plot(), Figure)
    with pytest.raises(EmaError, match="form must be 'wide' or 'long', got 'tall'"):
        fit.to_pandas("tall")


def test_tune_result_honours_it_at_run_time():
    cfg = {"name": "one-gain", "actuator": {"plant": {"sat1": "off", "sat2": "off",
                                                      "sat3": "off"}},
           "simulation": {"duration_s": 0.05, "dt_s": 5e-5},
           "scenarios": {"step": {"input": {"kind": "step", "amplitude_deg": 1.0}}},
           "variables": {"Kpp": {"bounds": [20.0, 400.0], "scale": "log"}},
           "cost": {"normalise": False},
           "constraints": {"gain_margin": "off", "phase_margin": "off"},
           "optimiser": {"budget": 24, "pop": 8}}
    res = api.tune(cfg)
    assert isinstance(res, Result)
    m = res.metrics
    assert list(m["scenario"]) == ["step"]
    # the tuned controller is never worse than where the search started
    assert m.filter(like="_after").iloc[0, 0] <= m.filter(like="_before").iloc[0, 0]
    long = res.to_pandas("long")
    assert {"run", "generation", "quantity", "value"} <= set(long.columns)
    assert len(long) == len(res.to_pandas()) * (len(res.to_pandas().columns) - 4)


# ------------------------------------------------------------------ one markdown cell
@pytest.mark.parametrize(("value", "text"), [
    (math.nan, "n/a"), (None, "n/a"), (np.float64("nan"), "n/a"), (1.23456789, "1.235"),
    (12, "12"), (np.int64(3), "3"), (True, "True"), ("a|b", "a\\|b"), (["x", "y"], "x, y"),
    ([], "none"), (math.inf, "inf")])
def test_a_cell_says_nan_one_way(value, text):
    assert md_cell(value) == text


def test_md_table_of_a_frame_and_of_rows():
    df = pd.DataFrame({"a": [1.0, math.nan], "b": ["x", "y"]})
    assert md_table(df) == "| a | b |\n|---|---|\n| 1 | x |\n| n/a | y |"
    assert md_table([(0.5, "z")], ["v", "w"], headers=["v [s]", "w"]) == \
        "| v [s] | w |\n|---|---|\n| 0.5 | z |"
