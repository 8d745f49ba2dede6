"""Issue 24: one registry per acceptance test kind (acceptance/kinds.py): every kind has its
settings schema, metrics with units, runner, figure, measurable range and docs row, and the
schema, the registry and the docs agree. Fails until a new kind is complete."""

from __future__ import annotations

import inspect
from pathlib import Path
from typing import get_args

import pytest

from ema_cli.acceptance.kinds import KINDS
from ema_cli.config import acceptance as cfg
from ema_cli.report import acceptance_report
from ema_cli.units import SI_UNIT, UNITS, units_of

DOCS = Path(__file__).resolve().parents[2] / "docs" / "model.md"


def test_the_registry_the_schema_and_the_union_name_the_same_kinds():
    assert set(KINDS) == set(cfg._KINDS) == set(cfg.METRICS) == set(cfg.TEST_KINDS)


@pytest.mark.parametrize("name", sorted(KINDS))
def test_every_kind_is_complete(name):
    kind = KINDS[name]
    assert kind.schema is cfg._KINDS[name]
    assert get_args(kind.schema.model_fields["test"].annotation) == (name,)
    # metrics: at least one, each with a dimension that has an SI unit and units to limit in
    assert kind.metrics and set(kind.metrics) == set(cfg.METRICS[name])
    for metric, dim in kind.dimensions.items():
        assert dim in SI_UNIT and units_of(dim), (metric, dim)
        assert kind.metrics[metric] == SI_UNIT[dim]
        assert all(UNITS[u][0] == dim for u in units_of(dim))
    # runner, batched over units: (name, test, units, dt) -> list[TestRun]
    # (further parameters, e.g. the tuning's fewer recorded samples, only with defaults)
    params = list(inspect.signature(kind.runner).parameters.values())
    assert [p.name for p in params[:4]] == ["name", "test", "units", "dt"]
    assert all(p.default is not inspect.Parameter.empty for p in params[4:])
    # figure: a function of report/acceptance_report.py taking (run, test, title)
    fig = getattr(acceptance_report, kind.figure, None)
    assert callable(fig), kind.figure
    assert list(inspect.signature(fig).parameters) == ["run", "test", "title"]
    # measurable range described; every time span a real setting of the kind
    assert kind.measurable
    example = kind.schema.model_construct(**{
        f: info.default for f, info in kind.schema.model_fields.items()
        if not info.is_required()} | {"amplitudes_deg": [1.0], "torque_nm": 1.0})
    for key, span, steps in example.spans():
        assert key in kind.schema.model_fields and span > 0 and steps >= cfg.MIN_STEPS


@pytest.mark.parametrize("name", sorted(KINDS))
def test_docs_list_every_kind_and_metric(name):
    text = DOCS.read_text()
    section = text[text.index("### The acceptance battery"):]
    row = next((line for line in section.splitlines() if line.startswith(f"| `{name}` |")),
               None)
    assert row is not None, f"docs/model.md: no row for the acceptance kind {name}"
    for metric in KINDS[name].metrics:
        assert f"`{metric}`" in row, (name, metric)


def test_the_sine_period_floor_is_the_sinestreams():
    # config/ cannot import analysis/ (a lower layer): the number is repeated, checked here
    from ema_cli.analysis.freqresp import HARMONICS

    assert cfg.SINE_PERIOD_STEPS == 8 * (HARMONICS + 1)
