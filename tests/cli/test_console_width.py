"""Console output at any width (issue 20, item 5): every table readable at 80 and 120 columns
(no line longer than the console, no value cut), units on the numbers, words for non-finite
values; `print_table`'s three layouts; the one console number formatter."""

from __future__ import annotations

import json

import pytest
from typer.testing import CliRunner

from ema_cli.cli.main import app
from ema_cli.units import fmt_num

WIDTHS = (80, 120)


def invoke(width: int, *args: str):
    r = CliRunner().invoke(app, list(args), env={"COLUMNS": str(width)})
    return r, r.output


def check_width(text: str, width: int) -> None:
    lines = text.splitlines()
    assert lines, "no output"
    longest = max(lines, key=len)
    assert len(longest) <= width, f"{len(longest)} > {width}: {longest!r}"
    assert "…" not in text  # nothing cut with an ellipsis


def words(text: str) -> str:
    """The output's words in order, boxes and wrapping removed (for 'no value cut')."""
    for ch in "│┃┏┓┗┛┡┩└┘┌┐├┤┼━─╇╈┳┻╋═":
        text = text.replace(ch, " ")
    return " ".join(text.split())


@pytest.mark.parametrize("width", WIDTHS)
def test_locations_and_params_fit_without_losing_values(width):
    from ema_cli.model.nonlinearities import PLACEMENTS
    from ema_cli.model.params import PARAMS

    r, text = invoke(width, "locations")
    assert r.exit_code == 0, text
    check_width(text, width)
    flat = words(text)
    assert len(text.splitlines()) < 100  # it was 299 lines wrapped letter by letter
    for pl in PLACEMENTS:  # every value whole: the meaning and the paper's sweep too
        if width == 80:  # key/value blocks: each value on its lines
            assert " ".join(pl.meaning.split()) in flat and pl.paper_sweep in flat
        else:  # a table: prose wrapped at words within its column
            assert set(pl.meaning.split()) <= set(flat.split())
    r, text = invoke(width, "params")
    assert r.exit_code == 0, text
    check_width(text, width)
    for p in PARAMS:
        assert f" {p.name} " in f" {words(text)} "
    # the descriptions wrap at words inside their column
    assert "gear ratio (motor angle / load angle)" in words(text)


@pytest.mark.parametrize("width", WIDTHS)
def test_margins_in_words_and_units(width, tmp_path):
    r, text = invoke(width, "margins", "--out", str(tmp_path / "m"))
    assert r.exit_code == 0, text
    check_width(text, width)
    flat = words(text)
    # the speed loop of the default actuator never crosses -180 deg: said so, no inf/nan
    assert "no phase crossover" in flat and " inf " not in f" {flat} " and "nan" not in flat
    data = json.loads((tmp_path / "m" / "margins.json").read_text())
    pos = data["loops"]["position"] if "loops" in data else data["position"]
    assert f"{pos['gm_db']:.4g} dB" in flat and f"{pos['pm_deg']:.4g} deg" in flat


def test_simulate_says_what_nan_means(tmp_path):
    # 0.05 s of a 20 deg step: rise time and settling are never reached
    r, text = invoke(80, "simulate", "--duration", "0.05", "--out", str(tmp_path / "s"))
    assert r.exit_code == 0, text
    check_width(text, 80)
    flat = words(text.split("->")[0])  # (the folder's name holds "nan")
    assert "not settled within 0.05 s" in flat and "not reached" in flat
    assert "n/a" not in flat and "nan" not in flat
    assert " A " in flat and " V " in flat and "deg*s" in flat  # units beside the values


@pytest.mark.parametrize("width", WIDTHS)
def test_freqresp_table_units(width, tmp_path):
    r, text = invoke(width, "freqresp", "--amplitudes", "0.5,20", "--f-min", "2", "--f-max",
                     "20", "--n", "6", "--out", str(tmp_path / "f"))
    assert r.exit_code == 0, text
    check_width(text, width)
    flat = words(text)
    data = json.loads((tmp_path / "f" / "freqresp.json").read_text())
    for a in data["amplitudes"]:
        assert f"{a['amplitude_deg']:g} deg" in flat
        assert f"{a['peak_db']:.3g} dB" in flat and f"{a['max_thd_pct']:.3g} %" in flat


def test_sweep_table_at_80_and_no_figures(tmp_path):
    out = tmp_path / "sw"
    r, text = invoke(80, "sweep", "configs/deadzone2.yaml", "--no-figures", "--no-progress",
                     "--out", str(out))
    assert r.exit_code == 0, text
    check_width(text, 80)
    import pandas as pd

    df = pd.read_csv(out / "metrics.csv")
    flat = words(text)
    for _, row in df.iterrows():  # every job with its first metric, whole
        assert f"{row['job']} {row['label']} {row['status']} {row['iae_pos_deg_s']:.4g}" in flat
    assert "not shown at 80 columns" in flat and "(in metrics.csv)" in flat
    assert not (out / "figures").exists() and "no figures" in flat
    man = json.loads((out / "manifest.json").read_text())
    assert man["figures"] == [] and man["status"] == "complete"


def test_sweep_figures_drawn_while_the_table_prints(tmp_path):
    out = tmp_path / "sw"
    r, text = invoke(120, "sweep", "configs/deadzone2.yaml", "--no-progress", "--out",
                     str(out))
    assert r.exit_code == 0, text
    check_width(text, 120)
    # the table comes before the figures are waited for
    assert text.index("deadzone2: 4 jobs") < text.index("drawing 2 kinds of figures")
    man = json.loads((out / "manifest.json").read_text())
    assert sorted(man["figures"]) == ["figures/errors_deadzone2.png",
                                      "figures/metrics_deadzone2.png"]
    assert all((out / f).stat().st_size > 10_000 for f in man["figures"])
    assert man["timings_s"]["figures"] > 0
    assert json.loads((out / ".ema-run.json").read_text())["finished"] is True


@pytest.mark.parametrize("width", WIDTHS)
def test_acceptance_verdicts_fit(width, tmp_path):
    r, text = invoke(width, "acceptance", "configs/acceptance.yaml", "--only", "margins",
                     "--only", "load-deflection", "--out", str(tmp_path / f"a{width}"))
    assert r.exit_code == 0, text
    stdout = text.split("reference-ema: acceptance (reference EMA)", 1)[1]
    lines = [x for x in stdout.splitlines() if not x.startswith("note:")]  # stderr notes
    check_width("\n".join(lines), width)
    flat = words(stdout)
    assert "gain_margin (speed loop): no phase crossover" in flat or \
        "gain_margin (speed loop) no phase crossover" in flat
    assert "590 N*m/rad" in flat


def test_identify_exact_table_fits(tmp_path):
    r, text = invoke(80, "identify", "--method", "exact", "--out", str(tmp_path / "i"))
    assert r.exit_code == 0, text
    check_width(text, 80)
    assert "N*m/rad" in text and "rad" in text


def test_help_metavars_match_what_parses():
    for cmd, opt in (("identify", "--k-range"), ("identify", "--alpha-range"),
                     ("threshold", "--range")):
        r, text = invoke(120, cmd, "--help")
        assert f"{opt} LO HI" in text, text


# ---------------------------------------------------------------------------- the helpers


def test_fmt_num():
    assert fmt_num(12.3456, "dB") == "12.35 dB"
    assert fmt_num(float("inf"), "dB", inf="no phase crossover") == "no phase crossover"
    assert fmt_num(float("-inf"), "dB") == "-inf dB"
    assert fmt_num(float("nan"), "s", nan="not reached") == "not reached"
    assert fmt_num(None, "s") == "n/a" and fmt_num("off", "V") == "off"
    assert fmt_num(0.5, "-") == "0.5" and fmt_num(3, "A", 2) == "3 A"


@pytest.mark.parametrize("width", (40, 60, 80, 120, 200))
def test_print_table_layouts(width, monkeypatch):
    from ema_cli.cli import output
    from ema_cli.cli.common import console

    monkeypatch.setattr(console, "width", width)
    long = "a rather long description that does not fit beside the other columns at all"
    rows = [("k1", "1.5 s", long), ("k2", "22 N*m/rad", "short")]
    with console.capture() as cap:
        layout = output.print_table("T", ("name", "value", "description"), rows,
                                    optional=("description",), where="x.csv")
    text = cap.get()
    check_width(text, width)
    if width >= 120:
        assert layout == "table" and long in text
    elif width >= 40 and layout == "narrow":
        assert "description" in text and "x.csv" in text and long not in text
    assert layout in ("table", "narrow", "blocks")
    assert "1.5 s" in text and "22 N*m/rad" in text
    with console.capture() as cap:  # nothing optional: blocks keep every value, wrapped
        layout = output.print_table("T", ("name", "value", "description"), rows)
    text = cap.get()
    check_width(text, width)
    if width < 100:
        assert layout == "blocks"
    assert long in words(text) or " ".join(long.split()) in words(text)


@pytest.mark.parametrize("width", WIDTHS)
def test_show_fits(width):
    r, text = invoke(width, "show", "configs/deadzone2.yaml")
    assert r.exit_code == 0, text
    check_width(text, width)
    assert "deadzone2 = 0.001 deg" in words(text)


def test_tune_explains_its_budget_and_prints_units(tmp_path):
    from ema_cli.tune.run import evaluations_for, explain_budget

    r, text = invoke(80, "tune", "configs/tune.yaml", "--budget", "24", "--set",
                     "optimiser.pop=8", "--out", str(tmp_path / "t"))
    assert r.exit_code == 0, text
    expected = explain_budget("ga", 24, 8, 4, 0.33, "cma")
    spent = evaluations_for("ga", 24, 8, 4, 0.33, "cma")
    assert expected in text and f"budget 24 -> {spent} evaluations per run" in text
    assert f"{spent} evaluations in" in words(text)  # what ran is what was announced
    stdout = text[text.index("cost (relative, no unit)"):]  # (the stderr lines before it)
    check_width(stdout, 80)
    assert "Kpp = " in stdout and "1/s" in stdout and "V*s/rad" in stdout


@pytest.mark.parametrize("width", WIDTHS)
def test_threshold_table_units(width, tmp_path):
    cfg = tmp_path / "dz.yaml"
    cfg.write_text("name: dz\ninput: {kind: step, amplitude_deg: 0.1}\n"
                   "simulation: {duration_s: 0.3}\n")
    out = tmp_path / "out"
    r, text = invoke(width, "threshold", str(cfg), "--vary", "deadzone2", "--range", "1e-5",
                     "0.1", "--metric", "p2p_err_pos_deg", "--limit", "0.002", "--rtol", "0.05",
                     "--out", str(out))
    assert r.exit_code == 0, text
    check_width(text, width)
    res = json.loads((out / "threshold.json").read_text())
    flat = words(text)
    assert f"{res['threshold']:.5g} deg" in flat
    assert f"[{res['bracket'][0]:.5g} deg, {res['bracket'][1]:.5g} deg]" in flat
    assert f"{100 * res['relative_width']:.2g} %" in flat


@pytest.mark.parametrize("width", WIDTHS)
def test_help_summaries_are_whole(width):
    # `ema --help` used to cut every summary with "...": each command's summary is printed
    # whole, on one line, at 80 columns
    from ema_cli.cli.main import COMMANDS, SHORT_HELP

    r, out = invoke(width, "--help")
    assert r.exit_code == 0
    check_width(out, width)
    assert "..." not in out.split("\n", 1)[1]  # the usage line's [ARGS]... is click's
    for name, _ in COMMANDS:
        line = next(ln for ln in out.splitlines() if ln.strip().startswith(name + " "))
        assert line.strip().endswith(SHORT_HELP[name]), line


def test_closed_loop_table_keeps_the_interval_at_80_columns(monkeypatch, capsys):
    # issue 39: at 80 columns the closed-loop table dropped its 95 % interval, the column an
    # identification is for; now the standard error (and the truth columns) go first
    from ema_cli.cli import common, identify_logs

    monkeypatch.setenv("COLUMNS", "80")
    monkeypatch.setattr(common.console, "width", 80)  # restored after the test
    p = {"value": 598.123456, "standard_error": 3.21, "ci95": [591.8321, 604.4148],
         "determined": True, "unit": "N*m/rad"}
    params = {"kL": p, "alpha": {**p, "unit": "deg"}, "Fc": {**p, "unit": "N*m"},
              "sigma2": {**p, "unit": "N*m*s/rad"}}
    identify_logs._table("closed-loop fit", params, {"kL": 600.0, "alpha": 0.5, "Fc": 0.2,
                                                      "sigma2": 0.01})
    out = capsys.readouterr().out
    check_width(out, 80)
    assert "95 % interval" in out and "[591.832, 604.415 N*m/rad]" in out
    assert "not shown at 80 columns" in out and "SE" in out.split("not shown")[1]
