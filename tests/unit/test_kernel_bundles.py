"""The kernel's work array is laid out by name from the tables (``sim.layout``): every lane
parameter, state, memory slot and accumulator reads its own row, the generated moves between
the work array and the named tuples are each other's inverse, and nothing in the kernel reads a
row or a bundle by a literal position."""

from __future__ import annotations

import ast
import inspect

import numpy as np

from ema_cli.model.params import PARAMS
from ema_cli.model.states import STATES
from ema_cli.sim import kernel, layout
from ema_cli.sim.tables import ACCUMULATORS, SIGNALS


def _distinct_work_array(n_lanes: int = 3) -> np.ndarray:
    # row r of lane j holds r + 0.25*j + 0.5 (never 0: every flag reads True)
    return np.arange(layout.N_ROWS, dtype=np.float64)[:, None] + 0.25 * np.arange(n_lanes) + 0.5


def test_every_lane_field_reads_its_row():
    W = _distinct_work_array()
    for j in range(W.shape[1]):
        lp = layout.lane_params.py_func(W, j)
        assert isinstance(lp, layout.Lane)
        for name in layout.LANE_FIELDS:
            row = layout.ROW[name]
            want = W[row, j] != 0.0 if name in layout.BOOL_LANE else W[row, j]
            assert getattr(lp, name) == want, f"{name} should read row {row}"
    W[[layout.ROW[n] for n in layout.BOOL_LANE], 0] = 0.0
    lp = layout.lane_params.py_func(W, 0)
    assert [getattr(lp, n) for n in layout.BOOL_LANE] == [False] * len(layout.BOOL_LANE)


def test_states_memory_and_accumulators_round_trip_by_name():
    W = _distinct_work_array()
    x = layout.load_x.py_func(W, 1)
    assert x._fields == tuple(s.name for s in STATES)
    for s in STATES:
        assert getattr(x, s.name) == W[layout.ROW[s.name], 1]
    acc = layout.load_acc.py_func(W, 2)
    assert acc._fields == tuple(a.name for a in ACCUMULATORS)
    mem = layout.load_mem.py_func(W, 0)
    V = np.zeros_like(W)
    layout.store_x.py_func(V, 1, x)
    layout.store_acc.py_func(V, 2, acc)
    layout.store_mem.py_func(V, 0, mem)
    for name in (*x._fields, *mem._fields):
        col = 1 if name in x._fields else 0
        assert V[layout.ROW[name], col] == W[layout.ROW[name], col], name
    for a in ACCUMULATORS:
        assert V[layout.ROW[a.name], 2] == W[layout.ROW[a.name], 2], a.name


def test_the_layout_names_each_row_once_and_fills_the_work_array():
    rows = list(layout.ROW.values())
    assert sorted(rows) == list(range(layout.N_ROWS))
    assert [layout.ROW[p.name] for p in PARAMS] == list(
        range(layout.START["param"], layout.START["param"] + len(PARAMS)))
    assert [layout.ROW[f"rec.{c.name}"] for c in SIGNALS] == list(
        range(layout.START["rec"], layout.START["rec"] + len(SIGNALS)))
    assert kernel.N_ROWS == layout.N_ROWS


def test_no_positional_reads_in_the_kernel():
    # no lp[...], prm[...], x[...], acc[...], mem[...] and no W[<literal>, ...]: every row and
    # field by name (a tuple returned by a model function may be unpacked or indexed, those
    # are that function's documented results)
    tree = ast.parse(inspect.getsource(kernel))
    bad = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Subscript) and isinstance(node.value, ast.Name):
            if node.value.id in ("lp", "prm", "x", "acc", "mem", "inp", "fl"):
                bad.append(f"line {node.lineno}: {node.value.id}[...]")
            if node.value.id in ("W", "S") and isinstance(node.slice, ast.Tuple) \
                    and isinstance(node.slice.elts[0], ast.Constant):
                bad.append(f"line {node.lineno}: {node.value.id}[<literal row>, ...]")
    assert bad == []
