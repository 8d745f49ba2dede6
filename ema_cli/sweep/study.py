"""Load a study config for ``ema sweep``: YAML + ``--set`` overrides + the study schema."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

from ema_cli.config.loader import load_config
from ema_cli.config.schema import StudyConfig


def load_study(path: Path, overrides: Sequence[tuple[str, Any]] = ()) -> StudyConfig:
    """Read, override (``config.loader.apply_overrides``) and validate a study config; errors
    name the file and the key path."""
    return load_config(path, overrides, StudyConfig)
