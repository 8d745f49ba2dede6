"""report/rundir.py, files.py and report/figures.py: atomic writes, CSV/JSON round trips, run
folders, manifests, and the labels of the simulation figures."""

from __future__ import annotations

import datetime as real_dt
import hashlib
import json
import math
import os
import platform
import re
from pathlib import Path
from types import SimpleNamespace

import matplotlib

matplotlib.use("Agg")

import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402
import pytest  # noqa: E402

import ema_cli  # noqa: E402
from ema_cli.errors import EmaError  # noqa: E402
from ema_cli.files import atomic_write  # noqa: E402
from ema_cli.report import rundir  # noqa: E402
from ema_cli.report.figures import overlay_figure, tracking_figure  # noqa: E402
from ema_cli.report.rundir import (  # noqa: E402
    manifest,
    new_run_dir,
    write_csv,
    write_figure,
    write_json,
    write_text,
)


def leftovers(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir() if p.name.endswith(".tmp"))


# ------------------------------------------------------------------------------------------
# atomic writes


def test_write_text_atomic_and_no_temp_files(tmp_path):
    p = tmp_path / "sub" / "a.txt"  # the parent is created
    write_text(p, "first\nü°\n")
    write_text(p, "second\n")
    assert p.read_text(encoding="utf-8") == "second\n"
    assert sorted(x.name for x in p.parent.iterdir()) == ["a.txt"]
    mask = os.umask(0)
    os.umask(mask)
    assert p.stat().st_mode & 0o777 == 0o666 & ~mask  # as open() would create it


def test_failed_write_keeps_the_old_file_and_removes_the_temp(tmp_path):
    p = tmp_path / "a.txt"
    write_text(p, "old\n")

    def boom(tmp: Path) -> None:
        tmp.write_text("half", encoding="utf-8")
        raise RuntimeError("disk full")

    with pytest.raises(RuntimeError, match="disk full"):
        atomic_write(p, boom)
    assert p.read_text(encoding="utf-8") == "old\n"
    assert leftovers(tmp_path) == [] and sorted(x.name for x in tmp_path.iterdir()) == ["a.txt"]


def test_write_csv_round_trip(tmp_path):
    rng = np.random.default_rng(11)
    df = pd.DataFrame({
        "t_s": np.arange(50) * 1e-4,
        "theta_load_deg": rng.normal(0, 20, 50),
        "current_a": rng.normal(0, 1e-3, 50) * 10.0 ** rng.integers(-8, 3, 50),
        "diverged": np.zeros(50, dtype=int),
    })
    df.loc[3, "theta_load_deg"] = np.nan
    p = tmp_path / "ts.csv"
    write_csv(p, df, float_format="%.9g")
    back = pd.read_csv(p)
    assert list(back.columns) == list(df.columns)  # no index column
    assert len(back) == 50 and math.isnan(back.loc[3, "theta_load_deg"])
    for col in df.columns:  # %.9g: 9 significant digits -> relative error <= 5e-9
        np.testing.assert_allclose(back[col], df[col], rtol=5e-9, atol=0, equal_nan=True)
    assert (back["diverged"] == 0).all()
    assert leftovers(tmp_path) == []


def test_write_json_nan_and_inf_become_null(tmp_path):
    p = tmp_path / "m.json"
    data = {"a": float("nan"), "b": [1.0, float("inf"), {"c": -math.inf}], "d": (np.float64(2.5),
            np.nan), "e": np.int64(3), "f": np.array([1.0, 2.0]), "g": Path("x/y"), "h": "s"}
    write_json(p, data)
    text = p.read_text(encoding="utf-8")
    assert text.endswith("}\n") and "NaN" not in text and "Infinity" not in text
    assert json.loads(text) == {"a": None, "b": [1.0, None, {"c": None}], "d": [2.5, None],
                                "e": 3, "f": [1.0, 2.0], "g": "x/y", "h": "s"}
    assert leftovers(tmp_path) == []


def test_write_json_unserialisable_leaves_nothing(tmp_path):
    p = tmp_path / "m.json"
    with pytest.raises(TypeError, match="not JSON serialisable: object"):
        write_json(p, {"x": object()})
    assert list(tmp_path.iterdir()) == []


def test_write_figure_png_and_closes(tmp_path):
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots()
    ax.plot([0, 1], [0, 1])
    p = tmp_path / "f.png"
    write_figure(p, fig, dpi=50)
    assert p.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert not plt.fignum_exists(fig.number)
    assert leftovers(tmp_path) == []


# ------------------------------------------------------------------------------------------
# run folders


class _FixedNow:
    """Stands in for the datetime module inside rundir: now() is fixed."""

    @staticmethod
    def now(tz=None):
        return real_dt.datetime(2024, 5, 17, 13, 4, 5, tzinfo=tz)


def _marker(folder: Path) -> dict:
    return json.loads((folder / rundir.MARKER).read_text(encoding="utf-8"))


def test_new_run_dir_naming_and_no_overwrite(tmp_path, monkeypatch):
    monkeypatch.setattr(rundir, "RESULTS_ROOT", tmp_path / "results")
    monkeypatch.setattr(rundir, "_dt", SimpleNamespace(datetime=_FixedNow, UTC=real_dt.UTC))
    data = {"name": "s1", "plant": {"kL": 600}, "seed": 0}
    digest = hashlib.sha256(json.dumps(data, sort_keys=True).encode()).hexdigest()
    first = new_run_dir("s1", data, command="simulate")
    # results/<command>/<config-name>/<stamp>_<hash>, and latest pointing at it
    assert first == tmp_path / "results" / "simulate" / "s1" / f"20240517-130405_{digest[:8]}"
    assert [p.name for p in first.iterdir()] == [rundir.MARKER]  # only the marker
    assert _marker(first) == {"command": "simulate", "fingerprint": digest[:16],
                              "created": "2024-05-17T13:04:05+00:00", "finished": False,
                              "inputs": {"fingerprint": digest[:16]}, "sets": []}
    latest = first.parent / rundir.LATEST
    assert latest.is_symlink() and os.readlink(latest) == first.name  # relative
    # the same data, unfinished: completed in place; finished, the same second: a numbered
    # sibling, never the same folder
    assert new_run_dir("s1", data, command="simulate") == first
    rundir.finish_output(first)
    second = new_run_dir("s1", data, command="simulate")
    rundir.finish_output(second)
    third = new_run_dir("s1", data, command="simulate")
    assert second.name == f"20240517-130405_{digest[:8]}-1" and third.name.endswith("-2")
    assert len({first, second, third}) == 3 and all(p.is_dir() for p in (second, third))
    assert latest.resolve() == third.resolve()  # the newest
    assert _marker(new_run_dir("s1", data))["command"] == "s1"  # no command given: the name
    # different data: a different hash
    other = new_run_dir("s1", {**data, "seed": 1}, command="simulate")
    assert other.parent == first.parent and other.name[:16] == "20240517-130405_"
    assert other.name[16:] != digest[:8] and re.fullmatch(r"[0-9a-f]{8}", other.name[16:])
    assert leftovers(first) == []
    assert not list(first.parent.glob(".latest*"))  # no temporary link left


def test_default_folder_resumes_unfinished_run_of_same_inputs(tmp_path, monkeypatch):
    monkeypatch.setattr(rundir, "RESULTS_ROOT", tmp_path / "results")
    fp = "0123456789abcdef"
    a, state = rundir.prepare_output("sweep", "my study", fp)
    assert state == rundir.NEW and a.parent == tmp_path / "results" / "sweep" / "my-study"
    b, state = rundir.prepare_output("sweep", "my study", fp)
    assert state == rundir.RESUMED and b == a  # unfinished, same inputs: the same folder
    c, state = rundir.prepare_output("sweep", "my study", "f" * 16)
    assert state == rundir.NEW and c != a  # other inputs: a new folder
    rundir.finish_output(a)
    d, state = rundir.prepare_output("sweep", "my study", fp)
    assert state == rundir.NEW and d not in (a, c)  # finished: a new run gets a new folder
    assert (a.parent / rundir.LATEST).resolve() == d.resolve()
    # a real folder named latest is never replaced
    f, _ = rundir.prepare_output("simulate", "x", fp)
    (f.parent / rundir.LATEST).unlink()
    (f.parent / rundir.LATEST).mkdir()
    rundir.prepare_output("simulate", "x", "e" * 16)
    assert (f.parent / rundir.LATEST).is_dir() and not (f.parent / rundir.LATEST).is_symlink()


def test_new_run_dir_given_out(tmp_path):
    out = tmp_path / "a" / "b"
    assert new_run_dir("x", {}, out) == out and out.is_dir()  # parents created
    empty = tmp_path / "empty"
    empty.mkdir()
    assert new_run_dir("x", {}, empty) == empty  # an existing empty folder is fine
    # the same inputs, unfinished: completed in place; other inputs: refused
    assert new_run_dir("x", {}, out) == out
    with pytest.raises(EmaError, match=r"--out '.*b' already holds an unfinished `ema x` run "
                                       r"of other inputs"):
        new_run_dir("x", {"seed": 1}, out)
    other = tmp_path / "other"
    other.mkdir()
    (other / "keep.txt").write_text("x")
    with pytest.raises(EmaError, match=r"already holds other files; results are never overw"):
        new_run_dir("x", {}, other)
    assert (other / "keep.txt").read_text() == "x" and len(list(other.iterdir())) == 1


def test_new_run_dir_refuses_a_file(tmp_path):
    f = tmp_path / "file"
    f.write_text("x")
    with pytest.raises(EmaError, match=r"is a file; expected a folder") as ei:
        new_run_dir("x", {}, f)
    assert str(f) in ei.value.message and f.read_text() == "x"


def test_prepare_output_resume_and_finish(tmp_path):
    out = tmp_path / "run"
    assert rundir.prepare_output("sweep", "s", "f" * 16, out) == (out, rundir.NEW)
    # the same command and inputs, unfinished: completed in place
    assert rundir.prepare_output("sweep", "s", "f" * 16, out) == (out, rundir.RESUMED)
    with pytest.raises(EmaError, match=r"an unfinished `ema sweep` run of other inputs"):
        rundir.prepare_output("sweep", "s", "e" * 16, out)
    with pytest.raises(EmaError, match=r"already holds an unfinished `ema sweep` run;"):
        rundir.prepare_output("threshold", "s", "f" * 16, out)
    (out / "a.csv").write_text("x\n")
    rundir.finish_output(out)
    mark = _marker(out)
    assert mark["finished"] is True and mark["outputs"] == {"a.csv": 2}
    # finished, the same inputs: kept as it is (the caller writes nothing)
    assert rundir.prepare_output("sweep", "s", "f" * 16, out) == (out, rundir.FINISHED)
    with pytest.raises(EmaError, match=r"already holds a finished `ema sweep` run of other"):
        rundir.prepare_output("sweep", "s", "e" * 16, out)


@pytest.mark.skipif(os.geteuid() == 0, reason="root can write to read-only folders")
def test_new_run_dir_refuses_read_only(tmp_path):
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o500)
    try:
        with pytest.raises(EmaError, match="is not writable"):
            new_run_dir("x", {}, ro)
    finally:
        ro.chmod(0o700)


def test_manifest_fields():
    before = real_dt.datetime.now(real_dt.UTC).replace(microsecond=0)
    m = manifest("simulate", seed=3, dt_s=1e-5)
    after = real_dt.datetime.now(real_dt.UTC)
    assert m["ema_version"] == ema_cli.__version__ == "0.1.0"
    from importlib.metadata import version

    assert m["ema_version"] == version("ema-cli")  # pyproject.toml
    assert m["command"] == "simulate" and m["seed"] == 3 and m["dt_s"] == 1e-5
    created = real_dt.datetime.fromisoformat(m["created"])
    assert created.tzinfo is not None and before <= created <= after
    assert m["git_commit"] is None or re.fullmatch(r"[0-9a-f]{40}", m["git_commit"])
    assert m["python"] == platform.python_version() and m["numpy"] == np.__version__
    assert m["machine"] == platform.machine()
    json.dumps(m)  # plain JSON


# ------------------------------------------------------------------------------------------
# figures


def _timeseries() -> pd.DataFrame:
    t = np.linspace(0.0, 0.2, 21)
    ref = np.where(t >= 0, 20.0, 0.0)
    load = 20.0 * (1 - np.exp(-t / 0.03))
    return pd.DataFrame({
        "t_s": t, "theta_ref_deg": ref, "theta_load_deg": load, "theta_motor_deg": load * 1.01,
        "omega_ref_deg_s": np.zeros_like(t), "omega_load_deg_s": np.gradient(load, t),
        "err_pos_deg": ref - load, "err_vel_deg_s": -np.gradient(load, t),
    })


def test_tracking_figure_labels_units_title_legend():
    import matplotlib.pyplot as plt

    ts = _timeseries()
    fig = tracking_figure(ts, "run-1: 20 deg step")
    try:
        assert fig._suptitle is not None and fig._suptitle.get_text() == "run-1: 20 deg step"
        axes = fig.axes
        assert len(axes) == 4
        ylabels = [a.get_ylabel() for a in axes]
        assert ylabels == ["position [deg]", "velocity [deg/s]", "position error [deg]",
                           "velocity error [deg/s]"]
        for a in axes:
            assert a.get_title()  # every panel is titled
        assert [a.get_xlabel() for a in axes[2:]] == ["time [s]", "time [s]"]
        # legends on the tracking panels name the curves
        leg = [t.get_text() for t in axes[0].get_legend().get_texts()]
        assert leg == ["reference", "load angle", "motor angle / m"]
        assert [t.get_text() for t in axes[1].get_legend().get_texts()] == \
            ["reference", "load speed"]
        # the curves are the data, unchanged
        lines = {ln.get_label(): ln for ln in axes[0].get_lines()}
        np.testing.assert_array_equal(lines["load angle"].get_xdata(), ts["t_s"])
        np.testing.assert_array_equal(lines["load angle"].get_ydata(), ts["theta_load_deg"])
        np.testing.assert_array_equal(axes[2].get_lines()[0].get_ydata(), ts["err_pos_deg"])
    finally:
        plt.close(fig)


def test_overlay_figure_labels_units_title_legend():
    import matplotlib.pyplot as plt

    ts = _timeseries()
    ts2 = ts.assign(err_pos_deg=ts["err_pos_deg"] * 0.5)
    fig = overlay_figure([("baseline", ts), ("deadzone2 = 0.01 deg", ts2)], "Fig. 3",
                         legend_title="deadzone2")
    try:
        assert fig._suptitle.get_text() == "Fig. 3"
        top, bottom = fig.axes
        assert top.get_ylabel() == "position error [deg]"
        assert bottom.get_ylabel() == "velocity error [deg/s]"
        assert bottom.get_xlabel() == "time [s]"
        legend = top.get_legend()
        assert legend.get_title().get_text() == "deadzone2"
        assert [t.get_text() for t in legend.get_texts()] == ["baseline", "deadzone2 = 0.01 deg"]
        curves = [ln for ln in top.get_lines() if ln.get_label() in ("baseline",
                                                                        "deadzone2 = 0.01 deg")]
        assert curves[0].get_linestyle() == "--" and curves[1].get_linestyle() == "-"
        np.testing.assert_array_equal(curves[1].get_ydata(), ts2["err_pos_deg"])
    finally:
        plt.close(fig)


@pytest.mark.parametrize("data", [{"x": np.float32("nan")}, {"x": np.array([1.0, np.nan])},
                                  {"x": [np.inf]}])
def test_write_json_turns_numpy_nan_into_null(tmp_path, data):
    write_json(tmp_path / "m.json", data)
    back = json.loads((tmp_path / "m.json").read_text())
    assert None in (back["x"] if isinstance(back["x"], list) else [back["x"]])


def test_git_commit_read_from_files_matches_git(tmp_path, monkeypatch):
    import shutil
    import subprocess

    root = Path(__file__).resolve().parents[2]
    if shutil.which("git") and (root / ".git").exists():
        monkeypatch.chdir(root)
        head = subprocess.run(["git", "rev-parse", "HEAD"], capture_output=True, text=True,
                              check=True).stdout.strip()
        assert rundir.git_commit() == head
    # a packed ref, a detached HEAD, no repository at all
    git = tmp_path / "repo" / ".git"
    (git / "refs" / "heads").mkdir(parents=True)
    (git / "HEAD").write_text("ref: refs/heads/main\n")
    (git / "packed-refs").write_text("# pack-refs\n" + "a" * 40 + " refs/heads/main\n")
    (tmp_path / "repo" / "sub").mkdir()
    monkeypatch.chdir(tmp_path / "repo" / "sub")
    assert rundir.git_commit() == "a" * 40
    (git / "HEAD").write_text("b" * 40 + "\n")
    assert rundir.git_commit() == "b" * 40
    (tmp_path / "norepo").mkdir()
    monkeypatch.chdir(tmp_path / "norepo")
    assert rundir.git_commit() is None or (Path("/") / ".git").exists()
