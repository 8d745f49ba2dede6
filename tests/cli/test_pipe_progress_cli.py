"""Progress in a pipe (issue 39, item 4): every long command, run with its output going to a
pipe (the CLI runner's streams are not terminals) on a clock where every stage is long (each
reading of ``cli.progress``'s clock advances 3 s, so every stage passes ``LONG_S`` at once and
may print its tenths), prints each stage's first line and at most one line per tenth of it:
at most 11 lines per stage, whatever the number of generations, units, starts or cases.

The runs are the small ones of the interruption harness (tests/helpers/tiny_runs.py);
tune runs in the fast tier, the others in the slow tier."""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml
from typer.testing import CliRunner

import ema_cli.cli.progress as cli_progress
from ema_cli.cli.main import app
from ema_cli.cli.progress import stage_key
from tests.helpers.tiny_runs import (
    CLOSED_LOOP,
    DESIGN,
    DESIGN_SPEC,
    EXPERIMENT,
    SENSITIVITY,
    SPEC,
    STUDY,
    TOLERANCES,
    TUNE,
)

ROOT = Path(__file__).resolve().parents[2]
runner = CliRunner()


class FakeClock:
    """``time`` for cli.progress: every reading is 3 s after the one before."""

    def __init__(self) -> None:
        self.now = 0.0

    def perf_counter(self) -> float:
        self.now += 3.0
        return self.now

    monotonic = perf_counter
    time = perf_counter


def _write(work: Path, name: str, doc: object) -> None:
    (work / name).write_text(doc if isinstance(doc, str) else yaml.safe_dump(doc))


def _log(work: Path) -> None:
    r = runner.invoke(app, ["identify", "make-data", "closed-loop", "--set", "duration_s=0.6",
                            "--noise", "0.5", "--out", str(work / "mk")])
    assert r.exit_code == 0, r.output


def _setup(work: Path, name: str) -> None:
    docs = {"tune": {"tune.yaml": TUNE}, "sweep": {"study.yaml": STUDY},
            "sensitivity": {"sens.yaml": SENSITIVITY},
            "yield": {"spec.yaml": SPEC, "tol.yaml": TOLERANCES},
            "threshold": {"study.yaml": {**STUDY, "sweep": {"axes": []}}},
            "design": {"tune.yaml": TUNE, "design.yaml": DESIGN, "spec.yaml": DESIGN_SPEC},
            "reproduce": {"exp.yaml": EXPERIMENT,
                          "a.yaml": {**STUDY, "name": "a", "sweep": {"axes": [
                              {"nonlinearity": "deadzone2", "values": [0.001]}]}},
                          "b.yaml": {**STUDY, "name": "b", "sweep": {"axes": [
                              {"nonlinearity": "deadzone2", "values": [0.01, 0.1]}]}}}}
    for file, doc in docs.get(name, {}).items():
        _write(work, file, doc)
    if name in ("identify-closed-loop", "design"):
        _log(work)


COMMANDS = {
    "tune": ["tune", "tune.yaml"],
    "sweep": ["sweep", "study.yaml"],
    "sensitivity": ["sensitivity", "sens.yaml"],
    "yield": ["yield", "spec.yaml", "--tolerances", "tol.yaml", "--n", "8", "--block", "2",
              "--worst-budget", "4"],
    "acceptance": ["acceptance", str(ROOT / "configs" / "acceptance.yaml"), "--only",
                   "step-small", "--only", "margins"],
    "threshold": ["threshold", "study.yaml", "--vary", "deadzone2", "--range", "0.001", "0.1",
                  "--metric", "p2p_err_pos_deg", "--limit", "0.002"],
    "duty": ["duty", str(ROOT / "configs" / "duty" / "hold_and_move.yaml")],
    "identify-closed-loop": ["identify", "closed-loop", "--data", "mk/closed_loop.csv",
                             *CLOSED_LOOP],
    "identify-torque": ["identify", "torque", "--pop", "20", "--generations", "30", "--runs",
                        "2"],
    "identify-plant": ["identify", "plant",
                       str(ROOT / "experiments" / "data" / "emps" / "DATA_EMPS.mat"),
                       "--actuator", str(ROOT / "configs" / "actuators" / "emps.yaml")],
    "design": ["design", "mk/closed_loop.csv", "design.yaml", "--tune-config", "tune.yaml",
               "--spec", "spec.yaml", "--budget", "21"],
    "reproduce": ["reproduce", "exp.yaml", "--n-jobs", "1"],
}
FAST = {"tune"}


@pytest.mark.parametrize("name", [n if n in FAST else pytest.param(n, marks=pytest.mark.slow)
                                  for n in COMMANDS])
def test_a_pipe_gets_at_most_one_progress_line_per_tenth_of_each_stage(tmp_path, monkeypatch,
                                                                        name):
    monkeypatch.chdir(tmp_path)
    _setup(tmp_path, name)
    monkeypatch.setattr(cli_progress, "time", FakeClock())
    r = runner.invoke(app, [*COMMANDS[name], "--out", str(tmp_path / "out")])
    assert r.exit_code in (0, 1, 3), r.output
    prefixes = tuple(f"{word}: " for word in COMMANDS[name][:2])  # ema identify plant: plant
    per_stage: dict[str, int] = {}
    for line in r.output.splitlines():
        if line.startswith(prefixes) and (line.endswith(" ...") or line.endswith("%)")):
            key = stage_key(line.split(": ", 1)[1].removesuffix(" ...").split(" (")[0])
            per_stage[key] = per_stage.get(key, 0) + 1
    assert per_stage, r.output  # the command reported its stages
    assert max(per_stage.values()) <= 11, per_stage

