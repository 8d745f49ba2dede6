"""Content hashes of JSON-serialisable data: job keys, sweep keys, run-folder names.

Below every layer (imports nothing of the package), so compute code can key its results
without depending on the report layer.
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path
from typing import Any


def json_default(o: Any) -> Any:
    """JSON form of the values ``json`` cannot write: numpy scalars and arrays, paths."""
    import numpy as np

    if isinstance(o, np.integer):
        return int(o)
    if isinstance(o, np.floating):
        return float(o)
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, Path):
        return str(o)
    raise TypeError(f"not JSON serialisable: {type(o).__name__}")


def content_hash(data: Any, length: int = 12) -> str:
    """A stable short hash of JSON-serialisable ``data``."""
    text = json.dumps(data, sort_keys=True, default=json_default)
    return hashlib.sha256(text.encode()).hexdigest()[:length]
