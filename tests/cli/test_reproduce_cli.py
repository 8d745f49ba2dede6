"""`ema reproduce` end to end on a tiny batch: passing and failing claims, bad input."""

from __future__ import annotations

import numpy as np
import pandas as pd
from typer.testing import CliRunner

from ema_cli.cli.main import app

runner = CliRunner()

STUDY = """name: tiny
input: {kind: step, amplitude_deg: 0.1}
simulation: {duration_s: 0.2}
sweep:
  axes:
    - nonlinearity: deadzone2
      values: [0.001, 0.1]
"""

EXPERIMENT = """name: tinybatch
studies:
  - id: figA
    config: tiny.yaml
    figure: figA.png
    caption: "Figure A: dead band"
thresholds:
  - id: band
    config: tiny.yaml
    vary: deadzone2
    range: [1.0e-4, 0.1]
    require: ["p2p_err_pos_deg<=0.002"]
    rtol: 0.05
    percent_of_input: true
    paper_value: 2.0
claims:
  - id: osc
    paper: p
    statement: oscillation at 0.1 deg
    check: {kind: value, study: figA, where: {deadzone2_deg: 0.1}, metric: p2p_err_pos_deg,
            op: ">", value: LIMIT}
  - id: band_small
    paper: p
    statement: threshold below 2 %
    check: {kind: scalar, name: band, op: "<", value: 2.0}
"""


def _write(tmp_path, limit: float, threshold: bool = True):
    (tmp_path / "tiny.yaml").write_text(STUDY)
    exp = tmp_path / "exp.yaml"
    text = EXPERIMENT.replace("LIMIT", str(limit))
    if not threshold:  # the study and its claim only (the threshold search is the costly part)
        head, rest = text.split("thresholds:\n", 1)
        claims = "claims:" + rest.split("claims:", 1)[1]
        text = head + claims.split("  - id: band_small")[0]
    exp.write_text(text)
    return exp


def test_reproduce_passes_and_writes_report(tmp_path):
    out = tmp_path / "out"
    r = runner.invoke(app, ["reproduce", str(_write(tmp_path, 0.002)), "--out", str(out),
                            "--n-jobs", "1"])
    assert r.exit_code == 0, r.output
    claims = pd.read_csv(out / "claims.csv")
    assert claims["result"].tolist() == ["PASS", "PASS"]
    report = (out / "REPORT.md").read_text()
    assert "**2 of 2 claims PASS**" in report and "![figA](figA.png)" in report
    assert (out / "figA.png").stat().st_size > 10_000
    assert (out / "threshold_band.png").is_file()
    thr = pd.read_csv(out / "thresholds.csv")
    assert 0 < thr["value"][0] < 2.0  # % of the 0.1 deg input


def test_reproduce_exits_1_when_a_claim_fails(tmp_path):
    # the failing claim is the study's: the threshold (tested above) is left out
    out = tmp_path / "out"
    r = runner.invoke(app, ["reproduce", str(_write(tmp_path, 1e6, threshold=False)), "--out",
                            str(out), "--n-jobs", "1"])
    assert r.exit_code == 1
    claims = pd.read_csv(out / "claims.csv")
    assert claims.set_index("id")["result"]["osc"] == "FAIL"
    assert "FAIL" in (out / "REPORT.md").read_text()


def test_reproduce_bad_experiment_is_clear(tmp_path):
    exp = tmp_path / "exp.yaml"
    exp.write_text("name: x\nstudies:\n  - id: a\n    config: missing.yaml\n    figure: a.png\n"
                   "    caption: c\n")
    r = runner.invoke(app, ["reproduce", str(exp)])
    assert r.exit_code == 2 and "missing.yaml" in r.output and "does not exist" in r.output
    exp.write_text("name: x\nstudies: []\nbogus: 1\n")
    r = runner.invoke(app, ["reproduce", str(exp)])
    assert r.exit_code == 2 and "bogus: unknown key" in r.output
    assert "Traceback" not in r.output


SENS = """name: tinysens
inputs: [{name: s5, kind: step, amplitude_deg: 5.0}]
simulation: {duration_s: 0.1, output_interval_s: null}
factors:
  - {nonlinearity: deadzone2, range: [0.001, 0.1], scale: log}
  - {nonlinearity: gap1, range: [0.05, 10.0], scale: log}
  - {name: dummy, parameter: T_load, range: [0.0, 1.0e-9]}
metrics: [iae_pos_deg_s]
sensitivity: {num_resamples: 50, transform: log10}
parallel: {n_jobs: 1}
"""

SENS_EXPERIMENT = """name: sensbatch
studies:
  - id: figA
    config: tiny.yaml
    figure: figA.png
    caption: "Figure A: dead band"
ranking:
  metric: iae_pos_deg_s
  studies: [figA]
  paper_first: figA
sensitivity:
  config: sens.yaml
  n: 16
  input: s5
  metric: iae_pos_deg_s
  paper: the dead band is worst
  paper_first: PAPER_FIRST
  studies: {figA: deadzone2}
claims:
  - id: stiff_first
    paper: p
    statement: the stiffness ranks first by Sobol ST
    check: {kind: scalar, name: sensitivity.rank.gap1, op: "<=", value: 1}
  - id: dummy_last
    paper: p
    statement: the dummy has ST below 0.02
    check: {kind: scalar, name: sensitivity.rank.dummy, op: ">=", value: 3}
"""


def test_reproduce_ranks_by_global_sensitivity(tmp_path):
    (tmp_path / "tiny.yaml").write_text(STUDY)
    (tmp_path / "sens.yaml").write_text(SENS)
    exp = tmp_path / "exp.yaml"
    exp.write_text(SENS_EXPERIMENT.replace("PAPER_FIRST", "deadzone2"))
    out = tmp_path / "out"
    r = runner.invoke(app, ["reproduce", str(exp), "--out", str(out), "--n-jobs", "1"])
    assert r.exit_code == 0, r.output
    claims = pd.read_csv(out / "claims.csv")
    assert claims["result"].tolist() == ["PASS", "PASS"], claims
    ranking = pd.read_csv(out / "sensitivity_ranking.csv")
    mine = ranking[ranking["input"] == "s5"]
    assert mine["factor"].tolist()[0] == "gap1"
    assert mine.set_index("factor")["oat_rank"]["deadzone2"] == 1  # the only OAT study
    indices = pd.read_csv(out / "sensitivity" / "indices.csv").set_index("factor")
    assert indices.loc["dummy", "ST"] < 0.02
    # the ranking table is the folder's indices, sorted by ST
    np.testing.assert_allclose(mine["ST"], sorted(indices["ST"], reverse=True), rtol=1e-5,
                               atol=1e-12)
    report = (out / "REPORT.md").read_text()
    assert "Ranking of the nonlinearities by global sensitivity" in report
    assert "the paper names **deadzone2** — our model differs" in report


def test_reproduce_refuses_an_unknown_sensitivity_factor(tmp_path):
    (tmp_path / "tiny.yaml").write_text(STUDY)
    (tmp_path / "sens.yaml").write_text(SENS)
    exp = tmp_path / "exp.yaml"
    exp.write_text(SENS_EXPERIMENT.replace("PAPER_FIRST", "friction1"))
    r = runner.invoke(app, ["reproduce", str(exp), "--out", str(tmp_path / "o")])
    assert r.exit_code == 2
    assert "sensitivity.paper_first: 'friction1' is not a factor of sens.yaml" in r.output
    assert not (tmp_path / "o").exists()
