"""Bad config and experiment files through the CLI: exit code 2, one line naming the file and
key, never a traceback (the classes are tested in tests/unit/test_bad_config.py)."""

from __future__ import annotations

import time

import pytest
from typer.testing import CliRunner

from ema_cli.cli.main import app

runner = CliRunner()


def _fails_cleanly(args: list[str], *needles: str) -> str:
    r = runner.invoke(app, args)
    assert r.exit_code == 2, r.output
    assert "Traceback" not in r.output, r.output
    assert r.exception is None or isinstance(r.exception, SystemExit), repr(r.exception)
    lines = [ln for ln in r.output.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("error: "), r.output
    for needle in needles:
        assert needle in r.output, r.output
    return r.output


def _bomb() -> str:
    lines = ['a0: &a0 "lol"']
    lines += [f"a{i}: &a{i} [{', '.join([f'*a{i - 1}'] * 9)}]" for i in range(1, 10)]
    return "\n".join(lines) + "\n"


@pytest.mark.parametrize(("text", "needles"), [
    (_bomb(), ["bomb"]),
    ("name: a\nname: b\n", ["duplicate key 'name'", "line 2"]),
    ("a: " + "[" * 3000 + "]" * 3000 + "\n", ["nesting deeper than"]),
    ("name: ../escape\n", ["name: must be a plain name"]),
    ("input: {amplitude_deg: .nan}\n", ["input.amplitude_deg", "finite"]),
    ("sweep: {max_jobs: 1000000000}\n", ["sweep.max_jobs", "1000000"]),
    ("nonlinearities: {deadzone2: 0.01, deadzone@transmission: 0.1}\n",
     ["nonlinearities", "'deadzone2' and 'deadzone@transmission'"]),
])
def test_validate_refuses_bad_files(tmp_path, text, needles):
    p = tmp_path / "c.yaml"
    p.write_text(text, encoding="utf-8")
    t0 = time.perf_counter()
    _fails_cleanly(["validate", str(p)], str(p.name), *needles)
    assert time.perf_counter() - t0 < 5.0


def test_validate_refuses_binary_file(tmp_path):
    p = tmp_path / "c.yaml"
    p.write_bytes(b"\x00\x01\x02binary")
    _fails_cleanly(["validate", str(p)], "binary")


def test_reproduce_refuses_bad_experiment(tmp_path):
    (tmp_path / "s.yaml").write_text("name: s\n")
    exp = tmp_path / "exp.yaml"
    exp.write_text("name: e\nstudies:\n  - {id: s, config: s.yaml, figure: s.png, caption: c}\n"
                   "  - {id: s, config: s.yaml, figure: t.png, caption: c}\n")
    _fails_cleanly(["reproduce", str(exp)], "study id 's' is given twice")
    exp.write_text("name: e\nstudies:\n  - {id: ../s, config: s.yaml, figure: s.png, "
                   "caption: c}\n")
    _fails_cleanly(["reproduce", str(exp)], "studies.0.id: must be a plain name")


def test_simulate_same_placement_twice_is_refused(tmp_path):
    _fails_cleanly(["simulate", "--nl", "deadzone2=0.01", "--nl", "deadzone@transmission=0.1",
                    "--out", str(tmp_path / "x")], "'deadzone2' and 'deadzone@transmission'")
