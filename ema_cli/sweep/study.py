"""Load a study config for ``ema sweep``: YAML + ``--set`` overrides (list items too) + schema."""

from __future__ import annotations

import copy
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from ema_cli.config.loader import parse_value, read_yaml, validate
from ema_cli.config.schema import StudyConfig
from ema_cli.errors import EmaError
from ema_cli.model.params import INDEX


def apply_study_overrides(data: dict[str, Any], overrides: Sequence[tuple[str, Any]]
                          ) -> dict[str, Any]:
    """Set dotted paths in a copy of ``data``; numbers index lists (``sweep.axes.0.values``).

    A bare model parameter name means ``plant.NAME``. String values are read as YAML scalars
    or lists (``[0.01, 0.1]``); ``off`` stays the word.
    """
    out = copy.deepcopy(data)
    top = list(StudyConfig.model_fields)
    for path, raw in overrides:
        keys = path.split(".")
        if len(keys) == 1 and keys[0] not in top and keys[0] in INDEX:
            keys = ["plant", keys[0]]
        if keys[0] not in top:
            raise EmaError(f"--set {path}: unknown key '{keys[0]}'; expected one of "
                           f"{sorted(top)} or a model parameter name")
        value = parse_value(raw) if isinstance(raw, str) else raw
        node: Any = out
        for depth, k in enumerate(keys):
            last = depth == len(keys) - 1
            if isinstance(node, list):
                if not k.isdigit() or int(k) >= len(node):
                    raise EmaError(f"--set {path}: '{'.'.join(keys[:depth])}' is a list of "
                                   f"{len(node)} items; expected an index 0..{len(node) - 1}")
                if last:
                    node[int(k)] = value
                else:
                    node = node[int(k)]
                continue
            if not isinstance(node, dict):
                raise EmaError(f"--set {path}: '{'.'.join(keys[:depth])}' is a value, not a "
                               "section")
            if last:
                node[k] = value
            else:
                if node.get(k) is None:
                    node[k] = {}
                node = node[k]
    return out


def load_study(path: Path, overrides: Sequence[tuple[str, Any]] = ()) -> StudyConfig:
    """Read, override and validate a study config; errors name the file and the key path."""
    data = apply_study_overrides(read_yaml(path), overrides)
    return validate(StudyConfig, data, str(path))
