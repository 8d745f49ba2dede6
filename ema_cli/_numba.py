"""The one place numba is imported from (set NUMBA_DISABLE_JIT=1 to debug kernels in Python)."""

from numba import njit, prange

__all__ = ["njit", "prange"]
