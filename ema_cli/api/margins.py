"""``api.margins``: stability margins of the position and speed loops of the linear limit."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ema_cli.api._inputs import ConfigSource, Overrides, base_dir, folder_arg, override_pairs
from ema_cli.config.support import check_command, checked

if TYPE_CHECKING:
    import numpy as np
    import pandas as pd
    from matplotlib.figure import Figure

    from ema_cli.analysis.linear import Margins
    from ema_cli.config.study import StudyConfig

F_MIN_HZ, F_MAX_HZ, N_FREQ = 0.01, 10_000.0, 600  # the plotted/tabulated frequency grid


@dataclass
class LoopMargins:
    """Margins of both loops (``result``: loop -> analysis.linear.Margins) and their open-loop
    responses ``loops`` (loop -> L(j 2 pi f) at ``f_hz``)."""

    config: StudyConfig
    params: dict[str, float]
    result: dict[str, Margins]
    f_hz: np.ndarray
    loops: dict[str, np.ndarray]
    notes: list[str] = field(default_factory=list)
    overrides: list[tuple[str, Any]] = field(default_factory=list)
    inputs: Any = None
    """What the folder's marker records (``report.run_inputs.RunInputs``)."""

    @property
    def metrics(self) -> pd.DataFrame:
        """One row per loop: gm_db, pm_deg, f_gm_hz, f_pm_hz."""
        import pandas as pd

        return pd.DataFrame([{"loop": k, **m.to_json()} for k, m in self.result.items()])

    def to_pandas(self, form: str = "wide") -> pd.DataFrame:
        """The open-loop responses: ``wide`` (loops.csv) or ``long`` (f_hz, loop, gain_db,
        phase_deg)."""
        import numpy as np
        import pandas as pd

        from ema_cli.errors import EmaError

        if form not in ("wide", "long"):
            raise EmaError(f"form must be 'wide' or 'long', got {form!r}")
        rows = [pd.DataFrame({"f_hz": self.f_hz, "loop": k,
                              "gain_db": 20 * np.log10(np.abs(L)),
                              "phase_deg": np.degrees(np.unwrap(np.angle(L)))})
                for k, L in self.loops.items()]
        long = pd.concat(rows, ignore_index=True)
        if form == "long":
            return long
        wide = long.pivot(index="f_hz", columns="loop", values=["gain_db", "phase_deg"])
        wide.columns = [f"{loop}_{q}" for q, loop in wide.columns]
        return wide.reset_index()

    @property
    def title(self) -> str:
        return (f"{self.config.name} ({self.config.actuator_label()}): open loops of "
                "the linear limit")

    def plot(self) -> Figure:
        """Bode and Nichols plots of both open loops, margins marked."""
        from ema_cli.report.margins_report import margins_figure

        return margins_figure(self.f_hz, self.loops, self.result, self.title)

    def save(self, folder: str | Path | None = None) -> Path:
        """Write margins.json, loops.csv, margins.png, the resolved config and a manifest."""
        import yaml

        from ema_cli.report.margins_report import write_margins
        from ema_cli.report.run_inputs import run_inputs
        from ema_cli.report.rundir import write_run

        cfg_json = self.config.model_dump(mode="json")
        inputs = self.inputs or run_inputs(self.config, sets=self.overrides)
        return write_run("margins", self.config.name, inputs, folder_arg(folder),
                         lambda out: write_margins(
                             out, yaml.safe_dump(cfg_json, sort_keys=False), self.f_hz,
                             self.loops, self.result, self.title,
                             {"seed": self.config.seed, "parameters_si": self.params,
                              "overrides": [[k, v] for k, v in self.overrides],
                              "margins": {k: m.to_json() for k, m in self.result.items()}},
                             self.notes))


def margins(config: ConfigSource = None, overrides: Overrides = None) -> LoopMargins:
    """Gain and phase margins of the position and speed loops (each broken at its feedback,
    the other closed) of the configured actuator's linear limit: saturations, dead zones,
    backlash and quantisers removed, friction reduced to its viscous part, the controller
    continuous."""
    import numpy as np

    from ema_cli.analysis.linear import LOOPS, loop_transfer
    from ema_cli.analysis.linear import margins as loop_margins
    from ema_cli.config.loader import load_config, resolve_run
    from ema_cli.config.study import StudyConfig

    pairs = override_pairs(overrides)
    cfg = load_config(config, pairs, StudyConfig)
    check_command(cfg, "margins")
    params = resolve_run(cfg, base_dir(config)).params
    notes = []
    if params["Ts"] > 0:
        notes.append(f"the digital controller (Ts = {params['Ts']:g} s) is taken as continuous")
    if params["alpha"] > 0 or params["d1"] > 0 or params["d3"] > 0 or params["d4"] > 0:
        notes.append("dead zones and backlash are removed in the linear limit")
    f = np.geomspace(F_MIN_HZ, F_MAX_HZ, N_FREQ)
    result = {loop: loop_margins(params, loop) for loop in LOOPS}
    loops = {loop: loop_transfer(params, loop, f) for loop in LOOPS}
    from ema_cli.report.run_inputs import run_inputs

    return LoopMargins(cfg, params, result, f, loops, notes, pairs, run_inputs(cfg, sets=pairs))


def margins_inputs(config: ConfigSource = None, overrides: Overrides = None) -> Any:
    """The inputs (``report.run_inputs.RunInputs``) :func:`margins` records in its folder's
    marker: what ``ema margins`` checks ``--out`` against first."""
    from ema_cli.config.loader import load_config
    from ema_cli.config.study import StudyConfig
    from ema_cli.report.run_inputs import run_inputs

    pairs = override_pairs(overrides)
    return run_inputs(checked(load_config(config, pairs, StudyConfig), "margins"), sets=pairs)
