"""The registry of acceptance test kinds: per kind its settings schema, metrics with units,
runner, figure and measurable range, in one place (``tests/unit/test_acceptance_kinds.py``
checks that every kind is complete).

Adding a kind: a schema class in ``config/acceptance.py`` (``test: Literal[KIND]``, its
``METRICS`` with dimensions, its ``spans()``), listed in ``config.acceptance._KINDS``; a runner
``run_KIND(name, test, units, dt) -> list[TestRun]`` in ``acceptance/battery*.py`` (every
actuator of ``units`` in the same kernel batches, each unit's result bit for bit its result
alone) that returns a bound (``_bound``) with a reason for every value outside its measurable
range; a figure
function in ``report/acceptance_report.py``; one :class:`Kind` entry below. The completeness
test fails until all of them exist and the docs table (docs/model.md) lists the kind.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from ema_cli.acceptance import battery as b
from ema_cli.acceptance import battery_duty as bd
from ema_cli.acceptance import battery_loops as bl
from ema_cli.acceptance import battery_sweeps as bs
from ema_cli.config import acceptance as c
from ema_cli.units import SI_UNIT


@dataclass(frozen=True)
class Kind:
    """One acceptance test kind: ``schema`` (its settings and limits), ``runner`` (batched over
    units: ``(name, test, units, dt) -> list[TestRun]``), the name of
    its figure function in ``report/acceptance_report.py`` (``figure``), and ``measurable``:
    when a value is only a bound (the INCONCLUSIVE cases)."""

    name: str
    schema: type[Any]
    runner: Callable[[str, Any, Sequence[Mapping[str, float]], float], list[b.TestRun]]
    figure: str
    measurable: str

    @property
    def metrics(self) -> dict[str, str]:
        """metric -> its SI unit."""
        return {m: SI_UNIT[dim] for m, dim in self.schema.METRICS.items()}

    @property
    def dimensions(self) -> dict[str, str]:
        """metric -> its dimension (:data:`ema_cli.units.UNITS`)."""
        return dict(self.schema.METRICS)


KINDS: dict[str, Kind] = {k.name: k for k in (
    Kind("step", c.StepTest, b.run_step, "figure_step",
         "settled (2 %) before duration_s ends; else every metric is a bound"),
    Kind("frequency_response", c.FrequencyResponseTest, bs.run_frequency_response,
         "figure_frequency_response",
         "bandwidth: the -3 dB crossing inside f_min_hz..f_max_hz; peak gain: not at the "
         "highest frequency (nor at the lowest above 0.5 dB)"),
    Kind("margins", c.MarginsTest, b.run_margins, "figure_margins",
         "crossovers inside 1e-3 Hz..f_max_hz (a missing phase crossover bounds the gain "
         "margin by |L(f_max_hz)|)"),
    Kind("threshold", c.ThresholdTest, b.run_threshold, "figure_threshold",
         "the threshold inside search_deg (a floor above the limit max is refused)"),
    Kind("hysteresis", c.HysteresisTest, bl.run_hysteresis, "figure_hysteresis",
         "the load spans half the command at least; free play: no limit cycle"),
    Kind("load_deflection", c.LoadDeflectionTest, bl.run_load_deflection, "figure_load_deflection",
         "the load angle is one line per branch (rms residual <= 2 % of its span)"),
    Kind("dynamic_stiffness", c.DynamicStiffnessTest, bs.run_dynamic_stiffness,
         "figure_dynamic_stiffness", "the minimum strictly inside f_min_hz..f_max_hz"),
    Kind("no_load_rate", c.NoLoadRateTest, b.run_no_load_rate, "figure_no_load_rate",
         "the peak rate before the end of the run"),
    Kind("duty", c.DutyTest, bd.run_duty, "figure_duty",
         "the winding's peak farther from its limit than the multirate method's error, every "
         "segment's cycle steady and no run diverged; else it is a bound (peak +- error)"),
)}
"""Every acceptance test kind, by name."""


def run_test(name: str, test: Any, params: Mapping[str, float], dt: float) -> b.TestRun:
    """Run one test of a spec on one actuator (SI ``params``) with its kind's runner, timed."""
    return run_units(name, test, [params], dt)[0]


def run_units(name: str, test: Any, units: Sequence[Mapping[str, float]],
              dt: float) -> list[b.TestRun]:
    """Run one test of a spec on every actuator of ``units`` (SI parameters) in the same
    kernel batches; each run's ``wall_s`` is the batch's wall time shared equally [s]."""
    t0 = time.perf_counter()
    runs = KINDS[test.test].runner(name, test, units, dt)
    share = (time.perf_counter() - t0) / max(len(runs), 1)
    for run in runs:
        run.wall_s = share
    return runs
