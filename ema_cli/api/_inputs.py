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
