"""Draw a figure in a forked child process while the parent simulates and writes its tables.

A short ``ema simulate`` spends most of its time importing numba (parent's work) and
matplotlib, and drawing one PNG (the figure's work). On a machine with two cores the two halves
can run at once: :class:`FigureWorker` forks before either is imported; the child imports
matplotlib and waits; the parent sends it what to draw once the run is done, writes its CSVs,
and waits for the PNG before it writes the manifest. The child writes through the same atomic
writer, so a failed or killed child leaves no partial file, and the parent turns a failure
into an EmaError naming the file.

Used only where it is safe: ``os.fork`` exists and this process runs no other thread (a fork
of a threaded process may deadlock). Otherwise :func:`start` returns None and the caller draws
in-process. Nothing here is needed for correctness: the PNG is byte-for-byte the one the
in-process path writes.
"""

from __future__ import annotations

import contextlib
import os
import pickle
import struct
import sys
import threading
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from ema_cli.errors import EmaError

_LEN = struct.Struct("<Q")


class FigureWorker:
    """A forked child that draws the tracking figure of one run (see the module docstring)."""

    def __init__(self) -> None:
        to_child_r, self._to_child = os.pipe()
        self._from_child, from_child_w = os.pipe()
        self.pid = os.fork()
        if self.pid == 0:  # the child: never returns
            os.close(self._to_child)
            os.close(self._from_child)
            _child(to_child_r, from_child_w)
        os.close(to_child_r)
        os.close(from_child_w)

    def submit(self, path: Path, table: Mapping[str, Any], title: str) -> None:
        """Ask the child to draw ``tracking_figure(table, title)`` into ``path``."""
        data = pickle.dumps((str(path), dict(table), title), protocol=pickle.HIGHEST_PROTOCOL)
        with os.fdopen(self._to_child, "wb", closefd=False) as f:
            f.write(_LEN.pack(len(data)))
            f.write(data)
        os.close(self._to_child)

    def wait(self) -> float:
        """Wait for the figure -> the child's drawing and writing time [s]; EmaError if it
        failed."""
        with os.fdopen(self._from_child, "rb", closefd=False) as f:
            reply = f.read()
        os.close(self._from_child)
        _, status = os.waitpid(self.pid, 0)
        code = os.waitstatus_to_exitcode(status)
        if code != 0 or not reply:
            message = reply.decode("utf-8", "replace").strip() if reply else ""
            raise EmaError(f"the figure could not be drawn: {message or f'exit code {code}'}", 1)
        return float(reply.decode())

    def cancel(self) -> None:
        """Let the child go without drawing (the run failed); safe to call at any point."""
        for fd in (self._to_child, self._from_child):
            with contextlib.suppress(OSError):
                os.close(fd)
        with contextlib.suppress(ChildProcessError):
            os.waitpid(self.pid, 0)


def _child(fd_in: int, fd_out: int) -> None:  # pragma: no cover - runs in the forked child
    code = 1
    try:
        import time

        from ema_cli.report.figures import tracking_figure
        from ema_cli.report.rundir import write_figure

        with os.fdopen(fd_in, "rb") as f:
            head = f.read(_LEN.size)
            if len(head) < _LEN.size:  # the parent cancelled
                os._exit(0)
            path, table, title = pickle.loads(f.read(_LEN.unpack(head)[0]))
        t0 = time.perf_counter()
        write_figure(Path(path), tracking_figure(table, title))
        reply = f"{time.perf_counter() - t0:.6f}".encode()
        code = 0
    except BaseException as exc:  # noqa: BLE001 - reported to the parent, one line
        reply = f"{type(exc).__name__}: {' '.join(str(exc).split())}"[:300].encode()
    try:
        os.write(fd_out, reply)
        os.close(fd_out)
    finally:
        sys.stdout.flush()
        os._exit(code)


def start() -> FigureWorker | None:
    """A worker if this process can fork safely, else None: POSIX, no other Python thread and
    numba not loaded yet (its native worker threads would be forked mid-flight), and
    ``EMA_NO_FORK`` unset."""
    if not hasattr(os, "fork") or threading.active_count() != 1 or "numba" in sys.modules:
        return None
    if os.environ.get("EMA_NO_FORK"):
        return None
    try:
        return FigureWorker()
    except OSError:
        return None
