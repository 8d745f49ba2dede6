"""The output folder of a threshold search: threshold.json, history.csv, threshold.png, manifest.

``ema threshold`` and ``api.Threshold.save`` write it through :func:`write_threshold`.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from ema_cli.analysis.threshold import ThresholdResult
from ema_cli.config.criteria import Criterion
from ema_cli.report.rundir import manifest, write_csv, write_figure, write_json, write_text
from ema_cli.report.threshold_figures import threshold_figure

OUTPUT_FILES = ("config.resolved.yaml", "threshold.json", "history.csv", "threshold.png",
                "manifest.json")


def write_threshold(folder: Path, config_yaml: str, result: ThresholdResult,
                    criteria: Sequence[Criterion], summary: Mapping[str, Any], xlabel: str,
                    title: str, log: bool, manifest_fields: Mapping[str, Any]) -> list[str]:
    """Write the folder -> the names written. ``summary`` is threshold.json's content."""
    write_text(folder / "config.resolved.yaml", config_yaml)
    write_json(folder / "threshold.json", dict(summary))
    write_csv(folder / "history.csv", result.history, float_format="%.9g")
    write_figure(folder / "threshold.png", threshold_figure(result, criteria, xlabel, title,
                                                            log=log))
    write_json(folder / "manifest.json", manifest("threshold", outputs=list(OUTPUT_FILES),
                                                  **{**summary, **manifest_fields}))
    return list(OUTPUT_FILES)
