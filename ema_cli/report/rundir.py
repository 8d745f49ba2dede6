"""Run folders, atomic file writes and manifests (every output folder describes itself).

The generic pieces live below every layer: atomic replacement and ``RESULTS_ROOT`` in
``ema_cli.files``, content hashes in ``ema_cli.hashing``.
"""

from __future__ import annotations

import datetime as _dt
import json
import os
import platform
import re
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

from ema_cli import __version__
from ema_cli.errors import EmaError
from ema_cli.files import RESULTS_ROOT, atomic_write
from ema_cli.hashing import content_hash, json_default
from ema_cli.report.run_inputs import RunInputs, differences, legacy_inputs


def write_text(path: Path, text: str) -> None:
    """Atomically write a text file (UTF-8)."""
    atomic_write(path, lambda p: p.write_text(text, encoding="utf-8"))


def write_json(path: Path, data: Any) -> None:
    """Atomically write JSON (numpy values converted; NaN written as null)."""
    text = json.dumps(_nan_to_none(data), indent=2, default=json_default, allow_nan=False)
    write_text(path, text + "\n")


def _nan_to_none(o: Any) -> Any:
    """NaN and infinities -> None, recursively, numpy scalars and arrays included."""
    import math

    if hasattr(o, "tolist") and not isinstance(o, str | bytes):  # numpy scalar or array
        o = o.tolist()
    if isinstance(o, float) and not math.isfinite(o):
        return None
    if isinstance(o, dict):
        return {k: _nan_to_none(v) for k, v in o.items()}
    if isinstance(o, list | tuple):
        return [_nan_to_none(v) for v in o]
    return o


def write_csv(path: Path, frame: Any, **kwargs: Any) -> None:
    """Atomically write a pandas DataFrame as CSV (no index)."""
    kwargs.setdefault("index", False)
    atomic_write(path, lambda p: frame.to_csv(p, **kwargs))


def write_figure(path: Path, fig: Any, dpi: int = 120) -> None:
    """Atomically save a matplotlib Figure as PNG (and close it if pyplot manages it); log
    axes get labels between the decades (:func:`label_log_axes`)."""
    import sys

    label_log_axes(fig)
    try:
        atomic_write(path, lambda p: fig.savefig(p, dpi=dpi, format="png"))
    finally:
        if "matplotlib.pyplot" in sys.modules:
            sys.modules["matplotlib.pyplot"].close(fig)


MINOR_LABEL_DECADES = 3.5  # log axes spanning fewer decades label some minor ticks [-]


def label_log_axes(fig: Any) -> None:
    """Label the minor ticks (2, 5, ...) of every log axis of ``fig`` that spans fewer than
    :data:`MINOR_LABEL_DECADES` decades: an axis labelled only at the decades is hard to read
    off (``0.3 Hz`` is between 0.1 and 1)."""
    from matplotlib.ticker import LogFormatterSciNotation

    for ax in fig.axes:
        for axis, scale in ((ax.xaxis, ax.get_xscale()), (ax.yaxis, ax.get_yscale())):
            if scale == "log":
                axis.set_minor_formatter(LogFormatterSciNotation(
                    labelOnlyBase=False, minor_thresholds=(MINOR_LABEL_DECADES, 1.0)))
                axis.set_tick_params(which="minor", labelsize="x-small")


def git_commit() -> str | None:
    """The git commit checked out in the working folder (or a parent), when there is one.

    Read from ``.git`` directly (HEAD, the ref it names, packed-refs): no subprocess."""
    here = Path.cwd().resolve()
    for folder in (here, *here.parents):
        git = folder / ".git"
        if git.is_file():  # a worktree or submodule: "gitdir: <path>"
            text = git.read_text(encoding="utf-8", errors="replace").strip()
            if text.startswith("gitdir:"):
                git = (folder / text.removeprefix("gitdir:").strip()).resolve()
        if git.is_dir():
            return _read_head(git)
    return None


def _read_head(git: Path) -> str | None:
    try:
        head = (git / "HEAD").read_text(encoding="utf-8").strip()
        if not head.startswith("ref:"):
            return head or None
        ref = head.removeprefix("ref:").strip()
        common = git
        if (git / "commondir").is_file():
            common = (git / (git / "commondir").read_text(encoding="utf-8").strip()).resolve()
        for base in (git, common):
            if (base / ref).is_file():
                return (base / ref).read_text(encoding="utf-8").strip() or None
        packed = common / "packed-refs"
        if packed.is_file():
            for line in packed.read_text(encoding="utf-8").splitlines():
                parts = line.split()
                if len(parts) == 2 and parts[1] == ref:
                    return parts[0]
    except OSError:
        return None
    return None


CACHE_NAME = ".cache"
"""A sweep's job cache inside its output folder (when that is outside results/)."""
MARKER = ".ema-run.json"
"""Written first into every output folder (:func:`prepare_output`): which command made it, its
inputs (named components and their fingerprint, ``run_inputs``); rewritten last, atomically,
with the files written and ``finished: true`` (:func:`finish_output`)."""

NEW, RESUMED, FINISHED = "new", "resumed", "finished"
"""The states of an output folder :func:`prepare_output` returns: created (or empty), an
unfinished run of the same inputs to complete, the finished run of the same inputs (kept as it
is: nothing is written into it)."""

Inputs = RunInputs | str
"""A run's inputs (``run_inputs.RunInputs``), or a bare fingerprint (no components to name)."""


def _as_inputs(inputs: Inputs | None) -> RunInputs | None:
    if inputs is None or isinstance(inputs, RunInputs):
        return inputs
    return legacy_inputs(str(inputs))


def read_marker(folder: Path) -> dict[str, Any] | None:
    """The marker of ``folder`` (None: none, or unreadable)."""
    try:
        data = json.loads((folder / MARKER).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    return data if isinstance(data, dict) else None


_read_marker = read_marker


def _only_job_cache(path: Path) -> bool:
    """True if ``path`` (an output folder's ``.cache``) is a folder holding nothing but a job
    cache's own files (``sweep.cache``: the database, its journal files, ``signals/``)."""
    from ema_cli.sweep.cache import DB_NAME

    if path.is_symlink() or not path.is_dir():
        return False
    names = {DB_NAME, *(f"{DB_NAME}-{s}" for s in ("wal", "shm", "journal")), "signals"}
    for p in path.iterdir():
        if p.name not in names or (p.name == "signals") != (p.is_dir() and not p.is_symlink()):
            return False
    signals = path / "signals"
    if signals.is_dir():  # signals/<kk>/<key>-<random>-d<dec>.npy (and their temporaries)
        for sub in signals.iterdir():
            if not sub.is_dir() or sub.is_symlink():
                return False
            if any(not (f.name.endswith((".npy", ".tmp")) and f.is_file())
                   for f in sub.iterdir()):
                return False
    return True


_TEMPORARY = re.compile(r"\..+\.[0-9a-f]{12}\.tmp")
"""The name of a temporary file of ``files.AtomicFile`` (``.<name>.<12 hex>.tmp``)."""


def _busy(out: Path) -> bool:
    """True if ``out`` holds anything but a job cache and temporaries a killed run left."""
    try:
        return any((p.name != CACHE_NAME or not _only_job_cache(p))
                   and not (_TEMPORARY.fullmatch(p.name) and p.is_file())
                   for p in out.iterdir())
    except OSError as exc:
        raise EmaError(f"--out '{out}' cannot be read: {exc.strerror}") from None


def output_state(out: Path | None, command: str, inputs: Inputs | None = None) -> str:
    """The state of ``--out`` for a run of ``command`` with ``inputs``, without creating
    anything: :data:`NEW` (absent or empty), :data:`RESUMED` (an unfinished run of the same
    command and inputs: it is completed) or :data:`FINISHED` (the finished run of the same
    command and inputs: kept as it is). Anything else is refused (EmaError naming --out and,
    for a run of other inputs, what differs). ``inputs`` None: only the command is checked
    (the inputs are compared when the folder is prepared)."""
    if out is None:
        return NEW
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise EmaError(f"--out '{out}' is a file; expected a folder (new or empty)")
    if out.is_dir() and _busy(out):
        mark = read_marker(out)
        new = _as_inputs(inputs)
        if mark is not None and mark.get("command") == command and (
                new is None or mark.get("fingerprint") == new.fingerprint):
            return FINISHED if mark.get("finished") is True else RESUMED
        if mark is None:
            what = "other files"
        else:
            state = "finished" if mark.get("finished") is True else "unfinished"
            article = "an" if state == "unfinished" else "a"
            what = f"{article} {state} `ema {mark.get('command')}` run"
            if mark.get("command") == command and new is not None:
                what += (" of other inputs ("
                         + differences(mark.get("inputs"), new, mark.get("sets") or ()) + ")")
        raise EmaError(f"--out '{out}' already holds {what}; results are never overwritten: "
                       "choose a new folder or delete that one")
    parent = next((p for p in out.absolute().parents if p.exists()), None)
    if parent is not None and not parent.is_dir():
        raise EmaError(f"--out '{out}': '{parent}' is a file, not a folder")
    return NEW


def check_output(out: Path | None, command: str, inputs: Inputs | None = None) -> str:
    """Check ``--out`` before a long computation (:func:`output_state`) -> its state."""
    return output_state(out, command, inputs)


LATEST = "latest"
"""The symlink in ``results/<command>/<config-name>/`` to the newest run folder there."""


def default_folder(command: str, name: str) -> Path:
    """``results/<command>/<config-name>/``: where the default run folders of a command and a
    config go (``name`` made safe for a folder name)."""
    safe = re.sub(r"[^A-Za-z0-9._-]+", "-", str(name)).strip(".-") or "default"
    return RESULTS_ROOT / command / safe


def _unfinished(parent: Path, command: str, fingerprint: str) -> Path | None:
    """The newest unfinished run folder of ``command`` with ``fingerprint`` under ``parent``."""
    if not parent.is_dir():
        return None
    found = []
    for p in parent.iterdir():
        if p.is_symlink() or not p.is_dir() or f"_{fingerprint[:8]}" not in p.name:
            continue
        mark = read_marker(p)
        if (mark is not None and mark.get("command") == command
                and mark.get("fingerprint") == fingerprint and not mark.get("finished")):
            found.append(p)
    return max(found, key=lambda p: p.name) if found else None


def point_latest(folder: Path) -> None:
    """Point ``folder.parent/latest`` at ``folder`` (a relative symlink, replaced atomically:
    a reader sees the old or the new link, never none). Best effort: a file system without
    symlinks only loses the convenience."""
    import contextlib
    import secrets

    link = folder.parent / LATEST
    tmp = folder.parent / f".{LATEST}.{secrets.token_hex(4)}.tmp"
    with contextlib.suppress(OSError):
        if link.exists() and not link.is_symlink():
            return  # a real folder named 'latest': never replaced
        os.symlink(folder.name, tmp, target_is_directory=True)
        try:
            os.replace(tmp, link)
        except OSError:
            tmp.unlink()


def remove_stale_temporaries(folder: Path) -> None:
    """Delete the temporary files (``.<name>.<12 hex>.tmp``, ``files.AtomicFile``) a killed
    run left anywhere in ``folder`` (its job cache aside): the folder is being resumed, no
    other process writes there."""
    import contextlib

    for dirpath, dirnames, filenames in os.walk(folder):
        dirnames[:] = [d for d in dirnames if d != CACHE_NAME]
        for name in filenames:
            p = Path(dirpath) / name
            if _TEMPORARY.fullmatch(name) and not p.is_symlink():
                with contextlib.suppress(OSError):
                    p.unlink()


def prepare_output(command: str, name: str, inputs: Inputs, out: Path | None = None
                   ) -> tuple[Path, str]:
    """The one output-folder policy of every command -> (folder, state).

    ``out`` None: a new folder ``results/<command>/<name>/<stamp>_<hash>/`` (``name``: the
    config's name), and ``results/<command>/<name>/latest`` points at it; the newest unfinished
    run of the same inputs there, if any, is completed instead. A given ``out`` must be new or
    empty (:data:`NEW`: the marker is written first, ``finished: false``), or hold a run of the
    same ``command`` and ``inputs`` (``run_inputs.RunInputs``: the fingerprint of its named
    components): unfinished, it is completed (:data:`RESUMED`; the caller writes its files
    again, each atomically); finished, it is kept as it is (:data:`FINISHED`; the caller
    writes nothing). Earlier results of other inputs are never overwritten: errors name
    ``--out`` and what differs.
    """
    from ema_cli.progress import announce

    run = _as_inputs(inputs)
    assert run is not None
    fingerprint = run.fingerprint
    default = out is None
    if out is None:
        parent = default_folder(command, name)
        earlier = _unfinished(parent, command, fingerprint)
        if earlier is not None:
            remove_stale_temporaries(earlier)
            point_latest(earlier)
            announce(f"completing the unfinished run of the same inputs in {earlier}")
            return earlier, RESUMED
        stamp = _dt.datetime.now().strftime("%Y%m%d-%H%M%S")
        out = parent / f"{stamp}_{fingerprint[:8]}"
        k = 1
        base = out
        while out.exists():
            out = base.with_name(f"{base.name}-{k}")
            k += 1
    out = Path(out)
    state = output_state(out, command, run)
    if state == FINISHED:
        announce(f"--out '{out}' holds the finished run of these inputs: kept as it is")
        return out, state
    if state == RESUMED:
        remove_stale_temporaries(out)
        announce(f"completing the unfinished run of the same inputs in {out}")
        return out, state
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise EmaError(f"--out '{out}': cannot create the folder ({exc.strerror})") from None
    if not os.access(out, os.W_OK):
        raise EmaError(f"--out '{out}': the folder is not writable")
    remove_stale_temporaries(out)
    write_json(out / MARKER, {"command": command, "fingerprint": fingerprint,
                              "created": _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds"),
                              "finished": False, "inputs": run.components,
                              "sets": list(run.sets)})
    if default:
        point_latest(out)
    return out, NEW


def _outputs(folder: Path) -> dict[str, int]:
    """Every file in ``folder`` (its marker, job cache and temporaries aside) -> its size."""
    found = {}
    for dirpath, dirnames, filenames in os.walk(folder):
        dirnames[:] = sorted(d for d in dirnames if d != CACHE_NAME)
        for name in sorted(filenames):
            if name == MARKER or _TEMPORARY.fullmatch(name):
                continue
            p = Path(dirpath) / name
            try:
                found[p.relative_to(folder).as_posix()] = p.stat().st_size
            except OSError:
                continue
    return found


def finish_output(folder: Path) -> None:
    """Mark ``folder`` finished, last and atomically: the marker rewritten with the files
    written (``outputs``: path -> bytes) and ``finished: true``. A finished folder is kept as
    it is by a run of the same inputs, refused by any other."""
    mark = read_marker(folder) or {}
    mark["outputs"] = _outputs(folder)
    mark["finished"] = True
    write_json(folder / MARKER, mark)


def write_run(command: str, name: str, inputs: Inputs, folder: Path | None,
              write: Callable[[Path], None]) -> Path:
    """A command's whole folder: :func:`prepare_output`, ``write(folder)`` (every file, each
    atomically; not called when the folder holds the finished run of these inputs), then
    :func:`finish_output` -> the folder."""
    out, state = prepare_output(command, name, inputs, folder)
    if state != FINISHED:
        write(out)
        finish_output(out)
    return out


def new_run_dir(name: str, data_for_hash: Any, out: Path | None = None,
                command: str | None = None) -> Path:
    """An output folder (:func:`prepare_output`) with the content hash of ``data_for_hash``
    as its fingerprint."""
    folder, _ = prepare_output(command or name, name, content_hash(data_for_hash, 16), out)
    return folder


def write_columns(path: Path, columns: Mapping[str, Any], float_format: str = "%.9g") -> None:
    """Atomically write equal-length columns (numpy arrays or lists) as CSV, without pandas.

    Floats use ``float_format`` with NaN written empty (as pandas does), booleans True/False.
    """
    import re

    import numpy as np

    names = list(columns)
    cols = [np.asarray(columns[n]) for n in names]
    n = len(cols[0]) if cols else 0
    if any(len(c) != n for c in cols):
        raise ValueError("columns of different lengths")
    fmts = [float_format if c.dtype.kind == "f" else "%d" if c.dtype.kind in "iu" else "%s"
            for c in cols]
    row = ",".join(fmts)
    body = "\n".join(row % r for r in zip(*(c.tolist() for c in cols), strict=True))
    body = re.sub(r"(?<![^,\n])nan(?![^,\n])", "", body)  # NaN: an empty field
    write_text(path, ",".join(names) + "\n" + (body + "\n" if n else ""))


def manifest(command: str, **fields: Any) -> dict[str, Any]:
    """The common manifest: version, command, time, git commit, platform, the command's
    estimated and elapsed time so far (``progress.timing``), plus ``fields``."""
    import numba
    import numpy

    from ema_cli.progress import timing

    return {
        "ema_version": __version__,
        "command": command,
        "created": _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds"),
        "git_commit": git_commit(),
        "python": platform.python_version(),
        "numpy": numpy.__version__,
        "numba": numba.__version__,
        "machine": platform.machine(),
        "timing": timing(),
        **fields,
    }
