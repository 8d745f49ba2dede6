"""What an acceptance spec's requirements come to after a tuning (``tune/spec.py``): their
values as the console prints them, the requirements the tuned controller misses with why and
what to relax (:func:`shortfalls`), and the sentence naming those no gains inside the bounds
were found to meet (:func:`blocking_summary`)."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any


def fmt_value(req: Any, value: float) -> str:
    """A requirement's value as the console prints it: in the limit's unit, or a share for
    the threshold proxy."""
    from ema_cli.units import fmt_num, from_si

    if req.proxy:
        return f"followed {fmt_num(100 * value, '', 3)} % of the step"
    return fmt_num(from_si(value, req.unit), req.unit, 4)


def fmt_range(req: Any, low: float, high: float) -> str:
    """``321.1-321.3 deg/s`` (in the limit's unit)."""
    from ema_cli.units import fmt_num, from_si

    if req.proxy:
        return f"{fmt_num(100 * low, '', 3)}-{fmt_num(100 * high, '', 3)} % of the step"
    return (f"{fmt_num(from_si(low, req.unit), '', 4)}-"
            f"{fmt_num(from_si(high, req.unit), req.unit, 4)}")


def _outward(value: float, upper: bool) -> float:
    """``value`` rounded to 2 significant digits away from the limit it would replace (up for
    a maximum, down for a minimum), so that the value itself meets the relaxed limit."""
    if not math.isfinite(value) or value == 0.0:
        return value
    step = 10.0 ** (math.floor(math.log10(abs(value))) - 1)
    q = value / step
    return (math.ceil(q - 1e-9) if upper else math.floor(q + 1e-9)) * step


def shortfalls(reqs: Any, rows: Sequence[Any]) -> list[dict[str, str]]:
    """The requirements that the battery's verdict ``rows`` (``acceptance.verdict.Verdict``,
    of the tuned controller) do not pass, worst condition first: ``requirement`` (test:
    metric), ``limit``, ``result`` (FAIL or INCONCLUSIVE), ``value`` (the tuned controller's,
    the limit's unit, with its condition), ``best`` (the nearest to the limit the search saw),
    ``why`` (why no gains inside the bounds were found to meet it, or the battery's reason for
    an INCONCLUSIVE value) and ``relax`` (the limit the tuned controller would meet, "" when
    the value was not measured)."""
    from ema_cli.acceptance.verdict import FAIL, PASS
    from ema_cli.units import fmt_num

    out = []
    by_key = {r.key: r for r in reqs.requirements}
    groups: dict[str, list[Any]] = {}
    for v in rows:
        groups.setdefault(f"{v.test}: {v.metric}", []).append(v)
    for key, vs in groups.items():
        bad = [v for v in vs if v.result != PASS]
        if not bad or key not in by_key:
            continue
        r = by_key[key]
        worst = next((v for v in bad if v.result == FAIL), bad[0])
        t = reqs.tallies[key]
        # no gains inside the bounds were found to meet it: the controller plays no part, it is
        # out of its reach, or no controller measured met it
        blocking = worst.result == FAIL and (r.tier == "fixed" or key in reqs.unreachable
                                             or (t.seen > 0 and t.met == 0))
        if worst.result != FAIL:
            why = f"not measured: {worst.reason}"
        elif r.tier == "fixed":
            why = "the controller plays no part in this test (motor locked)"
        elif key in reqs.unreachable:
            why = f"out of the controller's reach: {reqs.unreachable[key]}"
        elif t.met == 0:
            who = ("the search measured" if r.tier == "search" else
                   "the battery checked after the search")
            why = f"none of the {t.seen} controllers {who} met it"
        else:
            why = (f"met by {t.met} of the {t.seen} controllers measured, but not together "
                   "with the other requirements")
        relax = ""
        if worst.result == FAIL:
            lo, hi = (worst.value, worst.value) if worst.measured else (worst.lower, worst.upper)
            upper = worst.max is not None and lo > worst.max
            edge = hi if upper else lo  # the value lies in lo..hi: the limit must cover it
            if math.isfinite(edge) and (upper or edge > 0.0):  # not ">= 0": nothing to relax to
                relax = (f"{'<=' if upper else '>='} "
                         f"{fmt_num(_outward(edge, upper), worst.unit, 6)}")
        cond = f" ({worst.condition})" if worst.condition else ""
        reached = ("not measured" if not worst.measured and worst.result != FAIL else
                   fmt_num(worst.value, worst.unit, 4))
        value = reached + cond
        out.append({"requirement": key, "limit": r.limit_text, "result": worst.result,
                    "value": value, "reached": reached,
                    "best": fmt_value(r, t.best) if t.seen else "",
                    "why": why, "relax": relax, "tier": r.tier, "blocking": blocking,
                    "proxy": bool(r.proxy)})
    return sorted(out, key=lambda row: not row["blocking"])  # stable: the spec's order


def blocking_summary(rows: Sequence[Mapping[str, Any]]) -> str:
    """One sentence naming the requirements no gains inside the bounds were found to meet
    (``shortfalls`` rows with ``blocking``): first those the controller cannot move (fixed
    tier: their value whatever the gains), then the others with the best value the search
    reached; "" when there is none."""
    fixed = [f"{r['requirement']} {r['limit']} ({r['reached']} whatever the gains)"
             for r in rows if r.get("blocking") and r["tier"] == "fixed"]
    found = [f"{r['requirement']} {r['limit']} ("
             + (f"tuned {r['reached']}, the search's proxy {r['best']}" if r.get("proxy")
                else f"best {r['best'] or r['reached']}") + ")"
             for r in rows if r.get("blocking") and r["tier"] != "fixed"]
    parts = []
    if fixed:
        parts.append("no gains can meet " + "; ".join(fixed))
    if found:
        parts.append(("and none inside the bounds was found to meet " if fixed else
                      "no gains inside the bounds were found to meet ") + "; ".join(found))
    if not parts:
        return ""
    return " ".join(parts) + ": no PASS without relaxing these limits or changing the actuator"
