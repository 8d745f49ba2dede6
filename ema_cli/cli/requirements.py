"""The console's account of an acceptance spec's requirements after a tuning (``ema tune
--spec``, ``ema design``): the verdict, each requirement not met with the value reached, why
no gains were found to meet it, and the limit the tuned controller would meet."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from ema_cli.cli.common import console


def print_shortfalls(rows: Sequence[dict[str, str]], title: str) -> None:
    """A table of the requirements not met (``tune.shortfalls.shortfalls``) and one line of what
    to relax (nothing when every requirement is met)."""
    from ema_cli.cli.output import print_table

    if not rows:
        return
    print_table(title, ["requirement", "limit", "tuned", "best in search", "why"],
                [[r["requirement"], r["limit"], r["value"], r["best"] or "-", r["why"]]
                 for r in rows],
                justify=["left", "left", "right", "right", "left"], wrap=["why"],
                optional=["best in search"])
    relax = [f"{r['requirement']} {r['relax']}" for r in rows if r["relax"]]
    if relax:
        import textwrap

        from ema_cli.cli.output import width

        console.print(textwrap.fill("to pass with the tuned controller, relax: "
                                    + "; ".join(relax) + " (or change the actuator)",
                                    width(), subsequent_indent="  "), highlight=False)


def print_blocking(text: str) -> None:
    """The sentence naming the requirements no gains inside the bounds were found to meet
    (nothing when it is empty)."""
    import textwrap

    from ema_cli.cli.output import width

    if text:  # (not broken at a test name's hyphen)
        console.print(textwrap.fill(text, width(), subsequent_indent="  ",
                                    break_on_hyphens=False), highlight=False)


def print_requirements(res: Any) -> None:
    """After ``ema tune --spec``: the battery's verdict on the tuned controller and what it
    misses."""
    o = res.outcome
    pick = o.checked[o.chosen]
    style = {"PASS": "bold green", "FAIL": "bold red", "INCONCLUSIVE": "bold yellow"}
    n_tests = len(o.spec.spec.tests)
    console.print(f"[{style[pick['verdict']]}]{pick['verdict']}[/]: the spec "
                  f"{o.spec.source} ({n_tests} tests) with the tuned controller, by the "
                  "battery", highlight=False)
    print_shortfalls(res.shortfalls(), "requirements not met")
    print_blocking(res.unmeetable())
