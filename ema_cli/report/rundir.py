"""Run folders, atomic file writes and manifests (every output folder describes itself).

The generic pieces live below every layer: atomic replacement and ``RESULTS_ROOT`` in
``ema_cli.files``, content hashes in ``ema_cli.hashing``.
"""

from __future__ import annotations

import datetime as _dt
import json
import os
import platform
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from ema_cli import __version__
from ema_cli.errors import EmaError
from ema_cli.files import RESULTS_ROOT, atomic_write
from ema_cli.hashing import content_hash, json_default


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
    """Atomically save a matplotlib Figure as PNG (and close it if pyplot manages it)."""
    import sys

    try:
        atomic_write(path, lambda p: fig.savefig(p, dpi=dpi, format="png"))
    finally:
        if "matplotlib.pyplot" in sys.modules:
            sys.modules["matplotlib.pyplot"].close(fig)


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
"""Written first into every output folder: which command made it, for which inputs, finished."""


def _read_marker(folder: Path) -> dict[str, Any] | None:
    try:
        data = json.loads((folder / MARKER).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    return data if isinstance(data, dict) else None


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


def check_output(out: Path | None, command: str, fingerprint: str | None = None,
                 resume: bool = False) -> bool:
    """Check ``--out`` against the policy of :func:`prepare_output` without creating anything
    (commands call it before a long computation) -> True if it is a run to resume."""
    if out is None:
        return False
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise EmaError(f"--out '{out}' is a file; expected a folder (new or empty)")
    if out.is_dir():
        try:  # a job cache (.cache) alone does not make a folder a result
            busy = any(p.name != CACHE_NAME or not _only_job_cache(p) for p in out.iterdir())
        except OSError as exc:
            raise EmaError(f"--out '{out}' cannot be read: {exc.strerror}") from None
        if busy:
            mark = _read_marker(out)
            same = (mark is not None and mark.get("command") == command
                    and mark.get("fingerprint") == fingerprint)
            if resume and same and not mark.get("finished"):
                return True
            if mark is None:
                what = "other files"
            elif mark.get("finished"):
                what = f"a finished `ema {mark.get('command')}` run"
            elif same:
                what = f"an unfinished `ema {command}` run of the same inputs (it cannot resume)"
            elif mark.get("command") != command:
                what = f"an unfinished `ema {mark.get('command')}` run"
            else:
                what = f"an unfinished `ema {mark.get('command')}` run of other inputs"
            raise EmaError(f"--out '{out}' already holds {what}; results are never overwritten: "
                           "choose a new folder or delete that one")
    parent = next((p for p in out.absolute().parents if p.exists()), None)
    if parent is not None and not parent.is_dir():
        raise EmaError(f"--out '{out}': '{parent}' is a file, not a folder")
    return False


LATEST = "latest"
"""The symlink in ``results/<command>/<config-name>/`` to the newest run folder there."""


def default_folder(command: str, name: str) -> Path:
    """``results/<command>/<config-name>/``: where the default run folders of a command and a
    config go (``name`` made safe for a folder name)."""
    import re

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
        mark = _read_marker(p)
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


def prepare_output(command: str, name: str, fingerprint: str, out: Path | None = None,
                   resume: bool = False) -> tuple[Path, bool]:
    """The one output-folder policy of every command -> (folder, resumed).

    ``out`` None: a new folder ``results/<command>/<name>/<stamp>_<hash>/`` (``name``: the
    config's name), and ``results/<command>/<name>/latest`` points at it; with ``resume``, an
    unfinished run of the same inputs there is continued instead. A given ``out`` must be new
    or empty: earlier results are never overwritten. The one exception, when ``resume`` is
    set, is an unfinished run of the same ``command`` with the same ``fingerprint`` (the hash of
    its resolved inputs), which is continued. Errors name ``--out`` and what was expected.
    """
    default = out is None
    if out is None:
        parent = default_folder(command, name)
        earlier = _unfinished(parent, command, fingerprint) if resume else None
        if earlier is not None:
            point_latest(earlier)
            return earlier, True
        stamp = _dt.datetime.now().strftime("%Y%m%d-%H%M%S")
        out = parent / f"{stamp}_{fingerprint[:8]}"
        k = 1
        base = out
        while out.exists():
            out = base.with_name(f"{base.name}-{k}")
            k += 1
    out = Path(out)
    if check_output(out, command, fingerprint, resume):
        return out, True
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise EmaError(f"--out '{out}': cannot create the folder ({exc.strerror})") from None
    if not os.access(out, os.W_OK):
        raise EmaError(f"--out '{out}': the folder is not writable")
    write_json(out / MARKER, {"command": command, "fingerprint": fingerprint,
                              "created": _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds"),
                              "finished": False})
    if default:
        point_latest(out)
    return out, False


def finish_output(folder: Path) -> None:
    """Mark ``folder`` finished: :func:`prepare_output` will never resume into it."""
    mark = _read_marker(folder) or {}
    mark["finished"] = True
    write_json(folder / MARKER, mark)


def new_run_dir(name: str, data_for_hash: Any, out: Path | None = None,
                command: str | None = None) -> Path:
    """A new output folder for a run that cannot be resumed: :func:`prepare_output` with the
    content hash of ``data_for_hash`` as fingerprint."""
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
    """The common manifest: version, command, time, git commit, platform, plus ``fields``."""
    import numba
    import numpy

    return {
        "ema_version": __version__,
        "command": command,
        "created": _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds"),
        "git_commit": git_commit(),
        "python": platform.python_version(),
        "numpy": numpy.__version__,
        "numba": numba.__version__,
        "machine": platform.machine(),
        **fields,
    }
