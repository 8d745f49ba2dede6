"""Where results live and how a file is replaced atomically (temporary sibling + rename).

Below every layer (imports nothing of the package): the job cache and the report layer both
use it. Only ``report/`` writes result files (CSV, PNG, JSON, manifests) through it.
"""

from __future__ import annotations

import os
import secrets
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import Any

RESULTS_ROOT = Path("results")


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


_FILE_MODE = 0o666 & ~_umask()  # what open() would give a new file


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


def save_array(path: Path, array: Any) -> None:
    """Atomically write a numpy array as ``.npy`` (no pickles), through :class:`AtomicFile`."""
    import numpy as np

    f = AtomicFile(path)
    try:
        with open(f.tmp, "xb") as out:
            np.save(out, array, allow_pickle=False)
        f.commit()
    except BaseException:
        f.discard()
        raise


class AtomicFile:
    """A file written over time (e.g. streamed as results arrive) into a temporary sibling.

    ``tmp`` is a fresh unique name beside ``path`` that the writer creates (a new file: ext4
    flushes a file truncated by its writer when it is closed, measured 0.25 s per GB);
    :meth:`commit` renames it to ``path`` (atomic on one filesystem), :meth:`discard` deletes
    it. Until ``commit`` nothing exists under ``path``, so an interrupted write never leaves a
    partial file there.
    """

    def __init__(self, path: Path) -> None:
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self.tmp = self.path.with_name(f".{self.path.name}.{secrets.token_hex(6)}.tmp")

    def commit(self) -> Path:
        """Rename the finished temporary file into place; returns ``path``."""
        try:
            os.replace(self.tmp, self.path)
        except BaseException:
            self.discard()
            raise
        return self.path

    def discard(self) -> None:
        """Delete the temporary file (nothing is left behind)."""
        self.tmp.unlink(missing_ok=True)
