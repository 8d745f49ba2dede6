"""Plant identification of a rigid axis (identify/plant: controller check, output error,
adequacy, the record reader): the described controller against the EMPS log, the residual
tests against their textbook behaviour, bad records refused in one line; a short synthetic
record recovered (intervals holding their truths, a term the data lack at zero)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.io import savemat

from ema_cli.errors import EmaError
from ema_cli.identify.plant import adequacy as adq
from ema_cli.identify.plant import output_error as oe
from ema_cli.identify.plant.controller_check import MATCH_MAX, check_controller, chosen_delay
from ema_cli.identify.plant.records import read_plant_mat, read_plant_record
from tests.helpers.plant_records import EMPS, GTAU

EMPS_PRM = {"Ts": 1e-3, "dc_kp": 160.18, "dc_kv": 243.45, "dc_umax": 10.0, "dc_ndiff": 1.0,
            "dc_fir0": 0.5, "dc_fir1": 0.5, "dc_delay": 1.0}


# --- the controller check on the measured EMPS log ------------------------------------------

@pytest.fixture(scope="module")
def emps_check():
    rec = read_plant_mat(EMPS)
    return check_controller(EMPS_PRM, rec.q_m, rec.reference_m, rec.force_n / GTAU, "V",
                            first=49)


def test_the_emps_logs_command_is_the_same_samples_output(emps_check):
    # the log's vir is the law applied to the same sample's qm and qg (delay 0) to 0.24 % RMS;
    # the Simulink model's one-sample delay is 15x worse (3.5 %)
    c = emps_check
    assert c.best_delay == 0
    assert c.rel_rms[0] < 0.003
    assert 0.03 < c.rel_rms[1] < 0.04
    assert c.at_limit_log == 0 and c.matches
    assert chosen_delay(c, "auto", "log") == 0


def test_a_wrong_delay_or_gain_is_refused_with_the_figures(emps_check):
    with pytest.raises(EmaError) as e:
        chosen_delay(emps_check, 1, "data file 'x.mat'")
    msg = str(e.value)
    assert "\n" not in msg and "delay of 0 sample(s)" in msg and "3.54 %" in msg
    rec = read_plant_mat(EMPS)
    wrong = check_controller({**EMPS_PRM, "dc_kv": 200.0}, rec.q_m, rec.reference_m,
                             rec.force_n / GTAU, "V", first=49)
    assert min(wrong.rel_rms) > MATCH_MAX
    with pytest.raises(EmaError, match=r"does not match the logged command: RMS mismatch .* "
                                       r"largest mismatch .* at index \d+"):
        chosen_delay(wrong, "auto", "data file 'x.mat'")


# --- noise floors and residual tests --------------------------------------------------------

def test_noise_floors_from_the_data():
    rng = np.random.default_rng(1)
    t = np.arange(20000) * 1e-3
    # fast moves between slow creeps: the creeps visit adjacent levels of the 5e-8 m encoder
    q = np.round((0.1 * np.sin(2 * np.pi * 0.3 * t) + 2e-5 * np.sin(2 * np.pi * 7 * t)) / 5e-8)
    q = q * 5e-8
    assert oe.encoder_floor(q) == pytest.approx(5e-8 / np.sqrt(12), rel=1e-6)
    F = 30 * np.sign(np.sin(2 * np.pi * 0.5 * t)) + 0.2 * rng.standard_normal(t.size)
    assert oe.command_floor(F) == pytest.approx(0.2, rel=0.05)


def test_white_noise_passes_and_a_coloured_residual_fails():
    rng = np.random.default_rng(2)
    e = rng.standard_normal(5000)
    white = adq.correlation_test("w", e)
    assert white.passes and white.bound == pytest.approx(1.96 / np.sqrt(5000))
    ar = np.zeros_like(e)
    for k in range(1, e.size):
        ar[k] = 0.8 * ar[k - 1] + e[k]
    c = adq.correlation_test("ar", ar)
    assert not c.passes and c.lag == 1 and c.worst == pytest.approx(0.8, abs=0.03)
    assert adq.fit_percent(np.sin(np.arange(100.0)), np.sin(np.arange(100.0))) == 100.0
    assert oe.correlation_time(ar, 1e-3) == pytest.approx(-1e-3 / np.log(0.8), abs=2e-3)


def test_an_omitted_viscous_asymmetry_is_named_and_white_residuals_miss_nothing():
    rng = np.random.default_rng(3)
    t = np.arange(30000) * 1e-3
    v = 0.2 * np.sin(2 * np.pi * 0.2 * t)
    clusters = [np.arange(a, min(a + 500, t.size)) for a in range(0, t.size, 500)]
    noise = rng.standard_normal(t.size)
    clean = adq.omitted_terms(noise, v, ("M", "Fv", "Fc", "OF"), clusters)
    assert not any(o.missed for o in clean)
    r = noise + 20.0 * np.abs(v)  # Fv+ - Fv- = 40 N*s/m missing from a symmetric law
    out = {o.name: o for o in adq.omitted_terms(r, v, ("M", "Fv", "Fc", "OF"), clusters)}
    assert out["Fv asymmetry"].missed
    assert out["Fv asymmetry"].coefficient == pytest.approx(20.0, rel=0.03)
    per_dir = adq.omitted_terms(r, v, ("M", "Fv+", "Fc+", "Fv-", "Fc-"), clusters)
    assert "Fv asymmetry" not in {o.name for o in per_dir}


# --- the record reader ------------------------------------------------------------------------

def _csv(tmp_path, **cols):
    import pandas as pd

    p = tmp_path / "rec.csv"
    pd.DataFrame(cols).to_csv(p, index=False)
    return p


def test_a_csv_record_in_mm_with_the_descriptions_gain(tmp_path):
    t = np.arange(2000) * 1e-3
    x = 10 * np.sin(t)
    p = _csv(tmp_path, time=t, x_mm=x, ref_mm=x + 0.1, u=np.cos(3 * t))
    rec, ex = read_plant_record(p, {"time": "time", "position": "x_mm:mm",
                                    "reference": "ref_mm:mm", "actuation": "u:V"}, gain=35.0)
    np.testing.assert_allclose(rec.q_m, x / 1000, rtol=1e-15)
    np.testing.assert_allclose(rec.force_n, 35.0 * np.cos(3 * t), rtol=1e-15)
    assert ex["gain_from"] == "the description's drive gain"
    rec, ex = read_plant_record(p, {"time": "time", "position": "x_mm:mm",
                                    "reference": "ref_mm:mm", "actuation": "u:N"})
    assert ex["gain"] == 1.0


@pytest.mark.parametrize("cols,columns,match", [
    ({"t": "T", "qm": "Q", "qg": "Q"}, {}, r"has no variable 'vir' \(the actuation"),
    ({"t": "T", "qm": "Q", "qg": "Q", "vir": "C"}, {}, r"variable 'vir' is constant"),
    ({"t": "T", "qm": "Q", "qg": "Q", "vir": "S"}, {}, r"at its limit .* in 9\d % of the samples"),
    ({"t": "T", "qm": "Q", "vir": "U"}, {}, r"has no variable 'qg' \(the reference"),
    ({"t": "T", "qm": "Q", "qg": "Q", "vir": "U"}, {"position": "qm:furlong"},
     r"--columns position=qm:furlong: unknown unit 'furlong'"),
    ({"t": "T", "qm": "Q", "qg": "Q", "vir": "U"}, {}, r"no gain converts the actuation"),
])
def test_bad_records_are_one_line(tmp_path, cols, columns, match):
    t = np.arange(1000) * 1e-3
    data = {"T": t, "Q": np.sin(t), "U": np.cos(7 * t), "C": np.ones_like(t),
            "S": np.where(np.arange(t.size) < 950, 10.0, 3.0)}
    p = _csv(tmp_path, **{k: data[v] for k, v in cols.items()})
    with pytest.raises(EmaError, match=match) as e:
        read_plant_record(p, columns, gain=None if "gain" in match else 35.0,
                          saturation=10.0 if cols.get("vir") == "S" else None)
    assert "\n" not in str(e.value)
    assert "rec.csv" in str(e.value) or "--columns" in str(e.value)


def test_mat_struct_record_roles(tmp_path):
    """A record given by the roles of another layout (names differ from EMPS)."""
    t = np.arange(1000) * 1e-3
    p = tmp_path / "other.mat"
    savemat(p, {"time": t[:, None], "pos": np.sin(t)[:, None], "posref": np.sin(t)[:, None],
                "cmd": np.cos(5 * t)[:, None], "k": np.array([[2.0]])})
    rec, ex = read_plant_record(p, {"time": "time", "position": "pos", "reference": "posref",
                                    "actuation": "cmd", "gain": "k"})
    np.testing.assert_allclose(rec.force_n, 2.0 * np.cos(5 * t))
    assert rec.one_based and ex["gain_from"] == "variable 'k'"
