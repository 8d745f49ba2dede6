"""Issue 22, messages that point at the cause: out of memory names the log file and its length;
an infeasible tune names the worst constraint with its value and limit; ``ema validate`` reads
the files a config refers to; an input that does nothing within the run warns."""

from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace
from unittest import mock

import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

from ema_cli.api import identify_closed_loop, simulate
from ema_cli.api.tune_messages import infeasible_message, relative_violation
from ema_cli.cli.main import app
from ema_cli.errors import EmaError

ROOT = Path(__file__).resolve().parents[2]
LOG = str(ROOT / "experiments" / "logs" / "design_hc_1pct.csv")
runner = CliRunner()


def _oom(*_, **__):
    raise MemoryError


def test_out_of_memory_in_a_fit_names_the_log_and_its_length():
    with mock.patch("ema_cli.identify.closed_loop.ga_fit.run_closed_loop", _oom), \
            pytest.raises(EmaError) as exc:
        identify_closed_loop(data=LOG)
    text = str(exc.value)
    assert "design_hc_1pct.csv" in text and "-row, 2 s log" in text and "window" in text
    with mock.patch("ema_cli.identify.closed_loop.ga_fit.run_closed_loop", _oom):
        r = runner.invoke(app, ["identify", "--closed-loop", "--data", LOG])
    assert r.exit_code == 2 and "--window" in r.output and "Traceback" not in r.output


def _fake_tune(rows: list[dict]) -> SimpleNamespace:
    df = pd.DataFrame(rows)
    outcome = SimpleNamespace(after=SimpleNamespace(diverged=np.zeros(1, bool)),
                              timings={"evaluations": 24})
    return SimpleNamespace(constraints_frame=lambda: df, outcome=outcome)


def test_an_infeasible_tune_names_the_worst_constraint_not_the_first():
    rows = [  # table order: overshoot first, 1 % over its limit; settling 100 x over
        {"scenario": "a", "constraint": "overshoot", "min": None, "max": 10.0, "unit": "%",
         "after": 10.1, "met": False},
        {"scenario": "b", "constraint": "settling_time", "min": None, "max": 1.0, "unit": "ms",
         "after": 101.0, "met": False},
        {"scenario": "b", "constraint": "gain_margin", "min": 6.0, "max": None, "unit": "dB",
         "after": 9.0, "met": True}]
    res = _fake_tune(rows)
    # relative violations by hand: 0.1/10 = 0.01, 100/1 = 100
    assert list(relative_violation(res.constraints_frame())) == pytest.approx([0.01, 100, 0])
    text = infeasible_message(res)
    assert "scenarios.b settling_time 101 ms (limit <= 1 ms)" in text
    rows[0]["after"] = float("nan")  # not measured: the worst of all
    assert "scenarios.a overshoot nan %" in infeasible_message(_fake_tune(rows))


def test_validate_reads_the_input_profile_it_names(tmp_path):
    cfg = tmp_path / "run.yaml"
    cfg.write_text("input: {kind: csv, path: missing.csv}\n")
    r = runner.invoke(app, ["validate", str(cfg)])
    assert r.exit_code == 2 and "missing.csv" in r.output, r.output
    (tmp_path / "act.yaml").write_text("input: {kind: csv, path: gone.csv}\n")
    spec = tmp_path / "spec.yaml"
    spec.write_text("name: s\nactuator: {config: act.yaml}\ntests:\n  m: {test: margins, "
                    "limits: {gain_margin: {min: 6, unit: dB}}}\n")
    r = runner.invoke(app, ["validate", str(spec)])
    assert r.exit_code == 2 and "actuator.config" in r.output and "gone.csv" in r.output


def test_a_reference_or_profile_after_the_end_of_the_run_is_refused(tmp_path):
    # a reference starting after the end is refused by the run schema itself
    with pytest.raises(EmaError, match=r"input\.start_s \(2 s\) must be before the end"):
        simulate(None, {"input.start_s": 2.0, "simulation.duration_s": 0.01})
    prof = tmp_path / "late.csv"
    prof.write_text("t_s,theta_ref_deg\n5,0\n6,1\n")
    cfg = tmp_path / "run.yaml"
    cfg.write_text("input: {kind: csv, path: late.csv}\nsimulation: {duration_s: 0.01}\n")
    # a run whose profile starts after its end answers nothing: refused (issue 39); `validate`
    # warns (the file may be meant for a longer run)
    with pytest.raises(EmaError, match=r"input\.path: the profile .* starts at 5 s"):
        simulate(str(cfg))
    r = runner.invoke(app, ["validate", str(cfg)])
    assert r.exit_code == 0 and "warning: input.path" in " ".join(r.output.split())
