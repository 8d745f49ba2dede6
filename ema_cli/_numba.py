"""The one place numba is imported from (set NUMBA_DISABLE_JIT=1 to debug kernels in Python)."""

import os

from numba import config, njit, prange

if "NUMBA_DISABLE_PERFORMANCE_WARNINGS" not in os.environ:
    # sim.kernel.simulate_case_nb is compiled with parallel=True but has no prange, on purpose
    # (2x faster, see there); numba's "no transformation for parallel execution" advice is
    # expected. Set the variable yourself to see numba's performance warnings again.
    config.DISABLE_PERFORMANCE_WARNINGS = 1

__all__ = ["njit", "prange"]
