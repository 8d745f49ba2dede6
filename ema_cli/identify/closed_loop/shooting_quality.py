"""The fit quality of a closed-loop multiple-shooting fit: each channel's residual RMS over
its scale, the limits the verdict judges it by, and where it fits worst."""

from __future__ import annotations

import numpy as np

from ema_cli.identify.closed_loop.problem import FLOOR_NOTE, NOISE_NOTE, ClosedLoopProblem

NOISE_LEVEL_RATIO = 2.0  # a channel fits when its residual RMS is within this x its noise [-]
CONFIRM_RATIO = 1.2
"""An optimum is confirmed only when the segments fit every channel scaled by its noise
estimate within this x its noise [-]. The right model at its optimum leaves the noise (ratio
near 1: on the independent battery the fits that were right ended at 0.91-1.09, commit
73ca9c2); a model that leaves 20 % more than the noise explains the log only approximately,
and its parameters absorb the difference (measured: Hunt-Crossley logs fitted without that
law confirmed at 1.33 and 1.78 x with kL -9 % and +21 %)."""
AT_NOISE_RATIO = 1.1
"""A fit whose every channel (scaled by its noise estimate) is within this x its noise is at
the noise level (said in the verdict's reason; it does not confirm the optimum alone)."""


def channel_ratios(problem: ClosedLoopProblem, r: np.ndarray) -> dict[str, float]:
    """Per channel, the RMS of the weighted residuals ``r`` (channel after channel) [-]."""
    n = problem.log.n
    return {c: float(np.sqrt(np.mean(r[j * n:(j + 1) * n] ** 2)))
            for j, c in enumerate(problem.channels)}


JUDGED_NOTES = (NOISE_NOTE, FLOOR_NOTE)
"""Channels whose scale was chosen automatically (their noise estimate, or the floor of
noise-free data) are judged; a scale given by hand is the user's and is not. A noise-free
log's channels sit on the floor: judging them too keeps a fit of such a log from being
confirmed vacuously (measured: an independent steps log with 0.007 % noise, every channel on
the floor, "confirmed" at kL -2.6 % with its segments fitting the motor speed at
2.55 x and the current at 2.2 x the floor)."""


def too_high(ratios: dict[str, float], notes: dict[str, str],
             limit: float = NOISE_LEVEL_RATIO) -> dict[str, float]:
    """The channels with an automatic scale (:data:`JUDGED_NOTES`) whose ratio exceeds
    ``limit``."""
    return {c: v for c, v in ratios.items() if notes[c] in JUDGED_NOTES and v > limit}


def worst_windows(problem: ClosedLoopProblem, first: np.ndarray, r: np.ndarray, channel: str,
                  k: int = 2) -> list[tuple[float, float, float]]:
    """The ``k`` windows (the search's segments, starting at samples ``first``) where the
    weighted residuals ``r`` of ``channel`` are largest -> (t0 [s], t1 [s], RMS ratio [-])."""
    n = problem.log.n
    j = problem.channels.index(channel)
    rc = r[j * n:(j + 1) * n]
    edges = [*first.tolist(), n]
    t = problem.log.t
    out = [(float(t[a]), float(t[b - 1]), float(np.sqrt(np.mean(rc[a:b] ** 2))))
           for a, b in zip(edges[:-1], edges[1:], strict=True) if b > a]
    return sorted(out, key=lambda w: -w[2])[:k]


def mismatch_text(problem: ClosedLoopProblem, first: np.ndarray, r: np.ndarray,
                  high: dict[str, float], notes: dict[str, str] | None = None) -> str:
    """Each channel of ``high`` with its ratio and the time ranges where it fits worst
    (``notes``: the channels' scale notes; a channel on the floor says so)."""
    parts = []
    for c, v in high.items():
        w = worst_windows(problem, first, r, c)
        what = ("its scale (1e-4 of its range: the log is nearly noise-free)"
                if notes is not None and notes.get(c) == FLOOR_NOTE else "its noise estimate")
        parts.append(f"{c} {v:.3g} x {what}, worst at " + ", ".join(
            f"t = {a:.3g}-{b:.3g} s ({q:.3g} x)" for a, b, q in w))
    return "; ".join(parts)


__all__ = ["AT_NOISE_RATIO", "CONFIRM_RATIO", "JUDGED_NOTES", "NOISE_LEVEL_RATIO", "channel_ratios",
           "mismatch_text", "too_high", "worst_windows"]
