"""`ema duty`: the files, the verdict and its exit code, the trace against the report, bad
profiles in one line."""

from __future__ import annotations

import json
from pathlib import Path

import pandas as pd
import pytest
from typer.testing import CliRunner

from ema_cli.cli.main import app

ROOT = Path(__file__).resolve().parents[2]
PROFILE = str(ROOT / "configs" / "duty" / "hold_and_move.yaml")
SHORT = ["--set", "segments.0.repeat.segments.1.dwell.duration_s=0.2", "--set",
         "segments.0.repeat.segments.3.dwell.duration_s=0.2"]
"""The bundled profile with 0.2 s dwells (a 1.4 s cycle: the mechanics in about a second)."""
runner = CliRunner()


def test_a_profile_writes_everything_and_passes(tmp_path):
    out = tmp_path / "duty"
    r = runner.invoke(app, ["duty", PROFILE, *SHORT, "--no-hot", "--out", str(out)])
    assert r.exit_code == 0, r.output
    for name in ("duty.json", "duty.md", "temperature.png", "envelope.png", "trace.parquet",
                 "manifest.json", "profile.resolved.yaml"):
        assert (out / name).is_file(), name
    assert "PASS" in r.output and "peak winding / housing" in r.output
    d = json.loads((out / "duty.json").read_text())
    assert d["verdict"] == "PASS" and d["exit_code"] == 0
    # 300 x (move 24 deg out at 60 deg/s, 600 deg/s^2: d/v + v/a = 0.5 s; 0.2 s hold; the
    # move back; 0.2 s rest) + 200 cycles at 2 Hz = 300 * 1.4 + 100 = 520 s
    assert d["duration_s"] == pytest.approx(300 * (0.5 + 0.2 + 0.5 + 0.2) + 100, rel=1e-12)
    # the trace is the report's: its peak is the reported one, it starts at ambient
    tr = pd.read_parquet(out / "trace.parquet")
    assert tr.winding_peak_c.max() == pytest.approx(d["peak_winding_c"], abs=1e-9)
    assert tr.winding_c.iloc[0] == pytest.approx(40.0, abs=0.5)
    assert tr.t_s.iloc[-1] == pytest.approx(d["duration_s"], rel=1e-9)
    # holding 6 N*m on a 24:1 ratio with Kt 0.08 N*m/A is 3.125 A; the moves' acceleration
    # (600 deg/s^2 on the inertia) adds a little, the dither at the end (100 s) takes little
    rms = next(m for m in d["metrics"] if m["metric"] == "rms_current")
    assert 2.6 < rms["value_si"] < 3.3
    man = json.loads((out / "manifest.json").read_text())
    assert man["command"] == "duty" and man["verdict"] == "PASS"


def test_a_failing_limit_exits_1(tmp_path):
    r = runner.invoke(app, ["duty", PROFILE, *SHORT, "--no-hot", "--set",
                            "limits.winding_temperature.max=50", "--out",
                            str(tmp_path / "d")])
    assert r.exit_code == 1, r.output
    assert "FAIL" in r.output and "winding_temperature" in r.output


BAD = {
    "negative cycles": ("- sine: {amplitude: 0.1, frequency_hz: 1, cycles: -5}",
                        ["segments.0.sine.cycles", ">= 1"]),
    "unknown kind": ("- ramp: {to: 0.5}", ["segments.0", "unknown segment kind 'ramp'"]),
    "too fast a sine": ("- sine: {amplitude: 0.1, frequency_hz: 2000, cycles: 10}",
                        ["segments.0.sine.frequency_hz", "steps"]),
    "unknown key": ("- dwell: {duration_s: 5, speed: 3}", ["segments.0.dwell.speed",
                                                            "unknown key"]),
}


@pytest.mark.parametrize("case", sorted(BAD))
def test_bad_profiles_get_one_line(tmp_path, case):
    seg, needles = BAD[case]
    f = tmp_path / "p.yaml"
    f.write_text(f"name: bad\nstroke: 30 deg\nsegments:\n  {seg}\n")
    out = tmp_path / "out"
    r = runner.invoke(app, ["duty", str(f), "--no-hot", "--out", str(out)],
                      catch_exceptions=False)
    assert r.exit_code == 2, r.output
    lines = [ln for ln in r.output.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("error:"), r.output
    for n in needles:
        assert n in lines[0], r.output
    assert not out.exists()
