"""Issue 22, one strict loader for every file: a run config read through another file (a
tuning config's or an acceptance spec's ``actuator.config``) is validated as ``ema simulate``
validates it (an unknown key is named with its file, never dropped), and every schema's
documented defaults go through validation as user values do."""

from __future__ import annotations

import importlib
import pkgutil
from pathlib import Path
from typing import Annotated

import pytest
from pydantic import TypeAdapter
from typer.testing import CliRunner

import ema_cli.config as config_pkg
from ema_cli.api import acceptance, tune
from ema_cli.cli.main import app
from ema_cli.config.base import Strict
from ema_cli.config.loader import load_config, read_yaml
from ema_cli.config.tune import Limit, TuneConfig
from ema_cli.errors import EmaError

ROOT = Path(__file__).resolve().parents[2]
MISSPELT = "name: act\nplnat: {kL: 300}\n"  # plant, misspelt


def _schemas() -> list[type[Strict]]:
    for m in pkgutil.iter_modules(config_pkg.__path__):
        importlib.import_module(f"ema_cli.config.{m.name}")
    out, todo = [], [Strict]
    while todo:
        for sub in todo.pop().__subclasses__():
            out.append(sub)
            todo.append(sub)
    return sorted(set(out), key=lambda c: (c.__module__, c.__name__))


@pytest.mark.parametrize("schema", _schemas(), ids=lambda c: f"{c.__module__[15:]}.{c.__name__}")
def test_every_default_is_a_validated_value(schema):
    # a default that validation would change (a raw dict where a Limit is expected) is one
    # that never went through validation: it must be declared validate_default
    for name, field in schema.model_fields.items():
        if field.is_required():
            continue
        default = field.get_default(call_default_factory=True)
        if default is None:
            continue
        kind = Annotated[field.annotation, *field.metadata] if field.metadata else \
            field.annotation
        value = TypeAdapter(kind).validate_python(default)
        assert value == default or field.validate_default, (schema.__name__, name)


def test_tune_defaults_are_validated_limits():
    doc = read_yaml(ROOT / "configs" / "tune.yaml")
    doc.pop("constraints")
    cfg = load_config(doc, [], TuneConfig)
    limits = cfg.constraints_of("deadband")
    assert set(limits) == {"gain_margin", "phase_margin"}
    assert all(isinstance(v, Limit) for v in limits.values())
    assert limits["gain_margin"].si() == (6.0, float("inf"))


def _tune_doc(tmp_path: Path) -> Path:
    doc = (ROOT / "configs" / "tune.yaml").read_text()
    doc = doc.replace("  config: null ", "  config: act.yaml #", 1)
    (tmp_path / "act.yaml").write_text(MISSPELT)
    (tmp_path / "tune.yaml").write_text(doc)
    return tmp_path / "tune.yaml"


def test_tune_refuses_a_misspelt_section_of_its_actuator_config(tmp_path):
    path = _tune_doc(tmp_path)
    with pytest.raises(EmaError, match=r"^actuator\.config: .*act\.yaml: plnat: unknown key$"):
        tune(path, budget=188)  # (the smallest budget configs/tune.yaml's pop 64 accepts)
    r = CliRunner().invoke(app, ["tune", str(path), "--budget", "188", "--out",
                                 str(tmp_path / "out")])
    assert r.exit_code == 2 and "act.yaml: plnat: unknown key" in " ".join(r.output.split())
    assert not (tmp_path / "out").exists()


def test_acceptance_refuses_the_same_file(tmp_path):
    (tmp_path / "act.yaml").write_text(MISSPELT)
    spec = {"name": "s", "actuator": {"config": str(tmp_path / "act.yaml")},
            "tests": {"m": {"test": "margins", "limits": {"gain_margin": {"min": 6,
                                                                          "unit": "dB"}}}}}
    with pytest.raises(EmaError, match=r"act\.yaml: plnat: unknown key"):
        acceptance(spec)


def test_sensitivity_refuses_an_unknown_key(tmp_path):
    text = (ROOT / "configs" / "sensitivity.yaml").read_text() + MISSPELT.split("\n")[1] + "\n"
    (tmp_path / "s.yaml").write_text(text)
    r = CliRunner().invoke(app, ["sensitivity", str(tmp_path / "s.yaml"), "--out",
                                 str(tmp_path / "out")])
    assert r.exit_code == 2 and "s.yaml: plnat: unknown key" in r.output


@pytest.mark.parametrize(("section", "needle"), [
    ("identify: {shootng: {starts: 4}}\n", "identify: dict: shootng: unknown key"),
    ("tune: {optimser: {pop: 16}}\n", "unknown key 'optimser'"),
])
def test_validate_checks_a_design_configs_sections(tmp_path, section, needle):
    # a design config's sections belong to other schemas: validate checks them there
    path = tmp_path / "d.yaml"
    path.write_text("name: d\n" + section)
    r = CliRunner().invoke(app, ["validate", str(path), "--kind", "design"])
    assert r.exit_code == 2 and needle in " ".join(r.output.split()), r.output
    r = CliRunner().invoke(app, ["validate", str(ROOT / "configs" / "design_ci.yaml")])
    assert r.exit_code == 0, r.output
