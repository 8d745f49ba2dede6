"""MATLAB's ``filtfilt``, ``decimate`` and the benchmark's ``diffcent``, emulated to the sample:
the zero-phase filtering and decimation that the EMPS benchmark's IDIM script runs.

The three differ from their scipy namesakes in ways that move the benchmark's estimates in the
third or fourth significant digit (measured on DATA_EMPS.mat: ``plant.idim``'s docstring):

``filtfilt(b, a, x)`` (Signal Processing Toolbox, transfer-function form)
    pads ``nfact = 3*(max(len(a), len(b)) - 1)`` samples at each end by odd reflection about the
    end sample (``2*x[0] - x[nfact:0:-1]``), runs ``filter`` forward from the steady-state
    initial conditions ``zi*y[0]``, reverses, runs it again from ``zi*y[0]`` of the reversed
    sequence and keeps the central part. ``zi`` solves ``(I - A) zi = B - b0*A1`` for the
    transposed direct form II (the form of MATLAB's ``filter`` and scipy's ``lfilter``), i.e.
    the state the filter holds after a long constant input of 1. scipy's ``filtfilt`` pads
    ``3*max(len(a), len(b))`` samples by default (3 more at each end).

``decimate(x, r)`` (IIR default)
    designs ``cheby1(8, 0.05, 0.8/r)`` and lowers the order while the gain at ``0.8/r`` is not
    -0.05 dB within 1e-6 dB (the design is numerically poor); filters with ``filtfilt`` above and
    keeps every r-th sample *ending at the last one*: 1-based indices ``nbeg:r:nd`` with
    ``nbeg = r - (r*ceil(nd/r) - nd)``. scipy's ``decimate`` starts at the first sample and pads
    as its own ``filtfilt`` does.

``diffcent(y, h)`` (M. Gautier, LAN Robotique, 1994; shipped with the benchmark)
    central differences ``(y[k+1] - y[k-1])/(2h)`` inside, the one-sided first differences
    ``(y[1] - y[0])/h`` and ``(y[-1] - y[-2])/h`` at the two ends (``numpy.gradient`` with
    ``edge_order=1`` computes the same).

Units: samples in, samples out; ``h`` in seconds. Shape errors are the caller's (ValueError):
the user-facing checks live at the boundary (``plant.records``, ``plant.idim``).
"""

from __future__ import annotations

import numpy as np
from scipy import signal

DECIMATE_ORDER = 8  # MATLAB decimate's default Chebyshev type I order [-]
DECIMATE_RIPPLE_DB = 0.05  # its passband ripple [dB]
DECIMATE_CUTOFF = 0.8  # its cutoff as a fraction of the decimated Nyquist frequency [-]
DECIMATE_GAIN_TOL_DB = 1e-6  # gain at the cutoff must be -ripple within this, else order - 1 [dB]


def edge_length(b: np.ndarray, a: np.ndarray) -> int:
    """MATLAB filtfilt's padding at each end, ``max(1, 3*(max(len(a), len(b)) - 1))`` [samples];
    the input must be longer than this."""
    return max(1, 3 * (max(len(a), len(b)) - 1))


def steady_state(b: np.ndarray, a: np.ndarray) -> np.ndarray:
    """The state ``zi`` [nfilt - 1] of the transposed direct form II filter ``b/a`` after a long
    unit constant input (MATLAB filtfilt's initial conditions, scaled by the first sample).

    ``(I - A) zi = b[1:] - b[0]*a[1:]`` with ``A`` the companion matrix ``[-a[1:] | shift]``;
    ``a[0]`` must be 1 and ``len(a) == len(b)``.
    """
    n = len(a)
    if n < 2:
        return np.zeros(0)
    A = np.zeros((n - 1, n - 1))
    A[:, 0] = -a[1:]
    A[:-1, 1:] = np.eye(n - 2)
    return np.linalg.solve(np.eye(n - 1) - A, b[1:] - b[0] * a[1:])


def filtfilt(b: np.ndarray, a: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Zero-phase filtering of the vector ``x`` by ``b/a`` exactly as MATLAB's ``filtfilt``
    (transfer-function form): odd reflection of ``3*(nfilt - 1)`` samples at each end, the
    steady-state initial conditions at both passes. Output: same length as ``x``, gain
    ``|H(e^jw)|^2``, zero phase."""
    b = np.asarray(b, dtype=np.float64).ravel()
    a = np.asarray(a, dtype=np.float64).ravel()
    x = np.asarray(x, dtype=np.float64).ravel()
    nfilt = max(len(a), len(b))
    b = np.pad(b, (0, nfilt - len(b)))
    a = np.pad(a, (0, nfilt - len(a)))
    b, a = b / a[0], a / a[0]
    nfact = edge_length(b, a)
    if x.size <= nfact:
        raise ValueError(f"filtfilt needs more than {nfact} samples, got {x.size}")
    zi = steady_state(b, a)
    y = np.concatenate([2.0 * x[0] - x[nfact:0:-1], x, 2.0 * x[-1] - x[-2:-nfact - 2:-1]])
    y = signal.lfilter(b, a, y, zi=zi * y[0])[0][::-1]
    y = signal.lfilter(b, a, y, zi=zi * y[0])[0][::-1]
    return y[nfact:-nfact]


def gain_db(b: np.ndarray, a: np.ndarray, f: float) -> float:
    """The gain of ``b/a`` at the normalised frequency ``f`` (1 = Nyquist) [dB], as MATLAB
    decimate's ``filtmag_db`` computes it."""
    z = np.exp(-1j * np.pi * f)
    return float(20.0 * np.log10(abs(np.polyval(b[::-1], z) / np.polyval(a[::-1], z))))


def decimation_filter(r: int) -> tuple[np.ndarray, np.ndarray]:
    """MATLAB decimate's anti-aliasing filter for the factor ``r``: ``cheby1(n, 0.05, 0.8/r)``
    with ``n`` the largest order <= 8 whose gain at ``0.8/r`` is -0.05 dB within 1e-6 dB."""
    cutoff = DECIMATE_CUTOFF / r
    for order in range(DECIMATE_ORDER, 0, -1):
        b, a = signal.cheby1(order, DECIMATE_RIPPLE_DB, cutoff)
        if np.any(b != 0) and abs(gain_db(b, a, cutoff) + DECIMATE_RIPPLE_DB) \
                <= DECIMATE_GAIN_TOL_DB:
            return b, a
    raise ValueError(f"no Chebyshev filter of order 1-{DECIMATE_ORDER} meets MATLAB decimate's "
                     f"check for r = {r}")


def decimation_indices(n: int, r: int) -> np.ndarray:
    """The 0-based indices MATLAB ``decimate`` keeps of ``n`` samples: every r-th, ending at the
    last sample (1-based ``nbeg:r:n`` with ``nbeg = r - (r*ceil(n/r) - n)``)."""
    nout = -(-n // r)
    nbeg = r - (r * nout - n)  # 1-based
    return np.arange(nbeg - 1, n, r)


def decimate(x: np.ndarray, r: int) -> np.ndarray:
    """``x`` low-pass filtered (MATLAB decimate's Chebyshev I, zero phase by :func:`filtfilt`)
    and resampled every ``r`` samples ending at the last one, exactly as MATLAB's
    ``decimate(x, r)``; ``r = 1`` returns ``x``. Length ``ceil(len(x)/r)``."""
    x = np.asarray(x, dtype=np.float64).ravel()
    if r == 1:
        return x.copy()
    b, a = decimation_filter(r)
    return filtfilt(b, a, x)[decimation_indices(x.size, r)]


def diffcent(y: np.ndarray, h: float) -> np.ndarray:
    """The benchmark's ``diffcent``: the derivative of ``y`` sampled every ``h`` seconds by
    central differences ``(y[k+1] - y[k-1])/(2h)``, one-sided first differences at both ends
    (unit of ``y`` per second). Needs at least 3 samples."""
    y = np.asarray(y, dtype=np.float64).ravel()
    if y.size < 3:
        raise ValueError(f"diffcent needs at least 3 samples, got {y.size}")
    out = np.empty_like(y)
    out[1:-1] = (y[2:] - y[:-2]) / 2.0
    out[0] = y[1] - y[0]
    out[-1] = y[-1] - y[-2]
    return out / h
