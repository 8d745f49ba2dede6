"""The kernel's lane parameters are one named bundle (``kernel.LaneParams``) built from one
table (``kernel.LANE_PARAMS``): each field reads its own row of the work array, and nothing in
the kernel reads the bundle by position. (That the compiled code is unchanged by the naming was
checked by hand: the six entry-point variants' machine code, instruction for instruction.)"""

from __future__ import annotations

import ast
import inspect

import numpy as np

from ema_cli.sim import kernel


def test_every_field_reads_its_row():
    n_lanes = 3
    # distinct values: row r of lane j holds r + 0.25*j + 0.5 (never 0: every flag is True)
    W = np.arange(kernel.N_ROWS, dtype=np.float64)[:, None] + 0.25 * np.arange(n_lanes) + 0.5
    for j in range(n_lanes):
        lp = kernel._lane_params.py_func(W, j)
        assert isinstance(lp, kernel.LaneParams)
        for name, row, flag in kernel.LANE_PARAMS:
            want = W[row, j] != 0.0 if flag else W[row, j]
            assert getattr(lp, name) == want, f"{name} should read row {row}"
    W[[row for _, row, flag in kernel.LANE_PARAMS if flag], 0] = 0.0
    lp = kernel._lane_params.py_func(W, 0)
    assert [getattr(lp, n) for n, _, flag in kernel.LANE_PARAMS if flag] == [False] * 4


def test_the_table_names_each_field_and_row_once():
    names = [n for n, _, _ in kernel.LANE_PARAMS]
    rows = [r for _, r, _ in kernel.LANE_PARAMS]
    assert list(kernel.LaneParams._fields) == names
    assert len(set(names)) == len(names) and len(set(rows)) == len(rows)
    assert all(0 <= r < kernel.N_ROWS for r in rows)


def test_no_positional_reads_of_the_bundle():
    tree = ast.parse(inspect.getsource(kernel))
    bad = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Subscript) and isinstance(node.value, ast.Name) \
                and node.value.id in ("lp", "prm"):
            bad.append(f"line {node.lineno}: {node.value.id}[...]")
        if isinstance(node, ast.Assign) and isinstance(node.value, ast.Name) \
                and node.value.id in ("lp", "prm") and isinstance(node.targets[0], ast.Tuple):
            bad.append(f"line {node.lineno}: unpacks {node.value.id}")
    assert bad == []
