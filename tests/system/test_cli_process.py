"""`ema` as a real process: the start-up path (forked figure worker, fast exit) writes the same
outputs and keeps exit codes and messages."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

EMA = Path(sys.executable).with_name("ema")


def ema(*args: str, cwd: Path) -> subprocess.CompletedProcess:
    return subprocess.run([str(EMA), *args], capture_output=True, text=True, cwd=cwd,
                          timeout=300)


def test_simulate_in_a_process_writes_everything(tmp_path):
    r = ema("simulate", "--duration", "0.2", "--nl", "deadzone2=0.01", "--out", "run",
            cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    out = tmp_path / "run"
    names = {p.name for p in out.iterdir()}
    assert {"timeseries.csv", "metrics.csv", "tracking.png", "manifest.json",
            "config.resolved.yaml"} <= names
    assert not [n for n in names if n.endswith(".tmp")]
    assert (out / "tracking.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    t = json.loads((out / "manifest.json").read_text())["timings_s"]
    assert t["figure"] > 0 and t["simulation"] > 0
    assert [p.name for p in tmp_path.iterdir()] == ["run"]


def test_exit_codes_and_messages_survive_the_fast_exit(tmp_path):
    (tmp_path / "taken").mkdir()
    (tmp_path / "taken" / "x").write_text("mine")
    r = ema("simulate", "--out", "taken", cwd=tmp_path)
    assert r.returncode == 2
    assert r.stderr.strip().startswith("error: --out") and "Traceback" not in r.stderr
    r = ema("validate", "nope.yaml", cwd=tmp_path)
    assert r.returncode == 2 and "nope.yaml" in r.stderr
    r = ema("--help", cwd=tmp_path)
    assert r.returncode == 0 and "simulate" in r.stdout


def test_usage_errors_are_one_line(tmp_path):
    for args, needle in ((["simulate", "--duration", "abc"], "--duration"),
                         (["simulate", "--bogus"], "No such option: --bogus"),
                         (["bogus"], "No such command"),
                         (["threshold", "x.yaml", "--vary", "deadzone2", "--range", "1"],
                          "--range")):
        r = ema(*args, cwd=tmp_path)
        lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
        assert r.returncode == 2 and len(lines) == 1, r.stderr
        assert lines[0].startswith("error:") and needle in lines[0]
    r = ema(cwd=tmp_path)
    assert r.returncode == 0 and "Commands" in r.stdout


def test_a_pipe_gets_80_columns_and_the_default_folder_layout(tmp_path):
    """In a pipe (no terminal, no COLUMNS) every table fits 80 columns; the default folder is
    results/<command>/<config-name>/<stamp>_<hash> with a `latest` link beside it."""
    import os

    env = {k: v for k, v in os.environ.items() if k not in ("COLUMNS", "LINES")}
    for args in (("locations",), ("params",), ("margins",)):
        r = subprocess.run([str(EMA), *args], capture_output=True, text=True, cwd=tmp_path,
                           timeout=300, env=env)
        assert r.returncode == 0, r.stderr
        lines = r.stdout.splitlines()
        assert lines and max(len(x) for x in lines) <= 80, args
        assert "…" not in r.stdout
    runs = tmp_path / "results" / "margins" / "default"
    (run,) = (p for p in runs.iterdir() if p.name != "latest")
    assert (runs / "latest").is_symlink() and os.readlink(runs / "latest") == run.name
    assert (runs / "latest" / "margins.json").is_file()
