"""Run folders, atomic file writes and manifests (every output folder describes itself)."""

from __future__ import annotations

import datetime as _dt
import hashlib
import json
import os
import platform
import subprocess
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import Any

from ema_cli import __version__
from ema_cli.errors import EmaError

RESULTS_ROOT = Path("results")


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


_FILE_MODE = 0o666 & ~_umask()  # what open() would give a new file


def _json_default(o: Any) -> Any:
    import numpy as np

    if isinstance(o, np.integer):
        return int(o)
    if isinstance(o, np.floating):
        return float(o)
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, Path):
        return str(o)
    raise TypeError(f"not JSON serialisable: {type(o).__name__}")


def atomic_write(path: Path, write: Callable[[Path], None]) -> None:
    """Write ``path`` through ``write(tmp)`` into a temporary sibling, then rename it into place."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    os.close(fd)
    os.chmod(tmp, _FILE_MODE)  # mkstemp creates 0600; results are ordinary shared files
    try:
        write(Path(tmp))
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def write_text(path: Path, text: str) -> None:
    """Atomically write a text file (UTF-8)."""
    atomic_write(path, lambda p: p.write_text(text, encoding="utf-8"))


def write_json(path: Path, data: Any) -> None:
    """Atomically write JSON (numpy values converted; NaN written as null)."""
    text = json.dumps(_nan_to_none(data), indent=2, default=_json_default, allow_nan=False)
    write_text(path, text + "\n")


def _nan_to_none(o: Any) -> Any:
    import math

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
    """Atomically save a matplotlib Figure as PNG and close it."""
    import matplotlib.pyplot as plt

    try:
        atomic_write(path, lambda p: fig.savefig(p, dpi=dpi, format="png"))
    finally:
        plt.close(fig)


def content_hash(data: Any, length: int = 12) -> str:
    """A stable short hash of JSON-serialisable ``data``."""
    text = json.dumps(data, sort_keys=True, default=_json_default)
    return hashlib.sha256(text.encode()).hexdigest()[:length]


def git_commit() -> str | None:
    """The current git commit of the working directory, when available."""
    try:
        out = subprocess.run(["git", "rev-parse", "HEAD"], capture_output=True, text=True,
                             timeout=5, check=False)
    except (OSError, subprocess.SubprocessError):
        return None
    return out.stdout.strip() or None if out.returncode == 0 else None


def new_run_dir(name: str, data_for_hash: Any, out: Path | None = None) -> Path:
    """Create the output folder: ``out`` if given, else ``results/<name>/<stamp>_<hash>/``.

    An existing non-empty ``out`` is refused unless it is a previous run of the same kind
    (the caller decides); folders are never silently overwritten.
    """
    if out is None:
        stamp = _dt.datetime.now().strftime("%Y%m%d-%H%M%S")
        out = RESULTS_ROOT / name / f"{stamp}_{content_hash(data_for_hash, 8)}"
        k = 1
        base = out
        while out.exists():
            out = base.with_name(f"{base.name}-{k}")
            k += 1
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise EmaError(f"cannot create output folder '{out}': {exc.strerror}", 1) from None
    if not os.access(out, os.W_OK):
        raise EmaError(f"output folder '{out}' is not writable", 1)
    return out


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
