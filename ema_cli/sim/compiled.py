"""Compiling the simulator: what is compiled, whether it is cached, and telling the user
(compiling everything at once, ``ema compile``, is ``api.kernels``).

The kernel's entry points (``sim.kernel.KERNELS``: one lane or SIMD lanes) are compiled per
variant (``kernel.VARIANTS``), each the first time a batch needs it, into numba's on-disk cache
under the source key of ``ema_cli._numba`` (an edit of the model or the kernel selects a new,
empty folder). A marker file per compiled unit in that folder says the unit is cached: a unit
without one is compiled now, and that is announced on stderr ("compiling the simulator ...
first run after an install or an edit, ~N s"), with the time it took once done.
"""

from __future__ import annotations

import contextlib
import os
import sys
import time
from collections.abc import Iterator
from pathlib import Path

from ema_cli import progress

# seconds one unit takes to compile on this kind of machine (2 cores, `ema compile` from an empty
# cache; the inner functions compiled without numba's wrappers, `ema_cli._numba.njit`): the
# first unit of a family in a process (it compiles the callees the family shares: the model's
# functions, the integrator of its `sim.variants.rates_key`) and each further variant (only
# what the variant decides itself: the time loop and the step around the shared integrator);
# the identification kernels. The announcements' and `ema compile`'s estimates.
COMPILE_S = {"rows": (9.5, 2.5), "lanes": (10.5, 2.8), "identify": (2.0, 2.0)}
_COMPILED_HERE: set[str] = set()  # the families a unit of which this process compiled
QUIET_ENV = "EMA_COMPILE_QUIET"  # set: compile without announcing (ema compile's workers)


def entry_name(lanes: int, variant: int) -> str:
    """The unit's name: ``lanes/v1`` (``variant``: ``model.actuator``'s code)."""
    return f"{'lanes' if lanes > 1 else 'rows'}/v{int(variant)}"


def describe(name: str) -> str:
    """A reader's words for a unit name."""
    from ema_cli.model.actuator import describe_variant

    if "/" not in name:
        return name
    base, v = name.split("/")
    width = "16 lanes" if base.startswith("lanes") else "one lane"
    return f"{width}, {describe_variant(int(v[1:]))}"


def _cache_dir() -> Path:
    from numba import config

    return Path(config.CACHE_DIR)


def _marker(name: str) -> Path:
    return _cache_dir() / f"ema-compiled-{name.replace('/', '-')}.ok"


def is_cached(name: str) -> bool:
    """Whether unit ``name`` was compiled into the current cache folder."""
    return _marker(name).is_file()


def estimate_s(name: str, first: bool | None = None) -> float:
    """The estimated compile time of a unit [s]: the first of its family in a process, or a
    further one (``first`` None: whether this process has compiled one of its family yet)."""
    fam = _family(name)
    if first is None:
        first = fam not in _COMPILED_HERE
    one, more = COMPILE_S.get(fam, (5.0, 5.0))
    return one if first else more


def units_estimate_s(names: list[str]) -> float:
    """The estimated time to compile ``names`` in one fresh process [s] (the first unit of each
    family costs its first-unit time)."""
    fams = [_family(n) for n in names]
    return sum(estimate_s(n, first=f not in fams[:i])
               for i, (n, f) in enumerate(zip(names, fams, strict=True)))


def _family(name: str) -> str:
    """The family of unit ``name`` (``rows``, ``lanes``, ``identify``)."""
    return name.split("/")[0]


def _say(text: str) -> None:
    if progress._announcer is not None:  # a command runs: its own stderr line
        progress.announce(text)
    else:  # the API, a notebook, a test
        print(text, file=sys.stderr, flush=True)


@contextlib.contextmanager
def announce(name: str) -> Iterator[None]:
    """Around the compilation (or cache load) of unit ``name``: when it is not cached yet, say
    so before (with an estimate) and after (with the time it took), and mark it cached."""
    if os.environ.get("NUMBA_DISABLE_JIT") == "1" or is_cached(name):
        yield
        return
    if os.environ.get(QUIET_ENV):  # `ema compile` reports for its workers
        yield
        _COMPILED_HERE.add(_family(name))
        with contextlib.suppress(OSError):
            _marker(name).write_text("compiled\n")
        return
    _say(f"compiling the simulator ({describe(name)}), first run only: "
         f"~{estimate_s(name):.0f} s")
    t0 = time.perf_counter()
    yield
    _COMPILED_HERE.add(_family(name))
    with contextlib.suppress(OSError):
        _marker(name).write_text(f"{time.perf_counter() - t0:.3f}\n")
    _say(f"compiled in {time.perf_counter() - t0:.1f} s (cached; `ema compile` compiles all)")


def kernel_units() -> list[str]:
    """Every kernel unit: each entry point in each variant (``kernel.VARIANTS``)."""
    from ema_cli.sim.kernel import LANES, VARIANTS

    out = []
    for lanes in (1, LANES):
        for variant in VARIANTS[lanes]:
            out.append(entry_name(lanes, variant))
    return out


@contextlib.contextmanager
def quiet() -> Iterator[None]:
    """Compile without announcing (the caller reports each unit)."""
    previous = os.environ.get(QUIET_ENV)
    os.environ[QUIET_ENV] = "1"
    try:
        yield
    finally:
        if previous is None:
            os.environ.pop(QUIET_ENV, None)
        else:
            os.environ[QUIET_ENV] = previous
