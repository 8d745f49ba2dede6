"""The compiled-kernel cache cannot go stale: its key follows every source the kernel reads.

The scenario from the kernel-v2 issue: swapping the rows ``R`` and ``L`` of the parameter table
used to leave a cached kernel reading the old column numbers (peak current 3.41 A instead of the
30.35 A current limit on a 20 deg step) until the cache was deleted by hand.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from ema_cli._numba import CACHE_KEY, PACKAGE, keyed_sources, source_key

PEAK_CURRENT_SCRIPT = """
from ema_cli.model.params import resolve
from ema_cli.sim.runner import simulate
from ema_cli.sim.signals import InputSignal
from ema_cli.units import DEG
import ema_cli._numba as nb
res = simulate(resolve(), InputSignal("step", 20 * DEG), 0.05, output_interval=None)
print(nb.CACHE_KEY, res.metrics_frame()["peak_current_a"].iloc[0])
"""


def copy_package(dest: Path) -> Path:
    """A copy of the ema_cli package (no caches) under ``dest``; returns the package folder."""
    pkg = dest / "ema_cli"
    shutil.copytree(PACKAGE, pkg, ignore=shutil.ignore_patterns("__pycache__"))
    return pkg


def swap_r_and_l(pkg: Path) -> None:
    """Swap the table rows of R and L in the copy's model/params.py (a pure reordering)."""
    f = pkg / "model" / "params.py"
    lines = f.read_text(encoding="utf-8").splitlines(keepends=True)
    i_r = next(k for k, s in enumerate(lines) if s.strip().startswith('Param("R",'))
    i_l = next(k for k, s in enumerate(lines) if s.strip().startswith('Param("L",'))
    lines[i_r], lines[i_l] = lines[i_l], lines[i_r]
    f.write_text("".join(lines), encoding="utf-8")


def test_key_is_this_package_and_path_independent(tmp_path):
    assert source_key() == CACHE_KEY
    assert source_key(copy_package(tmp_path)) == CACHE_KEY  # content, not location


@pytest.mark.parametrize("edit", ["model/params.py", "sim/tables.py", "sim/kernel.py",
                                  "model/lugre.py", "units.py", "identify/torque/problem.py"])
def test_editing_any_kernel_dependency_changes_the_key(tmp_path, edit):
    pkg = copy_package(tmp_path)
    assert pkg / edit in [pkg / f.relative_to(PACKAGE) for f in keyed_sources()]
    with open(pkg / edit, "a", encoding="utf-8") as fh:
        fh.write("\n# edited\n")
    assert source_key(pkg) != CACHE_KEY


def test_editing_code_the_kernel_does_not_read_keeps_the_key(tmp_path):
    pkg = copy_package(tmp_path)
    with open(pkg / "cli" / "main.py", "a", encoding="utf-8") as fh:
        fh.write("\n# edited\n")
    assert source_key(pkg) == CACHE_KEY


def _peak_current(root: Path, cache: Path) -> tuple[str, float]:
    env = {**os.environ, "PYTHONPATH": str(root), "EMA_CACHE_DIR": str(cache)}
    env.pop("NUMBA_DISABLE_JIT", None)
    out = subprocess.run([sys.executable, "-c", PEAK_CURRENT_SCRIPT], env=env, cwd=root,
                         capture_output=True, text=True, timeout=600, check=True)
    key, peak = out.stdout.split()[-2:]
    return key, float(peak)


@pytest.mark.slow  # the slow tier: make test-all (CI runs it)
def test_swapped_parameter_rows_recompile_and_give_the_right_answer(tmp_path):
    # 20 deg step: the motor is current-limited, so the peak current is the limit, 30.35 A
    # (6.07*5, the default sat3); a stale kernel reading L's column as R gave 3.41 A.
    root = tmp_path / "src"
    pkg = copy_package(root)
    cache = tmp_path / "cache"
    key1, peak1 = _peak_current(root, cache)
    assert peak1 == pytest.approx(30.35, rel=1e-9)
    swap_r_and_l(pkg)
    key2, peak2 = _peak_current(root, cache)
    assert key2 != key1
    assert peak2 == pytest.approx(30.35, rel=1e-9)
    # both versions' compiled code sits in its own folder under the cache root
    assert {d.name for d in (cache / "ema-kernels").iterdir()} == {key1, key2}
