"""Where results live and how a file is replaced atomically (temporary sibling + rename).

Below every layer (imports only ``errors``): the job cache and the report layer both use it.
Only ``report/`` writes result files (CSV, PNG, JSON, manifests) through it. Reading a user's
CSV with one set of error messages (:func:`read_csv`) lives here too.
"""

from __future__ import annotations

import os
import secrets
from collections.abc import Callable
from pathlib import Path
from typing import Any

RESULTS_ROOT = Path("results")


def shown(path: str | Path) -> str:
    """A path as output shows it: relative to the working folder when inside it (no ``../``),
    else its last two parts (``configs/deadzone1.yaml``): never the machine's absolute path."""
    p = Path(path)
    full = p.resolve()
    try:
        return full.relative_to(Path.cwd().resolve()).as_posix() or "."
    except ValueError:
        return Path(*full.parts[-2:]).as_posix() if len(full.parts) > 2 else full.name


def atomic_write(path: Path, write: Callable[[Path], None]) -> None:
    """Write ``path`` through ``write(tmp)``, ``tmp`` a fresh temporary sibling that ``write``
    creates (:class:`AtomicFile`), then rename it into place; on any error nothing is left."""
    f = AtomicFile(path)
    try:
        write(f.tmp)
        f.commit()
    except BaseException:
        f.discard()
        raise


def save_array(path: Path, array: Any) -> None:
    """Atomically write a numpy array as ``.npy`` (no pickles), through :func:`atomic_write`;
    the temporary file is created exclusively (``xb``)."""
    import numpy as np

    def write(tmp: Path) -> None:
        with open(tmp, "xb") as out:
            np.save(out, array, allow_pickle=False)

    atomic_write(path, write)


class AtomicFile:
    """A file written (possibly over time, streamed as results arrive) into a temporary sibling:
    the one implementation behind :func:`atomic_write` and :func:`save_array`.

    ``tmp`` is a fresh unique name beside ``path`` (48 random bits) that the writer creates,
    with the mode ``open`` gives a new file; never an existing file truncated by its writer
    (ext4's auto_da_alloc forces out a file truncated and rewritten when it is closed: 0.25 s
    per GB measured). :meth:`commit` renames it to ``path`` (atomic on one filesystem),
    :meth:`discard` deletes it. Until ``commit`` nothing exists under ``path``, so an
    interrupted write never leaves a partial file there.
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


def read_csv(path: str | Path, what: str = "data file", hint: str = "") -> Any:
    """Read the CSV ``path`` as a DataFrame, or raise EmaError naming ``what`` and the file
    (it does not exist, is not a file (``hint`` says what it should be), or pandas cannot
    parse it)."""
    import pandas as pd

    from ema_cli.errors import EmaError

    p = Path(path)
    if not p.exists():
        raise EmaError(f"{what} '{p}' does not exist")
    if not p.is_file():
        raise EmaError(f"{what} '{p}' is not a file{hint}")
    try:
        return pd.read_csv(p)
    except Exception as exc:  # pandas raises many types for malformed files
        raise EmaError(f"{what} '{p}' is not a readable CSV: {exc}") from None
