"""The executor's two remote pools (``sweep.executor``): loky worker processes and a Dask
cluster, and the worker side of every block (:func:`call`).

A pool submits a block, waits for some to finish and cancels the rest; what a failure costs
(a retry, a report) is the executor's decision. Worker side: the kernel's threads are set for
the worker (one numba thread; on a Dask worker running several task threads, the serial
kernel), the block runs, its value comes back with the seconds it took there.
"""

from __future__ import annotations

import contextlib
import functools
import hashlib
import re
import time
import uuid
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

LOKY_IDLE_S = 300  # loky workers idle this long shut down (kept warm between stages) [s]


@dataclass
class _Outcome:
    """What the worker side returns: the value and the seconds the task took there."""

    value: Any
    seconds: float


def source_fingerprint(root: Path) -> str:
    """A hash of every ``*.py`` file under ``root`` (relative paths and contents) [12 hex]."""
    h = hashlib.sha256()
    for path in sorted(root.rglob("*.py")):
        h.update(path.relative_to(root).as_posix().encode() + b"\0" + path.read_bytes()
                 + b"\0")
    return h.hexdigest()[:12]


@functools.cache
def code_key() -> str:
    """This process's ema: its version and :func:`source_fingerprint` of the package. A Dask
    worker must run the same code as the client, or its blocks' bits could differ."""
    import ema_cli

    return f"{ema_cli.__version__}+{source_fingerprint(Path(ema_cli.__file__).parent)}"


def check_code(expected: str, where: str) -> None:
    """Refuse to run a block on a worker whose ema is not the client's (``expected``:
    the client's :func:`code_key`; ``where`` names the worker)."""
    from ema_cli.errors import EmaError

    if code_key() != expected:
        raise EmaError(f"{where} runs ema {code_key()}, this process ema {expected} "
                       "(version+source hash): install the same ema on every worker "
                       "(docs/cluster.md)", 1)


def call(fn: Callable[..., Any], args: tuple[Any, ...], where: str,
         code: str | None = None) -> _Outcome:
    """Worker side: ``fn(*args)`` with the kernel threads of ``where`` -> the value and its
    seconds. ``process``: a loky worker, one numba thread; ``dask``: a Dask worker, one numba
    thread when it runs one task thread, else the serial kernel (safe in any thread).
    ``code``: the client's :func:`code_key`, checked against this worker's first."""
    import numba

    from ema_cli.sim.runner import serial_kernels

    t0 = time.perf_counter()
    serial = False
    if where == "dask":
        from dask.distributed import get_worker

        worker = get_worker()
        if code is not None:
            check_code(code, f"dask worker {worker.address}")
        serial = worker.state.nthreads > 1
    elif code is not None:
        check_code(code, f"worker {where}")
    previous = numba.get_num_threads()
    numba.set_num_threads(1)
    try:
        with serial_kernels(serial):
            value = fn(*args)
    finally:
        numba.set_num_threads(previous)
    return _Outcome(value, time.perf_counter() - t0)


LOST = "worker lost"  # how a retry after a lost worker starts [-]


def killed_worker(exc: BaseException) -> bool:
    """True for Dask's KilledWorker: the scheduler gave a block up after losing workers."""
    return type(exc).__name__ == "KilledWorker"


def describe(exc: BaseException) -> str:
    """One line: the exception's type and message (a worker process that died: its exit
    code)."""
    name = type(exc).__name__
    if name in ("TerminatedWorkerError", "BrokenProcessPool"):
        codes = re.search(r"exit codes of the workers are (\{[^}]*\})", str(exc))
        return f"{LOST}: a worker process died" + (f" (exit {codes.group(1)})" if codes
                                                    else "")
    if killed_worker(exc):
        return "KilledWorker: the scheduler gave it up after losing the workers running it"
    text = " ".join(str(exc).split())[:300]
    return f"{name}: {text}" if text else name


class LokyPool:
    """Blocks in loky worker processes, at most one per worker in flight (a worker that dies
    breaks the pool: every block in flight is lost and run again on a fresh pool)."""

    def __init__(self, ex: Any) -> None:
        self.ex = ex
        self.futures: dict[Any, int] = {}
        self.pool = self._pool()

    def _pool(self) -> Any:
        """joblib's reusable loky pool (a fresh one if it broke), as joblib's own Parallel
        gets it, so the two can follow each other in one process; no memmapping."""
        from joblib.executor import get_memmapping_executor

        return get_memmapping_executor(self.ex.workers, timeout=LOKY_IDLE_S, max_nbytes=None)

    @property
    def in_flight(self) -> int:
        return len(self.futures)

    def submit(self, i: int, task: Any) -> None:
        from joblib.externals.loky.process_executor import BrokenProcessPool

        try:
            fut = self.pool.submit(call, task.fn, task.args, "process")
        except (BrokenProcessPool, RuntimeError):  # broken or shut down: a fresh pool
            self.pool = self._pool()
            fut = self.pool.submit(call, task.fn, task.args, "process")
        self.futures[fut] = i

    def wait(self) -> list[tuple[int, bool, Any]]:
        """Block until some finish -> (index, ok, outcome or exception) of each."""
        from concurrent.futures import FIRST_COMPLETED
        from concurrent.futures import wait as wait_any

        done, _ = wait_any(list(self.futures), return_when=FIRST_COMPLETED)
        out = []
        for fut in done:
            i = self.futures.pop(fut)
            exc = fut.exception()
            out.append((i, exc is None, fut.result() if exc is None else exc))
        if any(not ok for _, ok, _ in out):
            self.pool = self._pool()  # a new pool if this one broke
        return sorted(out, key=lambda r: r[0])

    def cancel(self) -> None:
        """Stop: blocks not started are cancelled; on an interruption the workers are
        killed (a running block would otherwise finish for nothing)."""
        for fut in self.futures:
            fut.cancel()
        if any(not f.done() for f in self.futures):
            with contextlib.suppress(Exception):
                self.pool.shutdown(wait=False, kill_workers=True)
        self.futures.clear()


class DaskPool:
    """Blocks on a Dask cluster (futures with keys of their own, so the scheduler's events
    name them)."""

    def __init__(self, ex: Any) -> None:
        from dask.distributed import as_completed

        self.ex = ex
        self.client = ex.client
        self.futures: dict[str, tuple[Any, int]] = {}
        self.done = as_completed([], with_results=False, loop=self.client.loop)

    @property
    def in_flight(self) -> int:
        return len(self.futures)

    def submit(self, i: int, task: Any) -> None:
        slug = re.sub(r"[^A-Za-z0-9_.-]+", "-", task.label)[:60]
        key = f"ema-{slug}-{uuid.uuid4().hex[:12]}"
        with self.ex._lock:
            self.ex._labels[key] = task.label
        fut = self.client.submit(call, task.fn, task.args, "dask", code_key(), key=key,
                                 pure=False, retries=0)
        self.futures[key] = (fut, i)
        self.done.add(fut)

    def wait(self) -> list[tuple[int, bool, Any]]:
        out = []
        for fut in self.done.next_batch(block=True):
            _, i = self.futures.pop(fut.key)
            with self.ex._lock:
                self.ex._labels.pop(fut.key, None)
            if fut.status == "finished":
                try:
                    out.append((i, True, fut.result()))
                except Exception as exc:  # lost between finishing and being fetched
                    out.append((i, False, exc))
            else:
                exc = fut.exception() if fut.status == "error" else None
                out.append((i, False, exc or RuntimeError(f"block {fut.status}")))
            fut.release()
        return sorted(out, key=lambda r: r[0])

    def cancel(self) -> None:
        futs = [f for f, _ in self.futures.values()]
        if futs:
            with contextlib.suppress(Exception):
                self.client.cancel(futs)
        with self.ex._lock:
            for key in self.futures:
                self.ex._labels.pop(key, None)
        self.futures.clear()


