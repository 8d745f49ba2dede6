"""`ema threshold` through typer's CliRunner."""

from __future__ import annotations

import json

from typer.testing import CliRunner

from ema_cli.cli.main import app

runner = CliRunner()


def test_threshold_cli_writes_result_and_plot(tmp_path):
    cfg = tmp_path / "dz.yaml"
    cfg.write_text("name: dz\ninput: {kind: step, amplitude_deg: 0.1}\n"
                   "simulation: {duration_s: 0.3}\n")
    out = tmp_path / "out"
    r = runner.invoke(app, ["threshold", str(cfg), "--vary", "deadzone2", "--range", "1e-5", "0.1",
                            "--metric", "p2p_err_pos_deg", "--limit", "0.002", "--rtol", "0.05",
                            "--out", str(out)])
    assert r.exit_code == 0, r.output
    res = json.loads((out / "threshold.json").read_text())
    assert res["status"] == "found" and res["relative_width"] <= 0.05
    lo, hi = res["bracket"]
    assert 1e-5 < lo < hi < 0.1
    assert res["threshold_percent_of_input"] == 100 * res["threshold"] / 0.1
    assert (out / "threshold.png").stat().st_size > 10_000


def test_threshold_cli_bad_input(tmp_path):
    cfg = tmp_path / "dz.yaml"
    cfg.write_text("name: dz\n")
    for args, needle in ((["--vary", "deadzone9", "--range", "1", "2", "--require", "t50_s<=1"],
                          "unknown nonlinearity 'deadzone9'"),
                         (["--vary", "deadzone2", "--range", "1", "2", "--require", "t50<=1"],
                          "unknown metric 't50'"),
                         (["--vary", "deadzone2", "--range", "2", "1", "--require", "t50_s<=1"],
                          "LO < HI"),
                         (["--vary", "deadzone2", "--range", "1", "2"], "one requirement")):
        r = runner.invoke(app, ["threshold", str(cfg), *args])
        assert r.exit_code != 0 and needle in r.output, (args, r.output)
        assert "Traceback" not in r.output


def test_the_cli_rtol_default_is_the_library_default():
    # cli/threshold.py keeps its own copy so that `ema --help` imports no numpy
    from ema_cli.cli.threshold import DEFAULT_RTOL as cli_default
    from ema_cli.config.criteria import DEFAULT_RTOL

    assert cli_default == DEFAULT_RTOL
