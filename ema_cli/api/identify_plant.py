"""``api.identify_plant``: plant identification of a rigid axis from a closed-loop record, as
``ema identify plant`` runs it (IDIM-LS start and baseline, controller check, output-error
refinement in closed loop, the two-part verdict, time-split validation), and
:meth:`PlantIdentification.validate` against another record (``ema identify validate``).

    >>> from ema_cli.api import identify_plant
    >>> fit = identify_plant("DATA_EMPS.mat", "configs/actuators/emps.yaml")
    >>> fit.parameters          # {'M': 95.3, 'Fv+': 172.2, ...} SI
    >>> fit.metrics             # value, unit, 95 % interval, status per parameter
    >>> fit.validate("other.mat").errors
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ema_cli.api._inputs import ConfigSource, Overrides, folder_arg, override_pairs

if TYPE_CHECKING:
    import pandas as pd
    from matplotlib.figure import Figure

    from ema_cli.identify.plant.fit import PlantFit
    from ema_cli.identify.plant.settings import PlantSettings
    from ema_cli.identify.plant.validation import PlantValidation


def plant_settings(config: ConfigSource = None, overrides: Overrides = None,
                   **settings: Any) -> PlantSettings:
    """Validated settings from a config (YAML, dict, model or None), ``overrides`` and keyword
    settings (``data``, ``actuator``, ``law``, ...; keys of ``PlantSettings``)."""
    from ema_cli.config.loader import load_config
    from ema_cli.identify.plant.settings import PlantSettings

    pairs = override_pairs(overrides) + [(k, v) for k, v in settings.items() if v is not None]
    return load_config(config, pairs, PlantSettings)


def plant_inputs(settings: PlantSettings) -> Any:
    """The inputs a run folder's marker records: every setting and the SHA-256 of the record,
    the description and the validation record."""
    from ema_cli.report.run_inputs import run_inputs

    return run_inputs(settings, files={"data": settings.data, "actuator": settings.actuator,
                                       "validate": settings.validate_data})


@dataclass
class PlantValidationResult:
    """The fitted model against another record: ``result`` is
    ``identify.plant.fit.PlantValidation``; ``axis`` rotary or translational."""

    result: PlantValidation
    axis: str = "translational"

    @property
    def metrics(self) -> pd.DataFrame:
        """One row per model: the benchmark's relative errors [%] and the RMS position error
        [m] (NaN where the inverse model simulates no motion)."""
        import pandas as pd

        return pd.DataFrame([{"model": k, **{f"{c}_pct": v for c, v in e.as_dict().items()},
                              "rms_position_m": self.result.rms_position_m[k]}
                             for k, e in self.result.errors.items()])

    errors = metrics

    def to_pandas(self, form: str = "wide") -> pd.DataFrame:
        """Time, the measured force and position and each model's (SI units in the names)."""
        import pandas as pd

        from ema_cli.api.result import long_form

        r = self.result
        cols = {"t_s": r.record.t_s, "force_measured_n": r.record.force_n,
                "position_measured_m": r.record.q_m}
        for k, sim in r.sims.items():
            cols[f"force_{k}_n"] = sim["F"]
            cols[f"position_{k}_m"] = sim["q"]
        return long_form(pd.DataFrame(cols), form, ["t_s"])

    def plot(self) -> Figure:
        """The record's force and each model's, with the force and position residuals."""
        from ema_cli.report.plant_report import channels_figure

        r = self.result
        sims = r.sims or {}
        return channels_figure(r.record.t_s, {"F": r.record.force_n, "q": r.record.q_m},
                               {k: {"F": v["F"], "q": v["q"]} for k, v in sims.items()},
                               self.axis, f"Validation on {r.record.source}")

    def save(self, folder: str | Path | None = None) -> Path:
        """Write validation.md, validation.json (and validation.png) -> the folder."""
        from ema_cli.report.plant_report import write_validation
        from ema_cli.report.run_inputs import run_inputs
        from ema_cli.report.rundir import write_run

        inputs = run_inputs({"validate": self.result.record.source})
        return write_run("identify", "validate", inputs, folder_arg(folder),
                         lambda out: write_validation(self.result, out, self.axis))


@dataclass
class PlantIdentification:
    """A plant identification: ``result`` is ``identify.plant.fit.PlantFit``."""

    result: PlantFit
    validation: PlantValidation | None = None
    extra: dict[str, Any] = field(default_factory=dict)

    @property
    def parameters(self) -> dict[str, float]:
        """The chosen law's estimate, SI, by term name."""
        return self.result.best.estimate

    @property
    def determined(self) -> bool:
        """Every parameter determined (or zero within its interval)."""
        return self.result.best.determined()[0]

    @property
    def adequacy(self) -> str:
        """ADEQUATE | NOT ADEQUATE | INCONCLUSIVE, the chosen law's."""
        return self.result.best.adequacy.verdict

    @property
    def metrics(self) -> pd.DataFrame:
        """One row per parameter: value, unit, SE, 95 % interval, status, IDIM-LS start."""
        import pandas as pd

        from ema_cli.report.plant_report import axis_of, parameters_table

        return pd.DataFrame(parameters_table(self.result.best, axis_of(self.result)))

    @property
    def errors(self) -> pd.DataFrame:
        """The benchmark's relative errors [%] of the fit and of IDIM-LS on the fitted samples."""
        import pandas as pd

        return pd.DataFrame([{"model": k, **e.as_dict()} for k, e in self.result.errors.items()])

    def to_pandas(self, form: str = "wide") -> pd.DataFrame:
        """fit.csv: time, measured and simulated force and position (edge units)."""
        import pandas as pd

        from ema_cli.api.result import long_form
        from ema_cli.report.plant_report import fit_columns

        return long_form(pd.DataFrame(fit_columns(self.result)), form, ["t_s"])

    def plot(self) -> list[Figure]:
        """The fit's channels with residuals, and the residual tests."""
        from ema_cli.report.plant_report import (
            axis_of,
            channels_figure,
            residual_tests_figure,
        )

        r = self.result
        return [channels_figure(r.record.t_s, {"F": r.record.force_n, "q": r.record.q_m},
                                {f"fit ({r.chosen})": {"F": r.best.F, "q": r.best.q},
                                 "IDIM-LS": r.baseline_sim}, axis_of(r), "Plant fit"),
                residual_tests_figure(r.best)]

    def validate(self, data: str | Path, columns: dict[str, str] | None = None
                 ) -> PlantValidationResult:
        """Simulate the fitted model and IDIM-LS against another record."""
        from ema_cli.identify.plant.validation import validate
        from ema_cli.report.plant_report import axis_of

        v = validate(self.result, data, columns)
        self.validation = v
        return PlantValidationResult(v, axis_of(self.result))

    def save(self, folder: str | Path | None = None) -> Path:
        """Write the folder ``ema identify plant`` writes -> the folder."""
        from ema_cli.report.plant_report import write_plant
        from ema_cli.report.rundir import write_run

        s = self.result.settings
        return write_run("identify", s.name, plant_inputs(s), folder_arg(folder),
                         lambda out: write_plant(self.result, out, self.validation))


def identify_plant(data: str | Path | None = None, actuator: str | Path | None = None,
                   config: ConfigSource = None, overrides: Overrides = None, *,
                   progress: Any = None, **settings: Any) -> PlantIdentification:
    """Identify a rigid axis from a closed-loop record (``ema identify plant DATA --actuator
    DESC``); ``settings``: law, delay, window, split, columns, set, max_iter, validate_data.
    ``progress(stage, done, total)`` is called as the fit advances."""
    from ema_cli.identify.plant.fit import run_plant
    from ema_cli.identify.plant.validation import validate

    s = plant_settings(config, overrides, data=None if data is None else str(data),
                       actuator=None if actuator is None else str(actuator), **settings)
    fit = run_plant(s, progress)
    v = None
    if s.validate_data:
        if progress is not None:
            progress(f"validation on {Path(s.validate_data).name}", None, None)
        v = validate(fit, s.validate_data)
    return PlantIdentification(fit, v)


def validate_folder(folder: str | Path, data: str | Path,
                    columns: dict[str, str] | None = None) -> PlantValidationResult:
    """The models a folder of ``ema identify plant`` holds (its plant.json: the fit and IDIM-LS,
    the settings, the delay) simulated against another record (``ema identify validate``)."""
    import json

    from ema_cli.errors import EmaError
    from ema_cli.identify.plant.settings import PlantSettings
    from ema_cli.identify.plant.validation import validate_models

    js = Path(folder) / "plant.json"
    if not js.is_file():
        raise EmaError(f"'{folder}': no plant.json; expected a folder `ema identify plant` "
                       "wrote")
    try:
        doc = json.loads(js.read_text())
        settings = PlantSettings(**doc["settings"])
        models, delay = doc["models"], int(doc["delay_samples"])
        inverse = doc.get("controller_check") is None
    except (ValueError, KeyError, TypeError) as exc:
        raise EmaError(f"'{js}': not a plant.json of this version ({type(exc).__name__}); "
                       "rerun `ema identify plant`") from None
    axis = "rotary" if doc.get("axis") == "rotary" else "translational"
    return PlantValidationResult(validate_models(settings, delay, models, data, columns,
                                                 inverse=inverse), axis)
