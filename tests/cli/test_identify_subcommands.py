"""`ema identify` as subcommands (torque, closed-loop, friction-sweep, make-data) beside the
earlier spelling (`ema identify [CONFIG] --closed-loop ...`): the help of the group and of each
subcommand, and both spellings giving identical results (cheap cases)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from typer.testing import CliRunner

from ema_cli.cli import main
from ema_cli.cli.main import app
from ema_cli.errors import EmaError

runner = CliRunner()
ROOT = Path(__file__).resolve().parents[2]
CONFIG = ROOT / "configs" / "identify.yaml"
SUBS = [n for n, _ in main.IDENTIFY_COMMANDS]


def invoke(*args: object):
    r = runner.invoke(app, ["identify", *map(str, args)], env={"COLUMNS": "100"})
    return r, " ".join(r.output.split())


def without_timings(obj: object) -> object:
    """``obj`` with every wall-time entry removed (the only thing two runs may differ in)."""
    if isinstance(obj, dict):
        return {k: without_timings(v) for k, v in obj.items()
                if "wall_time" not in k and k not in ("timings", "created", "git")}
    if isinstance(obj, list):
        return [without_timings(v) for v in obj]
    return obj


def test_group_help_lists_every_subcommand_with_its_whole_summary():
    r, text = invoke("--help")
    assert r.exit_code == 0, text
    assert SUBS[:4] == ["torque", "closed-loop", "friction-sweep", "make-data"]
    for name, fn in main.IDENTIFY_COMMANDS:
        first = " ".join(fn.__doc__.split("\n\n")[0].split())
        assert len(first) > 60  # longer than click's cut, so the check below can fail
        assert f"{name} {first}" in text.replace("- ", "-"), (name, text)
    # the earlier spelling is documented, with its options
    assert "Without a command: ema identify [CONFIG] [OPTIONS]" in text
    assert "--k-range LO HI" in text and "--closed-loop" in text


@pytest.mark.parametrize(("sub", "has", "lacks"), [
    ("torque", ["--k-range LO HI", "--method", "--bits", "--data"],
     ["--closed-loop", "--window", "--free", "--starts", "--make-data"]),
    ("closed-loop", ["--data", "--window T0,T1", "--free", "--starts", "--columns"],
     ["--k-range", "--closed-loop", "--bits", "--noise", "--friction-sweep"]),
    ("friction-sweep", ["--data", "--set", "--out"],
     ["--seed", "--free", "--k-range", "--noise", "--window"]),
    ("make-data", ["kind", "--noise", "--seed", "--out"],
     ["--data", "--free", "--k-range", "--make-data", "--window"]),
])
def test_each_subcommand_help_has_only_its_options(sub, has, lacks):
    r, text = invoke(sub, "--help")
    assert r.exit_code == 0, text
    assert f"Usage: ema identify {sub} [OPTIONS]" in text
    for opt in has:
        assert opt in text, (sub, opt)
    for opt in lacks:
        assert opt not in text, (sub, opt)
    first = " ".join(dict(main.IDENTIFY_COMMANDS)[sub].__doc__.split("\n\n")[0].split())
    assert first in text.replace("- ", "-")  # the whole summary opens the help


@pytest.mark.parametrize(("args", "needles"), [
    (["torque", "--window", "0,1"], ["No such option: --window", "identify torque --help"]),
    (["closed-loop", "--k-range", "1", "2"], ["No such option: --k-range"]),
    (["make-data", "foo"], ["make-data KIND", "closed-loop or friction-sweep", "'foo'"]),
    (["--bogus"], ["No such option: --bogus", " identify --help`"]),
])
def test_a_wrong_option_is_one_line_naming_it(tmp_path, capsys, args, needles):
    code = main.run(["identify", *args, "--out", str(tmp_path / "never")])
    cap = capsys.readouterr()
    output = cap.out + cap.err
    text = " ".join(output.split())
    assert code == 2, text
    lines = [ln for ln in output.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("error:"), output
    for n in needles:
        assert n in text, text
    assert not (tmp_path / "never").exists()


def test_torque_both_spellings_identical_with_a_positional_config(tmp_path):
    """A positional CONFIG goes to the earlier spelling (not taken for a subcommand name)."""
    args = [CONFIG, "--method", "exact", "--noise", "1", "--seed", "4"]
    r, text = invoke(*args, "--out", tmp_path / "old")
    assert r.exit_code == 0, text
    r, text = invoke("torque", *args, "--out", tmp_path / "new")
    assert r.exit_code == 0, text
    old, new = (json.loads((tmp_path / d / "identification.json").read_text())
                for d in ("old", "new"))
    assert without_timings(old) == without_timings(new)
    kl = old["optimum"]["kL"] if "optimum" in old else None
    assert kl is None or 500 < kl < 700


def test_make_data_and_friction_sweep_both_spellings_identical(tmp_path):
    for spelling, d in ((["--make-data", "friction-sweep"], "old"),
                        (["make-data", "friction-sweep"], "new")):
        r, text = invoke(*spelling, "--noise", "1", "--seed", "5", "--out", tmp_path / d)
        assert r.exit_code == 0, text
    old, new = (tmp_path / d / "friction_sweep.csv" for d in ("old", "new"))
    assert old.read_bytes() == new.read_bytes()
    assert ((tmp_path / "old" / "friction_sweep.truth.json").read_bytes()
            == (tmp_path / "new" / "friction_sweep.truth.json").read_bytes())
    for spelling, d in ((["--friction-sweep"], "fit_old"), (["friction-sweep"], "fit_new")):
        r, text = invoke(*spelling, "--data", old, "--out", tmp_path / d)
        assert r.exit_code == 0, text
    a, b = (json.loads((tmp_path / d / "identification.json").read_text())
            for d in ("fit_old", "fit_new"))
    assert a["parameters"] == b["parameters"]
    assert without_timings(a) == without_timings(b)


def test_closed_loop_both_spellings_reach_the_api_with_the_same_inputs(monkeypatch, tmp_path):
    """The fit itself is long: both spellings must hand the API the same (config, settings);
    the API call is replaced by one that records them."""
    import ema_cli.api.identify_logs as api

    seen: list[tuple] = []

    def record(config, pairs, **execution):
        seen.append((config, pairs, execution))
        raise EmaError("recorded")

    monkeypatch.setattr(api, "identify_closed_loop", record)
    log = tmp_path / "log.csv"
    log.write_text("t_s,theta_ref_deg,theta_load_deg\n0,0,0\n0.001,0,0\n")
    common = ["--data", log, "--free", "Fs=0,0.2", "--window", "0,0.001", "--starts", "3",
              "--seed", "7", "--set", "plant.contact_tau=1e-4", "--columns", "t_s=t_s:s",
              "--backend", "loky", "--n-jobs", "1"]
    for spelling in (["--closed-loop"], ["closed-loop"]):
        r, text = invoke(*spelling, *common)
        assert r.exit_code == 2 and "recorded" in text, text
    for spelling in (["--closed-loop", "--method", "ga", "--pop", "8"],
                     ["closed-loop", "--method", "ga", "--pop", "8"]):
        r, text = invoke(*spelling, "--data", log)
        assert r.exit_code == 2 and "recorded" in text, text
    assert len(seen) == 4
    assert seen[0] == seen[1] and seen[2] == seen[3]
    assert ("free.Fs", [0.0, 0.2]) in seen[0][1] and ("search", "ga") in seen[2][1]
    assert seen[0][2] == {"backend": "loky", "n_jobs": 1, "scheduler": None}


def test_registering_a_subcommand_is_one_pair(monkeypatch):
    """A new (name, function) pair in IDENTIFY_COMMANDS is a subcommand, listed in the help."""
    from ema_cli.cli.groups import command_group

    def extra_cmd() -> None:
        """A subcommand added for this test: it prints a word, with a summary longer than
        click's 45 characters."""
        print("extra ran")

    _, help_ = main.GROUPS["identify"]
    import typer

    root = typer.Typer(rich_markup_mode=None)
    root.callback()(lambda: None)
    group = command_group("identify", main.identify.identify_cmd,
                          [*main.IDENTIFY_COMMANDS, ("extra", extra_cmd)], help_)
    root.add_typer(group, name="identify")
    r = runner.invoke(root, ["identify", "extra"])
    assert r.exit_code == 0 and "extra ran" in r.output, r.output
    r = runner.invoke(root, ["identify", "--help"], env={"COLUMNS": "100"})
    assert "with a summary longer than click's 45 characters" in " ".join(r.output.split())


@pytest.mark.parametrize(("ref", "needles"), [
    (None, ["log.csv", "theta_ref_deg"]),  # the actuation (command) channel missing
    ("const", ["log.csv", "theta_ref_deg", "is constant", "does not excite"]),
])
def test_a_missing_or_constant_command_is_one_line_naming_file_and_channel(
        tmp_path, capsys, ref, needles):
    import numpy as np

    t = np.arange(200) * 1e-3
    cols = {"t_s": t, "theta_load_deg": np.sin(20 * t)}
    if ref == "const":
        cols["theta_ref_deg"] = np.full_like(t, 2.0)
    log = tmp_path / "log.csv"
    names = list(cols)
    log.write_text(",".join(names) + "\n" + "\n".join(
        ",".join(f"{cols[c][i]:.6g}" for c in names) for i in range(t.shape[0])) + "\n")
    code = main.run(["identify", "closed-loop", "--data", str(log),
                     "--out", str(tmp_path / "never")])
    cap = capsys.readouterr()
    lines = [ln for ln in (cap.out + cap.err).splitlines()
             if ln.strip() and not ln.startswith("identify: ")]  # progress lines apart
    assert code == 2 and len(lines) == 1 and lines[0].startswith("error:"), lines
    for n in needles:
        assert n in lines[0], lines[0]
    assert not (tmp_path / "never").exists()
