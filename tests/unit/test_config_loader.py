"""config/loader.py: YAML reading, --set overrides, validation messages and resolution to SI.

Expected SI values are computed here from first principles (math.radians, 2*pi/60, the
formulas of docs/model.md §2-§5), not with ema_cli.units, so a wrong conversion constant fails.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import yaml

from ema_cli.config.loader import (
    apply_overrides,
    input_signal,
    load_config,
    parse_value,
    read_yaml,
    resolve_params,
    resolve_run,
    validate,
)
from ema_cli.config.run import InputConfig, LoadConfig, RunConfig
from ema_cli.config.study import StudyConfig
from ema_cli.errors import EmaError

TOP = list(RunConfig.model_fields)


def _write(path: Path, text: str) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text, encoding="utf-8")
    return path


def _jeq(jm: float, m: float, jl: float) -> float:
    """Load-side equivalent inertia (docs/model.md §2), written out independently."""
    return (jm * m * m) * jl / (jm * m * m + jl)


# ------------------------------------------------------------------------------------------
# read_yaml


def test_read_yaml_valid_mapping(tmp_path):
    p = _write(tmp_path / "c.yaml", "name: s1\nplant:\n  kL: 600\n  sat2: .inf\n")
    assert read_yaml(p) == {"name": "s1", "plant": {"kL": 600, "sat2": math.inf}}
    assert read_yaml(str(p)) == read_yaml(p)  # str and Path alike


@pytest.mark.parametrize("text", ["", "\n\n", "# only a comment\n"])
def test_read_yaml_empty_file_is_empty_mapping(tmp_path, text):
    assert read_yaml(_write(tmp_path / "e.yaml", text)) == {}


@pytest.mark.parametrize(("text", "typename"), [("- 1\n- 2\n", "list"), ("42\n", "int"),
                                                 ("just words\n", "str")])
def test_read_yaml_not_a_mapping(tmp_path, text, typename):
    p = _write(tmp_path / "l.yaml", text)
    with pytest.raises(EmaError) as ei:
        read_yaml(p)
    assert str(p) in ei.value.message and typename in ei.value.message
    assert "mapping" in ei.value.message


def test_read_yaml_missing_file_and_folder(tmp_path):
    with pytest.raises(EmaError, match="does not exist") as ei:
        read_yaml(tmp_path / "nope.yaml")
    assert str(tmp_path / "nope.yaml") in ei.value.message
    with pytest.raises(EmaError, match="is not a file"):
        read_yaml(tmp_path)


def test_read_yaml_syntax_error_names_file_and_line(tmp_path):
    # line 3 opens a flow sequence that is never closed
    p = _write(tmp_path / "bad.yaml", "name: x\nplant:\n  kL: [1, 2\n")
    with pytest.raises(EmaError) as ei:
        read_yaml(p)
    msg = ei.value.message
    assert msg.startswith(f"{p}: YAML syntax error")
    assert " at line " in msg and ei.value.exit_code == 2


def test_read_yaml_syntax_error_line_number(tmp_path):
    # a tab is not allowed as indentation: the scanner reports line 2, column 1
    p = _write(tmp_path / "tab.yaml", "a: 1\n\tb: 2\n")
    with pytest.raises(EmaError, match=r"at line 2, column 1") as ei:
        read_yaml(p)
    assert str(p) in ei.value.message


def test_read_yaml_undecodable_bytes(tmp_path):
    p = tmp_path / "bin.yaml"
    p.write_bytes(b"name: \xff\xfe\xfa\n")
    with pytest.raises(EmaError) as ei:
        read_yaml(p)
    assert str(p) in ei.value.message and "UTF-8" in ei.value.message


# ------------------------------------------------------------------------------------------
# parse_value


@pytest.mark.parametrize(("text", "expected"), [
    ("1e-5", 1e-5),          # YAML 1.1 would leave this a string
    ("2.5E3", 2500.0),
    ("600", 600),
    ("-3", -3),
    ("off", "off"),          # YAML booleans keep their words
    ("on", "on"),
    ("true", "true"),
    ("No", "No"),
    ("[0.01, 0.1]", [0.01, 0.1]),
    ("inf", math.inf),
    ("-.inf", -math.inf),
    ("sine", "sine"),
    ("a: [", "a: ["),        # not YAML: returned as typed
    ("null", None),
])
def test_parse_value(text, expected):
    got = parse_value(text)
    assert got == expected and type(got) is type(expected)


def test_parse_value_nan():
    got = parse_value("nan")
    assert isinstance(got, float) and math.isnan(got)


# ------------------------------------------------------------------------------------------
# apply_overrides


def test_apply_overrides_sets_dotted_paths_in_a_copy():
    data = {"plant": {"kL": 590}, "input": {"kind": "step"}}
    out = apply_overrides(data, [("plant.kL", "600"), ("input.amplitude_deg", "0.1"),
                                 ("simulation.dt_s", "1e-5"), ("name", "run-2")], TOP)
    assert out == {"plant": {"kL": 600}, "input": {"kind": "step", "amplitude_deg": 0.1},
                   "simulation": {"dt_s": 1e-5}, "name": "run-2"}
    assert data == {"plant": {"kL": 590}, "input": {"kind": "step"}}  # input untouched


def test_apply_overrides_existing_vs_new_keys():
    data = {"nonlinearities": {"deadzone2": 0.01}}
    out = apply_overrides(data, [("nonlinearities.deadzone2", "0.1"),
                                 ("nonlinearities.saturation2", "off")], TOP)
    assert out["nonlinearities"] == {"deadzone2": 0.1, "saturation2": "off"}


def test_apply_overrides_bare_parameter_means_plant_and_non_strings_kept():
    out = apply_overrides({}, [("Kpp", "60"), ("plant.alpha", 0.001), ("seed", 7)], TOP)
    assert out == {"plant": {"Kpp": 60, "alpha": 0.001}, "seed": 7}


def test_apply_overrides_later_wins():
    out = apply_overrides({}, [("plant.kL", "1"), ("kL", "2")], TOP)
    assert out == {"plant": {"kL": 2}}


def test_apply_overrides_unknown_top_key_names_it():
    with pytest.raises(EmaError) as ei:
        apply_overrides({}, [("plnt.kL", "600")], TOP)
    assert "--set plnt.kL" in ei.value.message and "'plnt'" in ei.value.message
    assert "plant" in ei.value.message  # lists the valid keys


def test_apply_overrides_bare_name_without_plant_section_is_unknown():
    with pytest.raises(EmaError, match=r"--set kL: unknown key 'kL'"):
        apply_overrides({}, [("kL", "600")], ["name", "seed"])


def test_apply_overrides_through_a_value_names_the_key():
    with pytest.raises(EmaError) as ei:
        apply_overrides({"input": {"kind": "step"}}, [("input.kind.x", "1")], TOP)
    assert "--set input.kind.x" in ei.value.message and "'input.kind'" in ei.value.message


@pytest.mark.parametrize("path", ["plant..kL", "plant.", ".plant", ""])
def test_apply_overrides_empty_path_segment(path):
    with pytest.raises(EmaError, match="dotted key path"):
        apply_overrides({}, [(path, "1")], TOP)


STUDY_TOP = list(StudyConfig.model_fields)
AXES = {"sweep": {"axes": [{"nonlinearity": "deadzone2", "values": [0.01]},
                           {"parameter": "Kpp", "values": [40, 50]}]}}


def test_apply_overrides_list_indices():
    out = apply_overrides(AXES, [("sweep.axes.0.values", "[0.1, 1]"),
                                 ("sweep.axes.1.values.1", "60"),
                                 ("sweep.axes.1.name", "gain")], STUDY_TOP)
    assert out["sweep"]["axes"][0]["values"] == [0.1, 1]
    assert out["sweep"]["axes"][1] == {"parameter": "Kpp", "values": [40, 60], "name": "gain"}
    assert AXES["sweep"]["axes"][1] == {"parameter": "Kpp", "values": [40, 50]}  # a copy
    cfg = validate(StudyConfig, out, "x")
    assert cfg.sweep.axes[0].value_list() == [0.1, 1.0]


@pytest.mark.parametrize("path", ["sweep.axes.2.values", "sweep.axes.x.values",
                                  "sweep.axes.-1.values"])
def test_apply_overrides_bad_list_index_names_the_list(path):
    with pytest.raises(EmaError) as ei:
        apply_overrides(AXES, [(path, "[0.1]")], STUDY_TOP)
    msg = ei.value.message
    assert f"--set {path}" in msg and "'sweep.axes' is a list of 2 items" in msg
    assert "0..1" in msg


# ------------------------------------------------------------------------------------------
# validate and load_config


def test_validate_unknown_key_names_source_and_path():
    with pytest.raises(EmaError) as ei:
        validate(RunConfig, {"input": {"kindd": "step"}, "bogus": 1}, "my.yaml")
    msg = ei.value.message
    assert msg.startswith("my.yaml: ")
    assert "bogus: unknown key" in msg and "input.kindd: unknown key" in msg


def test_validate_dict_key_is_folded_into_the_path():
    # a plant key is a dict key; the validator's message is tagged so the path reads plant.kLL
    with pytest.raises(EmaError) as ei:
        validate(RunConfig, {"plant": {"kLL": 1}}, "c.yaml")
    assert ei.value.message.startswith("c.yaml: plant.kLL: unknown model parameter 'kLL'")
    with pytest.raises(EmaError, match=r"^c\.yaml: plant\.kL: parameter 'kL' must be >= 0"):
        validate(RunConfig, {"plant": {"kL": -1}}, "c.yaml")
    with pytest.raises(EmaError, match=r"^c\.yaml: nonlinearities\.deadzone9: unknown nonlin"):
        validate(RunConfig, {"nonlinearities": {"deadzone9": 1}}, "c.yaml")


def test_validate_value_error_names_field():
    with pytest.raises(EmaError, match=r"^s\.yaml: simulation\.duration_s: .*greater than 0"):
        validate(RunConfig, {"simulation": {"duration_s": 0}}, "s.yaml")


def test_load_config_file_with_overrides(tmp_path):
    p = _write(tmp_path / "c.yaml", yaml.safe_dump(
        {"name": "t1", "plant": {"kL": 500}, "input": {"kind": "step", "amplitude_deg": 2.0}}))
    cfg = load_config(p, [("plant.kL", "600"), ("Kpp", "60"), ("input.amplitude_deg", "0.1")])
    assert isinstance(cfg, RunConfig)
    assert cfg.name == "t1" and cfg.plant == {"kL": 600, "Kpp": 60}
    assert cfg.input.amplitude_deg == 0.1 and cfg.input.kind == "step"


def test_load_config_none_is_defaults_and_errors_say_defaults():
    cfg = load_config(None)
    assert cfg == RunConfig()
    assert cfg.input.amplitude_deg == 20.0 and cfg.simulation.dt_s == 1e-5
    with pytest.raises(EmaError, match=r"^defaults: input\.bogus: unknown key$"):
        load_config(None, [("input.bogus", "1")])


def test_load_config_error_names_the_file(tmp_path):
    p = _write(tmp_path / "c.yaml", "simulation:\n  dt_s: -1\n")
    with pytest.raises(EmaError) as ei:
        load_config(p, model=StudyConfig)
    assert ei.value.message.startswith(f"{p}: simulation.dt_s:")


def test_study_config_reads_yaml_off_as_the_word(tmp_path):
    # unquoted off is a YAML boolean; StudyConfig turns it back into 'off'
    p = _write(tmp_path / "c.yaml", "plant:\n  sat2: off\nnonlinearities:\n  friction1: off\n"
               "  saturation1: off\n")
    cfg = load_config(p, model=StudyConfig)
    params = resolve_run(cfg).params
    assert params["sat2"] == math.inf and params["sat1"] == math.inf
    assert params["friction"] == 0.0


# ------------------------------------------------------------------------------------------
# resolve_params / resolve_run


def test_resolve_params_defaults_match_doc():
    p = resolve_params({}, {})
    jeq = _jeq(3.0e-5, 24.0, 0.01)
    assert jeq == pytest.approx(6.3343e-3, rel=1e-4)  # docs/model.md §4
    assert p["c"] == pytest.approx(2 * 0.2 * math.sqrt(590.0 * jeq), rel=1e-12)
    assert p["sat1"] == pytest.approx(math.radians(800.0), rel=1e-15)


def test_resolve_params_nonlinearities_in_edge_units():
    p = resolve_params({}, {"deadzone2": 0.01, "deadzone3": 10, "deadzone4": "0.1",
                            "saturation2": "off", "saturation1": 400})
    assert p["alpha"] == pytest.approx(math.radians(0.01), rel=1e-15)
    assert p["d3"] == pytest.approx(10 * 2 * math.pi / 60, rel=1e-15)
    assert p["d4"] == pytest.approx(math.radians(0.1), rel=1e-15)
    assert p["sat2"] == math.inf
    assert p["sat1"] == pytest.approx(math.radians(400.0), rel=1e-15)


def test_resolve_params_gap1_uses_plant_gear_ratio_and_rederives_c():
    # gap1 is referred to the motor shaft: kL = value*m^2 with the config's m (30, not 24);
    # it sets the stiffness only, so a dead band from plant/deadzone2 stays
    p = resolve_params({"m": 30, "alpha": 0.002}, {"gap1": 0.5})
    assert p["kL"] == pytest.approx(0.5 * 30**2, rel=1e-15)
    assert p["alpha"] == 0.002
    assert p["c"] == pytest.approx(2 * 0.2 * math.sqrt(450.0 * _jeq(3.0e-5, 30.0, 0.01)),
                                   rel=1e-12)


def test_resolve_params_explicit_c_is_kept():
    p = resolve_params({"c": 1.25}, {"gap1": 0.5})
    assert p["c"] == 1.25 and p["kL"] == pytest.approx(0.5 * 24**2, rel=1e-15)


def test_resolve_params_friction_scale_reading():
    p = resolve_params({}, {"friction1": 0.05}, friction_reading="scale")
    assert p["friction"] == 1.0 and p["Fc"] == 0.05
    assert p["Fs"] == pytest.approx(0.075, rel=1e-15)
    assert p["sigma0"] == pytest.approx(50.0, rel=1e-15)
    assert p["sigma1"] == pytest.approx(math.sqrt(50.0 * 3.0e-5), rel=1e-14)
    assert p["sigma2"] == pytest.approx(1e-4, rel=1e-12)


def test_resolve_run_sections_and_units(tmp_path):
    # degrees -> radians, rpm -> rad/s, counts/rev -> rad; plant SI values pass through
    p = _write(tmp_path / "c.yaml", yaml.safe_dump({
        "plant": {"Kpp": 60, "sat3": "off"},
        "input": {"kind": "sine", "amplitude_deg": 5.0, "freq_hz": 2.0, "offset_deg": 1.5,
                  "start_s": 0.01},
        "simulation": {"duration_s": 0.2, "dt_s": 2e-5, "output_interval_s": 1e-3},
        "nonlinearities": {"deadzone4": 0.02, "saturation2": 24},
        "load": {"torque_nm": -2.0, "spring_nm_per_rad": 50.0},
        "controller": {"sample_time_s": 1e-4},
        "sensors": {"position_counts_per_rev": 4096, "speed_resolution_rpm": 3.0},
    }))
    cfg = load_config(p, model=StudyConfig)
    run = resolve_run(cfg, p.parent)
    q = run.params
    assert q["Kpp"] == 60.0 and q["sat3"] == math.inf
    assert q["d4"] == pytest.approx(math.radians(0.02), rel=1e-15)
    assert q["sat2"] == 24.0
    assert q["T_load"] == -2.0 and q["k_h"] == 50.0 and q["Ts"] == 1e-4
    assert q["q_pos"] == pytest.approx(2 * math.pi / 4096, rel=1e-15)
    assert q["q_pos"] == pytest.approx(1.534e-3, rel=1e-3)  # docs/model.md §3
    assert q["q_speed"] == pytest.approx(3.0 * 2 * math.pi / 60, rel=1e-15)
    assert (run.duration, run.dt, run.output_interval) == (0.2, 2e-5, 1e-3)
    s = run.signal
    assert s.kind == "sine" and s.freq == 2.0 and s.start == 0.01
    assert s.amplitude == pytest.approx(math.radians(5.0), rel=1e-15)
    assert s.offset == pytest.approx(math.radians(1.5), rel=1e-15)
    assert s.load_table is None and s.table is None


def test_resolve_run_parameter_row():
    # the kernel's parameter vector: config values at the table's columns, in SI
    from ema_cli.model.params import INDEX, to_row

    cfg = load_config(None, [("motor.locked", "true"), ("plant.kL", "600"),
                             ("nonlinearities.deadzone2", "0.05"), ("plant.sat1", "off")],
                      model=StudyConfig)
    row = to_row(resolve_run(cfg).params)
    assert row[INDEX["locked"]] == 1.0 and row[INDEX["kL"]] == 600.0
    assert row[INDEX["alpha"]] == pytest.approx(0.05 * math.pi / 180, rel=1e-15)
    assert row[INDEX["sat1"]] == math.inf
    assert row[INDEX["c"]] == pytest.approx(2 * 0.2 * math.sqrt(600 * _jeq(3e-5, 24, 0.01)),
                                            rel=1e-12)


def test_section_and_plant_setting_the_same_parameter_is_refused():
    with pytest.raises(EmaError, match=r"load\.torque_nm and plant\.T_load set the same"):
        validate(RunConfig, {"plant": {"T_load": 1.0}, "load": {"torque_nm": 2.0}}, "c.yaml")


# ------------------------------------------------------------------------------------------
# input_signal


@pytest.mark.parametrize(("fields", "expected"), [
    ({"kind": "step", "amplitude_deg": 0.1, "start_s": 0.05},
     {"kind": "step", "amplitude": math.radians(0.1), "start": 0.05}),
    ({"kind": "ramp", "amplitude_deg": 30.0, "rate_deg_s": -90.0},
     {"kind": "ramp", "amplitude": math.radians(30.0), "rate": math.radians(-90.0)}),
    ({"kind": "sine", "amplitude_deg": 5.0, "freq_hz": 3.0, "offset_deg": -2.0},
     {"kind": "sine", "amplitude": math.radians(5.0), "freq": 3.0,
      "offset": math.radians(-2.0)}),
    ({"kind": "chirp", "amplitude_deg": 5.0, "freq_hz": 0.5, "freq_end_hz": 8.0,
      "sweep_time_s": 4.0},
     {"kind": "chirp", "amplitude": math.radians(5.0), "freq": 0.5, "freq_end": 8.0,
      "sweep_time": 4.0}),
])
def test_input_signal_kinds(fields, expected):
    sig = input_signal(InputConfig(**fields))
    for name, value in expected.items():
        got = getattr(sig, name)
        if isinstance(value, float):
            assert got == pytest.approx(value, rel=1e-15, abs=0.0), name
        else:
            assert got == value, name
    assert sig.table is None and sig.load_table is None and sig.path is None


def test_input_signal_csv_and_load_profile_relative_to_config_folder(tmp_path, monkeypatch):
    cfg_dir = tmp_path / "cfgs"
    _write(cfg_dir / "prof.csv", "t_s,theta_ref_deg\n0,0\n0.1,10\n0.2,-5\n")
    _write(cfg_dir / "gust.csv", "t_s,torque_nm\n0,0\n0.5,2.5\n")
    p = _write(cfg_dir / "c.yaml", yaml.safe_dump({
        "input": {"kind": "csv", "path": "prof.csv"}, "load": {"profile": "gust.csv"},
        "simulation": {"duration_s": 0.2}}))
    monkeypatch.chdir(tmp_path)  # the profiles are not in the working directory
    cfg = load_config(p, model=StudyConfig)
    sig = resolve_run(cfg, p.parent).signal
    assert Path(sig.path) == cfg_dir / "prof.csv"
    assert Path(sig.load_path) == cfg_dir / "gust.csv"
    assert sig.table[0] == (0.0, 0.1, 0.2)
    np.testing.assert_allclose(sig.table[1], np.radians([0.0, 10.0, -5.0]), rtol=1e-15, atol=0)
    assert sig.load_table == ((0.0, 0.5), (0.0, 2.5))  # N*m: no conversion
    # without the config's folder the relative path is looked up in the working directory
    with pytest.raises(EmaError, match=r"profile 'prof\.csv' does not exist"):
        input_signal(cfg.input, None)


def test_input_signal_absolute_profile_path(tmp_path):
    prof = _write(tmp_path / "abs.csv", "t_s,theta_ref_deg\n0,1\n1,2\n")
    sig = input_signal(InputConfig(kind="csv", path=str(prof)), base_dir=tmp_path / "other")
    assert sig.path == str(prof)
    np.testing.assert_allclose(sig.table[1], np.radians([1.0, 2.0]), rtol=1e-15)


def test_input_signal_bad_load_profile_names_file(tmp_path):
    _write(tmp_path / "gust.csv", "t_s,torque\n0,0\n1,1\n")
    with pytest.raises(EmaError) as ei:
        input_signal(InputConfig(), tmp_path, LoadConfig(profile="gust.csv"))
    assert str(tmp_path / "gust.csv") in ei.value.message and "torque_nm" in ei.value.message


def test_run_config_reads_yaml_off_as_off(tmp_path):
    # YAML 1.1 reads unquoted off as False; every config model turns it back into the word
    p = tmp_path / "c.yaml"
    p.write_text("plant:\n  sat2: off\nnonlinearities:\n  friction1: off\n")
    params = resolve_run(load_config(p)).params
    assert params["sat2"] == math.inf
    assert params["friction"] == 0.0
