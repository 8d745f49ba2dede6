"""Log files (identify.log_files, closed_loop.load_log): one log written as CSV, Parquet,
MATLAB v5 (top-level vectors and a struct) and MATLAB v7.3 (HDF5 written as MATLAB lays it
out), also renamed and in other units through a column map, loads to IDENTICAL SI arrays; the
window; other sample rates and jittered stamps; every bad file named in one line.

Exactness: the log's values are binary fractions (k/2048 s, n/256 deg, n/16 rpm, n/1024 A),
so a value in ms, mA or mV (x 1000) is exact too, and the loader's division by the exact 1000
returns it bit for bit; a value in rad (rad/s) is written as the loader's own product
deg x DEG (rpm x RPM), which the rad (rad/s) path passes unchanged. Hence np.array_equal.
"""

from __future__ import annotations

import math

import h5py
import numpy as np
import pandas as pd
import pytest
import scipy.io as sio

from ema_cli.errors import EmaError
from ema_cli.identify.closed_loop.problem import MIN_LOG_ROWS, load_log
from ema_cli.identify.logs.channels import read_log, read_log_table
from ema_cli.units import DEG, RPM

N = 600  # samples of the test log
T_START = 10.0  # the log's own time of its first sample [s]
CHANNELS = ("t_s", "theta_ref_deg", "theta_load_deg", "omega_motor_rpm", "current_a",
            "voltage_cmd_v")
RENAMED = {"t_s": "time:ms", "theta_ref_deg": "ref:rad", "theta_load_deg": "pos:rad",
           "omega_motor_rpm": "wm:rad/s", "current_a": "i:mA", "voltage_cmd_v": "u:mV"}
MAT73_HEADER = (b"MATLAB 7.3 MAT-file, Platform: GLNXA64, Created on: Thu Jan  1 00:00:00 2026 "
                b"HDF5 schema 1.00 .")


def base_log() -> dict[str, np.ndarray]:
    """Edge units, binary fractions: ~512 Hz with stamps jittered by 0..2/2048 s."""
    rng = np.random.default_rng(21)
    k = np.arange(N)
    t = T_START + (4 * k + rng.integers(0, 3, N)) / 2048
    ph = 2 * np.pi * 1.5 * (t - T_START)
    q = lambda x, s: np.round(x * s) / s  # noqa: E731 - a binary fraction of step 1/s
    return {"t_s": t, "theta_ref_deg": q(5 * np.sin(ph), 256),
            "theta_load_deg": q(4.9 * np.sin(ph - 0.2), 256),
            "omega_motor_rpm": q(900 * np.cos(ph - 0.2), 16),
            "current_a": q(0.8 * np.cos(ph), 1024), "voltage_cmd_v": q(6 * np.cos(ph), 1024)}


def renamed_log(base: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """The same log under other names, in ms, rad, rad/s, mA and mV (exact, see the top)."""
    return {"time": base["t_s"] * 1000, "ref": base["theta_ref_deg"] * DEG,
            "pos": base["theta_load_deg"] * DEG, "wm": base["omega_motor_rpm"] * RPM,
            "i": base["current_a"] * 1000, "u": base["voltage_cmd_v"] * 1000}


def write_mat73(path, variables: dict[str, np.ndarray], group: str | None = None) -> None:
    """A MATLAB v7.3 file as MATLAB writes it: a 512-byte user block holding the MAT header
    (version 0x0200, 'IM'), HDF5 datasets with a MATLAB_class attribute, stored column-major
    (a MATLAB Nx1 vector is a (1, N) dataset, an NxM matrix an (M, N) one); ``group``: the
    variables are the fields of one struct."""
    with h5py.File(path, "w", userblock_size=512) as f:
        g = f
        if group is not None:
            g = f.create_group(group)
            g.attrs["MATLAB_class"] = np.bytes_("struct")
        for name, value in variables.items():
            if isinstance(value, str):
                d = g.create_dataset(name, data=np.array([[ord(c)] for c in value], np.uint16))
                d.attrs["MATLAB_class"] = np.bytes_("char")
                continue
            a = np.asarray(value)
            a = a[:, None] if a.ndim == 1 else a  # MATLAB's Nx1 column
            d = g.create_dataset(name, data=a.T)  # column-major on disk
            d.attrs["MATLAB_class"] = np.bytes_("double")
    with open(path, "r+b") as f:
        f.write(MAT73_HEADER.ljust(116, b" ") + bytes(8) + b"\x00\x02IM")


def write(path, cols: dict[str, np.ndarray], how: str = "") -> None:
    """Write ``cols`` in the format of ``path``'s extension (``how`` picks a MATLAB layout)."""
    s = path.suffix
    if s == ".csv":
        pd.DataFrame(cols).to_csv(path, index=False)
    elif s == ".parquet":
        pd.DataFrame(cols).to_parquet(path, index=False)
    elif how == "v5-struct":
        sio.savemat(path, {"log": {k: v[:, None] for k, v in cols.items()}})
    elif how == "v5":  # half the vectors Nx1 (columns), half 1xN (rows)
        sio.savemat(path, {k: (v[:, None] if i % 2 else v[None, :])
                           for i, (k, v) in enumerate(cols.items())})
    elif how == "v73-struct":
        write_mat73(path, cols, group="log")
    else:
        write_mat73(path, cols)


LAYOUTS = [("log.csv", ""), ("log.parquet", ""), ("log.mat", "v5"), ("log.mat", "v5-struct"),
           ("log.mat", "v73"), ("log.mat", "v73-struct")]


def test_mat73_test_file_is_what_scipy_calls_v73(tmp_path):
    p = tmp_path / "x.mat"
    write_mat73(p, {"a": np.arange(3.0)})
    assert sio.matlab.matfile_version(str(p)) == (2, 0)
    with h5py.File(p, "r") as f:  # MATLAB's Nx1 column is a (1, N) dataset
        assert f["a"].shape == (1, 3) and f["a"].attrs["MATLAB_class"] == b"double"


@pytest.mark.parametrize("renamed", [False, True])
@pytest.mark.parametrize("name, how", LAYOUTS)
def test_every_format_loads_the_same_arrays(tmp_path, name, how, renamed):
    base = base_log()
    ref_path = tmp_path / "ref.csv"
    write(ref_path, base)
    ref = load_log(ref_path)
    # the reference itself: SI, times from 0, t0 the first stamp (hand conversion)
    assert ref.t0 == T_START and np.array_equal(ref.t, base["t_s"] - T_START)
    assert np.array_equal(ref.theta_ref, base["theta_ref_deg"] * DEG)
    assert np.array_equal(ref.channels["omega_motor_rpm"], base["omega_motor_rpm"] * RPM)
    p = tmp_path / name
    write(p, renamed_log(base) if renamed else base, how)
    log = load_log(p, columns=RENAMED if renamed else None)
    assert log.n == N and log.t0 == ref.t0
    assert np.array_equal(log.t, ref.t) and np.array_equal(log.theta_ref, ref.theta_ref)
    assert set(log.channels) == set(ref.channels) == set(CHANNELS[2:])
    for c, y in ref.channels.items():
        assert np.array_equal(log.channels[c], y), c


@pytest.mark.parametrize("unit, factor", [
    ("us", 1e-6), ("ms", 1e-3), ("s", 1.0)])
def test_time_units(tmp_path, unit, factor):
    cols = base_log()
    del cols["t_s"]
    cols["stamp"] = np.arange(N) * 2.0  # 2 units apart
    p = tmp_path / "u.parquet"
    write(p, cols)
    t = read_log(p, ("t_s",), columns={"t_s": f"stamp:{unit}"}).values["t_s"]
    # 2 us, 2 ms, 2 s apart; the loader divides by an exact 1e6 or 1e3 (one rounding), the
    # reference multiplies by the inexact 1e-6 or 1e-3 (two): 1 ulp apart at most
    np.testing.assert_allclose(t, np.arange(N) * 2.0 * factor, rtol=2.3e-16, atol=0)


@pytest.mark.parametrize("channel, unit, si", [
    ("theta_load_deg", "mrad", 1e-3), ("theta_load_deg", "deg", math.pi / 180),
    ("omega_motor_rpm", "deg/s", math.pi / 180), ("omega_motor_rpm", "rpm", math.pi / 30),
    ("current_a", "A", 1.0), ("voltage_cmd_v", "V", 1.0)])
def test_other_units_by_hand(tmp_path, channel, unit, si):
    cols = base_log()
    p = tmp_path / "u.csv"
    write(p, {**cols, "x": cols[channel] * 8})
    log = load_log(p, columns={channel: f"x:{unit}"})
    # one product or quotient of exactly representable values: 1 ulp apart at most
    np.testing.assert_allclose(log.channels[channel], cols[channel] * 8 * si, rtol=1e-15)


def test_window_keeps_the_samples_and_re_zeroes(tmp_path):
    base = base_log()
    p = tmp_path / "log.parquet"
    write(p, base)
    lo, hi = T_START + 0.25, T_START + 0.75
    log = load_log(p, window=(lo, hi))
    keep = (base["t_s"] >= lo) & (base["t_s"] <= hi)
    first = base["t_s"][keep][0]
    assert log.n == int(keep.sum()) and log.n > MIN_LOG_ROWS
    assert log.t0 == first and first >= lo and base["t_s"][~keep & (base["t_s"] < lo)][-1] < lo
    assert np.array_equal(log.t, base["t_s"][keep] - first)
    assert np.array_equal(log.channels["theta_load_deg"], base["theta_load_deg"][keep] * DEG)
    assert "window 10.25 .. 10.75 s" in log.source
    # the whole log as a window: identical to no window
    whole = load_log(p, window=(base["t_s"][0], base["t_s"][-1]))
    assert np.array_equal(whole.t, load_log(p).t)


@pytest.mark.parametrize("rate_hz, jitter", [(500.0, 0.0), (2000.0, 0.3)])
def test_other_rates_and_jittered_stamps(tmp_path, rate_hz, jitter):
    rng = np.random.default_rng(5)
    k = np.arange(1000)
    t = 3.0 + (k + jitter * rng.uniform(-1, 1, k.size)) / rate_hz  # jitter < half a step
    cols = {"t_s": t, "theta_ref_deg": np.sin(k / 50), "theta_load_deg": np.sin(k / 50 - 0.1)}
    p = tmp_path / "r.mat"
    sio.savemat(p, cols)
    log = load_log(p)
    assert log.n == 1000 and log.t0 == t[0]
    assert np.array_equal(log.t, t - t[0])
    assert np.array_equal(log.channels["theta_load_deg"], cols["theta_load_deg"] * DEG)
    steps = np.diff(log.t)
    assert (np.ptp(steps) == pytest.approx(0, abs=1e-12)) == (jitter == 0)


def _errors(tmp_path) -> dict[str, tuple]:
    """name -> (path, expected text, load_log kwargs) of every bad file."""
    b = base_log()
    d = tmp_path
    out = {}

    def case(key, fname, cols, how="", expect="", **kw):
        p = d / f"{key}{fname}"
        write(p, cols, how)
        out[key] = (p, expect, kw)

    nan = dict(b, theta_load_deg=np.where(np.arange(N) == 40, np.nan, b["theta_load_deg"]))
    case("nan_pq", ".parquet", nan, expect="column 'theta_load_deg' has 1 empty, non-numeric, "
         "NaN or inf value(s) (first at row 41)")
    inf = dict(b, current_a=np.where(np.arange(N) == 16, np.inf, b["current_a"]))
    case("inf_v5", ".mat", inf, "v5", "variable 'current_a' has 1 NaN or inf value(s) (first "
         "at index 17)")
    case("nan_v73", ".mat", nan, "v73", "variable 'theta_load_deg' has 1 NaN or inf value(s) "
         "(first at index 41)")
    txt = pd.DataFrame(b).astype({"voltage_cmd_v": str})  # a text column, as a logger may
    txt.loc[99, "voltage_cmd_v"] = "n/a"
    txt.to_parquet(d / "text_pq.parquet", index=False)
    out["text_pq"] = (d / "text_pq.parquet", "column 'voltage_cmd_v' has 1 empty, "
                      "non-numeric, NaN or inf value(s) (first at row 100)", {})
    sio.savemat(d / "char_v5.mat", {**b, "theta_load_deg": "abc"})
    out["char_v5"] = (d / "char_v5.mat", "variable 'theta_load_deg' is text; expected a "
                      "numeric vector", {})
    write_mat73(d / "char_v73.mat", {**b, "theta_load_deg": "abc"})
    out["char_v73"] = (d / "char_v73.mat", "variable 'theta_load_deg' is text", {})
    sio.savemat(d / "cplx_v5.mat", {**b, "current_a": b["current_a"] * 1j})
    out["cplx_v5"] = (d / "cplx_v5.mat", "variable 'current_a' is complex", {})
    case("short_v5", ".mat", dict(b, current_a=b["current_a"][:-1]), "v5",
         f"variable 'current_a' has {N - 1} values but 't_s' has {N}")
    case("short_v73", ".mat", dict(b, theta_ref_deg=b["theta_ref_deg"][:-2]), "v73",
         f"variable 'theta_ref_deg' has {N - 2} values but 't_s' has {N}")
    sio.savemat(d / "matrix_v5.mat", {**b, "theta_load_deg": np.ones((N, 2))})
    out["matrix_v5"] = (d / "matrix_v5.mat", f"variable 'theta_load_deg' is a {N}x2 matrix, "
                        "not a vector", {})
    write_mat73(d / "matrix_v73.mat", {**b, "theta_load_deg": np.ones((N, 2))})
    out["matrix_v73"] = (d / "matrix_v73.mat", f"variable 'theta_load_deg' is a {N}x2 "
                         "matrix, not a vector", {})
    sio.savemat(d / "empty_var.mat", {**b, "current_a": np.zeros((0, 0))})
    out["empty_var"] = (d / "empty_var.mat", "variable 'current_a' is empty", {})
    for ext in (".csv", ".parquet", ".mat"):
        (d / f"empty{ext}").write_bytes(b"")
        out[f"empty{ext}"] = (d / f"empty{ext}", f"data file '{d / f'empty{ext}'}' is empty", {})
    (d / "header.csv").write_text(",".join(CHANNELS) + "\n")
    out["header"] = (d / "header.csv", "has 0 data rows; a closed-loop log needs at least", {})
    (d / "text.mat").write_text("t_s,theta_ref_deg\n0,1\n" * 20)
    out["text_mat"] = (d / "text.mat", "is not a readable MATLAB file (.mat v5 or v7.3): no "
                       "MATLAB header", {})
    write(d / "whole.mat", b, "v73")
    data = (d / "whole.mat").read_bytes()
    (d / "trunc73.mat").write_bytes(data[: len(data) // 2])
    out["trunc73"] = (d / "trunc73.mat", "is not a readable MATLAB file (.mat v7.3, HDF5)", {})
    write(d / "whole5.mat", b, "v5")
    data = (d / "whole5.mat").read_bytes()
    (d / "trunc5.mat").write_bytes(data[: len(data) // 2])
    out["trunc5"] = (d / "trunc5.mat", "is not a readable MATLAB file (.mat v5)", {})
    (d / "junk.parquet").write_bytes(b"PAR1 this is not parquet" * 10)
    out["junk_pq"] = (d / "junk.parquet", "is not a readable Parquet file", {})
    (d / "log.xlsx").write_bytes(b"x")
    out["ext"] = (d / "log.xlsx", "unknown format '.xlsx'; expected .csv or .txt (CSV), "
                  ".parquet or .pq (Parquet), .mat (MATLAB v5 or v7.3)", {})
    out["none"] = (d / "nowhere.mat", f"data file '{d / 'nowhere.mat'}' does not exist", {})
    lacks = {k: v for k, v in b.items() if k != "theta_load_deg"}
    case("lacks_v5", ".mat", lacks, "v5", f"lacks variable(s) theta_load_deg; expected t_s, "
         "theta_ref_deg, theta_load_deg (optional: omega_motor_rpm, current_a, voltage_cmd_v); "
         f"map other names with --columns CHANNEL=COLUMN[:UNIT]; found t_s [{N}], "
         f"theta_ref_deg [{N}], omega_motor_rpm [{N}]")
    case("lacks_pq", ".parquet", lacks, expect="lacks column(s) theta_load_deg;")
    case("late_t", ".mat", dict(b, t_s=np.where(np.arange(N) == 70, b["t_s"][68],
                                                  b["t_s"])), "v73",
         "variable 't_s' must be strictly increasing; it is not at index 71")
    ren = renamed_log(b)
    case("map_missing", ".mat", ren, "v5", "--columns theta_load_deg=angle:rad: data file",
         columns=dict(RENAMED, theta_load_deg="angle:rad"))
    out["map_missing_list"] = (out["map_missing"][0], f"has no variable 'angle'; it has time "
                               f"[{N}], ref [{N}], pos [{N}]", out["map_missing"][2])
    out["map_unit"] = (out["map_missing"][0], f"--columns theta_load_deg=pos:deg/s (data file "
                       f"'{d / 'map_missing.mat'}'): 'deg/s' is a unit of speed; "
                       "theta_load_deg takes angle units: deg, rad, mrad",
                       {"columns": dict(RENAMED, theta_load_deg="pos:deg/s")})
    out["map_unknown_unit"] = (out["map_missing"][0], "map_missing.mat'): unknown unit "
                               "'min'; t_s takes time units: s, ms, us",
                               {"columns": dict(RENAMED, t_s="time:min")})
    out["map_channel"] = (out["map_missing"][0], "map_missing.mat'): unknown channel "
                          "'torque_nm'; expected one of t_s, theta_ref_deg", {"columns": {
                              **RENAMED, "torque_nm": "pos"}})
    sio.savemat(d / "map_matrix.mat", dict(ren, pos=np.ones((N, 3))))
    out["map_matrix"] = (d / "map_matrix.mat", f"variable 'pos' is a {N}x3 matrix, not a "
                         "vector; expected a numeric vector (N, Nx1 or 1xN) (--columns "
                         "theta_load_deg=pos:rad)", {"columns": RENAMED})
    case("map_constant", ".csv", dict(ren, pos=np.full(N, 0.5)), expect="column 'pos' "
         "(theta_load_deg) is constant", columns=RENAMED)
    case("win_out", ".parquet", b, expect=f"--window 9,10.5: the window passes the ends of "
         f"data file '{d / 'win_out.parquet'}', which spans 10 .. ", window=(9.0, 10.5))
    out["win_order"] = (out["win_out"][0], "--window 11,10.5 (data file '"
                        f"{d / 'win_out.parquet'}'): expected T0 < T1", {"window": (11.0, 10.5)})
    few = int(np.sum((b["t_s"] >= 10.1) & (b["t_s"] <= 10.15)))  # ~0.05 s x 512 Hz
    out["win_few"] = (out["win_out"][0], f"--window 10.1,10.15: the window keeps {few} sample(s) "
                      f"of data file '{d / 'win_out.parquet'}'; a closed-loop log needs at "
                      f"least {MIN_LOG_ROWS}", {"window": (10.1, 10.15)})
    return out


ERRORS = ["nan_pq", "inf_v5", "nan_v73", "text_pq", "char_v5", "char_v73", "cplx_v5",
          "short_v5", "short_v73", "matrix_v5", "matrix_v73", "empty_var", "empty.csv",
          "empty.parquet", "empty.mat", "header", "text_mat", "trunc73", "trunc5", "junk_pq",
          "ext", "none", "lacks_v5", "lacks_pq", "late_t", "map_missing", "map_missing_list",
          "map_unit", "map_unknown_unit", "map_channel", "map_matrix", "map_constant", "win_out",
          "win_order", "win_few"]


@pytest.fixture(scope="module")
def bad_files(tmp_path_factory):
    return _errors(tmp_path_factory.mktemp("bad"))


@pytest.mark.parametrize("key", ERRORS)
def test_bad_files_one_line_naming_file_column_and_place(bad_files, key):
    path, expect, kw = bad_files[key]
    with pytest.raises(EmaError) as exc:
        load_log(path, **kw)
    msg = exc.value.message
    assert expect in msg, msg
    assert "\n" not in msg and str(path) in msg, msg


def test_every_error_case_is_listed(bad_files):
    assert set(bad_files) == set(ERRORS)


def test_table_lists_what_a_mat_file_holds(tmp_path):
    p = tmp_path / "m.mat"
    sio.savemat(p, {"pos": np.arange(4.0), "M": np.ones((3, 2)), "note": "hi", "fs": 500.0})
    table = read_log_table(p)
    assert table.fmt == "MATLAB v5" and table.noun == "variable"
    assert table.listing() == "pos [4], M (a 3x2 matrix, not a vector), note (text), fs [1]"
    # a plain HDF5 file without the MATLAB header is read as v7.3 too
    q = tmp_path / "h.mat"
    with h5py.File(q, "w") as f:
        f["t_s"] = np.arange(5.0)
    cols = read_log(q, ("t_s",))
    assert cols.table.fmt == "MATLAB v7.3" and np.array_equal(cols.values["t_s"], np.arange(5.0))
