"""`ema identify plant`: bad inputs refused in one line before any simulation runs, naming the
option, file, channel or key and what was expected (the EMPS record, another description)."""

from __future__ import annotations

import pytest
from typer.testing import CliRunner

from ema_cli.cli.main import app
from tests.helpers.plant_records import ACTUATOR, EMPS

PAPER = ACTUATOR.parent / "paper_ema.yaml"


@pytest.mark.parametrize("extra,match", [
    (["--actuator", "nope.yaml"], "the actuator description 'nope.yaml' does not exist"),
    (["--actuator", str(PAPER)], "transmission.type must be rigid"),
    (["--set", "actuator.controller.velocity.kv=200"],
     "the described controller does not match the logged command: RMS mismatch"),
    (["--delay", "1"], "matches the logged command with a delay of 0 sample(s)"),
    (["--window", "1,1.3"], "shorter than the axis' mechanical time constant M/Fv"),
    (["--window", "1,99"], "expected a window inside it"),
    (["--law", "quadratic"], "law"),
    (["--columns", "position=qm:parsec"], "unknown unit 'parsec'"),
    (["--columns", "actuation=nothing"], "has no variable 'nothing'"),
    (["--split", "1.5"], "split"),
])
def test_bad_input_is_one_line(tmp_path, extra, match):
    args = ["identify", "plant", str(EMPS), "--out", str(tmp_path / "o")]
    if "--actuator" not in extra:
        args += ["--actuator", str(ACTUATOR)]
    r = CliRunner().invoke(app, args + extra)
    assert r.exit_code == 2, r.output
    msg = r.output.strip().replace("\n", " ")
    assert match in msg, msg
    assert "Traceback" not in r.output
    assert not (tmp_path / "o").exists()
