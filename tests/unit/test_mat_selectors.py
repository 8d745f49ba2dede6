"""MATLAB column selectors (ema_cli.logs): struct fields (nested too), one channel of a matrix
by index (0-based [k], [:, k], [k, :]; 1-based (k), (:, k)), in v5 (scipy.io.savemat) and
v7.3 (HDF5 written with h5py as MATLAB lays it out: column-major, so an N x 3 matrix is a
(3, N) dataset); the ':' of a selector beside a unit; every bad selector one line naming the
file, the selector, the variable or field and what exists."""

from __future__ import annotations

import h5py
import numpy as np
import pytest
from scipy.io import savemat

from ema_cli.errors import EmaError
from ema_cli.identify.logs.channels import parse_column_spec, read_log
from ema_cli.logs import parse_selector, read_log_table

N = 50
T = np.arange(N) * 1e-3
DATA = np.column_stack([T, np.sin(T), np.cos(T)])  # N x 3: time, two channels
POS = np.vstack([np.linspace(0, 1, N), np.linspace(0, 2, N)])  # 2 x N: two links


@pytest.fixture
def v5(tmp_path):
    p = tmp_path / "rec5.mat"
    savemat(p, {"rec": {"data": DATA, "pos_link": POS, "sub": {"x": T * 2}, "name": "run 1"},
                "other": T})
    return p


@pytest.fixture
def v73(tmp_path):
    p = tmp_path / "rec73.mat"
    with h5py.File(p, "w") as f:
        g = f.create_group("rec")
        g.create_dataset("data", data=DATA.T)  # MATLAB's N x 3, column-major on disk
        g.create_dataset("pos_link", data=POS.T)
        g.create_group("sub").create_dataset("x", data=(T * 2)[None, :])
    return p


@pytest.mark.parametrize("fixture", ["v5", "v73"])
def test_selectors_pick_the_same_channel(fixture, request):
    tab = read_log_table(request.getfixturevalue(fixture))
    np.testing.assert_array_equal(tab.column("rec.data[:, 2]"), DATA[:, 2])
    np.testing.assert_array_equal(tab.column("rec.data(:, 3)"), DATA[:, 2])  # MATLAB 1-based
    np.testing.assert_array_equal(tab.column("rec.data[1]"), DATA[:, 1])  # the shorter axis
    np.testing.assert_array_equal(tab.column("rec.pos_link[1]"), POS[1])
    np.testing.assert_array_equal(tab.column("rec.pos_link[0, :]"), POS[0])
    np.testing.assert_array_equal(tab.column("rec.sub.x"), T * 2)


def test_the_one_struct_may_be_named_or_not(tmp_path):
    p = tmp_path / "one.mat"
    savemat(p, {"rec": {"t": T, "data": DATA}})
    tab = read_log_table(p)
    np.testing.assert_array_equal(tab.column("t"), T)  # its fields are the columns
    np.testing.assert_array_equal(tab.column("rec.t"), T)
    np.testing.assert_array_equal(tab.column("data[:, 1]"), DATA[:, 1])


def test_read_log_maps_channels_with_selectors_and_units(v73):
    cols = read_log(v73, ("t_s", "theta_load_deg"), (),
                    {"t_s": "rec.data[:, 0]:s", "theta_load_deg": "rec.pos_link[1]:rad"})
    np.testing.assert_array_equal(cols.values["t_s"], T)
    np.testing.assert_allclose(cols.values["theta_load_deg"], POS[1], rtol=1e-15)
    assert parse_column_spec("t_s", "rec.data[:, 0]") == ("rec.data[:, 0]", "s")
    assert parse_column_spec("t_s", "rec.data(:,1):ms") == ("rec.data(:,1)", "ms")


@pytest.mark.parametrize("selector, expect", [
    ("rec.nope", "struct 'rec' has no field 'nope'; its fields: data, pos_link, sub, name"),
    ("rec.data[3]", "'rec.data' is a 50x3 matrix; column 3 (0-based) does not exist (0 .. 2)"),
    ("rec.data[70, :]", "row 70 (0-based) does not exist (0 .. 49)"),
    ("other[0]", "'other' is a vector of 50 values; use it without an index"),
    ("rec.name[0]", "'rec.name' is text; an index needs a numeric matrix"),
    ("rec.data.x", "'rec.data' is a 50x3 matrix, not a struct; it has no field 'x'"),
    ("rec.data(0)", "index 0 is below 1"),
    ("rec.data[a]", "index 'a' is not a whole number"),
    ("rec.data[1, 2]", "expected one index [k] or a row/column"),
    ("missing.x", "no variable 'missing'; it has rec (a struct), other [50]"),
    ("rec.data", "variable 'rec.data' is a 50x3 matrix, not a vector"),
])
def test_bad_selectors_one_line(v5, selector, expect):
    with pytest.raises(EmaError) as exc:
        read_log_table(v5).column(selector)
    msg = exc.value.message
    assert expect in msg and str(v5) in msg and "\n" not in msg, msg


def test_selector_grammar():
    s = parse_selector("rec.a.b[:, 2]")
    assert s is not None and s.path == ("rec", "a", "b") and s.index == (None, 2)
    s = parse_selector("x(4)")
    assert s is not None and s.index == (3,)
    assert parse_selector("a column with spaces") is None
