"""A sweep's outputs: signals.parquet (exact round trip, row groups, atomic), per-job CSVs on
request, the job cache's checks (damaged entries recomputed and reported), where the cache goes,
no cache without outputs."""

from __future__ import annotations

import json
import sqlite3
from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow.parquet as pq
import pytest
import yaml

import ema_cli.report.sweep_parquet as sweep_parquet
from ema_cli.api.study import run_sweep
from ema_cli.config.loader import load_config
from ema_cli.config.study import StudyConfig
from ema_cli.errors import EmaError
from ema_cli.files import AtomicFile, atomic_write
from ema_cli.report.sweep_report import default_cache_dir
from ema_cli.sim.tables import METRICS, PAPER_SIGNALS, SIGNALS
from ema_cli.sweep.cache import DB_NAME, DEFAULT_CACHE_DIR
from ema_cli.sweep.run import compute_sweep

SIGNAL_COLS = [c.edge for c in SIGNALS[:PAPER_SIGNALS]]
METRIC_COLS = [c.edge for c in METRICS]
N_OUT = 51  # 0.05 s every 1e-3 s, both ends


def study(tmp_path: Path, **outputs) -> Path:
    """A 0.1 deg step study over the transmission dead band (3 values + the baseline)."""
    data = {
        "name": "t",
        "input": {"kind": "step", "amplitude_deg": 0.1},
        "simulation": {"duration_s": 0.05, "dt_s": 1e-5, "output_interval_s": 1e-3},
        "sweep": {"axes": [{"nonlinearity": "deadzone2", "values": [0.001, 0.01, 0.1]}]},
        "outputs": {"timeseries": True, "figures": [], **outputs},
    }
    path = tmp_path / "study.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def sweep(tmp_path: Path, out: str = "run", cache: str = "cache", **outputs):
    cfg = load_config(study(tmp_path, **outputs), (), StudyConfig)
    return run_sweep(cfg, tmp_path / out, n_jobs=1, progress=False, cache_dir=tmp_path / cache)


def leftovers(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.rglob("*.tmp"))


def test_signals_parquet_round_trips_the_recorded_signals(tmp_path):
    res = sweep(tmp_path)
    path = tmp_path / "run" / "signals.parquet"
    assert res.signals_file == path and not leftovers(tmp_path / "run")
    df = pd.read_parquet(path)
    assert list(df.columns) == ["job", "deadzone2_deg", "t_s", *SIGNAL_COLS]
    assert len(df) == 4 * N_OUT
    assert list(df["job"].unique()) == ["j0000", "j0001", "j0002", "j0003"]
    metrics = pd.read_csv(tmp_path / "run" / "metrics.csv")
    for i, job in enumerate(res.jobs):
        rows = df[df["job"] == job.id]
        np.testing.assert_allclose(rows["t_s"], np.arange(N_OUT) * 1e-3, rtol=1e-12, atol=0)
        assert (rows["deadzone2_deg"] == metrics["deadzone2_deg"].iloc[i]).all()
        si = res.signals(i)  # from the cache: what the kernel recorded, bit for bit
        assert si.shape == (N_OUT, PAPER_SIGNALS)
        # every bit of float64 in edge units (NaN included)
        for k, c in enumerate(SIGNALS[:PAPER_SIGNALS]):
            assert rows[c.edge].dtype == np.float64
            np.testing.assert_array_equal(rows[c.edge].to_numpy().view(np.uint64),
                                          (si[:, k] * c.factor).view(np.uint64))
    # the figures' reader: one job's rows, t_s first, as `ema simulate` writes them
    ts = res.timeseries("j0002")
    assert list(ts.columns) == ["t_s", *SIGNAL_COLS] and len(ts) == N_OUT
    np.testing.assert_array_equal(ts.to_numpy(), df[df["job"] == "j0002"][ts.columns].to_numpy())
    meta = json.loads(pq.read_schema(path).metadata[b"ema"])
    assert meta["sweep_key"] == res.plan.key and meta["samples_per_job"] == N_OUT
    assert meta["units"]["theta_load_deg"] == "deg" and meta["units"]["omega_motor_rpm"] == "rpm"
    assert meta["units"]["deadzone2_deg"] == "deg" and meta["units"]["t_s"] == "s"
    assert pq.read_schema(path).field("current_a").metadata[b"unit"] == b"A"
    man = json.loads((tmp_path / "run" / "manifest.json").read_text())
    assert man["signals_file"] == "signals.parquet" and man["cache_corrupt_entries"] == 0
    assert man["signals_cache"]["cached"] is True and res.signals_cached  # 100 steps apart
    assert not (tmp_path / "run" / "timeseries").exists()  # no per-job CSVs unless asked


def test_row_groups_hold_whole_jobs_and_a_filter_reads_one(tmp_path, monkeypatch):
    row = (3 + PAPER_SIGNALS) * 8 * N_OUT  # bytes per job: job, swept value, t_s, signals
    monkeypatch.setattr(sweep_parquet, "ROW_GROUP_BYTES", 2 * row)  # two jobs per group
    res = sweep(tmp_path)
    meta = pq.ParquetFile(res.signals_file).metadata
    assert meta.num_row_groups == 2 and meta.num_rows == 4 * N_OUT
    stats = [meta.row_group(g).column(0).statistics for g in range(2)]
    assert [(s.min, s.max) for s in stats] == [("j0000", "j0001"), ("j0002", "j0003")]
    one = pq.read_table(res.signals_file, filters=[("job", "==", "j0003")])
    assert one.num_rows == N_OUT


def test_per_job_csv_only_on_request(tmp_path):
    res = sweep(tmp_path, per_job_csv=True)
    df = pd.read_parquet(res.signals_file)
    for job in res.jobs:
        csv = pd.read_csv(tmp_path / "run" / "timeseries" / f"{job.id}.csv")
        assert list(csv.columns) == ["t_s", *SIGNAL_COLS] and len(csv) == N_OUT
        rows = df[df["job"] == job.id][csv.columns].to_numpy()
        np.testing.assert_allclose(csv.to_numpy(), rows, rtol=1e-8, atol=0)  # %.9g text
    # CSVs without the parquet file: recorded all the same, written from the cache
    res = sweep(tmp_path, "csv-only", timeseries=False, per_job_csv=True)
    assert res.signals_file is None and not (tmp_path / "csv-only" / "signals.parquet").exists()
    csv = pd.read_csv(tmp_path / "csv-only" / "timeseries" / "j0001.csv")
    np.testing.assert_allclose(csv.to_numpy(), df[df["job"] == "j0001"][csv.columns].to_numpy(),
                               rtol=1e-8, atol=0)


@pytest.mark.parametrize("where", ["write_table", "close"])
@pytest.mark.parametrize("exc", [KeyboardInterrupt, OSError])
def test_an_interrupted_signals_write_leaves_no_file(tmp_path, monkeypatch, where, exc):
    monkeypatch.setattr(sweep_parquet, "ROW_GROUP_BYTES", 1)  # a row group per job
    calls = []
    real = getattr(pq.ParquetWriter, where)

    def boom(self, *args, **kw):
        calls.append(where)
        if len(calls) == (2 if where == "write_table" else 1):  # job 2's row group, or closing
            raise exc("interrupted while writing")
        return real(self, *args, **kw)

    monkeypatch.setattr(pq.ParquetWriter, where, boom)
    with pytest.raises(KeyboardInterrupt if exc is KeyboardInterrupt else EmaError):
        sweep(tmp_path)
    run = tmp_path / "run"
    assert not (run / "signals.parquet").exists() and leftovers(run) == []
    man = json.loads((run / "manifest.json").read_text())
    assert man["status"] == ("interrupted" if exc is KeyboardInterrupt else "incomplete")
    assert man["signals_file"] is None
    monkeypatch.setattr(pq.ParquetWriter, where, real)
    res = sweep(tmp_path)  # the same --out: resumed, the stored jobs from the cache
    # a row group written in the encoder thread fails at the next one: job 3 was stored too
    stored = 2 + sweep_parquet.PARQUET_THREAD if where == "write_table" else 4
    assert res.cached == stored and res.computed == 4 - res.cached
    assert len(pd.read_parquet(res.signals_file)) == 4 * N_OUT and leftovers(run) == []


def test_atomic_file_commit_and_discard(tmp_path):
    f = AtomicFile(tmp_path / "a" / "x.bin")
    f.tmp.write_bytes(b"data")
    assert not f.path.exists()
    assert f.commit() == tmp_path / "a" / "x.bin" and f.path.read_bytes() == b"data"
    g = AtomicFile(tmp_path / "a" / "y.bin")
    g.tmp.write_bytes(b"partial")
    g.discard()
    assert sorted(p.name for p in (tmp_path / "a").iterdir()) == ["x.bin"]


def test_atomic_write_creates_a_fresh_temporary_file(tmp_path):
    seen = []

    def write(tmp: Path) -> None:
        seen.append(tmp.exists())  # not created beforehand: the writer creates it
        tmp.write_text("new")

    target = tmp_path / "x.txt"
    target.write_text("old")
    atomic_write(target, write)
    assert seen == [False] and target.read_text() == "new" and leftovers(tmp_path) == []
    mask = __import__("os").umask(0)
    __import__("os").umask(mask)
    assert target.stat().st_mode & 0o777 == 0o666 & ~mask  # as open() makes a new file


def test_damaged_cache_entries_are_recomputed_and_reported(tmp_path):
    first = sweep(tmp_path, "first")
    cache = tmp_path / "cache"
    keys = [j.key for j in first.jobs]
    row_bytes = N_OUT * PAPER_SIGNALS * 8
    with sqlite3.connect(cache / DB_NAME) as db:  # an edited metrics row (job 0)
        blob = db.execute("SELECT metrics FROM jobs WHERE key = ?", (keys[0],)).fetchone()[0]
        edited = np.frombuffer(blob).copy()
        edited[0] *= 2
        db.execute("UPDATE jobs SET metrics = ? WHERE key = ?", (edited.tobytes(), keys[0]))

        def where(key: str) -> tuple[Path, int]:  # a job's signals file, its row's offset
            (file, row), = db.execute("SELECT file, row FROM signals WHERE key = ?", (key,))
            path = cache / "signals" / file
            return path, np.load(path, mmap_mode="r").offset + row * row_bytes

        flip, flip_at = where(keys[2])
        cut, cut_at = where(keys[3])
    data = bytearray(flip.read_bytes())
    data[flip_at + 8 * 7] ^= 0x40  # a flipped bit in job 2's signals
    flip.write_bytes(bytes(data))
    cut.write_bytes(cut.read_bytes()[:cut_at + row_bytes // 3])  # job 3's row truncated
    again = sweep(tmp_path, "again")
    assert again.cache_corrupt == 3 and again.computed == 3 and again.cached == 1
    (warning,) = [w for w in again.warnings if "job cache" in w]
    assert "3 damaged entries not used and recomputed" in warning and "\n" not in warning
    assert warning in again.run_warnings and warning not in again.plan.warnings
    assert f"- warning: {warning}" in (tmp_path / "again" / "summary.md").read_text()
    man = json.loads((tmp_path / "again" / "manifest.json").read_text())
    assert man["cache_corrupt_entries"] == 3 and warning in man["warnings"]
    np.testing.assert_array_equal(again.metrics[METRIC_COLS].to_numpy(float),
                                  first.metrics[METRIC_COLS].to_numpy(float))
    # the cached job's rows come first (jobs are written as they finish), the values are equal
    table = [pd.read_parquet(r.signals_file).astype({"job": str}).sort_values(
        ["job", "t_s"], ignore_index=True) for r in (again, first)]
    pd.testing.assert_frame_equal(*table)
    third = sweep(tmp_path, "third")  # the recomputed jobs replaced the damaged entries
    assert third.cache_corrupt == 0 and third.cached == 4 and not third.warnings


def test_no_cache_and_no_files_without_outputs(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    cfg = load_config(study(tmp_path), (), StudyConfig)
    res = run_sweep(cfg, n_jobs=1, progress=False, write=False)
    assert res.cache is None and res.folder is None and res.signals_file is None
    assert sorted(p.name for p in tmp_path.iterdir()) == ["study.yaml"]  # no ./results/.cache
    ref = compute_sweep(cfg, n_jobs=1, progress=False)
    assert ref.cache is None and sorted(p.name for p in tmp_path.iterdir()) == ["study.yaml"]
    # the signals are kept in memory instead
    assert res.signals(3).shape == (N_OUT, PAPER_SIGNALS)
    np.testing.assert_array_equal(res.signals(3), ref.signals(3))
    ts = res.timeseries("j0001")
    np.testing.assert_array_equal(ts["theta_load_deg"].to_numpy(),
                                  res.signals(1)[:, 1] * SIGNALS[1].factor)


def test_the_default_cache_follows_the_output_folder(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    cfg = load_config(study(tmp_path), (), StudyConfig)
    res = run_sweep(cfg, tmp_path / "out", n_jobs=1, progress=False)  # outside results/
    assert res.cache is not None and res.cache.root == tmp_path / "out" / ".cache"
    assert (tmp_path / "out" / ".cache" / DB_NAME).is_file()
    assert not (tmp_path / "results").exists()
    res = run_sweep(cfg, None, n_jobs=1, progress=False)  # results/sweep/<name>/...: shared cache
    assert res.cache is not None and res.cache.root == DEFAULT_CACHE_DIR
    assert res.cached == 0 and res.computed == 4  # another cache
    assert (tmp_path / DEFAULT_CACHE_DIR / DB_NAME).is_file()
    assert default_cache_dir(Path("results") / "mine") == DEFAULT_CACHE_DIR
    assert default_cache_dir(tmp_path / "results" / "x") == DEFAULT_CACHE_DIR  # absolute
    assert default_cache_dir(tmp_path / "elsewhere") == tmp_path / "elsewhere" / ".cache"
