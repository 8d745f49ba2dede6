"""Every command that may take more than 10 s prints its estimate first (issue 39, item 2): each
command is driven on a fake slow machine (``progress.CPU_S_PER_STEP`` 1 ms: every run is
estimated far above ``progress.ESTIMATE_MIN_S``) and stopped at its first estimate, which must
be the cost model's number for the command's size."""

from __future__ import annotations

import re

import pytest
from typer.testing import CliRunner

from ema_cli import progress
from ema_cli.cli.main import app

runner = CliRunner()


def cores_here() -> int:
    from ema_cli.limits import cores

    return cores()


class Stop(Exception):
    """Raised at the first estimate: nothing is simulated."""


@pytest.mark.parametrize("args", [
    ["simulate"],
    ["sweep", "configs/deadzone1.yaml"],
    ["freqresp", "--n", "3"],
    ["acceptance", "configs/acceptance.yaml"],
    ["yield", "configs/acceptance.yaml", "--tolerances", "configs/tolerances.yaml", "--n", "8"],
    ["tune", "configs/tune.yaml"],
    ["sensitivity", "configs/sensitivity.yaml", "--n", "8", "--method", "morris"],
    ["reproduce", "experiments/paper2020.yaml"],
    ["threshold", "configs/deadzone2.yaml", "--vary", "deadzone2", "--range", "0.001", "0.1",
     "--metric", "p2p_err_pos_deg", "--limit", "0.002"],
    ["identify", "closed-loop", "--data", "experiments/logs/design_hc_1pct.csv"],
    ["design", "experiments/logs/design_hc_1pct.csv"],
], ids=lambda a: a[0])
def test_a_long_command_prints_its_estimate_first(monkeypatch, tmp_path, args):
    said: list[str] = []
    real = progress.announce

    def announce(text: str) -> None:
        said.append(text)
        real(text)
        if text.startswith("estimated time "):
            raise Stop

    monkeypatch.setattr(progress, "CPU_S_PER_STEP", 1e-3)  # a machine 45,000x slower
    monkeypatch.setattr(progress, "announce", announce)
    r = runner.invoke(app, [*args, "--out", str(tmp_path / "o")])
    est = [s for s in said if s.startswith("estimated time ")]
    assert len(est) == 1, (r.output, said)
    assert "estimated time ~" in r.output  # on the console (stderr), first
    # the figure is the cost model's for the size it states (n x steps x 1 ms / cores)
    when = est[0].split(":")[0].removeprefix("estimated time ")
    if args[0] == "identify":  # the fit's own cost model (api.identify_logs.fit_estimate)
        from ema_cli.api.identify_logs import fit_estimate
        from ema_cli.config.loader import load_config
        from ema_cli.identify.closed_loop.problem import load_log
        from ema_cli.identify.log_settings import ClosedLoopSettings

        cfg = load_config(None, [("data", args[3])], ClosedLoopSettings)
        assert when == progress.duration(fit_estimate(cfg, load_log(args[3]).duration)[0])
        assert "starts, about" in est[0], est[0]
        return
    if args[0] == "design":  # the sum of its three parts, each named with its own figure
        parts = re.findall(r"(identification|tuning|sign-off) (~[\d.]+ (?:s|min|h))", est[0])
        assert [p for p, _ in parts] == ["identification", "tuning", "sign-off"], est[0]
        return
    m = re.search(r"([\d,]+) simulations of ([\d,]+) steps on (\d+) core", est[0])
    one = re.search(r"one run of ([\d,]+) steps", est[0])
    if m:
        n, steps, cores = (int(g.replace(",", "")) for g in m.groups())
        extra = 0.0
        evals = re.search(r"\(([\d,]+) evaluations of", est[0])
        if evals:  # tune: each evaluation's time beyond the kernel (api.tune.EVAL_OVERHEAD_S)
            from ema_cli.api.tune import EVAL_OVERHEAD_S

            extra = int(evals.group(1).replace(",", "")) * EVAL_OVERHEAD_S
        assert when == progress.duration(n * steps * 1e-3 / cores + extra), est[0]
    elif one:
        assert when == progress.duration(int(one.group(1).replace(",", "")) * 1e-3), est[0]
    else:  # acceptance, freqresp: "..., 12,345,678 integration steps" on this process's cores
        steps = int(re.search(r"([\d,]+) integration steps", est[0]).group(1).replace(",", ""))
        assert when == progress.duration(steps * 1e-3 / cores_here()), est[0]
