"""The sensitivity config schema (config/sensitivity.py): the bundled config, and bad configs
refused with one line naming the file and the key."""

from __future__ import annotations

from pathlib import Path

import pytest

from ema_cli.config.loader import load_config
from ema_cli.config.sensitivity import SensitivityConfig
from ema_cli.errors import EmaError
from ema_cli.sensitivity.run import resolve_method

ROOT = Path(__file__).resolve().parents[2]
BASE = {"factors": [{"nonlinearity": "deadzone1", "range": [0.01, 1.0], "scale": "log"},
                    {"nonlinearity": "gap1", "range": [0.1, 10.0], "scale": "log"}]}


def cfg_with(**changes):
    data = {**BASE, **changes}
    return load_config(data, (), SensitivityConfig)


def test_the_bundled_config():
    cfg = load_config(ROOT / "configs" / "sensitivity.yaml", (), SensitivityConfig)
    names = [f.label for f in cfg.factors]
    assert names == ["deadzone1", "deadzone2", "deadzone3", "deadzone4", "saturation1",
                     "saturation2", "saturation3", "gap1", "friction1", "dummy"]
    assert [n for n, _ in cfg.input_list()] == ["step0.1", "step20"]
    assert [i.amplitude_deg for _, i in cfg.input_list()] == [0.1, 20.0]
    assert cfg.metrics == ["iae_pos_deg_s", "p2p_err_pos_deg"]
    assert cfg.sensitivity.n_sobol == 4096
    assert cfg.runs("sobol", 4096) == 2 * 4096 * 12
    assert cfg.simulation.output_interval_s is None  # metrics only
    # every value the paper tried lies inside its factor's range
    paper = {"deadzone1": (0.01, 1), "deadzone2": (0.001, 0.1), "deadzone3": (0.1, 10),
             "deadzone4": (0.001, 0.1), "saturation1": (800, 800), "saturation2": (40, 40),
             "saturation3": (30.35, 30.35), "gap1": (0.01, 10), "friction1": (1e-4, 0.1)}
    for f in cfg.factors[:9]:
        lo, hi = paper[f.label]
        assert f.range[0] <= lo and hi <= f.range[1], f.label


def test_a_resolved_config_round_trips():
    cfg = load_config(ROOT / "configs" / "sensitivity.yaml", (), SensitivityConfig)
    again = load_config(cfg.model_dump(mode="json"), (), SensitivityConfig)
    assert again == cfg


@pytest.mark.parametrize(("changes", "needle"), [
    ({"factors": [{"nonlinearity": "deadzone9", "range": [0, 1]}]},
     "factors.0.nonlinearity: unknown nonlinearity 'deadzone9'"),
    ({"factors": [{"parameter": "Kxx", "range": [0, 1]}]},
     "factors.0.parameter: unknown model parameter 'Kxx'"),
    ({"factors": [{"nonlinearity": "deadzone1", "range": [0.5, 0.5]}]},
     "factors.0.range: empty range [0.5, 0.5]"),
    ({"factors": [{"nonlinearity": "deadzone1", "range": [1.0, 0.1]}]},
     "factors.0.range: inverted range [1, 0.1]"),
    ({"factors": [{"nonlinearity": "deadzone1", "range": [0.0, 1.0], "scale": "log"}]},
     "factors.0.range: a log range needs low > 0"),
    ({"factors": [{"nonlinearity": "saturation2", "range": [0.0, 40.0]}]},
     "factors.0.range: 'saturation2' limit must be > 0"),
    ({"factors": [{"nonlinearity": "deadzone2", "range": [0.001, 0.1]},
                  {"nonlinearity": "deadzone@transmission", "range": [0.001, 0.1]}]},
     "factors.1: 'deadzone@transmission' varies in factors 0 and 1"),
    ({"factors": [{"nonlinearity": "deadzone2", "range": [0.001, 0.1]},
                  {"parameter": "alpha", "range": [0.0, 0.001]}]},
     "factors.1: factors 0 and 1 both set the model parameter 'alpha'"),
    ({"factors": []}, "factors: give at least one factor"),
    ({"factors": [{"range": [0, 1]}]}, "exactly one of 'nonlinearity' or 'parameter'"),
    ({"metrics": ["iae_pos"]}, "metrics.0: unknown metric 'iae_pos'"),
    ({"metrics": ["t50_s", "t50_s"]}, "metrics.1: metric 't50_s' is listed twice"),
    ({"sensitivity": {"n_sobol": 1000}}, "sensitivity.n_sobol: n_sobol must be a power of two"),
    ({"sensitivity": {"morris_levels": 3}}, "morris_levels must be even"),
    ({"input": {"amplitude_deg": 1.0}, "inputs": [{"name": "a"}]},
     "inputs: give either 'input' or 'inputs', not both"),
    ({"inputs": [{"name": "a"}, {"name": "a"}]}, "inputs.1.name: input name 'a' is given twice"),
])
def test_bad_configs_name_the_key(changes, needle):
    with pytest.raises(EmaError) as err:
        cfg_with(**changes)
    assert needle in err.value.message and "\n" not in err.value.message, err.value.message
    assert err.value.message.startswith("dict: ")


def test_method_and_n_from_the_options():
    cfg = cfg_with()
    assert resolve_method(cfg, None, None) == ("sobol", 1024)
    assert resolve_method(cfg, "morris", None) == ("morris", 64)
    assert resolve_method(cfg, "sobol", 256) == ("sobol", 256)
    with pytest.raises(EmaError, match=r"--n must be a power of two for Sobol sampling.*got "
                                       r"1000; e\.g\. 512 or 1024"):
        resolve_method(cfg, "sobol", 1000)
    assert resolve_method(cfg, "morris", 1000) == ("morris", 1000)  # Morris takes any n
    with pytest.raises(EmaError, match="--method must be sobol or morris"):
        resolve_method(cfg, "fast", None)
    with pytest.raises(EmaError, match="needs 3,000,000 simulations, more than "
                                       "sensitivity.max_runs"):
        resolve_method(cfg, "morris", 1_000_000)
