"""The Python API: what the ``ema`` commands do, for notebooks and scripts.

    >>> from ema_cli.api import simulate, sweep, identify, threshold, acceptance
    >>> run = simulate(nl={"deadzone2": 0.01})           # or simulate("configs/x.yaml", {...})
    >>> run.metrics                                       # one-row DataFrame, edge units
    >>> run.signal("theta_load_deg")                      # numpy array [deg] at run.t [s]
    >>> fig = run.plot(); folder = run.save("results/mine")

Every function takes what the command takes: a config (YAML path, dict, model or None for the
defaults) and ``overrides`` (the ``--set`` dotted paths, as a dict or (path, value) pairs).
Every result honours :class:`Result` (``api.result``): ``.metrics`` (a DataFrame, units in the
column names), ``.to_pandas(form)``, ``.plot()`` (a matplotlib Figure or a list of them) and
``.save(folder)`` (the command's own writers and output
folder policy: a given folder must be new or empty). Errors are ``ema_cli.errors.EmaError``
with a one-line message. Importing this module is cheap: numpy, numba, pandas and matplotlib
load when first needed.
"""

from __future__ import annotations

from ema_cli.api.acceptance import AcceptanceResult, acceptance
from ema_cli.api.freqresp import FrequencyResponse, freqresp
from ema_cli.api.identification import Identification, identify
from ema_cli.api.identify_logs import (
    ClosedLoopIdentification,
    FrictionSweepIdentification,
    SyntheticData,
    identify_closed_loop,
    identify_friction_sweep,
    make_identification_data,
)
from ema_cli.api.identify_plant import (
    PlantIdentification,
    PlantValidationResult,
    identify_plant,
    validate_folder,
)
from ema_cli.api.margins import LoopMargins, margins
from ema_cli.api.production import YieldResult, production_yield
from ema_cli.api.reproduce import ReproduceResult, reproduce
from ema_cli.api.result import Result
from ema_cli.api.sensitivity import Sensitivity, sensitivity
from ema_cli.api.simulation import Simulation, simulate
from ema_cli.api.study import Sweep, sweep
from ema_cli.api.threshold import Threshold, threshold
from ema_cli.api.tune import TuneResult, tune
from ema_cli.errors import EmaError

yield_ = production_yield
"""``ema yield`` by its command's name (``yield`` is a Python keyword)."""

__all__ = ["AcceptanceResult", "ClosedLoopIdentification", "EmaError", "FrequencyResponse",
           "FrictionSweepIdentification", "Identification", "LoopMargins",
           "PlantIdentification", "PlantValidationResult", "identify_plant", "validate_folder",
           "ReproduceResult", "Result", "Sensitivity", "Simulation", "Sweep",
           "SyntheticData", "Threshold", "TuneResult", "YieldResult", "acceptance",
           "freqresp", "identify", "identify_closed_loop", "identify_friction_sweep",
           "make_identification_data", "margins", "production_yield", "yield_", "reproduce",
           "sensitivity", "simulate", "sweep", "threshold", "tune"]
