"""`ema identify plant` end to end (slow tier: each kernel variant compiles once): synthetic
records with stated truths recovered within their intervals, a term the data lack at zero
within its interval, the law chosen by the data; the EMPS record through the CLI."""

from __future__ import annotations

import json

import numpy as np
import pytest

from ema_cli.identify.plant.fit import run_plant
from ema_cli.identify.plant.settings import PlantSettings
from tests.helpers.plant_records import ACTUATOR, EMPS, make_record

pytestmark = pytest.mark.slow

SYM = {"M": 90.0, "Fv+": 200.0, "Fc+": 20.0, "Fv-": 200.0, "Fc-": 20.0, "OF": -3.0}
ASYM = {"M": 90.0, "Fv+": 170.0, "Fc+": 23.0, "Fv-": 245.0, "Fc-": 17.0, "OF": 0.0}


def _fit(tmp_path, truth, law, seed=7):
    # white noise of 0.07 V (2.5 N) on the command: the EMPS fit's residual level
    p = make_record(tmp_path / f"r{seed}.mat", truth, seconds=6.0, noise_v=0.07, seed=seed)
    return run_plant(PlantSettings(data=str(p), actuator=str(ACTUATOR), law=law, split=0.0))


def _contains(lf, want):
    u = lf.uncertainty
    for j, n in enumerate(u.names):
        assert u.ci_low[j] <= want[n] <= u.ci_high[j], (n, u.x[j], u.ci_low[j], u.ci_high[j])


def test_symmetric_truth_recovered_and_adequate(tmp_path):
    fit = _fit(tmp_path, SYM, "symmetric")
    lf = fit.best
    assert fit.delay == 0
    _contains(lf, {"M": 90.0, "Fv": 200.0, "Fc": 20.0, "OF": -3.0})
    assert lf.determined()[0]
    assert lf.adequacy.verdict == "ADEQUATE", lf.adequacy.reasons


def test_per_direction_terms_the_data_lack_come_out_at_zero(tmp_path):
    """Symmetric data fitted per direction (no offset term: the Coulomb levels carry it,
    Fc+ = Fc + OF, Fc- = Fc - OF): the viscous difference is zero within its interval."""
    fit = _fit(tmp_path, SYM, "per-direction")
    u = fit.best.uncertainty
    i, j = u.names.index("Fv+"), u.names.index("Fv-")
    w = np.zeros(len(u.names))
    w[i], w[j] = 1.0, -1.0
    diff, se = float(w @ u.x), float(np.sqrt(w @ u.cov @ w))
    assert abs(diff) <= u.t_quantile * se, (diff, se)
    _contains(fit.best, {"M": 90.0, "Fv+": 200.0, "Fv-": 200.0, "Fc+": 17.0, "Fc-": 23.0})


def test_auto_law_follows_the_data(tmp_path):
    asym = _fit(tmp_path, ASYM, "auto")
    assert asym.chosen == "per-direction", asym.choice
    assert asym.laws["symmetric"].adequacy.verdict == "NOT ADEQUATE"
    _contains(asym.best, {k: ASYM[k] for k in ("M", "Fv+", "Fc+", "Fv-", "Fc-")})
    sym = _fit(tmp_path, SYM, "auto", seed=8)
    assert sym.chosen == "symmetric", sym.choice


def test_emps_through_the_cli(tmp_path):
    from typer.testing import CliRunner

    from ema_cli.cli.main import app

    out = tmp_path / "emps"
    r = CliRunner().invoke(app, ["identify", "plant", str(EMPS), "--actuator", str(ACTUATOR),
                                 "--out", str(out)])
    assert r.exit_code == 0, r.output
    js = json.loads((out / "plant.json").read_text())
    assert js["controller_check"]["delay_used"] == 0
    assert js["chosen_law"] == "per-direction"
    law = js["laws"]["per-direction"]
    assert law["determined"]
    err = js["benchmark_errors_pct"]
    # below the benchmark reference model's 5.848 % and the independently measured 3.72 %
    assert err["output error"]["force"] < 3.72 < err["IDIM-LS"]["force"] < 5.848
    split = js["time_split_validation"]["errors_pct"]
    assert split["output error"]["force"] < split["IDIM-LS"]["force"]
    for f in ("plant.md", "fit.csv", "fit.png", "residual_tests.png", "actuator_fitted.yaml",
              "parameters.csv", "manifest.json"):
        assert (out / f).is_file(), f
    r = CliRunner().invoke(app, ["identify", "validate", str(out), str(EMPS)])
    assert r.exit_code == 0, r.output
    assert "output error: position" in r.output and "IDIM-LS: position" in r.output


STRIBECK_DESC = """actuator:
  name: stribeck-axis
  axis: translational
  transmission: {type: rigid}
  motor: {inertia: 0}
  load: {mass: 95, viscous: 0, offset: -3}
  drive: {type: amplifier, gain: 35.15065188 N/V}
  friction:
    load: {law: stribeck, coulomb: 20 N, static: 26 N, stribeck_velocity: 0.01 m/s,
           viscous: 200 N*s/m}
  controller:
    type: discrete
    sample_time_s: 1.0e-3
    position: {kp: 160.18}
    velocity: {kv: 243.45 V*s/m}
    velocity_source: encoder
    fir: [0.5, 0.5]
    difference_samples: 1
    output_limit: 10
    delay_samples: 0
"""


def test_a_stribeck_law_freed_by_free(tmp_path):
    """A law beyond the linear terms: the static level and Stribeck velocity freed with
    --free-style bounds are recovered within their intervals; the Coulomb-only law misses the
    peak (NOT ADEQUATE, a positive Stribeck coefficient)."""
    truth = {"M": 90.0, "Fv+": 200.0, "Fc+": 20.0, "Fv-": 200.0, "Fc-": 20.0, "OF": -3.0,
             "Fs_L": 30.0, "Fs_L_neg": 30.0, "vs_L": 0.005}
    p = make_record(tmp_path / "strib.mat", truth, seconds=8.0, noise_v=0.07)
    desc = tmp_path / "strib.yaml"
    desc.write_text(STRIBECK_DESC)
    fit = run_plant(PlantSettings(data=str(p), actuator=str(desc), law="symmetric", split=0.0,
                                  free={"Fs_L": (0.0, 60.0), "vs_L": (1e-4, 0.1)}))
    _contains(fit.best, {"M": 90.0, "Fv": 200.0, "Fc": 20.0, "OF": -3.0, "Fs_L": 30.0,
                         "vs_L": 0.005})
    assert fit.best.determined()[0]
    plain = run_plant(PlantSettings(data=str(p), actuator=str(ACTUATOR), law="symmetric",
                                    split=0.0))
    a = plain.best.adequacy
    assert a.verdict == "NOT ADEQUATE"
    strib = next(o for o in a.omitted if o.name.startswith("Stribeck"))
    assert strib.missed and strib.coefficient > 0, a.reasons



def test_validation_on_a_record_with_logged_pulses(tmp_path):
    """A validation record whose logged command carries pulses the law does not compute: the
    difference is applied as a disturbance (said in a note) and the fitted model predicts the
    record as well as the one it was fitted on."""
    from ema_cli.identify.plant.validation import validate

    fit = _fit(tmp_path, SYM, "symmetric")
    val = make_record(tmp_path / "pulses.mat", SYM, seconds=6.0, noise_v=0.07, seed=11,
                      pulses_v=1.0)
    v = validate(fit, val)
    assert any("departs from the described law" in n for n in v.notes), v.notes
    own = fit.errors["output error"].force_pct
    assert v.errors["output error"].force_pct < 1.5 * own, (v.errors, own)
