"""Actuator descriptions (config section ``actuator``, ``config/actuator.py``): the paper's EMA
spelled out is the default bit for bit, the EMPS axis from its documentation reproduces the
benchmark's published simulation errors, a linear axis reads in mm, mm/s and N, and a bad
description is one line naming its key and what was expected."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml

from ema_cli.api import simulate
from ema_cli.config.loader import load_config
from ema_cli.errors import EmaError

ROOT = Path(__file__).resolve().parents[2]
ACTUATORS = ROOT / "configs" / "actuators"


def test_the_paper_ema_spelled_out_is_the_default_bit_for_bit():
    base = {"input": {"kind": "step", "amplitude_deg": 5.0},
            "simulation": {"duration_s": 0.05, "output_interval_s": 1e-4}}
    plain = simulate(base)
    described = simulate({**base, "actuator": str(ACTUATORS / "paper_ema.yaml")})
    assert plain.params == described.params
    np.testing.assert_array_equal(plain.batch.signals, described.batch.signals)
    np.testing.assert_array_equal(plain.batch.metrics, described.batch.metrics)
    assert list(plain.table()) == list(described.table())  # the same 17 columns, in deg


@pytest.fixture(scope="module")
def emps():
    """The EMPS simulation's benchmark scores with the command 1 sample late (the Simulink
    model) and on the same sample (the measured log)."""
    import importlib.util

    spec = importlib.util.spec_from_file_location(
        "emps_simulation", ROOT / "experiments" / "emps_simulation.py")
    mod = importlib.util.module_from_spec(spec)  # type: ignore[arg-type]
    spec.loader.exec_module(mod)  # type: ignore[union-attr]
    return {d: mod.emps_errors(d)[0].as_dict() for d in (1, 0)}


def test_emps_from_its_documentation_reproduces_the_published_errors(emps):
    # Janot, Gautier, Brunot 2019: velocity 0.22911 %, force 5.848 % (within 0.1 point)
    late = emps[1]
    assert abs(late["velocity"] - 0.22911) < 0.1 and abs(late["force"] - 5.848) < 0.1
    assert abs(late["velocity"] - 0.22911) < 0.005 and abs(late["force"] - 5.848) < 0.02
    # without the Simulink model's delay (the measured log's own timing) the model is closer:
    # 4.57 % force error, as measured independently for this rigid model (issue 37)
    same = emps[0]
    assert same["force"] == pytest.approx(4.573, abs=0.01)
    assert same["velocity"] < late["velocity"] and same["force"] < late["force"]


def test_a_linear_axis_reads_in_mm_mm_s_and_n(tmp_path):
    run = simulate(ROOT / "configs" / "emps.yaml", {"simulation.duration_s": 0.5})
    cols = list(run.table())
    assert cols[:5] == ["t_s", "x_ref_mm", "x_load_mm", "v_ref_mm_s", "v_load_mm_s"]
    assert {"drive_force_n", "friction_load_n", "force_load_n"} <= set(cols)
    assert not [c for c in cols + list(run.summary) if "deg" in c or c.endswith("_nm")]
    assert "current_a" not in cols  # an amplifier without a torque constant has no current
    assert "dx_mm" not in cols and "force_shaft_n" not in cols  # a rigid axis has no shaft
    # the reference is the log's qg [m] shown in mm, interpolated at k*1 ms: the log's time
    # stamps jitter by up to 4e-8 s, at most 125 mm/s * 4e-8 s = 5e-6 mm
    from ema_cli.logs import read_log_table

    qg = read_log_table(ROOT / "experiments" / "data" / "emps" / "DATA_EMPS.mat").column("qg")
    np.testing.assert_allclose(run.signal("x_ref_mm")[:100], qg[:100] * 1e3, rtol=0,
                               atol=5e-6)


def _bad(actuator: dict, **run) -> str:
    doc = {"actuator": actuator, **run}
    with pytest.raises(EmaError) as ei:
        load_config(doc)
    msg = ei.value.message
    assert "\n" not in msg
    return msg


@pytest.mark.parametrize(("actuator", "key", "words"), [
    ({"axis": "translational", "transmission": {"type": "compliant", "stiffness": "590 N*m/rad"}},
     "actuator.transmission.stiffness", "N*m/rad is a rotary unit; a translational axis expects "
                                        "stiffness in N/m"),
    ({"axis": "rotary", "load": {"inertia": "3 kg"}}, "actuator.load.inertia",
     "kg is a translational unit; a rotary axis expects mass in kg*m^2"),
    ({"axis": "translational", "load": {"mass": 0}, "transmission": {"type": "rigid"}},
     "actuator.load.mass", "must be > 0, got 0"),
    ({"axis": "rotary", "load": {"mass": 3}}, "actuator.load.mass",
     "a rotary axis has an inertia"),
    ({"controller": {"type": "discrete", "sample_time_s": 1e-3, "difference_samples": 0}},
     "actuator.controller.difference_samples", "greater than or equal to 1"),
    ({"friction": {"load": {"law": "coulomb", "coulomb": 20, "static": 10}}},
     "actuator.friction.load.static", "the breakaway level (10) must be >= the Coulomb level "
                                      "(20)"),
    ({"friction": {"load": {"law": "coulomb", "coulomb": -2}}},
     "actuator.friction.load.coulomb", "must be >= 0, got -2"),
    ({"friction": {"motor": {"law": "stribeck", "coulomb": 0.02}}},
     "actuator.friction.motor.stribeck_velocity", "the stribeck law needs it"),
    ({"transmission": {"type": "rigid", "stiffness": 500}}, "actuator.transmission.stiffness",
     "a rigid transmission has no stiffness"),
    ({"drive": {"type": "amplifier"}}, "actuator.drive.gain", "an amplifier needs its gain"),
    ({"drive": {"type": "armature", "gain": 3}}, "actuator.drive.gain", "is an amplifier's"),
    ({"axis": "translational", "ratio": {"gear": 24}}, "actuator.ratio.gear",
     "a translational axis gives screw_lead"),
    ({"controller": {"type": "discrete", "sample_time_s": 1e-3, "fir": [0.5, 0.2]}},
     "actuator.controller.fir", "the taps must sum to 1"),
    ({"controller": {"type": "none"}}, "input.signal", "reads the actuation (controller none)"),
    ({"transmission": {"preload": "0.2 N*m"}}, "actuator.transmission.preload",
     "a preload bridges the backlash: give transmission.backlash > 0"),
    ({"transmission": {"type": "rigid", "friction": "0.2 N*m"}},
     "actuator.transmission.friction", "a rigid transmission has no friction"),
    ({"transmission": {"friction": "0.2 N"}}, "actuator.transmission.friction",
     "N is a translational unit; a rotary axis expects force in N*m"),
    ({"transmission": {"friction": "-1 N*m"}}, "actuator.transmission.friction",
     "must be >= 0"),
])
def test_a_bad_description_is_one_line_naming_its_key(actuator, key, words):
    msg = _bad(actuator)
    assert key in msg and words in msg, msg


def test_a_delay_longer_than_the_run_is_refused():
    msg = _bad({"controller": {"type": "discrete", "sample_time_s": 1e-2, "delay_samples": 5}},
               simulation={"duration_s": 0.05})
    assert "actuator.controller.delay_samples: 5 samples of 0.01 s is not shorter than the run" \
        in msg


def test_a_missing_actuator_file_names_both_files(tmp_path):
    cfg = tmp_path / "run.yaml"
    cfg.write_text(yaml.safe_dump({"actuator": "nowhere.yaml"}))
    with pytest.raises(EmaError, match=r"run.yaml: actuator: the actuator file 'nowhere.yaml' "
                                       r"does not exist"):
        load_config(cfg)


def test_values_with_units_convert_to_si():
    cfg = load_config({"actuator": {
        "axis": "translational", "ratio": {"screw_lead": "10 mm"},
        "transmission": {"type": "compliant", "stiffness": "2 N/um", "backlash": "20 um"},
        "motor": {"inertia": "5 g*cm^2"}, "load": {"mass": "1500 g", "offset": "2 kN"},
        "drive": {"type": "amplifier", "gain": "35 N/V", "bandwidth_hz": 1000},
        "friction": {"load": {"law": "stribeck", "coulomb": "20 N", "static": "25 N",
                              "stribeck_velocity": "5 mm/s", "negative": {"coulomb": 18}}}}})
    p = cfg.actuator.params()  # type: ignore[union-attr]
    assert p["m"] == pytest.approx(2 * np.pi / 0.01)
    assert p["kL"] == pytest.approx(2e6) and p["alpha"] == pytest.approx(2e-5)
    assert p["Jm"] == pytest.approx(5e-7) and p["JL"] == pytest.approx(1.5)
    assert p["offset"] == pytest.approx(2000.0) and p["amp_gain"] == 35.0
    assert p["amp_tau"] == pytest.approx(1 / (2 * np.pi * 1000))
    assert p["vs_L"] == pytest.approx(5e-3) and p["Fc_L_neg"] == 18.0
    assert p["Fs_L"] == 25.0 and p["friction_L"] == "static" and "Fs_L_neg" not in p
