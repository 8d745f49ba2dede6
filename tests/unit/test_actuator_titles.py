"""Figure titles name the actuator that ran (issue 39, item 7): the description's name, or the
reference EMA with the plant parameters set on it (a fitted actuator is not the reference)."""

from __future__ import annotations

from pathlib import Path

from ema_cli.config.limits import ActuatorSpec
from ema_cli.config.run import actuator_label

ROOT = Path(__file__).resolve().parents[2]


def test_labels_say_which_actuator():
    assert actuator_label(None, []) == "reference EMA"
    assert actuator_label("emps", []) == "emps"
    assert actuator_label(None, ["kL", "alpha"]) == "reference EMA with kL, alpha set"
    assert actuator_label(None, ["kL", "alpha", "Fc", "sigma2", "JL"]) == \
        "reference EMA with kL, alpha, Fc +2 set"
    assert ActuatorSpec().label() == "reference EMA"
    assert ActuatorSpec(config="fits/geared.yaml", plant={"kL": 500.0}).label() == \
        "geared with kL set"


def test_a_described_actuator_titles_the_figures(tmp_path):
    import ema_cli.api as api

    cfg = tmp_path / "run.yaml"
    cfg.write_text(f"name: mine\nactuator: {ROOT / 'configs' / 'actuators' / 'paper_ema.yaml'}\n")
    m = api.margins(str(cfg))
    assert m.title.startswith("mine (paper-ema): ")
    assert m.plot()._suptitle.get_text().startswith("mine (paper-ema): ")
    plain = api.margins(None, [("plant.kL", 500.0)])
    assert "(reference EMA with kL set)" in plain.title
