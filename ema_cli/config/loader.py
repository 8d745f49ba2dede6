"""Read a YAML config, apply ``--set PATH=VALUE`` overrides, validate, and resolve it to SI.

Every failure becomes an :class:`EmaError` naming the file, the key path and what was expected.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TypeVar

import yaml
from pydantic import BaseModel, ValidationError

from ema_cli.config.schema import KEY_MARK, RunConfig
from ema_cli.errors import EmaError
from ema_cli.model.nonlinearities import nonlinearity_updates
from ema_cli.model.params import INDEX, resolve
from ema_cli.sim.signals import InputSignal, load_profile
from ema_cli.units import DEG

M = TypeVar("M", bound=BaseModel)


def read_yaml(path: str | Path) -> dict[str, Any]:
    """Parse a YAML mapping from ``path`` (errors name the file and the line)."""
    p = Path(path)
    if not p.exists():
        raise EmaError(f"config file '{p}' does not exist")
    if not p.is_file():
        raise EmaError(f"config '{p}' is not a file")
    try:
        data = yaml.safe_load(p.read_text(encoding="utf-8"))
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f" at line {mark.line + 1}, column {mark.column + 1}" if mark else ""
        problem = getattr(exc, "problem", None) or str(exc)
        raise EmaError(f"{p}: YAML syntax error{where}: {problem}") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise EmaError(f"config file '{p}' cannot be read: {exc}") from None
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
    except yaml.YAMLError:
        return text
    if isinstance(value, bool):  # YAML reads off/on as booleans; keep the words
        return text
    if isinstance(value, str):
        try:
            return float(value)  # YAML 1.1 misses '1e-5'
        except ValueError:
            return value
    return value


def apply_overrides(
    data: dict[str, Any], overrides: Sequence[tuple[str, Any]], top_keys: Sequence[str]
) -> dict[str, Any]:
    """Set dotted paths in a copy of ``data``; a bare model parameter name means ``plant.NAME``."""
    import copy

    out = copy.deepcopy(data)
    for path, value in overrides:
        keys = path.split(".")
        if len(keys) == 1 and keys[0] not in top_keys and keys[0] in INDEX:
            keys = ["plant", keys[0]]
        if keys[0] not in top_keys:
            raise EmaError(
                f"--set {path}: unknown key '{keys[0]}'; expected one of {sorted(top_keys)} "
                f"or a model parameter name")
        node = out
        for k in keys[:-1]:
            nxt = node.get(k)
            if nxt is None:
                nxt = node[k] = {}
            if not isinstance(nxt, dict):
                raise EmaError(f"--set {path}: '{k}' is not a section")
            node = nxt
        node[keys[-1]] = parse_value(value) if isinstance(value, str) else value
    return out


def validate(model: type[M], data: Mapping[str, Any], source: str) -> M:
    """Validate ``data`` against ``model``; errors name ``source`` and the key path."""
    try:
        return model.model_validate(data)
    except ValidationError as exc:
        lines = []
        for err in exc.errors():
            loc = ".".join(str(x) for x in err["loc"]) or "(top level)"
            msg = err["msg"].removeprefix("Value error, ")
            if msg.startswith(KEY_MARK):  # a dict key named by a validator
                key, msg = msg[1:].split(KEY_MARK, 1)
                loc = f"{loc}.{key}"
            if err["type"] == "extra_forbidden":
                msg = "unknown key"
            lines.append(f"{source}: {loc}: {msg}")
        raise EmaError("\n".join(lines)) from None


def load_config(
    path: str | Path | None,
    overrides: Sequence[tuple[str, Any]] = (),
    model: type[M] = RunConfig,  # type: ignore[assignment]
) -> M:
    """Load and validate a config file (None: the defaults) with dotted-path overrides."""
    data = read_yaml(path) if path is not None else {}
    data = apply_overrides(data, overrides, list(model.model_fields))
    return validate(model, data, str(path) if path is not None else "defaults")


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
    base = resolve(raw)
    for name, value in nonlinearities.items():
        raw.update(nonlinearity_updates(name, value, base, friction_reading))
    return resolve(raw)


def _local(path: str, base_dir: Path | None) -> Path:
    """A path from a config: as given, else relative to the config's folder."""
    p = Path(path)
    if not p.is_absolute() and base_dir is not None and not p.exists():
        p = base_dir / p
    return p


def input_signal(cfg_input: Any, base_dir: Path | None = None,
                 cfg_load: Any = None) -> InputSignal:
    """InputConfig (degrees) [+ LoadConfig] -> InputSignal (SI); CSV profiles (the reference's
    and the load torque's) are read and validated here."""
    table = None
    path = cfg_input.path
    if cfg_input.kind == "csv":
        p = _local(path, base_dir)
        t, th = load_profile(p)
        table = (tuple(t), tuple(th))
        path = str(p)
    load_table = load_path = None
    if cfg_load is not None and cfg_load.profile:
        p = _local(cfg_load.profile, base_dir)
        t, tq = load_profile(p, value="torque_nm", scale=1.0)
        load_table = (tuple(t), tuple(tq))
        load_path = str(p)
    return InputSignal(
        kind=cfg_input.kind,
        amplitude=cfg_input.amplitude_deg * DEG,
        start=cfg_input.start_s,
        rate=cfg_input.rate_deg_s * DEG,
        freq=cfg_input.freq_hz,
        freq_end=cfg_input.freq_end_hz,
        sweep_time=cfg_input.sweep_time_s,
        offset=cfg_input.offset_deg * DEG,
        path=path,
        table=table,
        load_table=load_table,
        load_path=load_path,
    )


def resolve_run(cfg: RunConfig, base_dir: Path | None = None) -> ResolvedRun:
    """A validated RunConfig -> ResolvedRun (SI)."""
    params = resolve_params(cfg.plant_overrides(), cfg.nonlinearities, cfg.friction_reading)
    sim = cfg.simulation
    return ResolvedRun(params, input_signal(cfg.input, base_dir, cfg.load), sim.duration_s,
                       sim.dt_s,
                       sim.output_interval_s)
