"""Wall-clock measurement for benchmarks: medians of repeats (the machines are shared, noisy)."""

from __future__ import annotations

import statistics
import time
from collections.abc import Callable
from typing import Any

DEFAULT_REPEATS = 5  # timed calls after one warm-up call


def median_time(fn: Callable[[], Any], repeats: int = DEFAULT_REPEATS) -> float:
    """Median wall time of ``fn()`` over ``repeats`` calls after one warm-up call [s]."""
    fn()
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times)
