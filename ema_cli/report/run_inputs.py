"""What a run folder's marker (``.ema-run.json``) records about the inputs of its run.

:func:`run_inputs` describes a run's inputs as named components: every leaf of its resolved
config by its dotted path (``plant.kL``, ``optimiser.budget``: the paths ``--set`` takes), the
command's options that shape the results (``--budget``, ``--n``), the SHA-256 of every data
file it reads (``data (sha256)``) and the ema version. The fingerprint is the hash of those
components: a pure function of the inputs (no path of the output folder, no time, nothing
computed), identical for identical inputs, so the same command given again recognises its
own folder. :func:`differences` names the components that differ between a marker and a new
run, for the one-line refusal of a folder of other inputs.

The resolved config (not the file's bytes) is what is compared: a comment edited in a config
file, or a ``--set`` equal to the file's value, changes nothing; a value changed in the file
or by ``--set`` is named by its path.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from ema_cli import __version__
from ema_cli.hashing import content_hash, json_default

LONG = 120
"""A component whose JSON text is longer than this is recorded as its hash [characters]."""
SHOWN = 3
"""Differences named in a refusal (the rest counted)."""


@dataclass(frozen=True)
class RunInputs:
    """The inputs of a run: ``components`` (label -> JSON value; what the fingerprint hashes)
    and ``sets`` (the ``--set`` paths given: a refusal says ``--set PATH`` for them; not part
    of the fingerprint, since a ``--set`` equal to the config's value changes nothing)."""

    components: dict[str, Any]
    sets: tuple[str, ...] = field(default=())
    key: str | None = None
    """A fingerprint given as it is (:func:`legacy_inputs`), instead of the components' hash."""

    @property
    def fingerprint(self) -> str:
        return self.key or content_hash(self.components, 16)

    def with_components(self, **extra: Any) -> RunInputs:
        """A copy with more components (``extra``, normalised like the others)."""
        return RunInputs({**self.components, **{k: _leaf(v) for k, v in extra.items()}},
                         self.sets, self.key)


def _json(value: Any) -> Any:
    """``value`` as plain JSON data (tuples as lists, numpy values and paths converted)."""
    return json.loads(json.dumps(value, default=json_default, sort_keys=True))


def _leaf(value: Any) -> Any:
    """A component's recorded value: itself, or ``sha256:<16 hex> (<n> chars)`` when long."""
    value = _json(value)
    text = json.dumps(value, sort_keys=True)
    if len(text) > LONG:
        return f"sha256:{hashlib.sha256(text.encode()).hexdigest()[:16]} ({len(text)} chars)"
    return value


def _document(config: Any) -> Any:
    """A config (pydantic model, mapping, or anything JSON-serialisable) as JSON data."""
    if hasattr(config, "model_dump"):
        try:
            return _json(config.model_dump(mode="json", by_alias=True))
        except TypeError:
            return _json(config.model_dump(mode="json"))
    try:
        return _json(config)
    except (TypeError, ValueError):
        return repr(config)


def flatten(doc: Any, prefix: str = "") -> dict[str, Any]:
    """Every leaf of ``doc`` by its dotted path (list items by index, as ``--set`` takes
    them); a list of scalars is one leaf; long leaves recorded by their hash."""
    out: dict[str, Any] = {}
    if isinstance(doc, dict) and doc:
        for k, v in doc.items():
            out.update(flatten(v, f"{prefix}.{k}" if prefix else str(k)))
    elif isinstance(doc, list) and doc and any(isinstance(v, dict | list) for v in doc):
        for i, v in enumerate(doc):
            out.update(flatten(v, f"{prefix}.{i}" if prefix else str(i)))
    else:
        out[prefix or "config"] = _leaf(doc)
    return out


def file_digest(path: str | Path | None) -> str | None:
    """``sha256:<64 hex>`` of a file's bytes; None for no file, ``missing`` for a path that
    cannot be read (the command itself then says why)."""
    if path is None:
        return None
    h = hashlib.sha256()
    try:
        with open(path, "rb") as f:
            for chunk in iter(lambda: f.read(1 << 20), b""):
                h.update(chunk)
    except OSError:
        return "missing"
    return f"sha256:{h.hexdigest()}"


def run_inputs(config: Any = None, *, sets: Sequence[tuple[str, Any]] | Sequence[str] = (),
               options: Mapping[str, Any] | None = None,
               files: Mapping[str, str | Path | None] | None = None,
               parts: Mapping[str, Any] | None = None) -> RunInputs:
    """The inputs of a run (module docstring).

    config   the resolved config (a validated model or a mapping): one component per leaf,
             by its dotted path; None: no config
    sets     the ``--set`` pairs (or paths) given, named ``--set PATH`` in a refusal
    options  the command's options that shape the results, by option name without dashes
             (``budget`` -> component ``--budget``); pass effective values where the option
             overrides the config, so that giving the config's value changes nothing
    files    data files by role (``data``, ``log``, ``spec``): their SHA-256
    parts    further configs by name (``tolerances``): their leaves as ``NAME: PATH``
    """
    comps: dict[str, Any] = {"ema version": __version__}
    if config is not None:
        comps.update(flatten(_document(config)))
    for name, part in (parts or {}).items():
        comps.update({f"{name}: {k}": v for k, v in flatten(_document(part)).items()})
    for name, value in (options or {}).items():
        comps[f"--{name.replace('_', '-')}"] = _leaf(value)
    for name, path in (files or {}).items():
        comps[f"{name} (sha256)"] = file_digest(path)
    paths = tuple(str(s[0]) if isinstance(s, tuple | list) else str(s) for s in sets)
    return RunInputs(comps, paths)


def legacy_inputs(fingerprint: str) -> RunInputs:
    """A bare fingerprint (a caller that has no components) as inputs: the fingerprint is
    ``fingerprint`` itself."""
    return RunInputs({"fingerprint": fingerprint}, key=fingerprint)


def _show(value: Any, missing: bool) -> str:
    if missing:
        return "not set"
    if isinstance(value, str) and value.startswith("sha256:"):
        return value[:19] + ("…" if len(value) > 19 and "(" not in value else "")
    text = json.dumps(value, sort_keys=True) if not isinstance(value, str) else value
    return text if len(text) <= 40 else text[:39] + "…"


def _label(key: str, sets: set[str]) -> str:
    """``--set PATH`` when ``key`` is (or lies under) a path given with --set, else ``key``."""
    if any(key == s or key.startswith(s + ".") for s in sets):
        return f"--set {key}"
    return key


def differences(old: Mapping[str, Any] | None, new: RunInputs,
                old_sets: Sequence[str] = ()) -> str:
    """``plant.kL 600 there, 700 here; --budget 240 there, 96 here`` (at most :data:`SHOWN`,
    the rest counted): what differs between a marker's components (``old``) and ``new``."""
    if not old:
        return "its marker does not list its inputs (an older ema)"
    sets = {*new.sets, *old_sets}
    keys = [*new.components, *(k for k in old if k not in new.components)]
    diff = []
    for k in keys:
        a_missing, b_missing = k not in old, k not in new.components
        a, b = old.get(k), new.components.get(k)
        if a_missing == b_missing and _json(a) == _json(b):
            continue
        diff.append(f"{_label(k, sets)} {_show(a, a_missing)} there, {_show(b, b_missing)} "
                    "here")
    if not diff:
        return "the same components, another fingerprint (an older ema's marker)"
    more = len(diff) - SHOWN
    return "; ".join(diff[:SHOWN]) + (f"; and {more} more" if more > 0 else "")
