"""Progress stages (issue 20, item 6), figures that show every curve (item 7) and defaults
that say what they do (item 8): the reporter's two modes, the hooks of the long computations,
coinciding curves, the budget explanation and the size estimate."""

from __future__ import annotations

import io

import numpy as np
import pytest

from ema_cli import progress
from ema_cli.cli.progress import StageReporter


class FakeTTY(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_pipe_prints_one_line_per_stage():
    out = io.StringIO()
    rep = StageReporter("identify", out)
    assert not rep.tty
    rep.t0 -= 10  # long past the grace period
    for g in range(1, 201):  # a quick stage (under LONG_S): its first line only
        rep("GA generation", g, 200, False)
    rep("polish over 0.5 s", 0, 2, False)
    rep("polish over 1 s", 1, 2, False)  # the same stage ("polish over"), further on
    rep("GA generation", 1, 5, False)  # a stage seen before: not announced again
    assert out.getvalue().splitlines() == ["identify: GA generation (200) ...",
                                           "identify: polish over 0.5 s (2) ..."]


class FakeClock:
    """``time`` for cli.progress: ``perf_counter`` advances ``step`` seconds per reading."""

    def __init__(self, step: float) -> None:
        self.now = 0.0
        self.step = step

    def perf_counter(self) -> float:
        self.now += self.step
        return self.now


def _pipe_lines(monkeypatch, calls, step=3.0):
    import ema_cli.cli.progress as cp

    monkeypatch.setattr(cp, "time", FakeClock(step))  # every stage long (LONG_S = 5 s)
    out = io.StringIO()
    rep = StageReporter("cmd", out)
    for stage, done, total in calls:
        rep(stage, done, total, False)
    return out.getvalue().splitlines()


@pytest.mark.parametrize("name,calls", [
    # closed-loop identification: 12 starts x 3 joint-fit rounds (issue 39: 36 lines)
    ("joint fit", [(f"joint fit, round {r} of 3 (J = {1 / (s + r):.4g})", None, None)
                   for s in range(12) for r in (1, 2, 3)]),
    # yield: 40 blocks of 25 units x 10 tests, then the worst case's stages per test
    ("yield", [(f"units {25 * b + 1}-{25 * b + 25} of 1000 (25 units): test {t}/10 t{t}",
                None, None) for b in range(40) for t in range(1, 11)]
     + [(f"worst case, {st} ({n} units): test 1/1 t{t}", None, None)
        for t in range(10) for st, n in (("corners", 16), ("search", 20))]),
    # the GA: 200 generations, each a report
    ("GA", [("GA generation", g, 200) for g in range(1, 201)]),
    # design: 17 cases x the acceptance battery's 8 tests
    ("design", [(f"test {k}/8 t{k} (step)", None, None) for c in range(17)
                for k in range(1, 9)]),
])
def test_pipe_prints_at_most_one_line_per_tenth_of_a_stage(monkeypatch, name, calls):
    from ema_cli.cli.progress import stage_key

    lines = _pipe_lines(monkeypatch, calls)
    keys = {stage_key(s) for s, _, _ in calls}
    per_key: dict[str, int] = {}
    for ln in lines:
        key = stage_key(ln.split(": ", 1)[1])
        per_key[key] = per_key.get(key, 0) + 1
    assert set(per_key) == keys  # every stage said once at least
    # its first line, then at most one per 10 % (the 10 tenths)
    assert all(n <= 11 for n in per_key.values()), per_key
    assert len(lines) <= 11 * len(keys)
    pcts = [ln for ln in lines if ln.endswith("%)")]
    for ln in pcts:  # a tenth's line says how far the stage is
        assert 0 < int(ln.rsplit("(", 1)[1].split(" %")[0]) <= 100


def test_stage_keys_and_fractions():
    from ema_cli.cli.progress import stage_fraction, stage_key

    assert stage_key("joint fit, round 2 of 3 (J = 0.01)") == "joint fit, round"
    assert stage_key("units 33-64 of 1000 (32 units): test 3/10 x") == "units"
    assert stage_key("worst case, search (20 units): test 1/1 x") == "worst case, search"
    assert stage_key("12 things") == "12 things"
    assert stage_fraction("units 33-64 of 1000", None, None) == 64 / 1000
    assert stage_fraction("joint fit, round 2 of 3", None, None) == 2 / 3
    assert stage_fraction("test 3/10 x", None, None) == 0.3
    assert stage_fraction("GA generation", 50, 200) == 0.25
    assert stage_fraction("reading the log", None, None) is None


def test_pipe_says_nothing_of_a_command_that_ends_at_once():
    out = io.StringIO()
    rep = StageReporter("identify", out)
    rep("reading the log", None, None, False)  # within the grace period: held
    assert out.getvalue() == ""
    rep.t0 -= 10  # ... the command went on
    rep("GA generation", 1, 200, False)
    assert out.getvalue().splitlines() == ["identify: reading the log ...",
                                           "identify: GA generation (200) ..."]


def test_terminal_redraws_one_line_and_clears_it(monkeypatch):
    out = FakeTTY()
    monkeypatch.setenv("COLUMNS", "60")
    rep = StageReporter("freqresp", out)
    rep("frequencies", 0, 30, False)
    rep("frequencies", 30, 30, False)  # the last step is always drawn
    text = out.getvalue()
    assert "\n" not in text and text.count("\r") == 2
    assert "freqresp: frequencies 0/30" in text and "freqresp: frequencies 30/30" in text
    assert all(len(part) <= 60 for part in text.split("\r"))
    rep.clear()
    assert out.getvalue().endswith("\r") and rep.drawn == 0
    before = out.getvalue()
    rep("simulations", 0, 10, True)  # the caller draws its own bar: nothing drawn
    assert out.getvalue() == before


def test_hooks_report_ga_generations_and_frequencies():
    from ema_cli.analysis.freqresp import sinestream
    from ema_cli.model.params import resolve
    from ema_cli.optim.ga import preset, run_ga

    seen: list[tuple[str, int | None, int | None]] = []
    with progress.reporting(lambda s, d, t, bar: seen.append((s, d, t))):

        class Sphere:
            lower = np.zeros(2)
            upper = np.ones(2)

            def evaluate(self, X):
                return ((X - 0.3) ** 2).sum(axis=1)

        run_ga(Sphere(), preset("improved", pop=10, generations=4), np.random.default_rng(0))
        sinestream(resolve(), [0.5], [2.0, 4.0, 8.0], dt=1e-4)
    assert [x for x in seen if x[0] == "GA generation"] == [("GA generation", k, 4)
                                                            for k in range(1, 5)]
    assert [x for x in seen if x[0] == "frequencies"] == [("frequencies", j, 3)
                                                          for j in range(3)]
    progress.report("nobody listens")  # no reporter installed: nothing happens


def test_estimate_and_announce():
    assert progress.estimate(98_304, 100_000, 2) == \
        "98,304 simulations of 100,000 steps, ~2 min on 2 cores"
    assert progress.estimate(20_000, 1_000, 1).endswith("~1 s on 1 core")
    assert progress.estimate(10**6, 10**6, 2).endswith("h on 2 cores")
    said: list[str] = []
    with progress.reporting(None, said.append):
        progress.announce_size(progress.BIG_RUN, 10, 2)  # not above the threshold
        progress.announce_size(progress.BIG_RUN + 1, 10, 2, "--n sets it")
    assert said == ["estimated time ~1 s: 10,001 simulations of 10 steps on 2 cores "
                    "(--n sets it)"]
    said.clear()
    with progress.reporting(None, said.append):
        progress.announce_size(100, 10**5, 2)  # 100 x 1e5 x 22 ns / 2: 0.11 s, not said
        assert said == [] and progress.timing()["estimated_s"] == pytest.approx(0.11)
        progress.announce_size(100, 10**7, 2)  # 11 s: above ESTIMATE_MIN_S, said
        assert said == ["estimated time ~11 s: 100 simulations of 10,000,000 steps on 2 cores"]
        assert progress.timing()["estimated_s"] == pytest.approx(11.11)
        assert progress.finished_line().startswith("took ")
        assert progress.finished_line().endswith("(estimated ~11 s)")
    assert progress.elapsed(192.4) == "3 min 12 s" and progress.duration(192.4) == "~3 min"


def test_sensitivity_announces_its_size_before_any_simulation():
    from ema_cli.config.loader import load_config
    from ema_cli.config.sensitivity import SensitivityConfig
    from ema_cli.sensitivity.run import compute_sensitivity

    class Stop(Exception):
        pass

    said: list[str] = []

    def announcer(text: str) -> None:
        said.append(text)
        raise Stop  # stop before the first simulation

    cfg = load_config("configs/sensitivity.yaml", (), SensitivityConfig)
    with progress.reporting(None, announcer), pytest.raises(Stop):
        compute_sensitivity(cfg, n_jobs=2)
    (text,) = said
    # the estimate from the same cost model the limits use (progress.CPU_S_PER_STEP)
    sims = cfg.runs("sobol", 4096)
    est = progress.duration(progress.kernel_seconds(sims, 100_000, 2))
    assert text.startswith(f"estimated time {est}: {sims:,} simulations of 100,000 steps")
    assert "on 2 cores" in text and "--n sets it" in text


@pytest.mark.parametrize("method", ["ga", "de"])
@pytest.mark.parametrize("budget,pop,polish", [(200, 20, 0.33), (1440, 64, 0.33),
                                               (200, 38, 0.0), (997, 24, 0.5)])
def test_budget_explanation_matches_what_runs(method, budget, pop, polish):
    from ema_cli.tune.run import evaluations_for, explain_budget

    n_var = 4
    text = explain_budget(method, budget, pop, n_var, polish, "cma")
    spent = evaluations_for(method, budget, pop, n_var, polish, "cma")
    assert text.startswith(f"budget {budget} -> {spent} evaluations per run: ")
    assert ("left unspent" in text) == (spent < budget)
    if spent < budget:
        assert f"{budget - spent} left unspent" in text


def test_coinciding_curves_found_numerically():
    from ema_cli.report.figures import coincidence_note, coinciding, curve_style

    x = np.linspace(0, 1, 20)
    curves = {"a": x, "b": x + 0.01, "c": x + 1.0, "d": x + 1.0, "e": 2 * x}
    assert coinciding(curves, 0.05) == [["a", "b"], ["c", "d"]]
    assert coinciding(curves, 0.001) == [["c", "d"]]
    assert coincidence_note([["a", "b"]], 0.05, "dB") == "a = b (within 0.05 dB)"
    assert coincidence_note([], 0.05, "dB") == ""
    styles = [curve_style(k, 20, 4) for k in range(4)]
    assert len({(str(s["ls"]), s["marker"]) for s in styles}) == 4  # all distinct
    assert len({s["markevery"][0] for s in styles}) == 4  # markers staggered


def test_bode_figure_notes_coinciding_curves_and_keeps_legend_off_the_data():
    from types import SimpleNamespace

    from ema_cli.report.freqresp_report import bode_figure

    f = np.geomspace(0.5, 50, 12)
    lin = 1 / (1 + 1j * f / 6)
    pts = []
    for a in (0.1, 1.0, 20.0):
        g = lin * (0.7 if a == 20.0 else 1.0)  # the large amplitude differs
        pts += [SimpleNamespace(amplitude_deg=a, f_hz=fk, gain_db=20 * np.log10(abs(gk)),
                                phase_deg=np.degrees(np.angle(gk)), thd_pct=0.01, limits=())
                for fk, gk in zip(f, g, strict=True)]
    res = SimpleNamespace(f_hz=f, linear=lin, amplitudes=[0.1, 1.0, 20.0],
                          block=lambda a: [p for p in pts if p.amplitude_deg == a])
    fig = bode_figure(res, "t")
    fig.canvas.draw()
    ax = fig.axes[0]
    leg = ax.get_legend()
    assert [t.get_text() for t in leg.get_texts()] == ["0.1 deg", "1 deg", "20 deg",
                                                       "linear model"]
    # outside the axes: the legend starts right of the plotting area
    assert leg.get_window_extent().x0 > ax.get_window_extent().x1
    notes = " ".join(t.get_text() for t in fig.axes[1].texts).replace("\n", " ")
    # a gain scaled by 0.7: the gain curve apart, the phase curve on the others
    assert "gain: 0.1 deg = 1 deg = linear model (within 0.05 dB)" in notes
    assert "phase: 0.1 deg = 1 deg = 20 deg = linear model (within 0.5 deg)" in notes
    styles = {(str(line.get_linestyle()), line.get_marker()) for line in ax.get_lines()[:4]}
    assert len(styles) == 4


def test_sweep_overlay_says_which_curves_lie_on_each_other_and_keeps_legend_below():
    import pandas as pd

    from ema_cli.report.sweep_figures import overlay_figure

    t = np.linspace(0, 1, 200)
    a = pd.DataFrame({"t_s": t, "err": np.exp(-5 * t)})
    b = pd.DataFrame({"t_s": t, "err": np.exp(-5 * t) + 1e-6})  # on a
    c = pd.DataFrame({"t_s": t, "err": 0.5 * np.exp(-5 * t)})
    fig = overlay_figure([("baseline", a), ("x = 1", b), ("x = 2", c)], "t",
                         [("err", "error [deg]")], legend_title="x")
    title = fig.axes[0].get_title().replace("\n", " ")
    assert "on each other" in title and "baseline = x = 1" in title and "x = 2" not in title
    fig.canvas.draw()
    (leg,) = fig.legends
    assert leg.get_window_extent().y1 <= min(ax.get_window_extent().y0 for ax in fig.axes)


def test_a_whole_estimate_counts_its_parts_once_and_a_part_of_nothing_is_quiet():
    """A command made of other computations (design, sensitivity) announces one estimate; the
    parts it runs neither add to it nor announce again; after the block they count again; a
    part that adds nothing (every job cached) says nothing."""
    said: list[str] = []
    with progress.reporting(None, said.append):
        with progress.whole_estimate(100.0, "the whole"):
            progress.announce_estimate(50.0, "a part inside")
        assert progress.timing()["estimated_s"] == 100.0
        progress.announce_estimate(0.0, "a cached part")
        progress.announce_estimate(30.0, "a part after")
        assert progress.timing()["estimated_s"] == 130.0
    assert said == ["estimated time ~2 min: the whole", "estimated time ~2 min: a part after"]
