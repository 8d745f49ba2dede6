"""Multiple shooting on longer segments (:mod:`ema_cli.identify.closed_loop.shooting_fit`, steps
2-3):
the best start and the runner-up continued on longer segments (fewer free states, less of
their bias), the refinement at another step, and the estimate's segments cut into parts for
its covariance when there are too few of them."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

import numpy as np

from ema_cli.identify.closed_loop.shooting_quality import CONFIRM_RATIO, channel_ratios, too_high
from ema_cli.identify.closed_loop.shooting_search import (
    AGREE_REL,
    RESEAT_RATIO,
    ShootingSearch,
    chain_seat,
    lm_many,
    new_state,
)

LENGTHEN_ITER = 20  # joint LM iterations at each longer segment length
MIN_SEGMENTS = 10
"""The fewest clusters of the jackknife covariance (its t quantile has one degree of freedom
fewer than there are clusters, and its variance estimate is the spread of as many
deletions): when the estimate ends on fewer segments, its covariance is taken on each of its
segments cut into equal parts (:func:`split_for_covariance`) [-]."""
MIN_FIT_SEGMENTS = 2
"""A lengthening that would leave fewer segments is skipped [-]. Longer segments leave fewer
free states and so less of their bias and variance: at the truth of the independent
battery's stated-law logs, the information bound of kL on log06 (a 1 kHz chirp, 1.6 %
noise) is 0.33 % (one standard deviation) on 0.4 s segments, 0.25 % on 0.8 s, 0.10 % on
1.6 s and 0.09 % for the whole log from rest (experiments/identify_crb.py); 0.4 -> 0.8 s
moved kL errors of +0.51 and +0.57 % to +0.08 and +0.42 %, and 0.8 -> 1.6 s log06's +0.61 %
to +0.09 %. Few segments are too few clusters for a covariance (a 5-cluster jackknife gave
one log kL +-0.25 % around an error of +0.51 %): hence the split. A lengthening that costs
the fit is refused (:func:`lengthened`), so logs whose long horizons the model cannot
follow (a multisine with the jump law: impact timing) stay on shorter segments."""


def continue_at(res: ShootingSearch, dt: float, iterations: int) -> int:
    """Continue the best start at step ``dt`` [s] (in place): re-seated, then joint LM ->
    the LM iterations used. The states were seated at the search's step, so when the LM
    stalls only the segments that fit clearly worse than the median one are re-fitted."""
    st = new_state(res.sp, res.V[None], dt)
    st.V, st.R, st.cost = chain_seat(res.sp, st.V, dt)
    lm_many(res.sp, st, dt, iterations, stall_ratio=RESEAT_RATIO)
    res.V, res.cost = st.V[0].copy(), float(st.cost[0])
    res.x = res.sp.unpack(res.V)[0]
    return int(st.iterations[0])


def _reseat_on(res: ShootingSearch, seg: Any, dt: float, sweeps: int | None = None
               ) -> tuple[Any, np.ndarray, float]:
    """The estimate ``res`` on other segments ``seg``: each new segment starts from the state
    of the old segment that started at or before its first sample, then chained
    (:func:`chain_seat`, ``sweeps`` of them) -> (the new problem, its scaled unknowns, their
    data cost)."""
    from ema_cli.identify.closed_loop.shooting import ShootingProblem

    sp = res.sp
    sp2 = ShootingProblem(sp.base, seg, sp.sigma, tie=sp.tie, work=sp.work)
    x, S = sp.unpack(res.V)
    k = np.clip(np.searchsorted(sp.seg.first, seg.first, side="right") - 1, 0, sp.seg.n - 1)
    kw = {} if sweeps is None else {"sweeps": sweeps}
    V2, R2, _ = chain_seat(sp2, sp2.pack(x, S[k])[None], dt, **kw)
    return sp2, V2[0], float(np.sum(R2[0, :sp2.n_data] ** 2))


CONTACT_TAUS = (1e-5, 3e-5, 1e-4, 3e-4)
"""The contact ramp-in times [s] tried by :func:`contact_restart` (within its bounds)."""
RESTART_ITER = 6  # joint LM iterations of every contact-law candidate before choosing [-]
JUMP_LAW_FRACTION = 0.01
"""The restart runs only for a fit on the jump law's ridge: ``contact_tau`` within this
fraction of its range from its lower bound [-] (it costs about a lengthening stage)."""


def on_jump_ridge(res: ShootingSearch) -> bool:
    """Whether ``res`` has the contact's ramp-in time free and sits on the jump law's ridge
    (``contact_tau`` within :data:`JUMP_LAW_FRACTION` of its range from its lower bound)."""
    b = res.sp.base
    if "contact_tau" not in b.names:
        return False
    jt = b.names.index("contact_tau")
    return bool(res.x[jt] <= b.lower[jt] + JUMP_LAW_FRACTION * (b.upper[jt] - b.lower[jt]))


def contact_restart(res: ShootingSearch, dt: float, iterations: int) -> bool:
    """When the contact's shape is free (``contact_tau``, ``contact_hc``: nuisance parameters)
    and the fit sits on the jump law (``contact_tau`` on its lower bound, within
    :data:`JUMP_LAW_FRACTION`), try the estimate with other contact laws and continue from the
    best if it costs clearly less (in place) -> whether it moved. The cost is rugged across
    the laws: a ramp-in that softens each impact looks like a slightly wider gap, so a fit can
    stop on the jump law (tau = 0, a bound) with the Hunt-Crossley share compensating and
    alpha biased (measured on
    the README's example: tau 2e-9 s for a truth of 1e-4 s, alpha +0.21 % outside its
    interval, whole-log J 14920 against 13814 at the truth, the current's residuals
    autocorrelated at 0.22). Each candidate: the ramp-in times :data:`CONTACT_TAUS` within
    the bounds, with the Hunt-Crossley share at 0 or as fitted, states re-seated, all
    candidates through :data:`RESTART_ITER` joint LM iterations at once, then the best
    continued (``iterations``) and kept only if it ends lower."""
    sp = res.sp
    names = sp.base.names
    if not on_jump_ridge(res):
        return False  # no contact shape free, or a ramp-in found: not the jump law's ridge
    jt = names.index("contact_tau")
    jh = names.index("contact_hc") if "contact_hc" in names else None
    x, S = sp.unpack(res.V)
    lo, hi = sp.base.lower[jt], sp.base.upper[jt]
    cands = []
    for tau in CONTACT_TAUS:
        if not lo <= tau <= hi:
            continue
        for hc in ((None,) if jh is None else (0.0, float(x[jh]))):
            x2 = x.copy()
            x2[jt] = tau
            if jh is not None:
                x2[jh] = hc
            cands.append(sp.pack(x2, S))
    if not cands:
        return False
    V, _, _ = chain_seat(sp, np.array(cands), dt)
    # the other parameters follow the law (the damping zeta_t means another thing on a
    # ramp-in: at tau = 1e-4 s the README example's cost was 22x higher at the jump law's
    # zeta_t than at the truth's, 1 % away): a few joint LM iterations for every candidate
    # at once, then the best continued
    st = new_state(sp, V, dt)
    lm_many(sp, st, dt, RESTART_ITER)
    k = int(np.argmin(st.cost))
    if not float(st.cost[k]) < res.cost * (1.0 - AGREE_REL):
        return False
    st1 = new_state(sp, st.V[k][None], dt)
    lm_many(sp, st1, dt, iterations, stall_ratio=RESEAT_RATIO)
    if not float(st1.cost[0]) < res.cost:
        return False
    res.V, res.cost = st1.V[0].copy(), float(st1.cost[0])
    res.x = sp.unpack(res.V)[0]
    return True


def lengthened(res: ShootingSearch, length: float, dt: float, iterations: int,
               notes: dict[str, str] | None = None) -> int:
    """Continue the search's best start on segments of ``length`` [s] (in place): each new
    segment starts from the state of the old segment that started at the same sample (the
    nearest before it), chained (:func:`chain_seat`), then joint LM. Kept only if the data
    cost per sample does not rise by more than 5 %, and (given the channels' ``notes``) no
    channel that fitted within :data:`CONFIRM_RATIO` x its noise on the shorter segments
    fits worse than that on the longer ones: a lengthening must not cost the verdict its
    fit (measured: a noise-free battery log's 0.8 s segments fit the current at 1.47 x its
    floor where the 0.4 s ones were within 1.2 x). When the LM stalls, only the segments
    that fit clearly worse than the median one are re-fitted (the states come from the
    converged shorter segments). Longer segments leave fewer free states
    (with one state per 0.05 s the estimator of the parameters is biased on some logs: the
    incidental-parameter problem), but a longer horizon is harder to seat. Returns the LM
    iterations used (0: skipped, as when fewer than :data:`MIN_FIT_SEGMENTS` segments would
    be left)."""
    from ema_cli.identify.closed_loop.shooting import make_segments

    sp = res.sp
    seg = make_segments(sp.base.log.t, length)
    if seg.n >= sp.seg.n or seg.n < MIN_FIT_SEGMENTS:
        return 0
    sp2, V2, _ = _reseat_on(res, seg, dt)
    st = new_state(sp2, V2[None], dt)
    lm_many(sp2, st, dt, iterations, stall_ratio=RESEAT_RATIO)
    keep = bool(st.cost[0] <= 1.05 * res.cost)
    if keep and notes is not None:
        r_short = sp.residuals_many(res.V[None], dt)[0][0, :sp.n_data]
        r_long = st.R[0, :sp2.n_data]  # the LM keeps the residuals of its point
        before = too_high(channel_ratios(sp.base, r_short), notes, CONFIRM_RATIO)
        after = too_high(channel_ratios(sp.base, r_long), notes, CONFIRM_RATIO)
        keep = not set(after) - set(before)
    if keep:
        res.sp, res.V, res.cost = sp2, st.V[0].copy(), float(st.cost[0])
        res.x = sp2.unpack(res.V)[0]
        res.lengths.append(length)
        res.x_at[length] = res.x.copy()
    return int(st.iterations[0])


def split_for_covariance(res: ShootingSearch, dt: float, iterations: int = 4
                         ) -> ShootingSearch:
    """The estimate ``res`` on its segments cut into equal parts, so that there are at least
    :data:`MIN_SEGMENTS` (returned as it is when there already are): the clusters of its
    covariance. Each part starts on the state the estimate's own simulation reaches there
    (the first part of each segment on its fitted start; :func:`chain_seat` carries the
    others along), then the parts' states are fitted for the estimate's parameters
    (``iterations`` of :func:`fit_states`; the parameters stay). Its covariance is that of the
    shorter segments' estimator (more free states, so no narrower than the longer
    segments'), evaluated at the estimate, with the clusters' scores taken at the parts' own
    (linearised) optimum (:func:`ema_cli.identify.uncertainty.covariance_clustered`)."""
    from ema_cli.identify.closed_loop.shooting import Segments
    from ema_cli.identify.closed_loop.shooting_seat import fit_states

    sp = res.sp
    if sp.seg.n >= MIN_SEGMENTS:
        return res
    m = -(-MIN_SEGMENTS // sp.seg.n)
    first = np.unique(np.concatenate([
        f + np.round(np.arange(m) * (e - f) / m).astype(int)
        for f, e in zip(sp.seg.first, sp.seg.last, strict=True)]))
    seg = Segments(first, np.r_[first[1:], sp.seg.last[-1]])
    sp2, V, cost = _reseat_on(res, seg, dt, sweeps=m + 1)
    if iterations > 0:
        x2, S2 = sp2.unpack(V)
        S2, c = fit_states(sp2, x2[None], S2[None], np.zeros(1, dtype=int), dt, iterations)
        V, cost = sp2.pack(x2, S2[0]), float(np.sum(c[0]))
    return dataclasses.replace(res, sp=sp2, V=V, x=sp2.unpack(V)[0], cost=cost)


@dataclass
class Lengthening:
    """The best start and the runner-up after the longer segments (:func:`lengthen_both`).

    best, runner    the two candidates (runner None with one finished start)
    shift           the best's move at its last lengthening [SI]
    runner_won      the runner-up ended lower on the longest segments and became the best
    anchor          the same at the last length with at least :data:`MIN_SEGMENTS`
                    segments, when the lengthening went on beyond it (else None): the
                    fall-back when the longest segments do not fit at the fine step
    """

    best: ShootingSearch
    runner: ShootingSearch | None
    shift: np.ndarray
    runner_won: bool
    anchor: Lengthening | None = None


def _decide(cands: list[ShootingSearch], shifts: list[np.ndarray]) -> Lengthening:
    """Best and runner-up, swapped when the runner-up won on the longest segments."""
    res = cands[0]
    runner = cands[1] if len(cands) > 1 else None
    # the cost that counts is the longest segments': a runner-up that ends lower there wins
    # (on multisine logs the truth's basin can be the lower one at 0.2 s and not at 0.05 s)
    # (a runner-up that kept a longer length than the best and still costs less wins too:
    # longer segments leave fewer free states, so they cannot cost less for the same fit)
    won = bool(runner is not None
               and (runner.lengths == res.lengths or len(runner.lengths) > len(res.lengths))
               and runner.cost < res.cost * (1.0 - AGREE_REL))
    if won:
        return Lengthening(runner, res, shifts[1], True)
    return Lengthening(res, runner, shifts[0], False)


def _snapshot(c: ShootingSearch) -> ShootingSearch:
    return dataclasses.replace(c, V=c.V.copy(), x=c.x.copy(), lengths=list(c.lengths),
                               x_at=dict(c.x_at))


def candidates(res: ShootingSearch) -> list[ShootingSearch]:
    """The search's best start and its runner-up (when another start finished), each its own
    copy: the runner-up goes the same way as the best, so that their agreement compares like
    with like."""
    cands = [_snapshot(res)]
    if res.final_V is not None and len(res.final_V) > 1:
        cands.append(dataclasses.replace(res, V=res.final_V[1].copy(),
                                         x=res.final_x[1].copy(),
                                         cost=float(res.final_cost[1]), lengths=[],
                                         x_at={}))
    return cands


def restart_contact(cands: list[ShootingSearch], dt: float, iters: dict[str, int]) -> bool:
    """:func:`contact_restart` of each candidate (in place) -> whether any moved (the best's
    move recorded as ``iters["contact_restart"]``)."""
    moved = False
    for k, c in enumerate(cands):
        if contact_restart(c, dt, LENGTHEN_ITER):
            moved = True
            if k == 0:
                iters["contact_restart"] = 1
    return moved


def lengthen_both(cands: list[ShootingSearch], lengthen: tuple[float, ...],
                  dt_search: float, iters: dict[str, int], report: Any = None,
                  notes: dict[str, str] | None = None) -> Lengthening:
    """The best start and the runner-up (:func:`candidates`, in place) continued on the longer
    segments ``lengthen`` [s] (:func:`lengthened`), with the state at the last length that
    leaves :data:`MIN_SEGMENTS` segments kept as the anchor when they go on beyond it."""
    res = cands[0]
    for c in cands:  # each its own record, from the search's segments on
        c.x_at = {0.0: c.x.copy()}
    shifts = [np.zeros_like(res.x) for _ in cands]
    anchor = None
    for length in lengthen:  # longer segments from the optimum: fewer free states
        if report:
            report(f"segments of {length:g} s", 0, 1)
        for k, cand in enumerate(cands):
            x_before, kept = cand.x.copy(), len(cand.lengths)
            n_it = lengthened(cand, length, dt_search, LENGTHEN_ITER, notes)
            if k == 0:
                iters[f"lengthen_{length:g}_s"] = n_it
            if len(cand.lengths) > kept:
                shifts[k] = cand.x - x_before
        if cands[0].sp.seg.n >= MIN_SEGMENTS:
            anchor = ([_snapshot(c) for c in cands], [v.copy() for v in shifts])
    out = _decide(cands, shifts)
    if anchor is not None and out.best.sp.seg.n < MIN_SEGMENTS:
        out.anchor = _decide(*anchor)
    return out


def on_same_segments(best: ShootingSearch, runner: ShootingSearch
                     ) -> tuple[float, np.ndarray, np.ndarray]:
    """The longest segments both candidates were fitted on -> (their length [s], 0.0 for the
    search's; the best's parameters there; the runner-up's). A runner-up whose lengthening
    was refused is compared with the best at the length it kept, not at the best's longest:
    the estimates on different segments differ by the free states' bias, not by optimum."""
    common = set(best.x_at) & set(runner.x_at)
    length = max(common) if common else 0.0
    xb = best.x_at.get(length, best.x)
    xr = runner.x_at.get(length, runner.x)
    return length, xb, xr


__all__ = ["LENGTHEN_ITER", "MIN_FIT_SEGMENTS", "MIN_SEGMENTS", "Lengthening", "candidates",
           "contact_restart", "continue_at", "lengthen_both", "lengthened", "on_jump_ridge",
           "on_same_segments", "restart_contact",
           "split_for_covariance"]
