"""A sweep's tables: metric labels with edge units, axis units, the per-job CSV files."""

from __future__ import annotations

import math
from pathlib import Path
from typing import TYPE_CHECKING

from ema_cli.report.rundir import write_csv
from ema_cli.sim.tables import METRIC_BY_EDGE, SIGNALS
from ema_cli.sweep.run import JOB_COLUMN, TIME_COLUMN, SweepResult
from ema_cli.units import DEG

if TYPE_CHECKING:
    from ema_cli.sweep.plan import AxisInfo

CSV_FORMAT = "%.9g"  # float format of every CSV (as `ema simulate` writes them)
FINISHED = ("ok", "diverged")
"""The job states whose signals were recorded."""
SHORT_LABELS = {
    "iae_pos_deg_s": "IAE position [deg·s]",
    "ise_pos_deg2_s": "ISE position [deg²·s]",
    "itae_pos_deg_s2": "ITAE position [deg·s²]",
    "rms_err_pos_deg": "RMS position error [deg]",
    "max_abs_err_pos_deg": "max abs position error [deg]",
    "iae_vel_deg": "IAE velocity [deg]",
    "ise_vel_deg2_s": "ISE velocity [deg²/s]",
    "itae_vel_deg_s": "ITAE velocity [deg·s]",
    "rms_err_vel_deg_s": "RMS velocity error [deg/s]",
    "max_abs_err_vel_deg_s": "max abs velocity error [deg/s]",
    "ss_err_pos_deg": "steady-state error, last 10 % [deg]",
    "overshoot_pct": "overshoot [% of step]",
    "rise_time_s": "rise time 10-90 % [s]",
    "settling_time_s": "settling time 2 % [s]",
    "t50_s": "time to 50 % (lag) [s]",
    "p2p_err_pos_deg": "residual oscillation p-p, last 20 % [deg]",
    "p2p_err_vel_deg_s": "velocity oscillation p-p, last 20 % [deg/s]",
    "peak_current_a": "peak current [A]",
    "peak_voltage_cmd_v": "peak voltage demand [V]",
    "peak_load_rate_deg_s": "peak load rate [deg/s]",
    "peak_torque_shaft_nm": "peak shaft torque [N·m]",
    "t_end_s": "time reached [s]",
}
"""Short metric names with edge units, for figure panels and table headers."""


def metric_label(edge: str) -> str:
    """A metric's short name with its edge unit, e.g. ``RMS velocity error [deg/s]``."""
    if edge in SHORT_LABELS:
        return SHORT_LABELS[edge]
    col = METRIC_BY_EDGE[edge]
    unit = col.si_unit
    if math.isclose(col.factor, 1 / DEG):
        unit = unit.replace("rad", "deg")
    elif math.isclose(col.factor, 1 / DEG**2):
        unit = unit.replace("rad^2", "deg^2")
    return f"{col.description} [{unit}]"


def axis_unit(info: AxisInfo) -> str:
    """The unit of the axis's last column (the absolute magnitude for relative axes)."""
    if info.kind == "parameter":
        return info.unit
    from ema_cli.model.nonlinearities import lookup

    return lookup(info.targets[0]).unit


def write_job_csvs(result: SweepResult, folder: Path) -> None:
    """timeseries/<job>.csv for every finished job (t_s, then every signal in edge units):
    read row group by row group from signals.parquet when it was written."""
    columns = [TIME_COLUMN, *(c.edge for c in SIGNALS[:result.plan.n_signals])]
    if result.signals_file is None:
        df = result.metrics
        for j in result.plan.jobs:
            if df["status"].iloc[j.index] in FINISHED:
                write_csv(folder / f"{j.id}.csv", result.timeseries(j.id),
                          float_format=CSV_FORMAT)
        return
    import pyarrow.parquet as pq

    pf = pq.ParquetFile(result.signals_file)
    for g in range(pf.num_row_groups):
        table = pf.read_row_group(g, columns=[JOB_COLUMN, *columns]).to_pandas()
        for job, rows in table.groupby(JOB_COLUMN, sort=False, observed=True):
            write_csv(folder / f"{job}.csv", rows[columns], float_format=CSV_FORMAT)
