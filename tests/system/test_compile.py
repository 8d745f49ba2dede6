"""`ema compile` and the compiled-code cache: cold units are compiled once (announced), warm ones
load at once; a batch compiles only the variant it needs."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


def _ema(args: list[str], cache: Path) -> subprocess.CompletedProcess:
    env = {**os.environ, "EMA_CACHE_DIR": str(cache), "COLUMNS": "80"}
    env.pop("NUMBA_DISABLE_JIT", None)
    return subprocess.run([sys.executable, "-c", "from ema_cli.cli.main import main; main()",
                           *args], cwd=ROOT, env=env, capture_output=True, text=True,
                          timeout=600)


@pytest.mark.slow  # the slow tier: make test-all (CI runs it)
def test_a_cold_unit_is_announced_compiled_once_and_then_marked_cached(tmp_path):
    # one unit (one lane, no friction: what `ema simulate` needs) in a fresh cache: announced
    # on stderr with its estimate, compiled, marked; a second process loads it silently
    script = ("from ema_cli.sim import compiled, runner\n"
              "name = compiled.entry_name(1, 0)\n"
              "print(compiled.is_cached(name))\n"
              "runner.load_kernel(1, 0)\n"
              "print(compiled.is_cached(name))\n")
    env = {**os.environ, "EMA_CACHE_DIR": str(tmp_path / "cache")}
    env.pop("NUMBA_DISABLE_JIT", None)
    env.pop("EMA_COMPILE_QUIET", None)
    first = subprocess.run([sys.executable, "-c", script], cwd=ROOT, env=env,
                           capture_output=True, text=True, timeout=600)
    assert first.returncode == 0, first.stderr
    assert first.stdout.split() == ["False", "True"]
    assert "compiling the simulator (one lane, no friction), first run only" in first.stderr
    assert "compiled in" in first.stderr
    assert max(len(ln) for ln in first.stderr.splitlines()) <= 80
    second = subprocess.run([sys.executable, "-c", script], cwd=ROOT, env=env,
                            capture_output=True, text=True, timeout=600)
    assert second.stdout.split() == ["True", "True"]
    assert "compiling" not in second.stderr


def test_units_cover_every_entry_point_and_variant():
    from ema_cli.api import kernels
    from ema_cli.sim import compiled
    from ema_cli.sim.kernel import KERNELS, LANES, VARIANTS

    names = kernels.units()
    assert len(names) == len(set(names))
    expected = len(VARIANTS[1]) + len(VARIANTS[LANES]) + 1  # + identification
    assert len(names) == expected == 8
    for lanes in KERNELS:
        width = LANES if lanes else 1
        for variant in VARIANTS[width]:
            assert compiled.entry_name(width, variant) in names
    assert compiled.describe("lanes/v1") == "16 lanes, LuGre (exponent 1)"
    assert compiled.describe("rows/v6") == "one lane, LuGre, extras"


def test_families_are_dealt_whole_to_processes():
    # the units of one family share numba's index files: never split over two processes
    from ema_cli.api import kernels

    fams: dict[str, list[str]] = {}
    for n in kernels.units():
        fams.setdefault(kernels.family(n), []).append(n)
    assert set(fams) == {"rows", "lanes", "identify"}
    shares = kernels.deal(list(fams.values()), 2)
    for fam in fams.values():
        assert sum(all(n in s for n in fam) for s in shares) == 1


@pytest.mark.slow
def test_ema_compile_from_scratch_then_warm(tmp_path):
    # every unit from an empty cache in two processes, then a second run loads them all
    cache = tmp_path / "cache"
    cold = _ema(["compile"], cache)
    assert cold.returncode == 0, cold.stderr
    assert "compiling the simulator: 8 of 8 units" in cold.stderr
    assert "[8/8]" in cold.stderr
    for line in (cold.stderr + cold.stdout).splitlines():  # an 80-column terminal
        assert len(line) <= 80, line
    assert "kernels: all 8 units compiled and cached" in cold.stdout
    warm = _ema(["compile"], cache)
    assert warm.returncode == 0
    assert warm.stderr == ""
    assert "kernels: all 8 units compiled and cached" in warm.stdout
    secs = float(warm.stdout.rsplit("(", 1)[1].split(" s)")[0])
    assert secs < 2.0


_PY_MODE = """
import json, numpy as np
from ema_cli.model.params import resolve, to_row
from ema_cli.sim.runner import simulate_batch
from ema_cli.sim.signals import InputSignal, sample
out = {}
for name, ov in (("paper", {"friction": 1, "Fc": 0.02, "vs": 0.1}), ("static", {"friction": 2})):
    P = np.array([to_row(resolve(ov))])
    ref = sample(InputSignal("step", 0.01), 1e-5, 60)
    out[name] = simulate_batch(P, [ref], None, 1e-5, 60, 10, lanes=1).metrics[0].tolist()
print(json.dumps(out))
"""


@pytest.mark.slow  # the slow tier: pure Python is slow
def test_the_kernel_runs_as_plain_python_with_the_jit_disabled(tmp_path):
    # NUMBA_DISABLE_JIT=1 (the module docstring of ema_cli._numba: for debugging) runs the
    # same kernel as Python, the integrator picked per variant included (sim.integrate,
    # advance_for): the same metrics as compiled code, to rounding (no fused multiply-adds)
    import json

    import numpy as np

    def run(disable: bool) -> dict:
        env = {**os.environ, "EMA_CACHE_DIR": str(tmp_path / "cache")}
        env.pop("NUMBA_DISABLE_JIT", None)
        if disable:
            env["NUMBA_DISABLE_JIT"] = "1"
        r = subprocess.run([sys.executable, "-c", _PY_MODE], cwd=ROOT, env=env,
                           capture_output=True, text=True, timeout=600)
        assert r.returncode == 0, r.stderr[-2000:]
        return json.loads(r.stdout.strip().splitlines()[-1])

    py, jit = run(True), run(False)
    for name in ("paper", "static"):
        a, b = np.array(py[name]), np.array(jit[name])
        assert np.isfinite(b[:3]).all() and b[0] > 0
        np.testing.assert_allclose(a, b, rtol=1e-9, atol=1e-15, equal_nan=True)
