"""Compiling every kernel at once (``ema compile``, run by ``make run`` and ``make test``).

The units are ``sim.compiled.kernel_units`` (each kernel entry point in each variant) and the
identification kernels. Units not cached yet are compiled in up to ``jobs`` processes, one per
family of units that share compiled callees and numba's index files (one lane, SIMD lanes,
identification), so what a family shares is compiled once. Other processes may compile into the
same cache at the same time: its saves are serialised (``ema_cli._numba``).
"""

from __future__ import annotations

import time
from collections.abc import Callable

from ema_cli.sim import compiled

IDENTIFY = "identify"  # the unit of the identification kernels (Eq. 8 cost and profile)


def units() -> list[str]:
    """Every unit ``ema compile`` makes."""
    return [*compiled.kernel_units(), IDENTIFY]


def describe(name: str) -> str:
    """What a unit is, in words (``sim.compiled.describe``)."""
    return compiled.describe(name)


def compile_unit(name: str, quiet: bool = False) -> float:
    """Compile (or load from the cache) one unit in this process -> seconds (``quiet``: no
    announcement, the caller reports)."""
    if quiet:
        with compiled.quiet():
            return compile_unit(name)
    t0 = time.perf_counter()
    if name == IDENTIFY:
        from ema_cli.identify.torque.run import warm_kernels

        with compiled.announce(name):
            warm_kernels()
        return time.perf_counter() - t0
    from ema_cli.sim.runner import load_kernel

    base, v = name.split("/")
    load_kernel(16 if base == "lanes" else 1, int(v[1:]))
    return time.perf_counter() - t0


def family(name: str) -> str:
    """The units that share compiled callees (and an entry point's index file): one process
    each."""
    return name.split("/")[0].split("-")[0]


def deal(families: list[list[str]], jobs: int) -> list[list[str]]:
    """Families dealt to ``jobs`` processes, the costliest first to the least loaded."""
    load = [0.0] * jobs
    out: list[list[str]] = [[] for _ in range(jobs)]
    for fam in sorted(families, key=lambda f: -compiled.units_estimate_s(f)):
        i = load.index(min(load))
        out[i].extend(fam)
        load[i] += compiled.units_estimate_s(fam)
    return out


def plan(jobs: int) -> tuple[list[str], list[list[str]], float]:
    """What :func:`compile_all` would do with ``jobs`` processes -> (the units not cached, their
    shares per process, the estimated wall time [s]: the busiest share's)."""
    todo = [n for n in units() if not compiled.is_cached(n)]
    families: dict[str, list[str]] = {}
    for n in todo:
        families.setdefault(family(n), []).append(n)
    shares = deal(list(families.values()), max(1, min(jobs, len(families)))) if todo else []
    est = max((compiled.units_estimate_s(sh) for sh in shares), default=0.0)
    return todo, shares, est


def _family_worker(names: list[str], queue: object) -> None:
    try:
        for n in names:
            queue.put((n, compile_unit(n)))  # type: ignore[attr-defined]
    except BaseException:
        queue.put((None, 0.0))  # type: ignore[attr-defined]
        raise


def compile_all(jobs: int = 2, on_done: Callable[[str, float, int, int], None] | None = None
                ) -> dict[str, float]:
    """Compile every unit (:func:`units`) not cached yet -> seconds per unit compiled;
    ``on_done(name, seconds, done, total)`` after each (a unit a worker could not compile is
    compiled here, so its error is this process's)."""
    todo, shares, _ = plan(jobs)
    out: dict[str, float] = {}
    done = 0
    if len(shares) > 1:
        import multiprocessing as mp

        ctx = mp.get_context("spawn")  # a fresh interpreter each: nothing compiled is inherited
        queue = ctx.Queue()
        procs = [ctx.Process(target=_family_worker, args=(names, queue), daemon=True)
                 for names in shares]
        with compiled.quiet():  # the workers inherit it: this process reports
            for p in procs:
                p.start()
        try:
            while done < len(todo):
                n, sec = queue.get()
                if n is None:  # a worker failed: what is left is compiled here
                    break
                done += 1
                out[n] = sec
                if on_done:
                    on_done(n, sec, done, len(todo))
        finally:
            for p in procs:
                p.join()
    for n in todo:
        if n not in out:
            out[n] = compile_unit(n, quiet=True)
            done += 1
            if on_done:
                on_done(n, out[n], done, len(todo))
    return out


def missing() -> list[str]:
    """The units not cached (after :func:`compile_all`: none, unless the cache is not
    writable)."""
    return [n for n in units() if not compiled.is_cached(n)]


__all__ = ["compile_all", "compile_unit", "missing", "plan", "units"]
