"""Interrupt a command at many instants, as a user would (Ctrl-C or SIGTERM to its process
group), and check what it leaves and what the same command makes of it.

Used by tests/system/test_interrupted_runs.py (the slow tier). Each case is a tiny run of one
command that writes an --out folder (written into a work folder: its configs, a small log);
:func:`check_case` runs it uninterrupted twice (the reference, and its duration T), then for
each of N instants spread evenly over T (signals alternating SIGINT, SIGTERM) starts it,
signals it, checks the exit code and the folder, and runs the same command again, whose
folder must hold the reference's numbers.
"""

from __future__ import annotations

import json
import math
import os
import re
import signal
import subprocess
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

EMA = Path(sys.executable).with_name("ema")
MARKER = ".ema-run.json"
TEMPORARY = re.compile(r"\..+\.[0-9a-f]{12}\.tmp")
VOLATILE = re.compile(r"(^|_)(wall|timings?|elapsed|created|throughput)(_|$)|_s_per_|"
                      r"^(steps_per_s|git_commit|kernel_s|kernel_load|load_s|python|numpy|numba|"
                      r"machine|ema_version|cache_dir|workers|backend|computed|cached)$")
"""Keys and columns that hold times, the machine or how the work was done (computed anew or
read back from a cache), never the results: left out of the comparison."""
SKIPPED = {"manifest.json", MARKER}
"""Compared apart: the manifest (times, versions; checked readable) and the marker (its
inputs and its list of outputs are compared, not its times)."""


@dataclass
class Case:
    """One command: ``args`` (without --out, relative to the work folder), the files a
    finished folder must hold (``files``: glob patterns), what ``setup(work)`` writes first,
    the exit code of a complete run, and how many instants to try."""

    name: str
    args: list[str]
    files: list[str]
    setup: Callable[[Path], None] | None = None
    instants: int = 8
    timeout_s: float = 300.0
    notes: list[str] = field(default_factory=list)


@dataclass
class Attempt:
    instant_s: float
    signal: str
    code: int
    state: str
    rerun_code: int
    rerun_s: float


def _env() -> dict[str, str]:
    env = dict(os.environ)
    env.setdefault("COLUMNS", "100")
    return env


def run(case: Case, work: Path, out: str, delay: float | None = None,
        sig: int = signal.SIGINT) -> tuple[int, float, str]:
    """Run the case into ``work/out`` -> (exit code, seconds, stderr); ``delay``: send ``sig``
    to its process group that many seconds after the start (if it still runs)."""
    err_path = work / f".{out}.stderr"
    with open(err_path, "w") as err:
        t0 = time.monotonic()
        p = subprocess.Popen([str(EMA), *case.args, "--out", out], cwd=work, env=_env(),
                             stdout=subprocess.DEVNULL, stderr=err, start_new_session=True)
        if delay is not None:
            try:
                p.wait(timeout=delay)
            except subprocess.TimeoutExpired:
                os.killpg(p.pid, sig)
        try:
            code = p.wait(timeout=case.timeout_s)
        except subprocess.TimeoutExpired:
            os.killpg(p.pid, signal.SIGKILL)
            p.wait()
            raise AssertionError(f"{case.name}: no exit within {case.timeout_s} s") from None
        seconds = time.monotonic() - t0
    return code, seconds, err_path.read_text(errors="replace")


# ------------------------------------------------------------------ what a folder holds
def _readable(path: Path) -> None:
    """Raise unless ``path`` is a whole file of its kind."""
    suffix = path.suffix.lower()
    if suffix == ".png":
        data = path.read_bytes()
        assert data[:8] == b"\x89PNG\r\n\x1a\n" and data[-8:-4] == b"IEND", path
    elif suffix == ".json":
        json.loads(path.read_text())
    elif suffix in (".yaml", ".yml"):
        yaml.safe_load(path.read_text())
    elif suffix == ".csv":
        import pandas as pd

        pd.read_csv(path)
    elif suffix == ".parquet":
        import pandas as pd

        pd.read_parquet(path)
    else:
        path.read_bytes()


def files_of(folder: Path) -> list[Path]:
    """Every file of ``folder``, its job cache (.cache) aside."""
    return sorted(p for p in folder.rglob("*")
                  if p.is_file() and ".cache" not in p.relative_to(folder).parts)


def state_of(case: Case, folder: Path) -> str:
    """``absent``, ``unfinished`` or ``finished`` (complete: every documented file there and
    readable, the marker's list of outputs the files there); every file there whole, no
    temporary file left. AssertionError otherwise."""
    if not folder.exists():
        return "absent"
    files = files_of(folder)
    temps = [p for p in files if TEMPORARY.fullmatch(p.name)]
    assert not temps, f"{case.name}: temporary files left: {temps}"
    for p in files:
        _readable(p)
    if not files:
        return "absent"  # created, nothing written yet (not even the marker)
    mark = json.loads((folder / MARKER).read_text())
    if mark.get("finished") is not True:
        return "unfinished"
    for pattern in case.files:
        assert list(folder.glob(pattern)), f"{case.name}: finished without {pattern}"
    listed = set(mark.get("outputs", {}))
    there = {p.relative_to(folder).as_posix() for p in files if p.name != MARKER}
    assert listed == there, f"{case.name}: marker lists {sorted(listed ^ there)} wrongly"
    return "finished"


def _clean(o: Any) -> Any:
    if isinstance(o, dict):
        return {k: _clean(v) for k, v in o.items() if not VOLATILE.search(str(k))}
    if isinstance(o, list):
        return [_clean(v) for v in o]
    if isinstance(o, float) and math.isnan(o):
        return "NaN"
    return o


def snapshot(folder: Path) -> dict[str, Any]:
    """The numbers of a folder: every CSV, Parquet, JSON and YAML file's values (times and
    how the work was done left out: :data:`VOLATILE`), the marker's inputs and outputs' names,
    the names of the figures and reports."""
    out: dict[str, Any] = {}
    for p in files_of(folder):
        rel = p.relative_to(folder).as_posix()
        suffix = p.suffix.lower()
        if p.name == MARKER:
            mark = json.loads(p.read_text())
            out[rel] = {"command": mark["command"], "fingerprint": mark["fingerprint"],
                        "inputs": mark.get("inputs"), "outputs": sorted(mark.get("outputs", {}))}
        elif p.name in SKIPPED:
            out[rel] = "present"
        elif suffix in (".csv", ".parquet"):
            import pandas as pd

            df = pd.read_csv(p) if suffix == ".csv" else pd.read_parquet(p)
            df = df[[c for c in df.columns if not VOLATILE.search(str(c))]]
            if suffix == ".parquet" and "job" in df.columns:
                # a sweep's signals.parquet is written as jobs finish: its rows come in the
                # order of completion (a resumed sweep serves its cached jobs first), each
                # job's samples in time order; the result is the rows of each job
                df = df.assign(job=df["job"].astype(str)).sort_values(
                    "job", kind="stable").reset_index(drop=True)
            out[rel] = _clean(json.loads(df.to_json(orient="split", double_precision=15)))
        elif suffix == ".json":
            out[rel] = _clean(json.loads(p.read_text()))
        elif suffix in (".yaml", ".yml"):
            out[rel] = _clean(yaml.safe_load(p.read_text()))
        else:
            out[rel] = "present"  # figures, markdown (its text quotes times)
    return out


def differences(a: dict[str, Any], b: dict[str, Any]) -> list[str]:
    """The files and top-level keys where two snapshots differ (for the failure message)."""
    diff = [f"only in one: {k}" for k in sorted(set(a) ^ set(b))]
    for k in sorted(set(a) & set(b)):
        if a[k] != b[k]:
            x, y = a[k], b[k]
            if isinstance(x, dict) and isinstance(y, dict):
                keys = [j for j in sorted(set(x) | set(y), key=str) if x.get(j) != y.get(j)]
                diff.append(f"{k}: {keys[:6]}")
            else:
                diff.append(k)
    return diff


# ------------------------------------------------------------------ the check
def _fresh_run(case: Case, work: Path, ref: dict[str, Any], k: int) -> str:
    """For a failure message: whether one more uninterrupted run, into a new folder, gives
    the reference's results (a defect of resuming) or not (the command's results differ
    from process to process)."""
    out = f"fresh{k:02d}"
    code, _, err = run(case, work, out)
    if code not in (0, 1, 3):
        return f"a fresh uninterrupted run exited {code}: {err[-500:]}"
    diff = differences(ref, snapshot(work / out))
    return ("a fresh uninterrupted run gives the reference's results (a defect of resuming)"
            if not diff else f"a fresh uninterrupted run differs too ({diff}): the command's "
            "results differ from process to process, whatever the interruption")


def check_case(case: Case, work: Path, instants: int | None = None) -> list[Attempt]:
    """Run ``case`` uninterrupted twice, then interrupted at ``instants`` instants (default
    the case's) and again; AssertionError naming the instant and signal on any failure."""
    if case.setup is not None:
        case.setup(work)
    code, _, err = run(case, work, "ref")  # also compiles what it needs
    assert state_of(case, work / "ref") == "finished", err
    ref = snapshot(work / "ref")
    code2, total, err = run(case, work, "ref2")
    assert code2 == code, err
    assert state_of(case, work / "ref2") == "finished", err
    assert not differences(ref, snapshot(work / "ref2")), \
        f"{case.name}: two uninterrupted runs differ: {differences(ref, snapshot(work / 'ref2'))}"
    n = instants or case.instants
    attempts = []
    for k in range(n):
        delay = total * (0.05 + 1.0 * k / max(n - 1, 1))  # 5 % .. 105 % of a run
        sig = (signal.SIGINT, signal.SIGTERM)[k % 2]
        out = f"run{k:02d}"
        got, _, err = run(case, work, out, delay, sig)
        where = f"{case.name}: {sig.name} at {delay:.2f} s of {total:.2f} s"
        allowed = {code, 128 + sig, -sig}
        assert got in allowed, f"{where}: exit {got} (expected one of {allowed}): {err[-2000:]}"
        state = state_of(case, work / out)
        if got == -sig:  # the signal came before ema started: nothing written
            assert state == "absent", f"{where}: killed before ema started, left {state}"
        if got == code:
            assert state == "finished", f"{where}: exit {got} with a folder {state}"
        again, seconds, err = run(case, work, out)
        assert again == code, f"{where}, then again: exit {again}: {err[-2000:]}"
        assert state_of(case, work / out) == "finished", f"{where}, then again: unfinished"
        diff = differences(ref, snapshot(work / out))
        assert not diff, (f"{where} (folder then {state}), then again: results differ from a "
                          f"whole run: {diff}; {_fresh_run(case, work, ref, k)}")
        attempts.append(Attempt(delay, sig.name, got, state, again, seconds))
    return attempts
