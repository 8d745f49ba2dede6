"""Sweep expansion and planning: grid, zip, baseline, 'off', placements, relative sizes, keys."""

from __future__ import annotations

import math

import numpy as np
import pytest

from ema_cli.config.loader import resolve_params, validate
from ema_cli.config.study import StudyConfig
from ema_cli.errors import EmaError
from ema_cli.sweep.expand import count_jobs, expand
from ema_cli.sweep.plan import plan_sweep, unit_slug
from ema_cli.units import DEG, RPM

SHORT = {"duration_s": 0.01, "dt_s": 1e-5, "output_interval_s": 1e-3}


def study(sweep: dict, **extra) -> StudyConfig:
    data = {"input": {"kind": "step", "amplitude_deg": 0.1}, "simulation": SHORT,
            "sweep": sweep, "outputs": {"timeseries": False, "figures": []}, **extra}
    return validate(StudyConfig, data, "test.yaml")


def test_grid_is_the_cartesian_product_in_axis_order():
    cfg = study({"axes": [{"nonlinearity": "deadzone2", "values": [0.001, 0.01]},
                          {"parameter": "Kpp", "values": [40, 50, 60]}], "baseline": False})
    specs = expand(cfg)
    assert count_jobs(cfg.sweep) == len(specs) == 6  # 2 x 3
    pairs = [(s.points[0].value, s.points[1].value) for s in specs]
    assert pairs == [(0.001, 40), (0.001, 50), (0.001, 60), (0.01, 40), (0.01, 50), (0.01, 60)]


def test_zip_advances_axes_together_and_needs_equal_lengths():
    cfg = study({"mode": "zip", "baseline": False,
                 "axes": [{"nonlinearity": "deadzone1", "values": [0.01, 0.1, 1]},
                          {"parameter": "Kpp", "linspace": {"start": 40, "stop": 60, "num": 3}}]})
    specs = expand(cfg)
    assert [(s.points[0].value, s.points[1].value) for s in specs] == [
        (0.01, 40.0), (0.1, 50.0), (1, 60.0)]
    with pytest.raises(EmaError, match=r"sweep.axes: zip needs axes of equal length"):
        study({"mode": "zip", "axes": [{"nonlinearity": "deadzone1", "values": [1, 2]},
                                       {"parameter": "Kpp", "values": [1]}]})


def test_baseline_first_with_swept_nonlinearities_off():
    cfg = study({"axes": [{"nonlinearity": "deadzone2", "values": [0.01]},
                          {"nonlinearity": "friction1", "values": [0.001]},
                          {"nonlinearity": "saturation2", "values": [20]}]},
                nonlinearities={"deadzone2": 0.05, "saturation2": 30, "deadzone1": 0.1})
    plan = plan_sweep(cfg)
    assert len(plan.jobs) == 2 and plan.jobs[0].baseline and plan.jobs[0].label == "baseline"
    base = plan.jobs[0].params
    assert base["alpha"] == 0.0  # swept dead zone -> 0 (overrides the fixed 0.05 deg)
    assert base["friction"] == 0.0  # swept friction -> off
    assert math.isinf(base["sat2"])  # swept saturation -> off
    assert base["d1"] == pytest.approx(0.1)  # a fixed, unswept nonlinearity stays
    job = plan.jobs[1].params
    assert job["alpha"] == pytest.approx(0.01 * DEG) and job["sat2"] == 20.0
    assert job["friction"] == 1.0 and job["sigma2"] == 0.001
    assert plan.jobs[0].values == {"deadzone2_deg": 0.0, "friction1_nms_per_rad": "off",
                                   "saturation2_v": "off"}


def test_off_values_and_a_baseline_equal_to_a_job_is_run_once():
    cfg = study({"axes": [{"nonlinearity": "saturation1", "values": [800, False]}]})
    plan = plan_sweep(cfg)  # YAML's unquoted off arrives as False: read as the word 'off'
    assert [j.label for j in plan.jobs] == ["saturation1 = 800 deg/s", "saturation1 = off"]
    assert math.isinf(plan.jobs[1].params["sat1"])
    assert plan.jobs[0].params["sat1"] == pytest.approx(800 * DEG)
    assert plan.notes and "baseline equals job 'saturation1 = off'" in plan.notes[0]
    assert plan.jobs[1].values["saturation1_deg_s"] == "off"


def test_placement_axis_same_type_different_location_with_per_name_values():
    cfg = study({"axes": [{"nonlinearity": ["deadzone1", "deadzone@speed_sensor"],
                           "values": {"deadzone1": [0.1, 1], "deadzone@speed_sensor": [10]}}],
                 "baseline": False})
    plan = plan_sweep(cfg)
    assert plan.axes[0].name == "location" and plan.axes[0].unit == ""  # V and rpm differ
    assert [j.label for j in plan.jobs] == [
        "deadzone1 = 0.1 V", "deadzone1 = 1 V", "deadzone@speed_sensor = 10 rpm"]
    assert plan.jobs[2].params["d3"] == pytest.approx(10 * RPM)
    assert plan.jobs[2].values == {"location": "deadzone@speed_sensor", "location_magnitude": 10,
                                   "location_unit": "rpm"}
    cfg2 = study({"axes": [{"nonlinearity": ["deadzone2", "gap1"], "values": [1]}]})
    assert cfg2.sweep.axes[0].label == "type"  # different types at the transmission


def test_relative_dead_zones_scale_with_the_baseline_peaks():
    cfg = study({"axes": [{"nonlinearity": ["deadzone@transmission", "deadzone@amplifier"],
                           "relative": True, "values": [2]}]})
    plan = plan_sweep(cfg)
    # transmission: 2 % of the 0.1 deg input signal = 0.002 deg
    assert plan.scales["deadzone@transmission"] == pytest.approx(0.1)
    assert plan.jobs[1].params["alpha"] == pytest.approx(0.002 * DEG, rel=1e-12)
    # amplifier: 2 % of the baseline's peak voltage demand (the metric, full resolution)
    from ema_cli.sim.runner import simulate

    base = simulate(plan.jobs[0].params, plan.signal, plan.duration, plan.dt, None)
    peak_v = float(base.metrics_frame()["peak_voltage_cmd_v"][0])
    assert plan.scales["deadzone@amplifier"] == pytest.approx(peak_v, rel=1e-12)
    assert plan.jobs[2].params["d1"] == pytest.approx(0.02 * peak_v, rel=1e-12)
    assert plan.jobs[2].values["location_pct"] == 2


def test_logspace_values_are_geometric_and_the_axis_is_logarithmic():
    cfg = study({"axes": [{"nonlinearity": "deadzone2",
                           "logspace": {"start": 0.001, "stop": 0.1, "num": 3}}]})
    plan = plan_sweep(cfg)
    vals = [j.values["deadzone2_deg"] for j in plan.jobs[1:]]
    np.testing.assert_allclose(vals, [0.001, 0.01, 0.1], rtol=1e-12)
    assert plan.axes[0].log and plan.axes[0].columns == ("deadzone2_deg",)


def test_parameter_axis_goes_into_the_plant_and_derived_values_follow():
    cfg = study({"axes": [{"parameter": "kL", "values": [100, 400]}], "baseline": False})
    plan = plan_sweep(cfg)
    for job, kl in zip(plan.jobs, (100, 400), strict=True):
        ref = resolve_params({"kL": kl}, {})
        assert job.params == ref  # c re-derived from kL at the same damping ratio
    assert plan.axes[0].columns == ("kL_nm_per_rad",)


def test_keys_are_content_hashes_identical_runs_share_one():
    cfg = study({"axes": [{"nonlinearity": "deadzone2", "values": [0.01, 0.01, 0.02]}],
                 "baseline": False})
    plan = plan_sweep(cfg)
    keys = [j.key for j in plan.jobs]
    assert keys[0] == keys[1] != keys[2] and plan.n_unique == 2
    other = plan_sweep(study({"axes": [{"nonlinearity": "deadzone2", "values": [0.01]}]},
                             plant={"Kpp": 51}))
    assert other.jobs[1].key != keys[0]  # a different plant is a different run


def test_job_cap_and_empty_sweep_are_refused():
    with pytest.raises(EmaError, match=r"expands to 1,001 jobs, more than sweep.max_jobs = 1,000"):
        plan_sweep(study({"axes": [{"nonlinearity": "deadzone2",
                                    "linspace": {"start": 0, "stop": 1, "num": 1000}}],
                          "max_jobs": 1000}))
    with pytest.raises(EmaError, match=r"sweep.axes: empty sweep"):
        plan_sweep(study({"axes": []}))


@pytest.mark.parametrize(("unit", "slug"), [
    ("deg", "deg"), ("deg/s", "deg_s"), ("N*m/rad", "nm_per_rad"), ("N*m*s/rad", "nms_per_rad"),
    ("1/s", "1_per_s"), ("kg*m^2", "kgm2"), ("-", ""), ("%", "pct")])
def test_unit_slugs(unit, slug):
    assert unit_slug(unit) == slug
