"""The output folder of one simulation: resolved config, time series, metrics, figure, manifest.

Layout (``ema simulate``, ``api.Simulation.save``)::

    config.resolved.yaml   the validated config, every default filled in
    timeseries.csv         the recorded signals in edge units (deg, deg/s, A, V, N*m), t_s first
    metrics.csv            one row of metrics in edge units
    tracking.png           position/velocity tracking and errors vs time
    manifest.json          version, seed, grid, timings, SI parameters, warnings

Written without pandas (``rundir.write_columns``): a short run's outputs take milliseconds.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

from ema_cli.report.rundir import manifest, write_columns, write_figure, write_json, write_text

OUTPUT_FILES = ("config.resolved.yaml", "timeseries.csv", "metrics.csv", "tracking.png",
                "manifest.json")
CSV_FORMAT = "%.9g"  # float format of the CSVs


def write_simulation(
    folder: Path,
    config_yaml: str,
    table: Mapping[str, Any] | None,
    metrics: Mapping[str, Any],
    figure: Any,
    manifest_fields: Mapping[str, Any],
    timings: dict[str, float] | None = None,
) -> list[str]:
    """Write the folder (see the module docstring) -> names written.

    ``table``: edge-unit columns of the recorded signals (None: nothing recorded);
    ``metrics``: one value per edge-unit metric column; ``figure``: a Figure, a
    ``(FigureWorker, title)`` pair (the figure is drawn in the worker's process while the CSVs
    are written here), or None; ``timings`` (if given) gains ``csv`` and ``figure`` [s] before
    the manifest is written.
    """
    import time

    timings = timings if timings is not None else {}
    written = []
    worker = None
    if isinstance(figure, tuple):
        worker, title = figure
        if table is not None:
            worker.submit(folder / "tracking.png", table, title)
        else:
            worker.cancel()
            worker = None
        figure = None
    write_text(folder / "config.resolved.yaml", config_yaml)
    written.append("config.resolved.yaml")
    t0 = time.perf_counter()
    if table is not None:
        write_columns(folder / "timeseries.csv", table, CSV_FORMAT)
        written.append("timeseries.csv")
    write_columns(folder / "metrics.csv", {k: [v] for k, v in metrics.items()}, CSV_FORMAT)
    written.append("metrics.csv")
    t1 = time.perf_counter()
    if figure is not None:
        write_figure(folder / "tracking.png", figure)
        written.append("tracking.png")
    t2 = time.perf_counter()
    timings["csv"] = t1 - t0
    timings["figure"] = t2 - t1 + timings.get("figure_draw", 0.0)
    if worker is not None:  # drawn meanwhile in the worker's process
        timings["figure"] = worker.wait()
        timings["figure_wait"] = time.perf_counter() - t2
        written.append("tracking.png")
    written.append("manifest.json")
    write_json(folder / "manifest.json", manifest("simulate", timings_s=timings,
                                                  outputs=written, **manifest_fields))
    return written


def simulation_title(name: str, signal: str, nonlinearities: Mapping[str, Any],
                     options: str) -> str:
    """The figure and table title: config name, input, nonlinearities, options."""
    nls = ", ".join(f"{k}={v}" for k, v in nonlinearities.items()) or "no study nonlinearities"
    return f"{name}: {signal}, {nls}" + (f", {options}" if options else "")
