"""What every API function takes: a config (file, dict, model or None) and overrides."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from ema_cli.errors import EmaError

ConfigSource = str | Path | Mapping[str, Any] | Any | None
"""A YAML file path, a dict (the YAML document), a validated config model, or None (defaults)."""

Overrides = Mapping[str, Any] | Sequence[tuple[str, Any]] | None
"""``{"plant.kL": 600, "sweep.axes.0.values": [0.01]}`` or ``[("plant.kL", 600)]``: the same
dotted paths as ``--set``."""


def override_pairs(overrides: Overrides, nl: Mapping[str, Any] | None = None
                   ) -> list[tuple[str, Any]]:
    """``overrides`` (+ ``nl`` as ``nonlinearities.NAME``) -> a list of (path, value) pairs."""
    if overrides is None:
        pairs: list[tuple[str, Any]] = []
    elif isinstance(overrides, Mapping):
        pairs = [(str(k), v) for k, v in overrides.items()]
    elif isinstance(overrides, str | bytes) or not hasattr(overrides, "__iter__"):
        raise EmaError(f"overrides: expected a dict or (path, value) pairs, got "
                       f"{type(overrides).__name__}")
    else:
        pairs = []
        for item in overrides:
            if not (isinstance(item, tuple | list) and len(item) == 2):
                raise EmaError(f"overrides: expected (path, value) pairs, got {item!r}")
            pairs.append((str(item[0]), item[1]))
    if nl is not None and not isinstance(nl, Mapping):
        raise EmaError(f"nl: expected a mapping of nonlinearity names to magnitudes, got "
                       f"{type(nl).__name__}")
    for name, value in (nl or {}).items():
        pairs.append((f"nonlinearities.{name}", value))
    return pairs


def folder_arg(folder: object) -> Path | None:
    """A ``save(folder)`` argument -> Path (None: a new folder under results/)."""
    if folder is None:
        return None
    if not isinstance(folder, str | Path):
        raise EmaError(f"folder: expected a path, got {type(folder).__name__}")
    return Path(folder)


def base_dir(config: ConfigSource) -> Path | None:
    """The folder relative paths in ``config`` are looked up in (a file's own folder)."""
    if isinstance(config, str | Path):
        return Path(config).parent
    return None


def source_name(config: ConfigSource) -> str:
    """How errors and manifests name ``config``."""
    if config is None:
        return "defaults"
    if isinstance(config, str | Path):
        return str(config)
    if isinstance(config, Mapping):
        return "dict"
    return type(config).__name__


def number_arg(value: Any, name: str, *, low: float | None = None, high: float | None = None,
               low_open: bool = False, integer: bool = False, optional: bool = True) -> Any:
    """``value`` as a finite number (an int when ``integer``) within ``low``..``high``, or None
    when None and ``optional``; else EmaError naming the argument ``name``."""
    import math

    if value is None and optional:
        return None
    kind = "an integer" if integer else "a finite number"
    ok_type = isinstance(value, int) if integer else isinstance(value, int | float)
    if isinstance(value, bool) or not ok_type or not math.isfinite(value):
        raise EmaError(f"{name} must be {kind}, got {value!r}")
    if low is not None and (value <= low if low_open else value < low):
        raise EmaError(f"{name} must be {'>' if low_open else '>='} {low:g}, got {value!r}")
    if high is not None and value > high:
        raise EmaError(f"{name} must be <= {high:g}, got {value!r}")
    return value


def choice_arg(value: Any, name: str, choices: Sequence[str]) -> Any:
    """``value`` one of ``choices`` (or None); else EmaError naming ``name``."""
    if value is not None and (not isinstance(value, str) or value not in choices):
        raise EmaError(f"{name} must be one of {', '.join(choices)}, got {value!r}")
    return value


def flag_arg(value: Any, name: str) -> bool:
    """``value`` a bool; else EmaError naming ``name``."""
    if not isinstance(value, bool):
        raise EmaError(f"{name} must be True or False, got {value!r}")
    return value


def callable_arg(value: Any, name: str) -> Any:
    """``value`` a callable or None; else EmaError naming ``name``."""
    if value is not None and not callable(value):
        raise EmaError(f"{name} must be a function or None, got {value!r}")
    return value


def names_arg(value: Any, name: str) -> list[str] | None:
    """``value`` a list of strings (a single string is one name) or None; else EmaError."""
    if value is None:
        return None
    if isinstance(value, str):
        return [value]
    if not isinstance(value, Sequence) or not all(isinstance(v, str) for v in value):
        raise EmaError(f"{name} must be a list of names (str), got {value!r}")
    return list(value)


def path_arg(value: Any, name: str) -> Path | None:
    """``value`` a path (str or Path) or None; else EmaError naming ``name``."""
    if value is None:
        return None
    if not isinstance(value, str | Path) or not str(value):
        raise EmaError(f"{name} must be a path (str or Path), got {value!r}")
    return Path(value)


def check_sweep_steps(cfg: Any, source: str) -> None:
    """Refuse a sweep whose jobs x steps exceed :data:`ema_cli.limits.MAX_CASE_STEPS`."""
    from ema_cli.limits import check_steps
    from ema_cli.sweep.expand import check_size

    if not cfg.sweep.axes:
        return
    n = check_size(cfg.sweep, source)  # the baseline included
    steps = cfg.simulation.duration_s / cfg.simulation.dt_s
    check_steps(n * steps, f"{source}: {n:,} jobs x {steps:.3g} steps",
                "shrink sweep.axes, shorten simulation.duration_s or raise simulation.dt_s")


def check_sensitivity_steps(cfg: Any, method: str | None, n: int | None, source: str) -> None:
    """Refuse a sensitivity study whose runs x steps exceed the cap."""
    from ema_cli.limits import check_steps
    from ema_cli.sensitivity.run import resolve_method

    method, n = resolve_method(cfg, method, n)
    runs = cfg.runs(method, n)
    steps = cfg.simulation.duration_s / cfg.simulation.dt_s
    check_steps(runs * steps, f"{source}: {runs:,} runs ({method}, n = {n}) x {steps:.3g} "
                              "steps", "lower n, shorten simulation.duration_s or raise "
                                       "simulation.dt_s")


def capped_jobs(n_jobs: int | None, cfg: Any, backend: str | None) -> int | None:
    """``n_jobs`` (else the config's ``parallel.n_jobs``) capped at the cores available, with
    a warning, unless a dask cluster runs the jobs (:func:`ema_cli.limits.cap_workers`)."""
    import warnings

    from ema_cli.limits import cap_workers

    par = getattr(cfg, "parallel", None)
    given = n_jobs if n_jobs is not None else getattr(par, "n_jobs", None)
    cluster = (backend or getattr(par, "backend", None)) == "dask"
    out, note = cap_workers(given, "n_jobs", cluster=cluster)
    if note:
        warnings.warn(note, stacklevel=3)
    return out


def backend_args(backend: Any, n_jobs: Any, scheduler: Any) -> int | None:
    """The execution arguments of ``yield``, ``tune``, ``design`` and the closed-loop fit
    (``sweep.executor``): ``backend`` one of ``limits.BACKENDS`` or None (in this process, as
    before), ``n_jobs`` -1/None or 1 .. ``MAX_WORKERS`` (capped at the cores with a warning,
    unless a dask cluster runs them), ``scheduler`` the dask scheduler (only with ``backend``
    dask; dask.distributed installed); EmaError naming the argument -> ``n_jobs`` to use."""
    from ema_cli.limits import BACKENDS, MAX_WORKERS

    choice_arg(backend, "backend", BACKENDS)
    if n_jobs is not None and n_jobs != -1:
        number_arg(n_jobs, "n_jobs", low=1, high=MAX_WORKERS, integer=True)
    if scheduler is not None and not isinstance(scheduler, str):
        raise EmaError(f"scheduler must be an address (str), got {scheduler!r}")
    if scheduler is not None and backend != "dask":
        raise EmaError("scheduler is for backend dask; give backend dask with it")
    if backend == "dask":
        from ema_cli.sweep.executor import check_dask

        check_dask(scheduler)
    return capped_jobs(n_jobs, None, backend)
