"""Inner compiled functions (``ema_cli._numba.njit`` without ``entry=True``): compiled without
numba's wrappers, called from compiled code as any function, and from Python through a twin
that gives the same numbers; the entry points keep numba's own dispatcher."""

from __future__ import annotations

import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from ema_cli._numba import INNER_LOG_ENV, InnerDispatcher, njit

ROOT = Path(__file__).resolve().parents[2]


@njit(cache=False, error_model="numpy")
def _inner_hypot(a, b):
    return math.sqrt(a * a + b * b)


@njit(cache=False, error_model="numpy", entry=True)
def _entry_sum(x):
    s = 0.0
    for v in x:
        s += _inner_hypot(v, 1.0)
    return s


def test_inner_and_entry_functions_compute_the_same_numbers():
    x = np.linspace(-3.0, 3.0, 13)
    assert isinstance(_inner_hypot, InnerDispatcher)
    assert not isinstance(_entry_sum, InnerDispatcher)
    expected = float(np.sum(np.hypot(x, 1.0)))
    assert _entry_sum(x) == pytest.approx(expected, rel=1e-15)  # inner called from compiled code
    assert _inner_hypot(3.0, 4.0) == 5.0  # from Python: the twin
    # the twin is compiled once and kept
    twin = _inner_hypot.__dict__["_ema_twin"]
    assert _inner_hypot(6.0, 8.0) == 10.0 and _inner_hypot.__dict__["_ema_twin"] is twin


def test_the_kernel_model_functions_keep_their_values_from_python():
    """A model function the tests call directly (an inner function): the same value as its
    formula (LuGre's steady friction: sign(w) (Fc + (Fs - Fc) exp(-(|w|/vs)^delta)) + sigma2 w)."""
    from ema_cli.model.lugre import steady_friction_nb

    fc, fs, vs, delta, sigma2, v = 0.3, 0.5, 0.01, 2.0, 0.02, 0.004
    g = fc + (fs - fc) * math.exp(-((v / vs) ** delta))
    assert steady_friction_nb(v, fc, fs, vs, delta, sigma2) == pytest.approx(
        g + sigma2 * v, rel=1e-12)
    assert steady_friction_nb(-v, fc, fs, vs, delta, sigma2) == pytest.approx(
        -(g + sigma2 * v), rel=1e-12)


@pytest.mark.slow  # whole processes, cold caches possible
def test_no_command_calls_an_inner_function_from_python(tmp_path):
    """The commands run with EMA_INNER_LOG set: no inner function is called from Python (each
    such call would compile an uncached twin on every run)."""
    log = tmp_path / "inner.log"
    env = {**os.environ, INNER_LOG_ENV: str(log)}
    ema = str(Path(sys.executable).with_name("ema"))
    runs = [["simulate", "--duration", "0.2", "--nl", "deadzone2=0.01"],
            ["duty", str(ROOT / "configs" / "duty" / "hold_and_move.yaml")],
            ["identify", "make-data", "friction-sweep"],
            ["identify", "plant", str(ROOT / "experiments" / "data" / "emps" / "DATA_EMPS.mat"),
             "--actuator", str(ROOT / "configs" / "actuators" / "emps.yaml"), "--split", "0"],
            ["identify", "torque", "--pop", "20", "--generations", "10"]]
    for i, args in enumerate(runs):
        r = subprocess.run([ema, *args, "--out", str(tmp_path / f"o{i}")], env=env, cwd=tmp_path,
                           capture_output=True, text=True, timeout=600)
        assert r.returncode in (0, 1, 3), r.stderr
    r = subprocess.run([ema, "identify", "friction-sweep", "--data",
                        str(tmp_path / "o2" / "friction_sweep.csv"), "--out",
                        str(tmp_path / "fs")], env=env, cwd=tmp_path, capture_output=True,
                       text=True, timeout=600)
    assert r.returncode in (0, 1, 3), r.stderr
    assert not log.exists(), log.read_text()


_INNER_MODULE = '''
import numpy as np
from ema_cli._numba import njit

@njit(cache=True)
def inner(x):
    if x < 0:
        raise ValueError("negative input")
    a = np.empty(3)
    a[:] = x
    return a.sum()

@njit(cache=True, entry=True)
def outer(x):
    return inner(x) + 1.0
'''
_LATER_MODULE = '''
from ema_cli._numba import njit
from inner_mod import inner

@njit(cache=True, entry=True)
def later(x):
    return inner(x) * 3.0
'''
_CHECK = '''
import sys, {mod}
f = {mod}.{fn}
print(f(2.0))
try:
    f(-1.0)
except ValueError as e:
    print("raised", e)
print({mod}.inner(1.0) if "{mod}" == "inner_mod" else "")
'''


def test_inner_code_is_cached_as_ir_and_links_into_a_later_entry(tmp_path):
    """An inner function gets no machine code of its own (``_inner_code_without_machine_code``):
    its cache entry is its optimised IR (no object file), an entry compiled in the same
    process runs it, raises its exception and is cached; a later process compiles another
    entry point against the inner function read back from the cache, and a third loads both
    entry points from the cache; a call from Python runs the twin."""
    from ema_cli._numba import INNER_KIND

    (tmp_path / "inner_mod.py").write_text(_INNER_MODULE)
    (tmp_path / "later_mod.py").write_text(_LATER_MODULE)
    env = {**os.environ, "EMA_CACHE_DIR": str(tmp_path / "cache"),
           "PYTHONPATH": os.pathsep.join([str(ROOT), str(tmp_path)])}
    env.pop("NUMBA_DISABLE_JIT", None)

    def run(mod: str, fn: str) -> list[str]:
        r = subprocess.run([sys.executable, "-c", _CHECK.format(mod=mod, fn=fn)], env=env,
                           capture_output=True, text=True, timeout=300, cwd=tmp_path)
        assert r.returncode == 0, r.stderr[-2000:]
        return r.stdout.split("\n")

    assert run("inner_mod", "outer")[:3] == ["7.0", "raised negative input", "3.0"]
    data = sorted((tmp_path / "cache").rglob("inner_mod.inner-*.nbc"))
    assert len(data) == 1
    raw = data[0].read_bytes()  # (unpickling it needs the module: read the bytes)
    assert INNER_KIND.encode() in raw and b"\x7fELF" not in raw  # IR, no object file
    assert b"\x7fELF" in next((tmp_path / "cache").rglob("inner_mod.outer-*.nbc")).read_bytes()
    assert run("later_mod", "later")[:2] == ["18.0", "raised negative input"]
    assert sorted((tmp_path / "cache").rglob("later_mod.later-*.nbc"))
    assert run("later_mod", "later")[:2] == ["18.0", "raised negative input"]  # from the cache
    assert run("inner_mod", "outer")[:3] == ["7.0", "raised negative input", "3.0"]
