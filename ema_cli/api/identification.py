"""``api.identify``: the GA identification of kL, alpha (and c), as ``ema identify`` runs it."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ema_cli.api._inputs import ConfigSource, Overrides, folder_arg, override_pairs
from ema_cli.errors import EmaError

if TYPE_CHECKING:
    import numpy as np
    import pandas as pd
    from matplotlib.figure import Figure

    from ema_cli.identify.torque.run import IdentificationResult
    from ema_cli.identify.torque.settings import IdentifySettings

DATA_COLUMNS = {"t_s": "t", "dtheta_rad": "dth", "domega_rad_s": "dw", "torque_nm": "torque"}
"""Identification data columns (edge name -> IdentData field); ``torque_model_nm`` is the
model's torque at the best run's parameters."""


@dataclass
class Identification:
    """An identification: ``result`` is ``identify.torque.run.IdentificationResult`` (SI)."""

    result: IdentificationResult

    @property
    def parameters(self) -> dict[str, float]:
        """The identified values (median over the runs), SI: kL [N*m/rad], alpha [rad], c."""
        return {n: float(s["median"]) for n, s in self.result.summary().items()}

    @property
    def metrics(self) -> pd.DataFrame:
        """One row per parameter: identified (median), truth, error % (median / worst), the
        least-squares optimum and its standard error, SI units in ``unit``."""
        import pandas as pd

        from ema_cli.identify.torque.problem import PARAM_UNITS

        rows = [{"parameter": n, "unit": PARAM_UNITS[n], **s}
                for n, s in self.result.summary().items()]
        return pd.DataFrame(rows)

    @property
    def runs(self) -> pd.DataFrame:
        """One row per GA run (runs.csv)."""
        return self.result.runs_frame()

    def signal(self, name: str) -> np.ndarray:
        """A data column by name (``t_s``, ``dtheta_rad``, ``domega_rad_s``, ``torque_nm``) or
        ``torque_model_nm`` (the fitted model's torque at the best run) [SI]."""
        if name == "torque_model_nm":
            best = min(self.result.runs, key=lambda r: r.cost)
            return self.result.problem.model_torque(best.x)
        if name not in DATA_COLUMNS:
            raise EmaError(f"unknown signal {name!r}; expected one of "
                           f"{', '.join([*DATA_COLUMNS, 'torque_model_nm'])}")
        return getattr(self.result.data, DATA_COLUMNS[name])

    def to_pandas(self, form: str = "wide") -> pd.DataFrame:
        """The data and the fit: ``wide`` (one column per quantity, units in the names) or
        ``long`` (``t_s``, ``signal``, ``value``)."""
        import pandas as pd

        wide = pd.DataFrame({n: self.signal(n) for n in [*DATA_COLUMNS, "torque_model_nm"]})
        if form == "wide":
            return wide
        if form != "long":
            raise EmaError(f"form must be 'wide' or 'long', got {form!r}")
        return wide.melt(id_vars="t_s", var_name="signal", value_name="value")

    def plot(self, kind: str = "fit") -> Figure:
        """``fit`` (measured vs model torque) or ``convergence`` (J per generation)."""
        from ema_cli.report.identify_figures import convergence_figure, fit_figure

        if kind not in ("fit", "convergence"):
            raise EmaError(f"kind must be 'fit' or 'convergence', got {kind!r}")
        return fit_figure(self.result) if kind == "fit" else convergence_figure(self.result)

    def save(self, folder: str | Path | None = None) -> Path:
        """Write the folder ``ema identify`` writes -> the folder (new or empty if given)."""
        from ema_cli.report.identify_figures import write_identification
        from ema_cli.report.rundir import write_run

        return write_run("identify", "torque", identification_inputs(self.result.settings),
                         folder_arg(folder),
                         lambda out: write_identification(self.result, out, command="identify"))


def identification_inputs(settings: IdentifySettings) -> Any:
    """The inputs (``report.run_inputs.RunInputs``) an identification with the validated
    ``settings`` records in its folder's marker: every setting, and the data file's SHA-256
    (what ``ema identify`` checks ``--out`` against first)."""
    from ema_cli.report.run_inputs import run_inputs

    return run_inputs(settings, files={"data": getattr(settings, "data", None)})


def load_settings(config: ConfigSource = None, overrides: Overrides = None
                  ) -> IdentifySettings:
    """The validated identification settings of ``config`` with ``overrides`` (what
    :func:`identify` runs), e.g. to report the method before a long run."""
    from ema_cli.config.loader import load_config
    from ema_cli.identify.torque.settings import IdentifySettings

    return load_config(config, override_pairs(overrides), IdentifySettings)


def identify(config: ConfigSource = None, overrides: Overrides = None,
             **settings: Any) -> Identification:
    """Identify kL and alpha (and c) as ``ema identify`` does.

    config     identification settings: a YAML file, a dict, an ``IdentifySettings`` or None
    overrides  dotted paths -> values, e.g. ``{"ga.pop": 50}``
    settings   top-level settings by name, e.g. ``k_range=(500, 700)``, ``method="exact"``,
               ``data="log.csv"``, ``runs=5`` (see ``identify.torque.settings.IdentifySettings``)
    """
    from ema_cli.config.loader import load_config
    from ema_cli.identify.torque.run import run_identification
    from ema_cli.identify.torque.settings import IdentifySettings

    pairs = override_pairs(overrides)
    pairs += [(k, list(v) if isinstance(v, tuple) else v) for k, v in settings.items()]
    cfg = load_config(config, pairs, IdentifySettings)
    return Identification(run_identification(cfg))
