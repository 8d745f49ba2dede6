"""`ema identify` through typer's CliRunner: outputs, config, data files, every bad-data case."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

from ema_cli.cli.main import app
from ema_cli.identify.torque.run import load_data
from ema_cli.identify.torque.settings import IdentifySettings
from ema_cli.report.identify_figures import write_example_csv

runner = CliRunner()
CONFIG = Path(__file__).resolve().parents[2] / "configs" / "identify.yaml"


def invoke(*args: str):
    r = runner.invoke(app, ["identify", *map(str, args)])
    text = " ".join(r.output.split())  # rich wraps long lines
    return r, text


@pytest.fixture(scope="module")
def csv_dir(tmp_path_factory):
    """Example data files written from synthetic data (noise-free, contact damping)."""
    d = tmp_path_factory.mktemp("identify_data")
    data = load_data(IdentifySettings())
    write_example_csv(d / "good.csv", data)
    wide = load_data(IdentifySettings(synthetic={"alpha": 0.006}))
    write_example_csv(d / "wide_gap.csv", wide)
    return d


def test_default_run_prints_the_table_and_writes_everything(tmp_path):
    out = tmp_path / "run"
    r, text = invoke("--k-range", 500, 700, "--generations", 60, "--out", out)
    assert r.exit_code == 0, r.output
    for word in ("kL", "alpha", "truth", "LS optimum", "590", "0.003", "matched"):
        assert word in text, word
    for f in ("identification.json", "runs.csv", "history.csv", "convergence.png", "fit.png",
              "manifest.json"):
        assert (out / f).is_file(), f
    js = json.loads((out / "identification.json").read_text())
    assert js["truth"] == {"kL": 590.0, "alpha": 0.003}
    assert js["runs"][0]["evaluations"] == 100 + 59 * 98
    opt = js["least_squares_optimum"]["params"]
    assert opt["kL"] == pytest.approx(590.0, rel=1e-9)
    assert opt["alpha"] == pytest.approx(0.003, rel=1e-9)
    hist = pd.read_csv(out / "history.csv")
    assert len(hist) == 60 and "best_ever_kL_Nm_per_rad" in hist.columns
    runs = pd.read_csv(out / "runs.csv")
    assert {"kL_error_pct", "alpha_dist_opt_pct", "wall_time_s"} <= set(runs.columns)
    man = json.loads((out / "manifest.json").read_text())
    assert man["command"] == "identify" and man["settings"]["k_range"] == [500.0, 700.0]


def test_config_file_and_overrides(tmp_path):
    out = tmp_path / "run"
    r, text = invoke(CONFIG, "--method", "ga-paper", "--pop", 20, "--generations", 10,
                     "--bits", 12, "--runs", 2, "--out", out)
    assert r.exit_code == 0, r.output
    js = json.loads((out / "identification.json").read_text())
    assert js["method"] == "ga-paper" and len(js["runs"]) == 2
    assert js["ga_options"]["bits"] == 12 and js["ga_options"]["encoding"] == "binary"
    assert all(run["evaluations"] == 200 for run in js["runs"])


def test_data_file_with_mapped_columns_fits_c(tmp_path, csv_dir):
    df = pd.read_csv(csv_dir / "good.csv").rename(columns={"torque_nm": "T_meas"})
    path = tmp_path / "renamed.csv"
    df.to_csv(path, index=False)
    out = tmp_path / "run"
    r, _ = invoke("--data", path, "--columns", "torque_nm=T_meas", "--method", "exact",
                  "--out", out)
    assert r.exit_code == 0, r.output
    js = json.loads((out / "identification.json").read_text())
    assert js["parameters"] == ["kL", "alpha", "c"] and js["truth"] is None
    opt = js["least_squares_optimum"]["params"]
    # noise-free contact data fitted with the contact form: exact to rounding (c ~ 0.7733)
    np.testing.assert_allclose([opt["kL"], opt["alpha"]], [590.0, 0.003], rtol=1e-9)
    assert opt["c"] == pytest.approx(0.7732780510796391, rel=1e-7)


def _bad(tmp_path, csv_dir, edit):
    df = pd.read_csv(csv_dir / "good.csv")
    df = edit(df)
    path = tmp_path / "bad.csv"
    df.to_csv(path, index=False)
    return path


def _set_value(col, row, value):
    def edit(df):
        df[col] = df[col].astype(float)
        df.loc[row, col] = value
        return df
    return edit


@pytest.mark.parametrize("edit, message", [
    (lambda df: df.drop(columns=["domega_rad_s"]), "lacks column(s) domega_rad_s"),
    (_set_value("torque_nm", 7, np.nan), "'torque_nm' has 1 empty, non-numeric, NaN or inf"),
    (_set_value("dtheta_rad", 3, np.inf), "'dtheta_rad' has 1 empty, non-numeric, NaN or inf"),
    (lambda df: df.head(5), "has 5 data rows; at least 20 are needed"),
    (_set_value("t_s", 10, 0.0), "must be strictly increasing"),
    (lambda df: df.assign(domega_rad_s=0.0), "the data do not determine kL, alpha, c"),
])
def test_bad_data_files_fail_clearly(tmp_path, csv_dir, edit, message):
    path = _bad(tmp_path, csv_dir, edit)
    r, text = invoke("--data", path, "--method", "exact", "--out", tmp_path / "o")
    assert r.exit_code == 2, r.output
    assert message in text
    assert "Traceback" not in r.output
    assert not (tmp_path / "o").exists()


def test_missing_and_unreadable_files(tmp_path):
    r, text = invoke("--data", tmp_path / "nope.csv")
    assert r.exit_code == 2 and "data file" in text and "does not exist" in text
    empty = tmp_path / "empty.csv"
    empty.write_text("")
    r, text = invoke("--data", empty)
    assert r.exit_code == 2 and "is not a readable CSV" in text
    assert "Traceback" not in r.output


def test_dead_band_outside_the_search_range(tmp_path, csv_dir):
    # data generated with alpha = 6 mrad, searched over the paper's 2..4 mrad
    r, text = invoke("--data", csv_dir / "wide_gap.csv", "--method", "exact")
    assert r.exit_code == 2, r.output
    assert "dead band lies outside the alpha search range" in text
    assert "widen --alpha-range" in text and "Traceback" not in r.output
    # widening the range identifies it (exactly: noise-free, matched)
    out = tmp_path / "run"
    r, _ = invoke("--data", csv_dir / "wide_gap.csv", "--method", "exact",
                  "--alpha-range", 0.002, 0.008, "--out", out)
    assert r.exit_code == 0, r.output
    opt = json.loads((out / "identification.json").read_text())["least_squares_optimum"]
    assert opt["params"]["alpha"] == pytest.approx(0.006, rel=1e-9)


def test_data_that_never_reach_contact(csv_dir):
    r, text = invoke("--data", csv_dir / "good.csv", "--alpha-range", 0.02, 0.03)
    assert r.exit_code == 2
    assert "do not reach gear contact" in text and "Traceback" not in r.output


@pytest.mark.parametrize("args, message", [
    (["--columns", "torque=T"], "unknown column 'torque'"),
    (["--columns", "torque_nm"], "--columns expects NAME=VALUE"),
    (["--k-range", 700, 500], "k_range needs LO < HI"),
    (["--method", "simplex"], "method"),
    (["--model", "coulomb"], "model"),
    (["--pc", 1.5], "--pc"),
    (["--set", "ga.pc=1.5"], "ga.pc"),
    (["--noise", -1], "--noise"),
    (["--set", "synthetic.noise_pct=-1"], "noise_pct"),
])
def test_bad_options_fail_clearly(args, message):
    r, text = invoke(*args)
    assert r.exit_code == 2, r.output
    assert message in text and "Traceback" not in r.output


def test_noise_with_data_is_refused_and_out_must_be_empty(tmp_path, csv_dir):
    r, text = invoke("--data", csv_dir / "good.csv", "--noise", 1)
    assert r.exit_code == 2 and "describe synthetic data" in text
    out = tmp_path / "full"
    out.mkdir()
    (out / "x.txt").write_text("keep me")
    r, text = invoke("--method", "exact", "--out", out)
    assert r.exit_code == 2 and "never overwritten" in text


def test_optimum_outside_the_k_range_warns(tmp_path):
    r, text = invoke("--method", "exact", "--k-range", 600, 700, "--out", tmp_path / "o")
    assert r.exit_code == 0, r.output
    assert "least-squares kL = 590 N*m/rad lies outside the search range [600, 700]" in text
    js = json.loads((tmp_path / "o" / "identification.json").read_text())
    assert len(js["warnings"]) == 1
