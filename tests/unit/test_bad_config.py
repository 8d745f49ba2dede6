"""Every bad config or experiment file is answered with one clear error naming the file and key.

Classes of bad input, each through the public functions (``config.loader.read_yaml``,
``load_config``, ``validate``, ``analysis.reproduce.load_experiment``,
``model.nonlinearities``): unsafe YAML (size, alias bombs, nesting, encoding, duplicate keys),
names that would escape the output folder, numbers that are not finite or out of range, caps
against resource exhaustion, inconsistent experiment files, and nonlinearity settings that
would depend on their order.
"""

from __future__ import annotations

import math
import time
from pathlib import Path
from typing import Any

import pytest
from pydantic import BaseModel

from ema_cli.analysis.reproduce import load_experiment
from ema_cli.config import base, claims, experiment, run, study
from ema_cli.config.criteria import Criterion
from ema_cli.config.experiment import ExperimentConfig
from ema_cli.config.loader import (
    MAX_YAML_BYTES,
    MAX_YAML_DEPTH,
    load_config,
    read_yaml,
    resolve_params,
    validate,
)
from ema_cli.config.run import RunConfig
from ema_cli.config.study import StudyConfig
from ema_cli.errors import EmaError
from ema_cli.identify.torque import settings as id_settings
from ema_cli.identify.torque.settings import IdentifySettings
from ema_cli.model.nonlinearities import check_distinct, combined_updates, nonlinearity_updates
from ema_cli.model.params import resolve

BASE = resolve()


def _write(path: Path, text: str | bytes) -> Path:
    if isinstance(text, bytes):
        path.write_bytes(text)
    else:
        path.write_text(text, encoding="utf-8")
    return path


def _error(fn: Any, *args: Any, **kwargs: Any) -> str:
    """The message of the EmaError ``fn`` raises; it must be one line."""
    with pytest.raises(EmaError) as ei:
        fn(*args, **kwargs)
    msg = ei.value.message
    assert "\n" not in msg, msg
    assert ei.value.exit_code == 2
    return msg


# ------------------------------------------------------------------------------------------
# 1. YAML safety


def billion_laughs(levels: int = 9, fanout: int = 9) -> str:
    lines = ['a0: &a0 "lol"']
    for i in range(1, levels + 1):
        refs = ", ".join([f"*a{i - 1}"] * fanout)
        lines.append(f"a{i}: &a{i} [{refs}]")
    return "\n".join(lines) + "\n"


def test_alias_bomb_is_refused_fast(tmp_path):
    p = _write(tmp_path / "bomb.yaml", billion_laughs())
    t0 = time.perf_counter()
    msg = _error(read_yaml, p)
    assert time.perf_counter() - t0 < 1.0
    assert str(p) in msg and "alias" in msg
    # and through load_config, as every command reads configs
    assert str(p) in _error(load_config, p, (), StudyConfig)


def test_a_few_aliases_are_fine(tmp_path):
    p = _write(tmp_path / "ok.yaml", "a: &v [1, 2]\nb: *v\nbase: &b {x: 1}\nd: {<<: *b, y: 2}\n")
    assert read_yaml(p) == {"a": [1, 2], "b": [1, 2], "base": {"x": 1}, "d": {"x": 1, "y": 2}}


def test_recursive_alias_is_refused(tmp_path):
    p = _write(tmp_path / "rec.yaml", "a: &x [1, *x]\n")
    assert "recursive" in _error(read_yaml, p)


@pytest.mark.parametrize("text", [
    "a: " + "[" * 5000 + "]" * 5000 + "\n",  # flow: would overflow the recursive composer
    "a: " + "{b: " * (MAX_YAML_DEPTH + 5) + "1" + "}" * (MAX_YAML_DEPTH + 5) + "\n",
    "".join("  " * k + f"k{k}:\n" for k in range(MAX_YAML_DEPTH + 5)) + "  " * 60 + "x: 1\n",
])
def test_absurd_nesting_is_refused_without_recursion_error(tmp_path, text):
    p = _write(tmp_path / "deep.yaml", text)
    msg = _error(read_yaml, p)
    assert str(p) in msg and f"deeper than {MAX_YAML_DEPTH}" in msg


def test_nesting_at_the_limit_is_read(tmp_path):
    depth = MAX_YAML_DEPTH - 1  # the top-level mapping is one level
    p = _write(tmp_path / "ok.yaml", "a: " + "[" * depth + "1" + "]" * depth + "\n")
    assert read_yaml(p)["a"] is not None


def test_oversized_file_is_refused_before_parsing(tmp_path):
    # not even valid YAML past the first line: the size is checked first
    p = _write(tmp_path / "big.yaml", "a: [\n" + "x" * (MAX_YAML_BYTES + 10))
    msg = _error(read_yaml, p)
    assert str(p) in msg and "1 MiB" in msg and "syntax" not in msg


@pytest.mark.parametrize(("data", "needle"), [
    (b"\x89PNG\r\n\x1a\n\x00\x00\x00\rIHDR", "binary"),
    ("name: caf\xe9\n".encode("latin-1"), "UTF-8"),
    (b"\xff\xfe n\x00a\x00", "binary"),  # UTF-16
])
def test_binary_or_non_utf8_file(tmp_path, data, needle):
    p = _write(tmp_path / "c.yaml", data)
    msg = _error(read_yaml, p)
    assert str(p) in msg and needle in msg


def test_utf8_with_bom_is_read(tmp_path):
    p = _write(tmp_path / "bom.yaml", "\ufeffname: x\n")
    assert read_yaml(p) == {"name": "x"}


@pytest.mark.parametrize(("text", "key", "line"), [
    ("name: a\ninput: {kind: step}\nname: b\n", "name", 3),
    ("name: a\nsimulation:\n  dt_s: 1.0e-5\n  duration_s: 1\n  dt_s: 1.0e-4\n", "dt_s", 5),
    ("sweep:\n  axes:\n    - {nonlinearity: deadzone2, values: [1], values: [2]}\n", "values", 3),
])
def test_duplicate_key_names_the_key_and_line(tmp_path, text, key, line):
    p = _write(tmp_path / "dup.yaml", text)
    msg = _error(read_yaml, p)
    assert str(p) in msg and f"duplicate key '{key}'" in msg and f"line {line}" in msg


def test_merge_key_override_is_not_a_duplicate(tmp_path):
    p = _write(tmp_path / "m.yaml", "b: &b {x: 1, y: 2}\nd:\n  <<: *b\n  x: 3\n")
    assert read_yaml(p)["d"] == {"x": 3, "y": 2}


@pytest.mark.parametrize("text", ["a: 1\n---\nb: 2\n", "a: !!python/object:os.system x\n",
                                  "a: [1, 2\n"])
def test_other_yaml_problems_are_one_line_errors(tmp_path, text):
    p = _write(tmp_path / "y.yaml", text)
    assert str(p) in _error(read_yaml, p)


# ------------------------------------------------------------------------------------------
# 2. Names that become file or folder names

BAD_NAMES = ["../x", "/abs", "a/b", "", "..", ".", "a" * 65, "a b", "a\\b", "x\n", ".hidden",
             "-rf"]


@pytest.mark.parametrize("bad", BAD_NAMES)
def test_run_name_must_be_a_plain_name(bad):
    msg = _error(validate, StudyConfig, {"name": bad}, "c.yaml")
    assert msg.startswith("c.yaml: name: must be a plain name")


@pytest.mark.parametrize("bad", BAD_NAMES)
def test_axis_name_must_be_a_plain_name(bad):
    data = {"sweep": {"axes": [{"name": bad, "nonlinearity": "deadzone2", "values": [0.01]}]}}
    assert "c.yaml: sweep.axes.0.name: must be a plain name" in _error(
        validate, StudyConfig, data, "c.yaml")


@pytest.mark.parametrize("bad", BAD_NAMES)
def test_identify_name_must_be_a_plain_name(bad):
    assert "i.yaml: name: must be a plain name" in _error(
        validate, IdentifySettings, {"name": bad}, "i.yaml")


def _experiment(**over: Any) -> dict[str, Any]:
    exp: dict[str, Any] = {
        "name": "exp",
        "studies": [{"id": "s1", "config": "s1.yaml", "figure": "s1.png", "caption": "c"}],
        "claims": [{"id": "c1", "figure": "s1", "paper": "p", "statement": "s",
                    "check": {"kind": "value", "study": "s1", "metric": "t50_s", "op": "<",
                              "value": 1.0}}],
    }
    exp.update(over)
    return exp


def _study(**over: Any) -> dict[str, Any]:
    return {"id": "s1", "config": "s1.yaml", "figure": "s1.png", "caption": "c", **over}


@pytest.mark.parametrize("bad", BAD_NAMES)
@pytest.mark.parametrize(("make", "key"), [
    (lambda b: _experiment(name=b), "name"),
    (lambda b: _experiment(studies=[_study(id=b)]), "studies.0.id"),
    (lambda b: _experiment(studies=[_study(figure=b)]), "studies.0.figure"),
])
def test_experiment_names_must_be_plain(make, key, bad):
    assert f"e.yaml: {key}: must be a plain name" in _error(
        validate, ExperimentConfig, make(bad), "e.yaml")


@pytest.mark.parametrize("bad", ["../x", "/abs", "a/b", "", ".."])
def test_threshold_id_must_be_plain(bad):
    thr = {"id": bad, "config": "s1.yaml", "vary": "deadzone2", "range": [1e-4, 0.1],
           "require": ["p2p_err_pos_deg<=0.002"]}
    assert "e.yaml: thresholds.0.id: must be a plain name" in _error(
        validate, ExperimentConfig, _experiment(thresholds=[thr]), "e.yaml")


def test_plain_names_that_are_fine():
    for good in ("fig03_deadzone2.png", "paper2020", "a", "A-1.b_2", "x" * 64):
        assert base.check_plain_name(good) == good


def test_figure_needs_an_image_suffix():
    assert "studies.0.figure: a figure file name ends in .png" in _error(
        validate, ExperimentConfig, _experiment(studies=[_study(figure="s1.exe")]), "e.yaml")


# ------------------------------------------------------------------------------------------
# 3. One base model


def test_every_schema_uses_the_one_strict_base():
    assert run.Strict is base.Strict and study.Strict is base.Strict
    assert experiment.Strict is base.Strict
    assert id_settings.Strict is base.Strict and claims.Strict is base.Strict
    models = [run.RunConfig, run.InputConfig, study.StudyConfig, study.SweepAxis, study.Span,
              experiment.ExperimentConfig, experiment.ThresholdSpec, claims.Claim,
              claims.ValueCheck, id_settings.IdentifySettings, id_settings.GASettings,
              id_settings.SyntheticSettings]
    for m in models:
        assert issubclass(m, base.Strict), m
        assert m.model_config.get("frozen") and m.model_config.get("extra") == "forbid", m
    for m in (claims.Claim, IdentifySettings):
        assert not any(b is BaseModel for b in m.__bases__)


# ------------------------------------------------------------------------------------------
# 4. Numbers: finite, in range, capped


@pytest.mark.parametrize("value", [".nan", ".inf", "-.inf", "1e400", "yes"])
@pytest.mark.parametrize("key", [
    "input.amplitude_deg", "input.start_s", "input.rate_deg_s", "input.freq_hz",
    "input.offset_deg", "simulation.duration_s", "simulation.dt_s",
    "simulation.output_interval_s", "load.torque_nm", "load.spring_nm_per_rad",
    "controller.sample_time_s", "sensors.position_counts_per_rev",
    "sensors.speed_resolution_rpm",
])
def test_run_numbers_must_be_finite(tmp_path, key, value):
    section, field = key.split(".")
    p = _write(tmp_path / "c.yaml", f"{section}:\n  {field}: {value}\n")
    msg = _error(load_config, p, (), StudyConfig)
    assert msg.startswith(f"{p}: {key}: ")


def test_nan_step_amplitude_is_refused_at_validation():
    msg = _error(validate, RunConfig, {"input": {"amplitude_deg": math.nan}}, "c")
    assert msg == "c: input.amplitude_deg: must be a finite number, got nan"


@pytest.mark.parametrize(("data", "key"), [
    ({"simulation": {"duration_s": -1}}, "simulation.duration_s"),
    ({"simulation": {"dt_s": 0}}, "simulation.dt_s"),
    ({"input": {"start_s": -0.1}}, "input.start_s"),
    ({"input": {"freq_hz": 0}}, "input.freq_hz"),
    ({"input": {"sweep_time_s": -1}}, "input.sweep_time_s"),
    ({"controller": {"sample_time_s": 0}}, "controller.sample_time_s"),
    ({"sensors": {"position_counts_per_rev": -4096}}, "sensors.position_counts_per_rev"),
    ({"seed": -1}, "seed"),
    ({"seed": 2**64}, "seed"),
])
def test_run_numbers_out_of_range(data, key):
    assert _error(validate, StudyConfig, data, "c").startswith(f"c: {key}: ")


def test_signal_must_start_before_the_end():
    msg = _error(validate, RunConfig, {"input": {"start_s": 2.0},
                                      "simulation": {"duration_s": 1.0}}, "c")
    assert "input.start_s" in msg and "simulation.duration_s" in msg


@pytest.mark.parametrize(("sweep", "key", "cap"), [
    ({"max_jobs": 10**9}, "sweep.max_jobs", "1000000"),
    ({"max_jobs": 0}, "sweep.max_jobs", "1"),
    ({"axes": [{"parameter": "Kpp", "linspace": {"start": 1, "stop": 2, "num": 10**8}}]},
     "sweep.axes.0.linspace.num", "1000000"),
    ({"axes": [{"parameter": "Kpp", "linspace": {"start": 1, "stop": math.inf, "num": 3}}]},
     "sweep.axes.0.linspace.stop", "finite"),
])
def test_sweep_caps(sweep, key, cap):
    msg = _error(validate, StudyConfig, {"sweep": sweep}, "c")
    assert msg.startswith(f"c: {key}: ") and cap in msg


@pytest.mark.parametrize(("parallel", "key"), [
    ({"n_jobs": 10**6}, "parallel.n_jobs"), ({"n_jobs": -2}, "parallel.n_jobs"),
    ({"n_jobs": True}, "parallel.n_jobs"),
    ({"chunk_size": 0}, "parallel.chunk_size"), ({"chunk_size": 10**9}, "parallel.chunk_size"),
])
def test_parallel_caps(parallel, key):
    assert _error(validate, StudyConfig, {"parallel": parallel}, "c").startswith(f"c: {key}: ")


@pytest.mark.parametrize(("data", "key", "needle"), [
    ({"ga": {"pop": 10**6}}, "ga.pop", "100000"),
    ({"ga": {"pop": 1}}, "ga.pop", "2"),
    ({"ga": {"generations": 10**7}}, "ga.generations", "1000000"),
    ({"ga": {"generations": 0}}, "ga.generations", "1"),
    ({"runs": 10**6}, "runs", "10000"),
    ({"runs": 0}, "runs", "1"),
    ({"n_jobs": 10**5}, "n_jobs", "4096"),
    ({"n_jobs": True}, "n_jobs", "boolean"),
    ({"ga": {"pop": True}}, "ga.pop", "boolean"),
    ({"ga": {"pc": math.nan}}, "ga.pc", "finite"),
    ({"ga": {"pm": 1.5}}, "ga.pm", "1"),
    ({"ga": {"eta_m": math.inf}}, "ga.eta_m", "finite"),
    ({"ga": {"patience": -1}}, "ga.patience", "0"),
    ({"c": math.nan}, "c", "finite"),
    ({"c": -1.0}, "c", "0"),
    ({"k_range": [500, math.inf]}, "k_range", "finite"),
    ({"k_range": [700, 500]}, "k_range", "LO < HI"),
    ({"synthetic": {"kL": math.nan}}, "synthetic.kL", "finite"),
    ({"synthetic": {"kL": 0}}, "synthetic.kL", "0"),
    ({"synthetic": {"alpha": -0.001}}, "synthetic.alpha", "0"),
    ({"synthetic": {"amplitude_deg": math.inf}}, "synthetic.amplitude_deg", "finite"),
    ({"synthetic": {"noise_pct": 1e6}}, "synthetic.noise_pct", "1000"),
    ({"synthetic": {"dt_s": 0}}, "synthetic.dt_s", "0"),
    ({"synthetic": {"plant": {"Jm": -1}}}, "synthetic.plant.Jm", ">= 0"),
    ({"synthetic": {"plant": {"kL": 500}}}, "synthetic.plant.kL", "synthetic.kL"),
    ({"synthetic": {"sample_interval_s": 10.0}}, "synthetic", "sample_interval_s"),
    ({"seed": 2**70}, "seed", "9223372036854775807"),
])
def test_identify_settings_ranges_and_caps(data, key, needle):
    msg = _error(validate, IdentifySettings, data, "i.yaml")
    assert msg.startswith(f"i.yaml: {key}: ") and needle in msg


def test_identify_total_work_is_capped():
    msg = _error(validate, IdentifySettings,
                 {"ga": {"pop": 100_000, "generations": 100_000}, "runs": 1}, "i.yaml")
    assert "ga.pop * ga.generations * runs" in msg and "1,000,000,000" in msg


@pytest.mark.parametrize("text", ["t50_s<=1e", "t50_s<=1.2.3", "t50_s<=inf", "t50_s<nan"])
def test_requirement_with_a_bad_number(text):
    _error(Criterion.parse, text)


# ------------------------------------------------------------------------------------------
# 5. Experiment files


def _exp_error(data: dict[str, Any]) -> str:
    return _error(validate, ExperimentConfig, data, "e.yaml")


def test_valid_experiment_passes():
    assert validate(ExperimentConfig, _experiment(), "e.yaml").studies[0].id == "s1"


def test_empty_experiment_is_refused():
    assert "at least one study or claim" in _exp_error({"name": "e"})
    assert "at least one study or claim" in _exp_error(_experiment(studies=[], claims=[]))


def test_duplicate_ids_are_named():
    two = [_study(), _study(figure="other.png")]
    assert "study id 's1' is given twice" in _exp_error(_experiment(studies=two))
    two = [_study(), _study(id="s2")]
    assert "figure file name 's1.png' is given twice" in _exp_error(_experiment(studies=two))
    claim = _experiment()["claims"][0]
    assert "claim id 'c1' is given twice" in _exp_error(_experiment(claims=[claim, claim]))
    thr = {"id": "t", "config": "s1.yaml", "vary": "deadzone2", "range": [1e-4, 0.1],
           "require": ["p2p_err_pos_deg<=0.002"]}
    assert "threshold id 't' is given twice" in _exp_error(_experiment(thresholds=[thr, thr]))


def test_claims_and_ranking_must_name_known_studies_and_results():
    claim = _experiment()["claims"][0]
    bad = {**claim, "check": {**claim["check"], "study": "nope"}}
    assert "claims.0 (c1): unknown study 'nope'" in _exp_error(_experiment(claims=[bad]))
    bad = {**claim, "figure": "fig99"}
    assert "figure 'fig99' is not a study id" in _exp_error(_experiment(claims=[bad]))
    scalar = {**claim, "check": {"kind": "scalar", "name": "nope", "op": "<", "value": 1}}
    assert "no result named 'nope'" in _exp_error(_experiment(claims=[scalar]))
    ranking = {"studies": ["s1", "ghost"]}
    assert "ranking.studies: unknown study 'ghost'" in _exp_error(_experiment(ranking=ranking))
    assert "ranking.metric" in _exp_error(_experiment(ranking={"studies": ["s1"],
                                                               "metric": "bogus"}))


@pytest.mark.parametrize(("thr", "needle"), [
    ({"range": [0.1, 0.01]}, "LO < HI"),
    ({"range": [0, 0.1]}, "thresholds.0.range.0"),
    ({"range": [1e-4, math.nan]}, "thresholds.0.range.1"),
    ({"rtol": 0}, "thresholds.0.rtol"),
    ({"rtol": 2}, "thresholds.0.rtol"),
    ({"require": []}, "at least one requirement"),
    ({"require_relative": [{"metric": "overshoot_pct", "factor": 1.5}]}, "reference_value"),
    ({"require_relative": [{"metric": "nope", "factor": 1.5}], "reference_value": 1},
     "unknown metric 'nope'"),
    ({"require_relative": [{"metric": "overshoot_pct", "factor": math.inf}],
      "reference_value": 1}, "factor"),
    ({"vary": "saturation2", "range": [0, 10]}, "thresholds.0.range.0"),
    ({"paper_value": math.nan}, "thresholds.0.paper_value"),
])
def test_threshold_specs(thr, needle):
    spec = {"id": "t", "config": "s1.yaml", "vary": "deadzone2", "range": [1e-4, 0.1],
            "require": ["p2p_err_pos_deg<=0.002"], **thr}
    assert needle in _exp_error(_experiment(thresholds=[spec]))


@pytest.mark.parametrize(("check", "key"), [
    ({"kind": "value", "study": "s1", "metric": "t50_s", "op": "<", "value": math.nan},
     "claims.0.check.value.value"),
    ({"kind": "value", "study": "s1", "where": {"x": math.inf}, "metric": "t50_s", "op": "<",
      "value": 1}, "claims.0.check.value.where.x"),
    ({"kind": "compare", "study": "s1", "a": {}, "b": {}, "metric": "t50_s", "op": "<",
      "factor": -1}, "claims.0.check.compare.factor"),
    ({"kind": "scalar", "name": "x", "op": "<", "value": math.inf},
     "claims.0.check.scalar.value"),
])
def test_claim_numbers_must_be_finite(check, key):
    claim = {**_experiment()["claims"][0], "check": check}
    assert f"e.yaml: {key}: " in _exp_error(_experiment(claims=[claim]))


def test_experiment_file_checks_the_identification_settings(tmp_path):
    _write(tmp_path / "s1.yaml", "name: s1\n")
    p = _write(tmp_path / "e.yaml", (
        "name: e\nstudies:\n  - {id: s1, config: s1.yaml, figure: s1.png, caption: c}\n"
        "identification:\n  settings: {runs: 0}\n"))
    assert f"{p}: identification.settings: runs: " in _error(load_experiment, p)


def test_bundled_experiment_and_configs_still_validate():
    root = Path(__file__).resolve().parents[2]
    load_experiment(root / "experiments" / "paper2020.yaml")
    from ema_cli.config.acceptance import AcceptanceSpec
    from ema_cli.config.design import DesignConfig

    models = {"identify": IdentifySettings, "acceptance": AcceptanceSpec,
              "acceptance_geared": AcceptanceSpec, "acceptance_duty": AcceptanceSpec,
              "design_ci": DesignConfig}
    for f in sorted((root / "configs").glob("*.yaml")):
        if f.stem in ("tolerances", "tolerances_thermal"):  # tolerance files (`ema yield`)
            from ema_cli.production.tolerances import load_tolerances

            assert load_tolerances(f).paths
            continue
        from ema_cli.config.sensitivity import SensitivityConfig
        from ema_cli.config.tune import TuneConfig

        models["sensitivity"] = SensitivityConfig
        models["tune"] = TuneConfig
        load_config(f, (), models.get(f.stem, StudyConfig))


# ------------------------------------------------------------------------------------------
# 6. Nonlinearity settings


def test_gap1_and_deadzone2_compose_in_either_order():
    a = resolve_params({}, {"deadzone2": 0.01, "gap1": 2.0})
    b = resolve_params({}, {"gap1": 2.0, "deadzone2": 0.01})
    assert a == b
    assert a["alpha"] == pytest.approx(math.radians(0.01))
    assert a["kL"] == pytest.approx(2.0 * BASE["m"] ** 2)
    # gap1 alone: the paper's gap without dead zone
    assert resolve_params({}, {"gap1": 2.0})["alpha"] == 0.0


def test_every_pair_of_settings_composes_in_either_order():
    values = {"deadzone1": 0.1, "deadzone2": 0.01, "deadzone3": 1.0, "deadzone4": 0.01,
              "saturation1": 500.0, "saturation2": "off", "saturation3": 20.0, "gap1": 2.0,
              "friction1": 0.01}
    names = list(values)
    for i, x in enumerate(names):
        for y in names[i + 1:]:
            ab = resolve_params({}, {x: values[x], y: values[y]})
            ba = resolve_params({}, {y: values[y], x: values[x]})
            assert ab == ba, (x, y)
    assert combined_updates(values, BASE) == combined_updates(dict(reversed(values.items())),
                                                              BASE)


def test_one_placement_named_twice_is_an_error_naming_both():
    with pytest.raises(EmaError, match=r"'deadzone2' and 'deadzone@transmission'"):
        check_distinct(["deadzone2", "deadzone@transmission"])
    with pytest.raises(EmaError, match=r"'gap1' and 'compliance@transmission'"):
        combined_updates({"gap1": 1.0, "compliance@transmission": 2.0}, BASE)
    msg = _error(validate, RunConfig,
                 {"nonlinearities": {"deadzone2": 0.01, "deadzone@transmission": 0.1}}, "c")
    assert msg.startswith("c: nonlinearities: ") and "'deadzone2'" in msg
    assert "'deadzone@transmission'" in msg


@pytest.mark.parametrize("reading", ["sigma2", "scale"])
@pytest.mark.parametrize("value", [0, 0.0, "0", "off", "OFF"])
def test_friction1_zero_or_off_means_no_friction(reading, value):
    assert nonlinearity_updates("friction1", value, BASE, reading) == {"friction": 0.0}
    assert resolve_params({}, {"friction1": value}, reading)["friction"] == 0.0


def test_friction1_positive_turns_lugre_on():
    assert nonlinearity_updates("friction1", 0.01, BASE) == {"friction": 1.0, "sigma2": 0.01}


@pytest.mark.parametrize(("name", "value"), [
    ("deadzone2", math.nan), ("deadzone2", math.inf), ("deadzone2", -1), ("deadzone2", True),
    ("saturation2", 0), ("gap1", "off"), ("gap1", 0), ("friction1", "lots"),
])
def test_bad_magnitudes_name_the_setting(name, value):
    assert f"'{name}'" in _error(nonlinearity_updates, name, value, BASE)
