"""Issue 22, property-based (hypothesis, derandomized: the same examples every run): random
arguments of every public API function and random mutations of every bundled config either
pass validation or are refused with EmaError -- never another exception, never a silent
default (an unknown key is always refused).

The heavy compute behind each API function is replaced by a stub that raises ``Accepted``: a
call that reaches it passed validation, and nothing is simulated (the suite stays within
seconds). Budget: ~20 s in ``make test``.
"""

from __future__ import annotations

import copy
import math
from contextlib import ExitStack, suppress
from pathlib import Path
from typing import Any
from unittest import mock

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from ema_cli import api
from ema_cli.config.acceptance import AcceptanceSpec, check_measurable
from ema_cli.config.design import DesignConfig
from ema_cli.config.loader import load_config, read_yaml
from ema_cli.config.sensitivity import SensitivityConfig
from ema_cli.config.study import StudyConfig
from ema_cli.config.tune import TuneConfig
from ema_cli.errors import EmaError
from ema_cli.identify.torque.settings import IdentifySettings

ROOT = Path(__file__).resolve().parents[2]
PROFILE = settings(derandomize=True, deadline=None, database=None, max_examples=300,
                   suppress_health_check=[HealthCheck.too_slow])
CONFIG_PROFILE = settings(PROFILE, max_examples=150)  # a config validates in ~10-50 ms


class Accepted(Exception):  # noqa: N818 - an outcome, not an error
    """Raised by the stubbed compute: the arguments passed validation."""


def _accept(*_: Any, **__: Any) -> Any:
    raise Accepted


STUBS = ["ema_cli.analysis.freqresp.sinestream", "ema_cli.sim.runner.simulate_batch",
         "ema_cli.analysis.threshold.find_threshold", "ema_cli.tune.run.run_tuning",
         "ema_cli.api.study.run_sweep",
         "ema_cli.api.sensitivity.run_sensitivity",
         "ema_cli.acceptance.kinds.run_test"]

# any Python value a caller might pass by mistake
ANY = st.one_of(
    st.none(), st.booleans(), st.integers(-10**12, 10**12),
    st.floats(allow_nan=True, allow_infinity=True), st.text(max_size=8),
    st.lists(st.one_of(st.floats(allow_nan=True), st.text(max_size=3), st.none()),
             max_size=4),
    st.dictionaries(st.text(max_size=4), st.integers(), max_size=2),
    st.tuples(st.floats(allow_nan=True), st.floats(allow_nan=True)),
    st.just(object()), st.just(b"x"), st.just(print))


def _import_everything() -> None:
    """Import every module first: a module imported while a stub is in place would keep the
    stub (``from x import f`` at module level) for the rest of the session."""
    import importlib

    from ema_cli.devtools.check_imports import modules

    for name in modules():
        importlib.import_module(name)


_import_everything()


def outcome(call: Any) -> str:
    """``ok`` (it returned), ``accepted`` (it reached the stubbed compute) or ``refused``
    (EmaError); any other exception fails the property."""
    with ExitStack() as stack:
        for target in STUBS:
            stack.enter_context(mock.patch(target, _accept))
        try:
            call()
        except Accepted:
            return "accepted"
        except EmaError as exc:
            assert "\n" not in str(exc) and str(exc), exc
            return "refused"
    return "ok"


TUNE = {"name": "t", "scenarios": {"s": {"input": {"kind": "step", "amplitude_deg": 0.1}}},
        "variables": {"Kpp": {"bounds": [10, 100]}}}
SPEC = {"name": "s", "tests": {"m": {"test": "margins", "loops": ["position"],
                                     "limits": {"gain_margin": {"min": 6, "unit": "dB"}}}}}
CALLS = {
    "freqresp": lambda v: {
        "amplitudes_deg": lambda: api.freqresp(amplitudes_deg=v),
        "f_min_hz": lambda: api.freqresp(f_min_hz=v),
        "f_max_hz": lambda: api.freqresp(f_max_hz=v),
        "n": lambda: api.freqresp(n=v),
        "nl": lambda: api.freqresp(nl=v)},
    "simulate": lambda v: {
        "config": lambda: api.simulate(v),
        "overrides": lambda: api.simulate(None, v),
        "step_deg": lambda: api.simulate(step_deg=v),
        "duration_s": lambda: api.simulate(duration_s=v),
        "dt_s": lambda: api.simulate(dt_s=v)},
    "threshold": lambda v: {
        "vary": lambda: api.threshold(None, v, (0.001, 0.1), metric="ss_err_pos_deg",
                                      limit=0.1),
        "range": lambda: api.threshold(None, "deadzone2", v, metric="ss_err_pos_deg",
                                       limit=0.1),
        "limit": lambda: api.threshold(None, "deadzone2", (0.001, 0.1),
                                       metric="ss_err_pos_deg", limit=v),
        "metric": lambda: api.threshold(None, "deadzone2", (0.001, 0.1), metric=v, limit=1),
        "require": lambda: api.threshold(None, "deadzone2", (0.001, 0.1), require=v),
        "direction": lambda: api.threshold(None, "deadzone2", (0.001, 0.1),
                                           require="t50_s<=1", direction=v),
        "rtol": lambda: api.threshold(None, "deadzone2", (0.001, 0.1), require="t50_s<=1",
                                      rtol=v),
        "log": lambda: api.threshold(None, "deadzone2", (0.001, 0.1), require="t50_s<=1",
                                     log=v)},
    "tune": lambda v: {
        "config": lambda: api.tune(v),
        "method": lambda: api.tune(TUNE, method=v),
        "runs": lambda: api.tune(TUNE, runs=v),
        "budget": lambda: api.tune(TUNE, budget=v),
        "progress": lambda: api.tune(TUNE, progress=v),
        "log": lambda: api.tune(TUNE, log=v)},
    "acceptance": lambda v: {
        "spec": lambda: api.acceptance(v),
        "overrides": lambda: api.acceptance(SPEC, v),
        "only": lambda: api.acceptance(SPEC, only=v),
        "progress": lambda: api.acceptance(SPEC, progress=v)},
    "sweep": lambda v: {
        "n_jobs": lambda: api.sweep("configs/deadzone2.yaml", n_jobs=v),
        "backend": lambda: api.sweep("configs/deadzone2.yaml", backend=v),
        "force": lambda: api.sweep("configs/deadzone2.yaml", force=v),
        "cache_dir": lambda: api.sweep("configs/deadzone2.yaml", cache_dir=v)},
    "sensitivity": lambda v: {
        "method": lambda: api.sensitivity("configs/sensitivity.yaml", method=v),
        "n": lambda: api.sensitivity("configs/sensitivity.yaml", n=v),
        "n_jobs": lambda: api.sensitivity("configs/sensitivity.yaml", n_jobs=v),
        "progress": lambda: api.sensitivity("configs/sensitivity.yaml", progress=v)},
}


@pytest.mark.filterwarnings("ignore:n_jobs .* is more than the")  # capped, with a warning
@pytest.mark.parametrize("function", sorted(CALLS))
@PROFILE
@given(data=st.data())
def test_api_arguments_are_validated_or_refused_with_ema_error(function, data):
    value = data.draw(ANY, label="value")
    calls = CALLS[function](value)
    argument = data.draw(st.sampled_from(sorted(calls)), label="argument")
    outcome(calls[argument])


@pytest.mark.parametrize(("call", "argument"), [
    (lambda: api.acceptance(SPEC, only=5), "only"),
    (lambda: api.acceptance(SPEC, only="m"), None),  # one name: accepted as [name]
    (lambda: api.freqresp(amplitudes_deg="abc"), "amplitudes_deg"),
    (lambda: api.freqresp(amplitudes_deg=None), "amplitudes_deg"),
    (lambda: api.freqresp(amplitudes_deg=[1, math.nan]), "amplitudes_deg"),
    (lambda: api.freqresp(n=2.5), "n"),
    (lambda: api.simulate(dt_s="1e-5"), "dt_s"),
    (lambda: api.tune(TUNE, progress=3), "progress"),
    (lambda: api.sweep("configs/deadzone2.yaml", n_jobs=0), "n_jobs"),
    (lambda: api.sweep("configs/deadzone2.yaml", backend="mpi"), "backend"),
    (lambda: api.sensitivity("configs/sensitivity.yaml", method="fast"), "method"),
    (lambda: api.threshold(None, 5, (0.001, 0.1), require="t50_s<=1"), "vary"),
    (lambda: api.threshold(None, "deadzone2", (0.001, 0.1), require=5), "require"),
    (lambda: api.threshold(None, "deadzone2", (0.001, 0.1), require="t50_s<=1", rtol="x"),
     "rtol"),
])
def test_api_errors_name_the_argument(call, argument):
    if argument is None:
        assert outcome(call) == "accepted"
        return
    with pytest.raises(EmaError, match=rf"^{argument} must"), ExitStack() as stack:
        for target in STUBS:
            stack.enter_context(mock.patch(target, _accept))
        call()


# ------------------------------------------------------------------- config mutations
CONFIGS = {"configs/acceptance.yaml": AcceptanceSpec, "configs/acceptance_geared.yaml":
           AcceptanceSpec, "configs/tune.yaml": TuneConfig, "configs/default.yaml": StudyConfig,
           "configs/deadzone2.yaml": StudyConfig, "configs/sensitivity.yaml": SensitivityConfig,
           "configs/design_ci.yaml": DesignConfig, "configs/identify.yaml": IdentifySettings}


def _paths(doc: Any, prefix: tuple = ()) -> list[tuple]:
    """Every key path of a YAML document (mappings only)."""
    out = []
    if isinstance(doc, dict):
        for k, v in doc.items():
            out.append((*prefix, k))
            out += _paths(v, (*prefix, k))
    return out


def _set(doc: dict, path: tuple, value: Any) -> None:
    for k in path[:-1]:
        doc = doc[k]
    doc[path[-1]] = value


@pytest.mark.parametrize("name", sorted(CONFIGS))
@CONFIG_PROFILE
@given(data=st.data())
def test_mutated_configs_load_or_are_refused(name, data):
    doc = read_yaml(ROOT / name)
    paths = _paths(doc)
    mutated = copy.deepcopy(doc)
    for _ in range(data.draw(st.integers(1, 3), label="mutations")):
        path = data.draw(st.sampled_from(paths), label="path")
        value = data.draw(ANY, label="value")
        with suppress(KeyError, TypeError):  # an earlier mutation replaced a parent
            _set(mutated, path, value)
    try:
        cfg = load_config(mutated, [], CONFIGS[name])
    except EmaError as exc:
        assert "\n" not in str(exc)
        return
    if isinstance(cfg, AcceptanceSpec):  # a loaded spec is checked against a time step
        for test_name, test in cfg.tests.items():
            with suppress(EmaError):
                check_measurable(test_name, test, 1e-5)


@pytest.mark.parametrize("name", sorted(CONFIGS))
@CONFIG_PROFILE
@given(data=st.data())
def test_an_unknown_key_is_never_dropped(name, data):
    doc = read_yaml(ROOT / name)
    mappings = [()] + [p for p in _paths(doc) if isinstance(_get(doc, p), dict)]
    where = data.draw(st.sampled_from(mappings), label="where")
    key = data.draw(st.from_regex(r"[a-z]{3,8}x", fullmatch=True), label="key")
    mutated = copy.deepcopy(doc)
    target = _get(mutated, where)
    if key in target or _free_form(name, where):
        return
    target[key] = 1
    with pytest.raises(EmaError):  # refused, whatever the reason: never dropped
        load_config(mutated, [], CONFIGS[name])


def _get(doc: Any, path: tuple) -> Any:
    for k in path:
        doc = doc[k]
    return doc


def _free_form(name: str, where: tuple) -> bool:
    """Mappings whose keys are names the user chooses (tests, scenarios, limits, plant
    parameters checked elsewhere), not schema keys."""
    free = {"tests", "scenarios", "variables", "set", "plant", "nonlinearities", "limits",
            "constraints", "factors", "controller"}
    if name.endswith("design_ci.yaml") and where[:1] in (("identify",), ("tune",)):
        return True  # sections of other schemas: `ema validate` and `ema design` check them
    return bool(where) and where[-1] in free
