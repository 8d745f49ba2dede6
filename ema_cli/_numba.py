"""The one place numba is imported from, with a compiled-code cache that cannot go stale.

numba's ``cache=True`` only notices edits to the file that defines a jitted function, but our
kernels inline the model's equations and bake the parameter, state and signal table indices into
the machine code. So the cache lives in a folder keyed on a hash of every source the compiled
code can read (:func:`source_key`): ``_numba.py``, ``units.py``, every module of ``model/`` and
``sim/``, and every module that imports this one (the modules that define compiled code). Any
edit to any of them selects a new, empty folder and everything is compiled afresh.

The cache root is ``$EMA_CACHE_DIR``, else ``$NUMBA_CACHE_DIR``, else ``$XDG_CACHE_HOME/ema``
(``~/.cache/ema``); an unwritable root falls back to the temporary folder. Set
``NUMBA_DISABLE_JIT=1`` to run the kernels as plain Python for debugging.
"""

from __future__ import annotations

import hashlib
import os
import re
import shutil
import tempfile
from pathlib import Path
from typing import Any

PACKAGE = Path(__file__).resolve().parent
KEYED_FOLDERS = ("model", "sim")  # every module in these is read by the compiled kernels
KEYED_FILES = ("_numba.py", "units.py")
KEEP_CACHES = 6  # cache folders of other source versions kept (most recent first) [-]
JIT_IMPORT = re.compile(r"^\s*(?:from\s+ema_cli\._numba\s+import|import\s+ema_cli\._numba)",
                        re.MULTILINE)
"""An import of this module: the files that have one define compiled code."""


def keyed_sources(package: Path = PACKAGE) -> list[Path]:
    """The source files the compiled code depends on, sorted (see the module docstring)."""
    files = {package / f for f in KEYED_FILES}
    for folder in KEYED_FOLDERS:
        files.update((package / folder).glob("*.py"))
    for f in package.rglob("*.py"):
        if JIT_IMPORT.search(f.read_text(encoding="utf-8")):
            files.add(f)
    return sorted(f for f in files if f.is_file())


def source_key(package: Path = PACKAGE) -> str:
    """A short hash of the contents (and relative paths) of :func:`keyed_sources`."""
    h = hashlib.sha256()
    for f in keyed_sources(package):
        h.update(f.relative_to(package).as_posix().encode())
        h.update(b"\0")
        h.update(f.read_bytes())
        h.update(b"\0")
    return h.hexdigest()[:16]


def cache_root() -> Path:
    """The folder holding one cache folder per source key."""
    for var in ("EMA_CACHE_DIR", "NUMBA_CACHE_DIR"):
        if os.environ.get(var):
            return Path(os.environ[var]).expanduser() / "ema-kernels"
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base).expanduser() / "ema" / "kernels"


def _prepare(root: Path, key: str) -> Path:
    folder = root / key
    if not folder.is_dir():
        try:
            folder.mkdir(parents=True, exist_ok=True)
        except OSError:
            root = Path(tempfile.gettempdir()) / f"ema-kernels-{os.getuid()}"
            folder = root / key
            folder.mkdir(parents=True, exist_ok=True)
        others = sorted((d for d in root.iterdir() if d.is_dir() and d.name != key),
                        key=lambda d: d.stat().st_mtime, reverse=True)
        for old in others[KEEP_CACHES:]:
            shutil.rmtree(old, ignore_errors=True)
    return folder


CACHE_KEY = source_key()
"""The key of the sources this process runs; the compiled code is cached under it."""

from numba import config, literally, prange  # noqa: E402  (after the key: config must be set first)
from numba import njit as _njit  # noqa: E402
from numba.core.registry import CPUDispatcher  # noqa: E402

INNER_LOG_ENV = "EMA_INNER_LOG"  # set to a file: Python-level calls of inner functions logged


class InnerDispatcher(CPUDispatcher):
    """A compiled function that only compiled code calls, compiled without numba's CPython and
    C-callable wrappers: a wrapper is a function of its own that LLVM optimises and emits for
    every compiled function, and they were a third of the time of compiling the kernels from
    an empty cache. A call from Python (a test, a debugger) runs a twin compiled with the
    wrappers, not cached (a cached twin would share the function's cache entries, which hold
    no wrapper)."""

    def __call__(self, *args: Any, **kwargs: Any) -> Any:
        twin = self.__dict__.get("_ema_twin")
        if twin is None:
            log = os.environ.get(INNER_LOG_ENV)
            if log:
                import traceback

                caller = traceback.extract_stack(limit=2)[0]
                with open(log, "a", encoding="utf-8") as f:
                    f.write(f"{self.py_func.__module__}.{self.py_func.__qualname__}\t"
                            f"{caller.filename}:{caller.lineno}\n")
            opts = {k: v for k, v in self.targetoptions.items()
                    if k not in ("no_cpython_wrapper", "no_cfunc_wrapper", "nopython")}
            twin = _njit(**opts)(self.py_func)
            self.__dict__["_ema_twin"] = twin
        return twin(*args, **kwargs)


def njit(*args: Any, entry: bool = False, **kwargs: Any) -> Any:
    """numba's ``njit`` with fused multiply-adds allowed (``fastmath={"contract"}``, the only
    fast-math flag: no reassociation, no finite-math assumption; docs/model.md, "Fused
    multiply-adds"), unless the caller sets ``fastmath``.

    ``entry=True``: a function Python calls (an entry point: compiled with numba's wrappers).
    Otherwise the function is *inner* (:class:`InnerDispatcher`): compiled code calls it, it
    is compiled without the wrappers, and a call from Python compiles a twin that has them.
    Used as ``@njit(...)`` with keywords only."""
    kwargs.setdefault("fastmath", {"contract"})
    if entry or config.DISABLE_JIT or args:
        return _njit(*args, **kwargs)
    cache = bool(kwargs.pop("cache", False))
    options = {**kwargs, "nopython": True, "no_cpython_wrapper": True,
               "no_cfunc_wrapper": True}

    def wrap(func: Any) -> Any:
        _INNER_FUNCS.add(func)
        disp = InnerDispatcher(py_func=func, locals={}, targetoptions=options)
        if cache:
            disp.enable_caching()
        return disp

    return wrap

config.CACHE_DIR = str(_prepare(cache_root(), CACHE_KEY))

if "NUMBA_DISABLE_PERFORMANCE_WARNINGS" not in os.environ:
    # numba's performance advice (e.g. "no transformation for parallel execution") is not for
    # users; set the variable yourself to see numba's performance warnings again.
    config.DISABLE_PERFORMANCE_WARNINGS = 1



def _serialise_cache_saves() -> None:
    """Make numba's cache safe for several processes compiling at once.

    numba's ``IndexDataCacheFile.save`` reads a function's index, picks the first data-file
    number the index does not use, writes the index, then the data. Two processes saving two
    overloads of one function at the same moment (two ``ema`` commands, or two test workers,
    compiling two variants of a kernel entry point) can pick the same number: the index then
    names one signature and the file holds the other's machine code, and every later process
    runs a kernel of another variant without an error (the one cross-process path found for a
    CI run in which the same fit gave other numbers; that it was the cause is not proven).

    Here each save holds an exclusive ``flock`` on a lock file beside the index for the
    whole read-pick-write, and each load checks that the entry it read was compiled for the
    signature asked for (a mismatch, e.g. in a cache written before this guard, is a miss:
    the function is compiled again and the entry replaced)."""
    import contextlib

    try:
        import fcntl
    except ImportError:  # not POSIX: numba's own behaviour
        return
    from numba.core import caching

    cls = caching.IndexDataCacheFile
    if getattr(cls, "_ema_guarded", False):
        return
    save, load = cls.save, cls.load

    def locked_save(self: Any, key: Any, data: Any) -> None:
        try:
            lock = open(self._index_path + ".lock", "a")  # noqa: SIM115 (held across save)
        except OSError:  # an unwritable cache: numba's save fails or skips as it would
            return save(self, key, data)
        with lock:
            # a file system without locks (some network mounts): numba's own, unguarded save
            with contextlib.suppress(OSError):
                fcntl.flock(lock, fcntl.LOCK_EX)
            return save(self, key, data)

    def checked_load(self: Any, key: Any) -> Any:
        data = load(self, key)
        if data is not None and not entry_matches(key, data):
            return None
        return data

    cls.save, cls.load = locked_save, checked_load
    cls._ema_guarded = True


def entry_matches(key: Any, data: Any) -> bool:
    """Whether a numba cache entry read back (``data``: a reduced compile result, whose fourth
    item is its signature) was compiled for the index ``key`` (whose first item is the
    argument types). Entries of another shape are not judged (True)."""
    try:
        sig = data[3]
        args = sig.args
    except (TypeError, IndexError, AttributeError):
        return True
    return tuple(args) == tuple(key[0])


_serialise_cache_saves()


INNER_KIND = "ema-inner"
"""How an inner function's compiled library is cached: its optimised LLVM bitcode, no machine
code (:func:`_inner_code_without_machine_code`)."""
_INNER_FUNCS: set[Any] = set()  # the Python functions of the InnerDispatchers


def _inner_code_without_machine_code() -> None:
    """Compile an inner function (:class:`InnerDispatcher`) to optimised LLVM IR only.

    numba turns every compiled function's own module into machine code, although the IR of an
    inner function is only ever linked into its callers' modules (and optimised and emitted
    there, inlined). Here an inner function's library is optimised as before (so its callers
    see the same IR and compile to the same machine code, bit for bit) but never handed to the
    execution engine, and the cache keeps its bitcode (:data:`INNER_KIND`) instead of an object
    file. Its environment pointer, never read by a function that touches no Python object, is
    left unset. A call from Python runs the twin (:class:`InnerDispatcher`), which has machine
    code of its own."""
    from numba.core import codegen as cg  # its llvmlite binding: cg.ll (numba's own pin)
    from numba.core.typed_passes import BaseNativeLowering

    if getattr(BaseNativeLowering, "_ema_inner_patched", False):
        return
    run_pass = BaseNativeLowering.run_pass

    def lowering(self: Any, state: Any) -> Any:
        if (state.library is None and state.flags.no_cpython_wrapper
                and state.func_id.func in _INNER_FUNCS):  # not the twin: it has wrappers
            lib = state.targetctx.codegen().create_library(state.func_id.func_qualname)
            lib.enable_object_caching()
            lib._ema_inner = True
            state.library = lib
        return run_pass(self, state)

    lib_cls = cg.JITCodeLibrary
    finalize_module = lib_cls._finalize_final_module
    pointer = lib_cls.get_pointer_to_function
    serialise = lib_cls.serialize_using_object_code
    unserialise = lib_cls._unserialize.__func__

    def _finalize_final_module(self: Any) -> None:
        if not getattr(self, "_ema_inner", False):
            return finalize_module(self)
        self._finalize_dynamic_globals()
        self._verify_declare_only_symbols()
        self._finalized = True

    def get_pointer_to_function(self: Any, name: str) -> int:
        if not getattr(self, "_ema_inner", False):
            return pointer(self, name)
        self._ensure_finalized()
        return 0  # no machine code: no wrapper (its callers inline or link its IR)

    def serialize_using_object_code(self: Any) -> tuple:
        if not getattr(self, "_ema_inner", False):
            return serialise(self)
        self._ensure_finalized()
        return (self.name, INNER_KIND, self._get_module_for_linking().as_bitcode())

    def _unserialize(cls: Any, codegen: Any, state: tuple) -> Any:
        name, kind, data = state
        if kind != INNER_KIND:
            return unserialise(cls, codegen, state)
        self = codegen.create_library(name)
        self._ema_inner = True
        self._final_module = cg.ll.parse_bitcode(data)
        self._finalize_final_module()
        return self

    set_env = cg.JITCPUCodegen.set_env

    def set_env_if_emitted(self: Any, env_name: str, env: Any) -> None:
        if self._engine.get_global_value_address(env_name):
            set_env(self, env_name, env)

    BaseNativeLowering.run_pass = lowering
    lib_cls._finalize_final_module = _finalize_final_module
    lib_cls.get_pointer_to_function = get_pointer_to_function
    lib_cls.serialize_using_object_code = serialize_using_object_code
    lib_cls._unserialize = classmethod(_unserialize)
    cg.JITCPUCodegen.set_env = set_env_if_emitted
    BaseNativeLowering._ema_inner_patched = True


_inner_code_without_machine_code()


def _defer_blas_probe() -> None:
    """Import ``numba.np.arraymath`` without its BLAS probe (a 0.3 s ``import scipy.linalg``).

    numba imports that module on the first call of any compiled function, even one loaded from
    the cache, and the module asks at import time whether BLAS is there by importing
    ``scipy.linalg``: most of the cost of a short ``ema simulate``. scipy is a dependency of
    this package, so the answer is known to be yes; the probe is answered without the import
    and the real check is put back at once (numba still calls it before compiling any BLAS
    function). Our kernels use no BLAS.
    """
    import sys

    if "numba.np.arraymath" in sys.modules:
        return
    import numba.np.linalg as nplinalg

    real = nplinalg.ensure_blas
    nplinalg.ensure_blas = lambda: None
    try:
        import numba.np.arraymath  # noqa: F401
    finally:
        nplinalg.ensure_blas = real


_defer_blas_probe()

__all__ = ["CACHE_KEY", "entry_matches", "literally", "njit", "prange", "source_key"]
