"""Read a YAML config, apply ``--set PATH=VALUE`` overrides, validate, and resolve it to SI.

Every failure becomes an :class:`EmaError` naming the file, the key path and what was expected.
"""

from __future__ import annotations

import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TypeVar

import yaml
from pydantic import BaseModel, ValidationError

from ema_cli.config.inputs import _local, input_signal  # noqa: F401 (re-exported)
from ema_cli.config.run import KEY_MARK, RunConfig
from ema_cli.errors import EmaError
from ema_cli.model.nonlinearities import combined_updates
from ema_cli.model.params import INDEX, resolve
from ema_cli.sim.signals import InputSignal

M = TypeVar("M", bound=BaseModel)


MAX_YAML_BYTES = 1 << 20
"""The largest config or experiment file read: 1 MiB (checked before parsing) [bytes]."""
MAX_YAML_NODES = 1_000_000
"""The most YAML nodes a file may expand to, aliases counted at their expanded size: a
1 MiB file holds far fewer without aliases; an alias bomb (billion laughs) is refused."""
MAX_YAML_DEPTH = 50
"""The deepest nesting of mappings and sequences accepted (the schemas need fewer than 10)."""

_MERGE_TAG = "tag:yaml.org,2002:merge"
_BaseLoader = getattr(yaml, "CSafeLoader", yaml.SafeLoader)


class _DuplicateKey(Exception):
    def __init__(self, key: Any, line: int) -> None:
        super().__init__(key, line)
        self.key, self.line = key, line


class _Loader(_BaseLoader):  # type: ignore[misc, valid-type]
    """The safe loader, refusing a key given twice in one mapping (PyYAML keeps the last)."""

    def construct_mapping(self, node: Any, deep: bool = False) -> Any:
        if isinstance(node, yaml.MappingNode):
            seen: set[Any] = set()
            for key_node, _ in node.value:
                if key_node.tag == _MERGE_TAG:
                    continue
                key = self.construct_object(key_node, deep=True)
                try:
                    duplicate = key in seen
                    seen.add(key)
                except TypeError:  # unhashable: SafeConstructor reports it
                    continue
                if duplicate:
                    raise _DuplicateKey(_one_line(key), key_node.start_mark.line + 1)
        return super().construct_mapping(node, deep=deep)


def _check_structure(text: str, p: Path) -> None:
    """Walk the YAML events (iteratively: no recursion, no construction) and refuse deep
    nesting, recursive aliases and alias expansion past :data:`MAX_YAML_NODES`."""
    sizes: dict[str, int] = {}  # anchor -> expanded node count of its (closed) node
    stack: list[list[Any]] = [[None, 0]]  # open collections: [anchor, expanded count]
    for event in yaml.parse(text, Loader=_BaseLoader):
        if isinstance(event, yaml.CollectionStartEvent):
            if len(stack) > MAX_YAML_DEPTH:
                line = event.start_mark.line + 1 if event.start_mark else 0
                raise EmaError(f"{p}: nesting deeper than {MAX_YAML_DEPTH} levels at line "
                               f"{line}; a config needs only a few")
            stack.append([event.anchor, 1])
            continue
        if isinstance(event, yaml.CollectionEndEvent):
            anchor, size = stack.pop()
            if anchor is not None:
                sizes[anchor] = size
        elif isinstance(event, yaml.ScalarEvent):
            size = 1
            if event.anchor is not None:
                sizes[event.anchor] = 1
        elif isinstance(event, yaml.AliasEvent):
            line = event.start_mark.line + 1 if event.start_mark else 0
            if event.anchor not in sizes:
                if any(frame[0] == event.anchor for frame in stack):
                    raise EmaError(f"{p}: alias *{event.anchor} at line {line} refers to a "
                                   "node that contains it (a recursive structure)")
                raise EmaError(f"{p}: alias *{event.anchor} at line {line} has no anchor "
                               f"&{event.anchor} before it")
            size = sizes[event.anchor]
        else:
            continue
        stack[-1][1] += size
        if stack[-1][1] > MAX_YAML_NODES or sum(f[1] for f in stack) > MAX_YAML_NODES:
            raise EmaError(f"{p}: expands to more than {MAX_YAML_NODES:,} values (aliases "
                           "counted at their expanded size); refused as an alias bomb")


def _one_line(text: object) -> str:
    return " ".join(str(text).split())


def read_yaml(path: str | Path) -> dict[str, Any]:
    """Parse a YAML mapping from ``path`` (errors name the file and the line).

    Refused with an EmaError: files over :data:`MAX_YAML_BYTES` (before parsing), binary or
    non-UTF-8 files, nesting deeper than :data:`MAX_YAML_DEPTH`, alias expansion past
    :data:`MAX_YAML_NODES` or recursive aliases, a key given twice in one mapping, and a top
    level that is not a mapping.
    """
    p = Path(path)
    if not p.exists():
        raise EmaError(f"config file '{p}' does not exist")
    if not p.is_file():
        raise EmaError(f"config '{p}' is not a file")
    try:
        size = p.stat().st_size
        if size > MAX_YAML_BYTES:
            raise EmaError(f"config file '{p}' is {size:,} bytes; at most {MAX_YAML_BYTES:,} "
                           "bytes (1 MiB) are read")
        with p.open("rb") as fh:
            raw = fh.read(MAX_YAML_BYTES + 1)
    except OSError as exc:
        raise EmaError(f"config file '{p}' cannot be read: {exc.strerror or exc}") from None
    if len(raw) > MAX_YAML_BYTES:
        raise EmaError(f"config file '{p}' is larger than {MAX_YAML_BYTES:,} bytes (1 MiB)")
    if b"\x00" in raw:
        raise EmaError(f"config file '{p}' is binary (it contains NUL bytes); expected YAML text")
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise EmaError(f"config file '{p}' is not UTF-8 text (invalid byte at offset "
                       f"{exc.start}); expected YAML text") from None
    try:
        _check_structure(text, p)
        loader = _Loader(text)
        try:
            data = loader.get_single_data()
        finally:
            loader.dispose()
    except _DuplicateKey as exc:
        raise EmaError(f"{p}: duplicate key '{exc.key}' at line {exc.line}; each key may be "
                       "given once in a mapping") from None
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f" at line {mark.line + 1}, column {mark.column + 1}" if mark else ""
        problem = getattr(exc, "problem", None) or str(exc)
        context = getattr(exc, "context", None)
        if context and context.startswith("expected"):  # e.g. "expected a single document"
            problem = f"{problem} ({context})"
        raise EmaError(f"{p}: YAML syntax error{where}: {_one_line(problem)}") from None
    except RecursionError:  # not expected after the depth check; never a traceback
        raise EmaError(f"{p}: nesting too deep; at most {MAX_YAML_DEPTH} levels") from None
    if data is None:
        return {}
    if not isinstance(data, dict):
        raise EmaError(
            f"{p}: expected a mapping of keys at the top level, got {type(data).__name__}")
    return data


def parse_value(text: str) -> Any:
    """A command-line value -> YAML scalar (``1e-5`` -> float, ``off`` stays 'off', lists)."""
    try:
        value = yaml.safe_load(text)
    except (yaml.YAMLError, ValueError):  # ValueError: an integer of > 4300 digits
        return text
    if isinstance(value, bool):  # YAML reads off/on as booleans; keep the words
        return text
    if isinstance(value, str):
        try:
            return float(value)  # YAML 1.1 misses '1e-5'
        except ValueError:
            return value
    return value


def dotted_pairs(tree: Mapping[str, Any], prefix: str = "") -> list[tuple[str, Any]]:
    """``{"controller": {"position_feedback": "motor"}}`` or ``{"controller.position_feedback":
    "motor"}`` -> ``[("controller.position_feedback", "motor")]`` (for :func:`apply_overrides`)."""
    out: list[tuple[str, Any]] = []
    for k, v in tree.items():
        key = f"{prefix}{k}"
        out += dotted_pairs(v, key + ".") if isinstance(v, Mapping) and v else [(key, v)]
    return out


def apply_overrides(
    data: Mapping[str, Any], overrides: Sequence[tuple[str, Any]], top_keys: Sequence[str]
) -> dict[str, Any]:
    """Set dotted paths in a copy of ``data``: the one ``--set PATH=VALUE`` mechanism of every
    command (and of the Python API's ``overrides``).

    Numbers index lists (``sweep.axes.0.values``); a bare model parameter name means
    ``plant.NAME`` when the config has a ``plant`` section. String values are read as YAML
    scalars or lists (``[0.01, 0.1]``, see :func:`parse_value`); other values are used as given.
    Errors name the path and what was expected.
    """
    import copy

    out = copy.deepcopy(dict(data))
    for path, raw in overrides:
        path = str(path).strip()
        keys = path.split(".")
        if not path or any(not k for k in keys):
            raise EmaError(f"--set {path!r}: expected a dotted key path such as plant.kL")
        if len(keys) == 1 and keys[0] not in top_keys and "plant" in top_keys and keys[0] in INDEX:
            keys = ["plant", keys[0]]
        if keys[0] not in top_keys:
            extra = " or a model parameter name" if "plant" in top_keys else ""
            raise EmaError(f"--set {path}: unknown key '{keys[0]}'; expected one of "
                           f"{sorted(top_keys)}{extra}")
        value = parse_value(raw) if isinstance(raw, str) else raw
        node: Any = out
        for depth, k in enumerate(keys):
            last = depth == len(keys) - 1
            where = ".".join(keys[:depth])
            if isinstance(node, list):
                if not k.isdigit() or int(k) >= len(node):
                    raise EmaError(f"--set {path}: '{where}' is a list of {len(node)} items; "
                                   f"expected an index 0..{len(node) - 1}")
                if last:
                    node[int(k)] = value
                else:
                    node = node[int(k)]
                continue
            if not isinstance(node, dict):
                raise EmaError(f"--set {path}: '{where}' is a value, not a section")
            if last:
                node[k] = value
            else:
                if node.get(k) is None:
                    if keys[depth + 1].isdigit():
                        raise EmaError(f"--set {path}: '{'.'.join(keys[:depth + 1])}' is not "
                                       "in the config, so it has no item to index")
                    node[k] = {}
                node = node[k]
    return out


_UNION_TAG = re.compile(r"^(float|int|str|bool|none|list|dict|tuple|set)$|[\[\]()]")
"""A ``loc`` element pydantic adds for a member of a union (``float``, ``list[...]``,
``function-after[...]``, ``tagged-union[...]``), not a key of the file."""


def _key_path(loc: Sequence[Any]) -> str:
    parts = [str(x) for x in loc
             if not (isinstance(x, str) and _UNION_TAG.search(x))]
    return ".".join(parts) or "(top level)"


def validate(model: type[M], data: Mapping[str, Any], source: str) -> M:
    """Validate ``data`` against ``model``; errors name ``source`` and the key path.

    The message is one line: ``SOURCE: KEY.PATH: what was expected`` for each key in error
    (``; `` between them), the failures of a union's members at one key joined by ``or``.
    """
    try:
        return model.model_validate(data)
    except (ArithmeticError, RecursionError) as exc:  # e.g. 1e308**2 inside a validator
        raise EmaError(f"{source}: a value is out of range ({_one_line(str(exc))}); use "
                       "physically sensible magnitudes") from None
    except ValidationError as exc:
        by_key: dict[str, list[str]] = {}
        for err in exc.errors():
            loc = _key_path(err["loc"])
            msg = err["msg"].removeprefix("Value error, ")
            if msg.startswith(KEY_MARK):  # a dict key named by a validator
                key, msg = msg[1:].split(KEY_MARK, 1)
                loc = f"{loc}.{key}" if loc != "(top level)" else key
            if err["type"] == "extra_forbidden":
                msg = "unknown key"
            msgs = by_key.setdefault(loc, [])
            msg = _one_line(msg)
            if msg not in msgs:
                msgs.append(msg)
        parts = [f"{loc}: {_either(msgs)}" for loc, msgs in by_key.items()]
        raise EmaError(f"{source}: " + "; ".join(parts)) from None


def _either(msgs: list[str]) -> str:
    """The failures of a union's members as one sentence (``a valid number or a valid string``)."""
    head = "Input should be "
    if len(msgs) > 1 and all(m.startswith(head) for m in msgs):
        rest = [m.removeprefix(head) for m in msgs]
        return head + ", ".join(rest[:-1]) + " or " + rest[-1]
    return " or ".join(msgs)


def load_config(
    source: str | Path | Mapping[str, Any] | BaseModel | None,
    overrides: Sequence[tuple[str, Any]] = (),
    model: type[M] = RunConfig,  # type: ignore[assignment]
) -> M:
    """Validate a config with dotted-path overrides (:func:`apply_overrides`).

    ``source`` is a YAML file, a dict (the YAML document), a validated model (re-validated
    with the overrides), or None (every default). Errors name the file (or "dict",
    "defaults") and the key path.
    """
    if source is None:
        data: dict[str, Any] = {}
        where = "defaults"
    elif isinstance(source, BaseModel):
        data = source.model_dump(mode="json", exclude_unset=True)
        where = type(source).__name__
    elif isinstance(source, Mapping):
        data = dict(source)
        where = "dict"
    elif isinstance(source, str | Path):
        data = read_yaml(source)
        where = str(source)
    else:
        raise EmaError(f"config: expected a YAML file path, a dict, a config model or None, got "
                       f"{type(source).__name__}")
    base = Path(source).parent if isinstance(source, str | Path) else None
    data = inline_actuator(data, base, where)
    try:
        data = apply_overrides(data, overrides, list(model.model_fields))
    except RecursionError:
        raise EmaError(f"{where}: the config refers to itself or is nested too deeply") from None
    return validate(model, data, where)


def inline_actuator(data: dict[str, Any], base: Path | None, where: str) -> dict[str, Any]:
    """``actuator: FILE.yaml`` -> the description that file holds (its top level, or its
    ``actuator`` section), read relative to the config's folder; a missing or bad file is one
    line naming both files."""
    ref = data.get("actuator") if isinstance(data, dict) else None
    if not isinstance(ref, str):
        return data
    p = _local(ref, base)
    if not p.is_file():
        raise EmaError(f"{where}: actuator: the actuator file '{ref}' does not exist (looked "
                       f"for '{p}')")
    desc = read_yaml(p)
    if isinstance(desc, dict) and set(desc) == {"actuator"}:
        desc = desc["actuator"]
    if not isinstance(desc, dict):
        raise EmaError(f"{where}: actuator: '{p}' holds no actuator description (a mapping)")
    return {**data, "actuator": desc}


@dataclass(frozen=True)
class ResolvedRun:
    """A config resolved to what the simulator takes: SI parameters, signal and grid."""

    params: dict[str, float]
    signal: InputSignal
    duration: float
    dt: float
    output_interval: float


def resolve_params(
    plant: Mapping[str, Any], nonlinearities: Mapping[str, Any], friction_reading: str = "sigma2"
) -> dict[str, float]:
    """Plant overrides (SI) + nonlinearities (edge units) -> complete SI parameters.

    Derived parameters (c, Fs, sigma0, sigma1) are re-derived after the nonlinearities are
    applied, so a stiffness change keeps the damping ratio, unless the user set them.
    """
    raw: dict[str, Any] = dict(plant)
    try:
        base = resolve(raw)
        raw.update(combined_updates(nonlinearities, base, friction_reading))
        return resolve(raw)
    except ArithmeticError as exc:  # derived values overflow (e.g. m = 1e308: m**2)
        raise EmaError(f"the parameters are out of range ({_one_line(str(exc))}); use "
                       "physically sensible magnitudes in plant and nonlinearities") from None


def inert_input_warnings(signal: InputSignal, duration: float) -> list[str]:
    """Warnings for inputs that do nothing within a run of ``duration`` [s]: a reference that
    starts at or after the end, a profile (reference or load torque) whose first row is at or
    after the end."""
    out = []
    if signal.kind != "csv" and signal.start >= duration:
        out.append(f"input.start_s = {signal.start:g} s is not before the end of the run "
                   f"(simulation.duration_s = {duration:g} s): the reference never moves")
    for table, path, key in ((signal.table, signal.path, "input.path"),
                             (signal.load_table, signal.load_path, "load.profile")):
        if table is not None and len(table[0]) and table[0][0] >= duration:
            out.append(f"{key}: the profile '{path}' starts at {table[0][0]:g} s, at or after "
                       f"the end of the run (simulation.duration_s = {duration:g} s): it is "
                       "never applied")
    return out


def check_input_start(signal: InputSignal, duration: float) -> None:
    """Refuse a run whose input does nothing (:func:`inert_input_warnings`: a reference or a
    profile that starts at or after the end): its result would answer nothing."""
    warnings = inert_input_warnings(signal, duration)
    if warnings:
        raise EmaError(f"{warnings[0]}; start it earlier or lengthen simulation.duration_s")


def resolve_run(cfg: RunConfig, base_dir: Path | None = None) -> ResolvedRun:
    """A validated RunConfig -> ResolvedRun (SI)."""
    params = resolve_params(cfg.plant_overrides(), cfg.nonlinearities, cfg.friction_reading)
    sim = cfg.simulation
    return ResolvedRun(params, input_signal(cfg.input, base_dir, cfg.load, cfg.axis),
                       sim.duration_s,
                       sim.dt_s,
                       sim.output_interval_s)
