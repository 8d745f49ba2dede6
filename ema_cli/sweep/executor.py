"""The one executor of every batch of independent kernel work: in-process, loky processes or a
Dask cluster, with the results in submission order and lost work retried.

A command cuts its work into blocks (a sweep's chunk of jobs, a yield's units, a tuning
generation's candidates, a design's acceptance cases, an identification's starts), each a
:class:`Task`: a module-level function, its arguments and a label naming what it holds
(``units 200-207``). :meth:`Executor.map` runs them on the backend and yields each result with
its index, in submission order by default, so what a command computes from them never depends
on the backend or on the number of workers.

Backends (:data:`BACKENDS`): ``threads`` runs every task here, one after the other, each
spreading its kernel batches over numba's threads (``serial``: one thread); ``loky`` runs them
in worker processes (one numba thread each); ``dask`` on the workers of a Dask scheduler (a
worker running one task thread uses the parallel kernel on one numba thread, a worker running
several uses the serial kernel, which is safe in any thread; both give the same bits). A
Dask worker runs a block only if its ema is the client's (version and a hash of every source,
``pools.code_key``): one with other code could give other bits, so it refuses with a user error.

Failures. An :class:`~ema_cli.errors.EmaError` raised by a task is the user's (a sampled
unit that is not a valid actuator, a missing file): it stops the run at once, as it would
have here. Any other failure costs the block an attempt: a worker process that died (loky:
the pool breaks and every block in flight is run again on a fresh one), a Dask worker lost
(the scheduler runs its blocks again elsewhere on its own, up to its ``allowed-failures``;
the executor learns of it from the scheduler's ``remove-worker`` events), an exception. A
block is run at most :data:`MAX_ATTEMPTS` times; a block that failed that often is reported
with its label (:class:`BlockFailed`, or returned as a :class:`Failure` to a caller that
carries on without it, as a sweep marks its jobs failed) and never silently dropped. Every
retry is recorded (:attr:`Executor.retries`).

Commands below the API take the executor from the context (:func:`executing`,
:func:`current`), as joblib's ``parallel_config`` does, so the compute code that dispatches
starts or candidates needs no new argument; without one they run in-process as before.
"""

from __future__ import annotations

import contextlib
import contextvars
import itertools
import os
import re
import threading
import time
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass
from typing import Any

from ema_cli.errors import EmaError
from ema_cli.sweep.pools import LOST, DaskPool, LokyPool, describe, killed_worker

BACKENDS = ("auto", "loky", "threads", "dask")
LOCAL_DEFAULT = "threads"
"""What ``auto`` means on one machine: threads in this process (numba's count). Measured with
experiments/bench_sweep.py (1,000 jobs of 1 s, 2 cores, fresh processes, medians of 5): threads
3.85 s end to end, loky 4.73 s; the kernel time is the same (3.43 s vs 3.46 s), loky's extra
~1 s is starting the workers and loading the kernel in each."""
MAX_ATTEMPTS = 2  # runs of one block at most: a lost worker's block is run once more [-]
DASK_AHEAD = 2  # blocks submitted per Dask worker thread (one running, one queued) [-]
BUFFER_FACTOR = 2  # finished blocks held for the submission order, per block in flight [-]
DASK_TIMEOUT = "10s"  # connecting to a Dask scheduler gives up after this
DASK_HINT = "the dask backend needs dask.distributed: pip install 'ema-cli[dask]'"
SCHEDULER_ADDRESS = re.compile(
    r"(?:(?:tcp|tls|ucx|ws|wss)://)?(?:\[[0-9A-Fa-f:.]+\]|[A-Za-z0-9_.-]+):[0-9]{1,5}")
"""What a dask scheduler address looks like: [tcp://]host:port (tls, ucx, ws(s) too)."""


@dataclass(frozen=True)
class Task:
    """One block of work: ``fn(*args)`` (a module-level function: it is pickled to workers)
    and ``label``, what the block holds in the user's words (``units 200-207``)."""

    fn: Callable[..., Any]
    args: tuple[Any, ...]
    label: str


@dataclass(frozen=True)
class Failure:
    """A block that failed :data:`MAX_ATTEMPTS` times: its label, the last error and how
    many workers were lost while running it."""

    label: str
    error: str
    lost: int = 0

    @property
    def message(self) -> str:
        lost = f" ({self.lost} worker{'s' if self.lost != 1 else ''} lost while it ran)" if (
            self.lost) else ""
        return f"{self.label}: failed {MAX_ATTEMPTS} times{lost}, last: {self.error}"


class BlockFailed(EmaError):
    """A block failed :data:`MAX_ATTEMPTS` times (exit 1): the message names its units."""

    def __init__(self, failure: Failure, hint: str = "") -> None:
        super().__init__(failure.message + (f"; {hint}" if hint else ""), 1)
        self.failure = failure

    def __reduce__(self) -> Any:
        return (type(self), (self.failure,))


def cpu_count() -> int:
    """Cores this process may use."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


def resolve_workers(n_jobs: int | None) -> int:
    """``n_jobs`` (None or -1: all cores) -> a worker count >= 1."""
    if n_jobs is None or n_jobs == -1:
        return cpu_count()
    if n_jobs < 1:
        raise EmaError(f"n_jobs must be >= 1, or -1 for all cores, got {n_jobs}")
    return n_jobs


def resolve_backend(backend: str | None, workers: int) -> str:
    """The backend to run: ``auto`` picks the local default; one worker runs serially."""
    backend = backend or "auto"
    if backend not in BACKENDS:
        raise EmaError(f"unknown backend '{backend}'; expected one of {', '.join(BACKENDS)}")
    if backend == "auto":
        backend = LOCAL_DEFAULT
    if backend in ("loky", "threads") and workers == 1:
        return "serial"
    return backend


def check_dask(scheduler: str | None) -> None:
    """Refuse the dask backend early: no scheduler address, or dask.distributed missing."""
    if not scheduler:
        raise EmaError("the dask backend needs a scheduler address: --scheduler ADDRESS "
                       "(or parallel.scheduler in the config)")
    if not SCHEDULER_ADDRESS.fullmatch(scheduler.strip()):
        raise EmaError(f"--scheduler {scheduler!r} is not a dask scheduler address; expected "
                       "tcp://HOST:PORT or HOST:PORT (or parallel.scheduler in the config)")
    try:
        import dask.distributed  # noqa: F401
    except ImportError:
        raise EmaError(DASK_HINT) from None


class Executor:
    """Runs :class:`Task` blocks on one backend (``serial``, ``threads``, ``loky``,
    ``dask``) with ``workers`` workers (the dask backend: every thread of the cluster).

    Use it as a context manager (the Dask client is connected on entry, closed on exit).
    ``retries`` lists every block run again (label and why); ``task_seconds`` the seconds each
    finished block took on its worker, in submission order of the last :meth:`map`.
    """

    def __init__(self, backend: str = "threads", workers: int = 1,
                 scheduler: str | None = None) -> None:
        self.backend = backend
        self.workers = max(int(workers), 1)
        self.scheduler = scheduler
        self.retries: list[tuple[str, str]] = []
        self.task_seconds: list[float] = []
        self.blocks = 0  # blocks finished, every map of this executor
        self._client: Any = None
        self._labels: dict[str, str] = {}  # dask key -> label, of the blocks in flight
        self._lock = threading.Lock()
        if backend == "dask":
            check_dask(scheduler)
        elif backend not in ("serial", "threads", "loky"):
            raise EmaError(f"unknown backend '{backend}'; expected one of "
                           f"{', '.join(BACKENDS)}")

    # ------------------------------------------------------------------ lifetime
    def __enter__(self) -> Executor:
        if self.backend == "dask" and self._client is None:
            self._connect()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        """Disconnect from the Dask scheduler (loky's workers stay for the next map)."""
        if self._client is not None:
            with contextlib.suppress(Exception):
                self._client.unsubscribe_topic("all")
            with contextlib.suppress(Exception):
                self._client.close()
            self._client = None

    def describe(self) -> dict[str, Any]:
        """Where the work ran, for a manifest: backend, workers, scheduler, the blocks run
        again (``retries``: block and why)."""
        return {"backend": self.backend, "workers": self.workers, "scheduler": self.scheduler,
                "blocks": self.blocks,
                "retries": [{"block": b, "why": w} for b, w in self.retries]}

    @property
    def remote(self) -> bool:
        """True when tasks run outside this process (loky, dask)."""
        return self.backend in ("loky", "dask")

    @property
    def client(self) -> Any:
        """The Dask client (connected on first use)."""
        if self._client is None:
            self._connect()
        return self._client

    def _connect(self) -> None:
        from dask.distributed import Client

        try:
            self._client = Client(self.scheduler, timeout=DASK_TIMEOUT, set_as_default=False)
        except (OSError, TimeoutError) as exc:
            raise EmaError(f"cannot reach the dask scheduler at {self.scheduler!r}: {exc}",
                           1) from None
        self._client.subscribe_topic("all", self._on_event)
        self.workers = max(1, sum(self._client.nthreads().values()))

    def _on_event(self, event: Any) -> None:
        """A scheduler event (client's loop thread): a worker lost while it ran (or held the
        result of) blocks of ours, which the scheduler runs again: record their retries."""
        msg = event[1] if isinstance(event, tuple) and len(event) == 2 else event
        if not isinstance(msg, dict) or msg.get("action") != "remove-worker" or msg.get(
                "expected"):
            return
        keys = set(msg.get("processing-tasks") or ()) | set(msg.get("lost-computed-tasks")
                                                            or ())
        with self._lock:
            for key in keys:
                if key in self._labels:
                    self.retries.append((self._labels[key],
                                         f"{LOST}: dask worker {msg.get('worker', '?')}"))

    def run_on_workers(self, fn: Callable[..., Any], *args: Any) -> None:
        """Run ``fn(*args)`` once on every Dask worker (e.g. load the kernel); nothing on the
        other backends."""
        if self.backend == "dask":
            self.client.run(fn, *args)

    # ------------------------------------------------------------------ the blocks
    def map(self, tasks: Iterable[Task], *, ordered: bool = True, failures: str = "raise"
            ) -> Iterator[tuple[int, Any]]:
        """Run every task -> ``(index, value)`` pairs, in submission order (``ordered``) or as
        they finish. ``failures``: ``raise`` (:class:`BlockFailed`) or ``return`` (the value
        is a :class:`Failure`). Tasks are drawn from ``tasks`` lazily, a few per worker ahead:
        a caller that stops iterating (a target reached) cancels the rest."""
        self.task_seconds = []
        if failures not in ("raise", "return"):
            raise ValueError(f"failures must be 'raise' or 'return', got {failures!r}")
        if not self.remote:
            yield from self._inline(tasks)
            return
        yield from self._remote(iter(tasks), ordered, failures)

    def run(self, tasks: Iterable[Task]) -> list[Any]:
        """Every task's value, in submission order (a failed block raises)."""
        return [v for _, v in self.map(tasks)]

    def _inline(self, tasks: Iterable[Task]) -> Iterator[tuple[int, Any]]:
        """In this process: each task with numba's threads (``workers`` of them; ``serial``:
        one); exceptions propagate as they are."""
        import numba

        for i, task in enumerate(tasks):
            previous = numba.get_num_threads()
            numba.set_num_threads(min(self.workers if self.backend == "threads" else 1,
                                      numba.config.NUMBA_NUM_THREADS))
            t0 = time.perf_counter()
            try:
                value = task.fn(*task.args)
            finally:
                numba.set_num_threads(previous)
            self.task_seconds.append(time.perf_counter() - t0)
            self.blocks += 1
            yield i, value

    def _remote(self, tasks: Iterator[Task], ordered: bool, failures: str
                ) -> Iterator[tuple[int, Any]]:
        pool = LokyPool(self) if self.backend == "loky" else DaskPool(self)
        ahead = self.workers * (DASK_AHEAD if self.backend == "dask" else 1)
        held: dict[int, Any] = {}  # finished, waiting for the blocks before them
        seconds: dict[int, float] = {}
        attempts: dict[int, int] = {}
        given: dict[int, Task] = {}
        nxt, count = 0, itertools.count()
        exhausted = False
        try:
            while True:
                while (not exhausted and pool.in_flight < ahead
                       and len(held) < BUFFER_FACTOR * ahead):
                    task = next(tasks, None)
                    if task is None:
                        exhausted = True
                        break
                    i = next(count)
                    given[i], attempts[i] = task, 1
                    pool.submit(i, task)
                if pool.in_flight == 0:
                    break
                for i, ok, value in pool.wait():
                    task = given[i]
                    if ok:
                        held[i], seconds[i] = value.value, value.seconds
                    elif isinstance(value, EmaError):
                        raise value
                    elif attempts[i] < MAX_ATTEMPTS:
                        attempts[i] += 1
                        if not killed_worker(value):  # else the scheduler's event told it
                            with self._lock:
                                self.retries.append((task.label, describe(value)))
                        pool.submit(i, task)
                        continue
                    else:
                        why = describe(value)
                        with self._lock:  # the losses retried, and this one
                            lost = sum(1 for b, w in self.retries if b == task.label
                                       and w.startswith(LOST)) + why.startswith(LOST)
                        fail = Failure(task.label, why, lost)
                        if failures == "raise":
                            raise BlockFailed(fail)
                        held[i], seconds[i] = fail, 0.0
                    if not ordered:
                        del given[i]
                        self.task_seconds.append(seconds.pop(i))
                        self.blocks += 1
                        yield i, held.pop(i)
                while ordered and nxt in held:
                    del given[nxt]
                    self.task_seconds.append(seconds.pop(nxt))
                    self.blocks += 1
                    yield nxt, held.pop(nxt)
                    nxt += 1
        finally:
            pool.cancel()


# ---------------------------------------------------------------------- the context
_CURRENT: contextvars.ContextVar[Executor | None] = contextvars.ContextVar("ema_executor",
                                                                          default=None)


def current() -> Executor:
    """The executor of the command running (:func:`executing`), else this process with
    numba's threads (what every command did before it had a backend)."""
    ex = _CURRENT.get()
    if ex is None:
        import numba

        ex = Executor("threads", numba.get_num_threads())
    return ex


@contextlib.contextmanager
def executing(backend: str | None = None, n_jobs: int | None = None,
              scheduler: str | None = None) -> Iterator[Executor]:
    """Open the executor of ``backend`` (``auto``/None: threads) with ``n_jobs`` workers (None
    or -1: every core; the dask backend: the cluster's threads) and make it :func:`current`
    for the block; a block inside another one's keeps the outer executor unless it names a
    backend of its own."""
    outer = _CURRENT.get()
    if outer is not None and backend is None and n_jobs is None and scheduler is None:
        yield outer
        return
    workers = resolve_workers(n_jobs)
    ex = Executor(resolve_backend(backend, workers), workers, scheduler)
    token = _CURRENT.set(ex)
    try:
        with ex:
            yield ex
    finally:
        _CURRENT.reset(token)


def split(n: int, min_items: int = 1) -> list[tuple[int, int]]:
    """``n`` items cut into blocks for the current executor -> ``(start, stop)`` of each: one
    block in this process (the kernel's threads share it), one per worker on the remote
    backends, each of at least ``min_items`` items (fewer blocks when ``n`` is small)."""
    ex = current()
    parts = ex.workers if ex.remote else 1
    parts = max(1, min(parts, n // max(min_items, 1)))
    size, extra = divmod(n, parts)
    bounds, start = [], 0
    for k in range(parts):
        stop = start + size + (1 if k < extra else 0)
        bounds.append((start, stop))
        start = stop
    return bounds
