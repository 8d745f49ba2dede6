"""Tiny runs of every command that writes a folder (configs and options small enough for a
run of a few seconds): the interruption harness (tests/system/test_interrupted_runs.py) and the
pipe-progress test (tests/cli/test_pipe_progress_cli.py) run them."""

from __future__ import annotations

TUNE = {"name": "tiny", "simulation": {"duration_s": 0.3, "dt_s": 5.0e-5},
        "scenarios": {"a": {"input": {"kind": "step", "amplitude_deg": 1.0}},
                      "b": {"input": {"kind": "step", "amplitude_deg": 0.5},
                            "nonlinearities": {"deadzone2": 0.01}}},
        "variables": {"Kpp": {"bounds": [20.0, 100.0], "scale": "log"},
                      "Kps": {"bounds": [0.05, 1.0], "scale": "log"}},
        "constraints": {"overshoot": "off"},
        "optimiser": {"budget": 240, "pop": 12}}
"""The issue's run: 2 scenarios, 2 variables, GA budget 240."""
STUDY = {"name": "tiny-sweep", "input": {"kind": "step", "amplitude_deg": 0.1},
         "simulation": {"duration_s": 0.05, "dt_s": 1e-5, "output_interval_s": 1e-3},
         "sweep": {"axes": [{"nonlinearity": "deadzone2", "values": [0.001, 0.01, 0.1]}]}}
SENSITIVITY = {
    "name": "tiny-sens",
    "inputs": [{"name": "s01", "kind": "step", "amplitude_deg": 0.1},
               {"name": "s5", "kind": "step", "amplitude_deg": 5.0}],
    "simulation": {"duration_s": 0.05, "dt_s": 1.0e-5, "output_interval_s": None},
    "factors": [{"nonlinearity": "deadzone1", "range": [0.01, 1.0], "scale": "log"},
                {"nonlinearity": "gap1", "range": [0.3, 10.0], "scale": "log"},
                {"name": "kpp", "parameter": "Kpp", "range": [40.0, 60.0]}],
    "metrics": ["iae_pos_deg_s", "p2p_err_pos_deg"],
    "sensitivity": {"n_sobol": 8, "num_resamples": 50},
    "parallel": {"chunk_size": 8}}
SPEC = {"name": "one-step", "actuator": {"config": None, "plant": {}, "nonlinearities": {}},
        "tests": {"step": {"test": "step", "amplitude_deg": 0.1, "duration_s": 0.3,
                           "limits": {"settling_time": {"max": 0.25, "unit": "s"}}}}}
TOLERANCES = {"tolerances": {"plant.kL": {"dist": "normal", "mean": 590, "sd": 30}}}
DESIGN = {"name": "tiny-design",
          "identify": {"shooting": {"starts": 2, "max_iter": 8, "lengthen_s": []},
                       "free": {"kL": [300.0, 900.0], "alpha": [0.0, 0.01]},
                       "max_iter": 5, "profile_points": 5, "dt_s": 2.0e-5},
          "tune": {"optimiser": {"pop": 8}}}
DESIGN_SPEC = {"name": "tiny-spec",
               "actuator": {"config": None, "plant": {}, "nonlinearities": {}},
               "tests": {"step": {"test": "step", "amplitude_deg": 10, "duration_s": 0.4,
                                  "limits": {"overshoot": {"max": 30, "unit": "%"}}},
                         "margins": {"test": "margins", "loops": ["position", "speed"],
                                     "limits": {"gain_margin": {"min": 3, "unit": "dB"}}}}}
EXPERIMENT = """name: tiny-batch
studies:
  - id: figA
    config: a.yaml
    figure: figA.png
    caption: "Figure A"
  - id: figB
    config: b.yaml
    figure: figB.png
    caption: "Figure B"
claims:
  - id: osc
    paper: p
    statement: oscillation at 0.1 deg
    check: {kind: value, study: figB, where: {deadzone2_deg: 0.1}, metric: p2p_err_pos_deg,
            op: ">=", value: 0.0}
"""
CLOSED_LOOP = ["--starts", "2", "--set", "shooting.max_iter=8", "--set",
               "shooting.lengthen_s=[]", "--set", "max_iter=5", "--set", "profile_points=5",
               "--set", "dt_s=2e-5"]
