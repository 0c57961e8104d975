"""Configuration: strict YAML loading into dataclasses (the one place for config loading).

A config file is YAML with one section per pipeline stage. Unknown keys, wrong
types and out-of-range values are rejected with one line naming the key and the
file. A file may start from another with ``extends: NAME`` (a path relative to
the file, or the name of an embedded config such as ``paper.yaml``); its keys
are merged over the base section by section.

Each stage owns the dataclass of its section (``fuzzyslam/*/params.py``); a
field's ``metadata`` may give ``min``, ``max`` (inclusive) and ``choices``.
"""

from __future__ import annotations

import dataclasses
import difflib
import types
import typing
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any, TypeVar, Union

import yaml

from fuzzyslam.errors import ConfigError
from fuzzyslam.evaluation.params import EvalParams
from fuzzyslam.fixes.params import FixParams
from fuzzyslam.maps.params import MapParams
from fuzzyslam.sim.params import (
    CameraParams,
    RobotParams,
    ScenarioParams,
    SonarParams,
    WorldParams,
)
from fuzzyslam.slam.params import SlamParams
from fuzzyslam.streams.ranges import RangeParams
from fuzzyslam.streams.topics import Topics

DEFAULT_CONFIG = "paper.yaml"

T = TypeVar("T")


@dataclass
class Config:
    """The whole configuration: scenario, sensors and every stage's parameters."""

    name: str = "paper"
    seed: int = field(default=0, metadata={"min": 0})
    topics: Topics = field(default_factory=Topics)
    world: WorldParams = field(default_factory=WorldParams)
    robot: RobotParams = field(default_factory=RobotParams)
    sonar: SonarParams = field(default_factory=SonarParams)
    ranges: RangeParams = field(default_factory=RangeParams)
    camera: CameraParams = field(default_factory=CameraParams)
    scenario: ScenarioParams = field(default_factory=ScenarioParams)
    slam: SlamParams = field(default_factory=SlamParams)
    fgm: MapParams = field(default_factory=MapParams)
    fixes: FixParams = field(default_factory=FixParams)
    evaluation: EvalParams = field(default_factory=EvalParams)


def embedded_names() -> list[str]:
    """Names of the configs shipped inside the package."""
    root = resources.files("fuzzyslam.configs")
    return sorted(p.name for p in root.iterdir() if p.name.endswith(".yaml"))


def _read_yaml(text: str, source: str) -> dict[str, Any]:
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f" at line {mark.line + 1}" if mark is not None else ""
        problem = getattr(exc, "problem", None) or "syntax error"
        raise ConfigError(source, f"malformed YAML{where}: {problem}") from None
    if data is None:
        data = {}
    if not isinstance(data, dict):
        raise ConfigError(source, "a config must be a YAML mapping of sections")
    return data


def _locate(name: str, relative_to: Path | None) -> tuple[str, str]:
    """Return (text, source label) of a config given by path or embedded name."""
    candidates = []
    p = Path(name)
    if relative_to is not None and not p.is_absolute():
        candidates.append(relative_to / p)
    candidates.append(p)
    for c in candidates:
        if c.is_file():
            try:
                return c.read_text(encoding="utf-8"), str(c)
            except (OSError, UnicodeDecodeError) as exc:
                raise ConfigError(c, f"cannot read config: {exc}") from None
    embedded = name if name.endswith(".yaml") else f"{name}.yaml"
    if embedded in embedded_names():
        text = resources.files("fuzzyslam.configs").joinpath(embedded).read_text(encoding="utf-8")
        return text, f"<embedded {embedded}>"
    if p.exists():
        raise ConfigError(p, "config path is not a file")
    raise ConfigError(
        name,
        f"config not found (not a file, nor one of the embedded: {', '.join(embedded_names())})",
    )


def _merge(base: dict[str, Any], over: dict[str, Any]) -> dict[str, Any]:
    out = dict(base)
    for k, v in over.items():
        if isinstance(v, dict) and isinstance(out.get(k), dict):
            out[k] = _merge(out[k], v)
        else:
            out[k] = v
    return out


def _load_raw(name: str, relative_to: Path | None, chain: tuple[str, ...]) -> tuple[dict, str]:
    text, source = _locate(name, relative_to)
    if source in chain:
        raise ConfigError(source, "'extends' forms a cycle")
    data = _read_yaml(text, source)
    parent = data.pop("extends", None)
    if parent is not None:
        if not isinstance(parent, str):
            raise ConfigError(source, "'extends' must be a config name or path")
        here = Path(source).parent if not source.startswith("<") else None
        base, _ = _load_raw(parent, here, (*chain, source))
        data = _merge(base, data)
    return data, source


def load_config(path: str | Path | None = None, seed: int | None = None) -> Config:
    """Load a config by path or embedded name (default: the paper scenario).

    ``seed`` overrides the file's seed when given (the CLI's ``--seed``).
    """
    data, source = _load_raw(str(path) if path is not None else DEFAULT_CONFIG, None, ())
    cfg = from_dict(Config, data, source)
    if seed is not None:
        if seed < 0:
            raise ConfigError(source, f"seed must be >= 0, got {seed}")
        cfg.seed = seed
    return cfg


def config_to_dict(cfg: Any) -> dict[str, Any]:
    """Plain-data form of a config dataclass (for YAML/JSON dumps and MCAP metadata)."""
    return dataclasses.asdict(cfg)


def dump_config(cfg: Any) -> str:
    """YAML text of a config, loadable again by load_config."""
    return yaml.safe_dump(config_to_dict(cfg), sort_keys=False)


# --- strict conversion -------------------------------------------------------------


def from_dict(cls: type[T], data: Any, source: str, where: str = "") -> T:
    """Build dataclass ``cls`` from ``data``, rejecting unknown keys and bad values."""
    if not isinstance(data, dict):
        raise ConfigError(source, f"'{where.rstrip('.') or '<top>'}' must be a mapping")
    hints = typing.get_type_hints(cls)
    fields = {f.name: f for f in dataclasses.fields(cls)}
    kwargs: dict[str, Any] = {}
    for key, value in data.items():
        if key not in fields:
            close = difflib.get_close_matches(str(key), list(fields), n=1)
            hint = f" (did you mean '{where}{close[0]}'?)" if close else ""
            raise ConfigError(source, f"unknown key '{where}{key}'{hint}")
        f = fields[key]
        kwargs[key] = _convert(hints[key], value, source, f"{where}{key}", f.metadata)
    try:
        return cls(**kwargs)
    except (TypeError, ValueError) as exc:
        raise ConfigError(source, f"'{where.rstrip('.') or '<top>'}': {exc}") from None


def _type_name(tp: Any) -> str:
    return getattr(tp, "__name__", str(tp))


def _convert(tp: Any, value: Any, source: str, key: str, meta: Any) -> Any:
    origin = typing.get_origin(tp)
    args = typing.get_args(tp)
    if origin in (Union, types.UnionType):
        if value is None and type(None) in args:
            return None
        rest = [a for a in args if a is not type(None)]
        return _convert(rest[0], value, source, key, meta)
    if dataclasses.is_dataclass(tp):
        return from_dict(tp, value, source, f"{key}.")
    if origin in (list, tuple):
        if not isinstance(value, (list, tuple)):
            raise ConfigError(source, f"'{key}' must be a list, got {type(value).__name__}")
        if origin is tuple and args and args[-1] is not Ellipsis:
            if len(value) != len(args):
                raise ConfigError(source, f"'{key}' must have {len(args)} items, got {len(value)}")
            items = [
                _convert(a, v, source, f"{key}[{i}]", meta)
                for i, (a, v) in enumerate(zip(args, value, strict=False))
            ]
            return tuple(items)
        inner = args[0] if args else Any
        items = [_convert(inner, v, source, f"{key}[{i}]", meta) for i, v in enumerate(value)]
        return tuple(items) if origin is tuple else items
    if origin is dict:
        if not isinstance(value, dict):
            raise ConfigError(source, f"'{key}' must be a mapping")
        return dict(value)
    if tp is Any:
        return value
    if tp is bool:
        if not isinstance(value, bool):
            raise ConfigError(source, f"'{key}' must be true or false, got {value!r}")
        return value
    if tp is int:
        if isinstance(value, bool) or not isinstance(value, int):
            if isinstance(value, float) and value.is_integer():
                value = int(value)
            else:
                raise ConfigError(source, f"'{key}' must be an integer, got {value!r}")
        _check_range(value, source, key, meta)
        return value
    if tp is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ConfigError(source, f"'{key}' must be a number, got {value!r}")
        value = float(value)
        if value != value:
            raise ConfigError(source, f"'{key}' must not be NaN")
        _check_range(value, source, key, meta)
        return value
    if tp is str:
        if not isinstance(value, str):
            raise ConfigError(source, f"'{key}' must be a string, got {value!r}")
        choices = meta.get("choices") if meta else None
        if choices and value not in choices:
            raise ConfigError(source, f"'{key}' must be one of {', '.join(choices)}, got {value!r}")
        return value
    raise ConfigError(source, f"'{key}': unsupported type {_type_name(tp)}")


def _check_range(value: float, source: str, key: str, meta: Any) -> None:
    if not meta:
        return
    lo, hi = meta.get("min"), meta.get("max")
    if lo is not None and value < lo:
        raise ConfigError(source, f"'{key}' must be >= {lo}, got {value}")
    if hi is not None and value > hi:
        raise ConfigError(source, f"'{key}' must be <= {hi}, got {value}")
