"""The forked figure worker of `ema simulate` draws exactly the in-process figure, reports a
failure as an EmaError, and leaves nothing when cancelled. Run in fresh interpreters (a fork is
only taken where it is safe: no threads, numba not loaded)."""

from __future__ import annotations

import subprocess
import sys
import textwrap

import pytest

SCRIPT = textwrap.dedent("""
    import sys
    from pathlib import Path
    import numpy as np
    from ema_cli.report import figure_worker
    out = Path(sys.argv[1])
    w = figure_worker.start()
    assert w is not None, "no worker in a fresh process"
    t = np.linspace(0, 1, 501)
    table = {"t_s": t, "theta_ref_deg": np.ones_like(t), "theta_load_deg": 1 - np.exp(-9 * t),
             "theta_motor_deg": 1 - np.exp(-8 * t), "omega_ref_deg_s": 0 * t,
             "omega_load_deg_s": 9 * np.exp(-9 * t), "err_pos_deg": np.exp(-9 * t),
             "err_vel_deg_s": -9 * np.exp(-9 * t)}
    mode = sys.argv[2]
    if mode == "draw":
        w.submit(out / "child.png", table, "a title")
        seconds = w.wait()
        assert seconds > 0
        from ema_cli.report.figures import tracking_figure
        from ema_cli.report.rundir import write_figure
        write_figure(out / "parent.png", tracking_figure(table, "a title"))
    elif mode == "fail":
        del table["err_vel_deg_s"]
        w.submit(out / "child.png", table, "a title")
        from ema_cli.errors import EmaError
        try:
            w.wait()
        except EmaError as exc:
            print(exc.message)
    else:
        w.cancel()
    print("done")
""")


def run(tmp_path, mode: str) -> str:
    r = subprocess.run([sys.executable, "-c", SCRIPT, str(tmp_path), mode], capture_output=True,
                       text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    return r.stdout


def test_the_child_draws_the_same_png(tmp_path):
    assert "done" in run(tmp_path, "draw")
    assert (tmp_path / "child.png").read_bytes() == (tmp_path / "parent.png").read_bytes()


def test_a_failure_in_the_child_is_one_line(tmp_path):
    out = run(tmp_path, "fail")
    assert "the figure could not be drawn: KeyError: 'err_vel_deg_s'" in out
    assert not any(tmp_path.iterdir())  # no partial PNG, no temporary file


def test_cancel_leaves_nothing(tmp_path):
    assert "done" in run(tmp_path, "cancel")
    assert not any(tmp_path.iterdir())


@pytest.mark.parametrize("env", [{"EMA_NO_FORK": "1"}])
def test_no_fork_when_asked(monkeypatch, env):
    from ema_cli.report import figure_worker

    for k, v in env.items():
        monkeypatch.setenv(k, v)
    assert figure_worker.start() is None
