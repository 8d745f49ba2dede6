"""`ema identify` on real-data shapes through typer's CliRunner: a linear friction map in mm/s
and N (the law chosen, the shape verdict printed and in the JSON), torque-twist loops from a
.mat struct with terms (terms_fit.png, intervals), bad terms, laws and units one line."""

from __future__ import annotations

import json

import numpy as np
import pytest
from scipy.io import savemat
from typer.testing import CliRunner

from ema_cli.cli.main import app

runner = CliRunner()


def invoke(*args: str):
    r = runner.invoke(app, [*map(str, args)])
    return r, " ".join(r.output.split())


@pytest.fixture(scope="module")
def screw(tmp_path_factory):
    """A ball-screw map: mm/s and N, both directions given as magnitudes, repeats, shuffled."""
    rng = np.random.default_rng(5)
    sp = np.geomspace(5.0, 3000.0, 9)
    v = np.concatenate([sp, sp, -sp, -sp])
    rng.shuffle(v)
    u = np.abs(v) / 1000
    F = np.where(v > 0, 40 + 20 * np.exp(-u / 0.02) + 150 * u,
                 52 + 18 * np.exp(-u / 0.03) + 170 * u) + 0.8 * rng.standard_normal(v.size)
    p = tmp_path_factory.mktemp("maps") / "screw.csv"
    p.write_text("v,F,temp\n" + "".join(f"{a:.17g},{b:.17g},30\n" for a, b in zip(v, F,
                                                                                  strict=True)))
    return p


def test_linear_friction_map_per_direction(screw, tmp_path):
    r, text = invoke("identify", "friction-sweep", "--data", screw, "--columns",
                     "omega_rpm=v:mm/s", "--columns", "torque_nm=F:N", "--out", tmp_path / "fs")
    assert r.exit_code == 0, text
    assert "law: stribeck-dir: lowest BIC" in text and "shape: the model fits" in text
    js = json.loads((tmp_path / "fs" / "identification.json").read_text())
    assert js["chosen_law"] == "stribeck-dir" and js["units"] == {"speed": "m/s",
                                                                  "friction": "N"}
    p = js["parameters"]
    for n, t in (("Fc", 40.0), ("Fc_neg", 52.0), ("sigma2", 150.0), ("sigma2_neg", 170.0)):
        assert abs(p[n]["value"] - t) < 3 * p[n]["standard_error"], (n, p[n])  # 99.7 % each
    assert not js["differences_neg_minus_pos"]["Fc_neg - Fc"]["zero_inside"]
    assert js["adequacy"]["verdict"] == "fits"


@pytest.fixture(scope="module")
def loops(tmp_path_factory):
    """Gearbox loops in a .mat struct: a matrix [t, twist(arcmin), torque], no twist rate."""
    t = np.linspace(0.0, 2.0, 2001)
    ph = 2 * np.pi * (0.5 * t + 0.8 * t**2)
    dth = (0.004 + 0.004 * t) * np.sin(ph) + 5e-4
    d = dth - 5e-4
    dw = np.gradient(dth, t)
    T = 800 * np.sign(d) * np.maximum(np.abs(d) - 1e-3, 0) + 0.2 * dw + 3.0 * np.sign(dw)
    T = T + 0.05 * np.random.default_rng(6).standard_normal(t.size)
    p = tmp_path_factory.mktemp("loops") / "gear.mat"
    savemat(p, {"rec": {"m": np.column_stack([t, np.degrees(dth) * 60, T])}})
    return p


def test_torque_twist_terms_from_a_mat_struct(loops, tmp_path):
    r, text = invoke("identify", "--data", loops, "--columns", "t_s=rec.m[:, 0]",
                     "--columns", "dtheta_rad=rec.m[:, 1]:arcmin", "--columns",
                     "torque_nm=rec.m(:, 3)", "--method", "exact", "--model", "paper",
                     "--alpha-range", "0", "0.004", "--k-range", "100", "2000",
                     "--terms", "offset,friction,preload", "--out", tmp_path / "tq")
    assert r.exit_code == 0, text
    assert "Eq. 8 shape: THE MODEL DOES NOT FIT" in text and "with terms shape: the model fits" \
        in text and "derived" in text
    js = json.loads((tmp_path / "tq" / "identification.json").read_text())
    tp = js["terms"]["parameters"]
    for n, v in (("kL", 800.0), ("alpha", 1e-3), ("dth0", 5e-4), ("Ft", 3.0)):
        assert tp[n]["ci95"][0] <= v <= tp[n]["ci95"][1], (n, tp[n])
    assert tp["preload"]["zero_inside"]  # not in the data: zero within its interval
    assert (tmp_path / "tq" / "terms_fit.png").is_file()


def test_only_the_chosen_laws_compete(screw, tmp_path):
    r, text = invoke("identify", "--friction-sweep", "--data", screw, "--set",
                     "columns.omega_rpm=v:mm/s", "--set", "columns.torque_nm=F:N",
                     "--laws", "coulomb,stribeck", "--out", tmp_path / "fs2")
    assert r.exit_code == 0, text
    js = json.loads((tmp_path / "fs2" / "identification.json").read_text())
    assert set(js["laws"]) == {"coulomb", "stribeck"}
    # the symmetric law on a map 30 % apart by direction: its shape is wrong, and it says so
    assert js["adequacy"]["verdict"] == "does not fit", js["adequacy"]["why"]


@pytest.mark.parametrize("args, expect", [
    (["--terms", "friction,dahl"], "terms friction and dahl are two laws of one friction"),
    (["--laws", "coulomb"], "--laws applies to --friction-sweep, not to the torque-data"),
    (["--set", "terms=[offset,backlash]"], "terms.1"),
    (["--columns", "torque_nm=T:furlong"], "unknown unit 'furlong'; torque_nm takes torque units"),
])
def test_bad_torque_options_one_line(loops, args, expect):
    r, text = invoke("identify", "--data", loops, "--method", "exact", *args)
    assert r.exit_code == 2 and expect in text and "Traceback" not in r.output, text


@pytest.mark.parametrize("args, expect", [
    (["--set", "laws=[]"], "name at least one candidate law"),
    (["--set", "laws=[viscous]"], "laws.0"),
    (["--set", "columns.omega_rpm=v:V"], "'V' is a unit of voltage; omega_rpm takes sweep speed"),
])
def test_bad_sweep_options_one_line(screw, args, expect):
    r, text = invoke("identify", "--friction-sweep", "--data", screw, *args)
    assert r.exit_code == 2 and expect in text and "Traceback" not in r.output, text
