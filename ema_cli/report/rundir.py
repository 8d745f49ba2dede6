"""Run folders, atomic file writes and manifests (every output folder describes itself).

The generic pieces live below every layer: atomic replacement and ``RESULTS_ROOT`` in
``ema_cli.files``, content hashes in ``ema_cli.hashing``.
"""

from __future__ import annotations

import datetime as _dt
import json
import os
import platform
import subprocess
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
