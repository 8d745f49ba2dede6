"""``api.acceptance``: run an acceptance battery (a spec) on the actuator it names."""

from __future__ import annotations

from collections.abc import Callable, Sequence  # noqa: F401 - Sequence in hints
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ema_cli.api._inputs import ConfigSource, Overrides, base_dir, folder_arg, override_pairs
from ema_cli.errors import EmaError

if TYPE_CHECKING:
    import pandas as pd
    from matplotlib.figure import Figure

    from ema_cli.acceptance.battery import TestRun
    from ema_cli.acceptance.verdict import Verdict
    from ema_cli.config.acceptance import AcceptanceSpec


@dataclass
class AcceptanceResult:
    """A battery's outcome: one :class:`TestRun` per test, the PASS/FAIL rows (``verdicts``,
    each measurement against its limit, in the limit's unit), the actuator's SI parameters."""

    spec: AcceptanceSpec
    source: str
    runs: list[TestRun]
    verdicts: list[Verdict]
    params: dict[str, float]
    wall_time_s: float
    overrides: list[tuple[str, Any]] = field(default_factory=list)
    inputs: Any = None
    """What the folder's marker records (``report.run_inputs.RunInputs``)."""

    @property
    def verdict(self) -> str:
        """FAIL if any limit fails on a measured value (or a bound wholly outside it), else
        INCONCLUSIVE if any value could not be measured against its limit, else PASS."""
        from ema_cli.acceptance.verdict import overall

        return overall([v.result for v in self.verdicts])

    @property
    def exit_code(self) -> int:
        """``ema acceptance``'s exit code: 0 PASS, 1 FAIL, 3 INCONCLUSIVE."""
        from ema_cli.acceptance.verdict import EXIT_CODES

        return EXIT_CODES[self.verdict]

    @property
    def passed(self) -> bool:
        """Whether every limit of every test was met (on measured values or decisive
        bounds)."""
        return self.verdict == "PASS"

    @property
    def failed(self) -> list[Verdict]:
        """The rows that FAIL."""
        return [v for v in self.verdicts if v.result == "FAIL"]

    def failed_limits(self) -> list[str]:
        """The rows that FAIL as lines: ``test: metric (condition) value`` (the value in the
        one vocabulary, ``ema_cli.vocab``)."""
        from ema_cli.vocab import verdict_text

        return [f"{v.test}: {v.metric} ({v.condition}) {verdict_text(v)}" for v in self.failed]

    @property
    def inconclusive(self) -> list[Verdict]:
        """The rows that are INCONCLUSIVE (not measured inside the test's range)."""
        return [v for v in self.verdicts if v.result == "INCONCLUSIVE"]

    @property
    def title(self) -> str:
        return f"{self.spec.name}: acceptance ({self.spec.actuator.label()})"

    @property
    def metrics(self) -> pd.DataFrame:
        """acceptance.csv: one row per measurement with a limit."""
        return self.to_pandas()

    def to_pandas(self, form: str = "wide") -> pd.DataFrame:
        """The verdict table: test, kind, metric, condition, value, min, max, unit, result
        (PASS, FAIL or INCONCLUSIVE), measured (inside the test's range), lower, upper (the
        bound when not measured, in ``unit``), value_si, si_unit, note, reason (why
        INCONCLUSIVE, naming the setting to change), reads (the value as the commands print it:
        ``ema_cli.vocab.quantity``) (``wide``), or ``long`` (test, metric,
        condition, quantity, value)."""
        import dataclasses

        import pandas as pd

        from ema_cli.vocab import quantity

        df = pd.DataFrame([dataclasses.asdict(v) for v in self.verdicts])
        if len(df):
            df.insert(df.columns.get_loc("result") + 1, "passed", df["result"] == "PASS")
            # the value as every command prints it (ema_cli.vocab): "no phase crossover
            # (> 109.4 dB)", "not measured"
            df["reads"] = [quantity(v.value, v.unit, metric=v.metric, measured=v.measured,
                                    lower=v.lower, upper=v.upper, note=v.note)
                           for v in self.verdicts]
        if form == "wide":
            return df
        if form != "long":
            raise EmaError(f"form must be 'wide' or 'long', got {form!r}")
        return df.melt(id_vars=["test", "metric", "condition"], var_name="quantity",
                       value_name="value")

    def run(self, name: str) -> TestRun:
        for r in self.runs:
            if r.name == name:
                return r
        raise EmaError(f"no test {name!r}; tests: {', '.join(r.name for r in self.runs)}")

    def plot(self, test: str | None = None) -> Figure:
        """The figure of one test (default: the first)."""
        from ema_cli.report.acceptance_report import test_figure

        run = self.run(test) if test is not None else self.runs[0]
        return test_figure(run, self.spec.tests[run.name], self.title, self.verdicts)

    def save(self, folder: str | Path | None = None) -> Path:
        """Write acceptance.md, acceptance.csv, one figure per test, the spec and a manifest."""
        import yaml

        from ema_cli.report.acceptance_report import write_acceptance
        from ema_cli.report.rundir import write_run

        spec_json = self.spec.model_dump(mode="json", by_alias=True)
        inputs = self.inputs or _inputs(self.spec, self.overrides, [r.name for r in self.runs])
        return write_run("acceptance", self.spec.name, inputs, folder_arg(folder),
                         lambda out: write_acceptance(
                             out, yaml.safe_dump(spec_json, sort_keys=False), self,
                             {"source": self.source, "wall_time_s": self.wall_time_s,
                              "passed": self.passed, "verdict": self.verdict,
                              "exit_code": self.exit_code, "parameters_si": self.params,
                              "overrides": [[k, v] for k, v in self.overrides],
                              "test_wall_s": {r.name: r.wall_s for r in self.runs}}))


def _inputs(spec: AcceptanceSpec, pairs: list[tuple[str, Any]], only: Sequence[str] | None
            ) -> Any:
    from ema_cli.report.run_inputs import run_inputs

    return run_inputs(spec, sets=pairs, options={"only": list(only) if only else None})


def acceptance_inputs(spec: ConfigSource, overrides: Overrides = None, *,
                      only: Sequence[str] | None = None) -> Any:
    """The inputs (``report.run_inputs.RunInputs``) an :func:`acceptance` with these arguments
    records in its folder's marker: what ``ema acceptance`` checks ``--out`` against first."""
    from ema_cli.api._inputs import names_arg
    from ema_cli.config.acceptance import AcceptanceSpec
    from ema_cli.config.loader import load_config

    pairs = override_pairs(overrides)
    return _inputs(load_config(spec, pairs, AcceptanceSpec), pairs, names_arg(only, "only"))


def acceptance(spec: ConfigSource, overrides: Overrides = None, *,
               only: Sequence[str] | None = None,
               progress: Callable[[TestRun], None] | None = None) -> AcceptanceResult:
    """Run the battery of ``spec`` (a YAML file, a dict or an :class:`AcceptanceSpec`;
    ``overrides`` are dotted paths of the spec, e.g. ``actuator.plant.alpha``); ``only`` runs
    the named tests; ``progress(run)`` is called after each test."""
    import time

    from ema_cli.acceptance.kinds import run_test
    from ema_cli.acceptance.verdict import verdicts
    from ema_cli.config.acceptance import AcceptanceSpec
    from ema_cli.config.loader import load_config

    if spec is None:
        raise EmaError("acceptance needs a spec (a YAML file such as configs/acceptance.yaml)")
    from ema_cli.api._inputs import callable_arg, names_arg

    only = names_arg(only, "only")
    callable_arg(progress, "progress")
    pairs = override_pairs(overrides)
    sp = load_config(spec, pairs, AcceptanceSpec)
    names = list(sp.tests)
    if only:
        unknown = [n for n in only if n not in sp.tests]
        if unknown:
            raise EmaError(f"only: no test {unknown[0]!r} in the spec; tests: "
                           f"{', '.join(names)}")
        names = [n for n in names if n in set(only)]
    from ema_cli.acceptance.setup import test_setups

    (params, _), setups = test_setups(sp, names, base_dir(spec))
    from ema_cli.limits import estimate

    work = sum(sp.tests[n].sim_seconds() / setups[n][1] for n in names)
    estimate(work, f"{len(names)} test(s), {work:,.0f} integration steps (--only runs fewer)")
    t0 = time.perf_counter()
    runs = []
    rows = []
    from ema_cli.progress import report

    for k, name in enumerate(names):
        report(f"test {k + 1}/{len(names)} {name} ({sp.tests[name].test})")
        test = sp.tests[name]
        p, d = setups[name]
        run = run_test(name, test, p, d)
        runs.append(run)
        rows += verdicts(run, test.limits)
        if progress is not None:
            progress(run)
    return AcceptanceResult(sp, str(spec) if isinstance(spec, str | Path) else "dict", runs,
                            rows, params, time.perf_counter() - t0, pairs,
                            _inputs(sp, pairs, only))
