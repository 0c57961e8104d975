"""Configuration: strict YAML loading into dataclasses (the one place for config loading).

A config file is YAML with one section per pipeline stage. Unknown keys, wrong
types and out-of-range values are rejected with one line naming the key and the
file. A file may start from another with ``extends: NAME`` (a file beside the
config or below its folder, or the name of an embedded config such as
``paper.yaml``); its keys are merged over the base section by section.

Every config is bounded before use (issue 14): the file size, the YAML's node count
(alias bombs) and nesting depth, the ``extends`` chain, list lengths (``max_items``,
``len``), every number finite and within its field's range (or within
``DEFAULT_BOUND`` where the field gives none), and what the sizes will allocate
(:func:`check_sizes`). An error quotes at most a short prefix of a value.

Each stage owns the dataclass of its section (``fuzzyslam/*/params.py``); a
field's ``metadata`` may give ``min``, ``max`` (inclusive) and ``choices``.
"""

from __future__ import annotations

import dataclasses
import difflib
import math
import os
import re
import stat
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
from fuzzyslam.streams.distro import OutputParams
from fuzzyslam.streams.ranges import RangeParams
from fuzzyslam.streams.topics import Topics

DEFAULT_CONFIG = "paper.yaml"

MAX_CONFIG_BYTES = 1 << 20  # a config file larger than 1 MiB is refused unread
MAX_EVENTS = 100_000  # YAML parser events (scalars, starts and ends of lists and mappings)
MAX_NODES = 200_000  # YAML nodes after aliases are expanded (a billion laughs is 1e9)
MAX_DEPTH = 32  # nesting of mappings and lists
MAX_EXTENDS = 16  # length of an ``extends`` chain
MAX_ITEMS = 10_000  # entries of a list, unless its field says otherwise (``max_items``)
DEFAULT_BOUND = 1e9  # |number| where a field gives no min or max
MAX_CAMERA_SAMPLES = 4096 * 4096  # width x height x supersample^2 rendered per frame
MAX_DRIVE_SECONDS = 36_000.0  # robot time the simulator drives (sim.path.drive)

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
    output: OutputParams = field(default_factory=OutputParams)


def embedded_names() -> list[str]:
    """Names of the configs shipped inside the package."""
    root = resources.files("fuzzyslam.configs")
    return sorted(p.name for p in root.iterdir() if p.name.endswith(".yaml"))


def short(value: Any, limit: int = 40) -> str:
    """``repr(value)`` cut to ``limit`` characters (an error quotes no more of a value);
    containers are not walked past the limit (a shared alias bomb prints instantly)."""
    if isinstance(value, (dict, list, tuple)):
        kind = type(value).__name__
        return f"a {kind} of {len(value)} item{'s' if len(value) != 1 else ''}"
    text = repr(value[: limit + 1] if isinstance(value, str) else value)
    return text if len(text) <= limit else text[: limit - 3] + "..."


def clip(text: str, limit: int) -> str:
    """``text`` cut to ``limit`` characters."""
    return text if len(text) <= limit else text[: limit - 3] + "..."


def _check_events(text: str, source: str, loader: Any) -> None:
    """Scan the YAML's parser events (no objects built) and stop at the first limit:
    too many events, or nesting deeper than MAX_DEPTH."""
    depth = 0
    for n, event in enumerate(yaml.parse(text, Loader=loader)):
        if n > MAX_EVENTS:
            raise ConfigError(source, f"too many YAML values (over {MAX_EVENTS}); refusing")
        if isinstance(event, (yaml.MappingStartEvent, yaml.SequenceStartEvent)):
            depth += 1
            if depth > MAX_DEPTH:
                raise ConfigError(source, f"YAML nested deeper than {MAX_DEPTH} levels; refusing")
        elif isinstance(event, (yaml.MappingEndEvent, yaml.SequenceEndEvent)):
            depth -= 1


def _check_shape(data: Any, source: str) -> None:
    """Refuse YAML whose node count (aliases expanded) or nesting depth is too large,
    walking iteratively and stopping at the first limit reached."""
    stack: list[tuple[Any, int]] = [(data, 0)]
    nodes = 0
    while stack:
        node, depth = stack.pop()
        nodes += 1
        if nodes > MAX_NODES:
            raise ConfigError(
                source, f"too many YAML values (over {MAX_NODES}, aliases expanded); refusing"
            )
        if depth > MAX_DEPTH:
            raise ConfigError(source, f"YAML nested deeper than {MAX_DEPTH} levels; refusing")
        if isinstance(node, dict):
            stack.extend((v, depth + 1) for v in node.values())
            nodes += len(node)  # the keys
        elif isinstance(node, list):
            stack.extend((v, depth + 1) for v in node)


_SafeLoader: Any = getattr(yaml, "CSafeLoader", yaml.SafeLoader)  # libyaml where available
_MERGE_TAG = "tag:yaml.org,2002:merge"


class StrictLoader(_SafeLoader):
    """A safe YAML loader that refuses a key given twice in one mapping (plain YAML
    keeps the last one silently): a ConfigError naming the config, the dotted key and
    its lines. A ``<<`` merge key may still be overridden by the mapping's own keys.

    Parameters
    ----------
    stream : str
        The YAML text.
    source : str
        The config's label in errors (its path as the user gave it).
    """

    def __init__(self, stream: str, source: str = "<config>") -> None:
        super().__init__(stream)
        self.source = source

    def construct_document(self, node: Any) -> Any:
        """Check every mapping of the document for repeated keys, then build it.

        Parameters
        ----------
        node : yaml.Node
            The document's root node.

        Returns
        -------
        object
            The document's data, as the safe loader builds it.
        """
        self._check_repeated_keys(node)
        return super().construct_document(node)

    def _check_repeated_keys(self, root: Any) -> None:
        """Walk the node graph iteratively, each node once (an alias is not walked
        again, so an alias bomb costs its size, not its expansion), and raise at the
        first mapping that holds a key twice."""
        walked: set[int] = set()
        stack: list[tuple[Any, str]] = [(root, "")]
        while stack:
            node, path = stack.pop()
            if id(node) in walked:
                continue
            walked.add(id(node))
            if isinstance(node, yaml.SequenceNode):
                stack.extend((v, f"{path}[{i}]") for i, v in reversed(list(enumerate(node.value))))
            elif isinstance(node, yaml.MappingNode):
                first: dict[Any, int] = {}
                children = []
                for key_node, value_node in node.value:
                    child = f"{path}.?" if path else "?"
                    if isinstance(key_node, yaml.ScalarNode) and key_node.tag != _MERGE_TAG:
                        key = self.construct_object(key_node)
                        child = f"{path}.{key}" if path else str(key)
                        line = key_node.start_mark.line + 1
                        try:
                            seen = first.get(key)
                            first.setdefault(key, line)
                        except TypeError:  # unhashable: the constructor refuses it next
                            seen = None
                        if seen is not None:
                            raise ConfigError(
                                self.source,
                                f"repeated key {short(child, 80)} at line {line} (first at "
                                f"line {seen}); give each key once",
                            )
                    children.append((value_node, child))
                stack.extend(reversed(children))


# YAML 1.2 floats that YAML 1.1 (PyYAML's resolver) reads as strings: an exponent without
# a dot or without a sign (1e-3, 2.5e3, 1E6); what the floats of every config look like
_EXPONENT_FLOAT = re.compile(r"^[-+]?(?:[0-9][0-9_]*(?:\.[0-9_]*)?|\.[0-9_]+)[eE][-+]?[0-9]+$")
StrictLoader.add_implicit_resolver(
    "tag:yaml.org,2002:float", _EXPONENT_FLOAT, list("-+.0123456789")
)


def yaml_value(text: str, source: str = "<value>") -> Any:
    """One value of a command line (``--set KEY=VALUE``) read as YAML by the configs'
    loader (:class:`StrictLoader`: ``1e-3`` is a number, as in a config file).

    Parameters
    ----------
    text : str
        The value's text.
    source : str
        What an error names (the option).

    Returns
    -------
    object
    """
    loader = StrictLoader(text, source)
    try:
        return loader.get_single_data()
    finally:
        loader.dispose()


def _read_yaml(text: str, source: str) -> dict[str, Any]:
    if len(text) > MAX_CONFIG_BYTES:
        raise ConfigError(source, f"config larger than {MAX_CONFIG_BYTES} bytes; refusing")
    try:
        _check_events(text, source, _SafeLoader)
        loader = StrictLoader(text, source)  # a safe loader
        try:
            data = loader.get_single_data()
        finally:
            loader.dispose()
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f" at line {mark.line + 1}" if mark is not None else ""
        problem = getattr(exc, "problem", None) or "syntax error"
        raise ConfigError(source, f"malformed YAML{where}: {clip(problem, 80)}") from None
    except RecursionError:
        raise ConfigError(source, f"YAML nested deeper than {MAX_DEPTH} levels; refusing") from None
    _check_shape(data, source)
    if data is None:
        data = {}
    if not isinstance(data, dict):
        raise ConfigError(source, "a config must be a YAML mapping of sections")
    return data


def _read_text(path: Path) -> str:
    """The text of a config file, refusing non-files and files over the size limit
    before reading them (a FIFO or /dev/zero never blocks or fills memory: opened
    without blocking, O_NONBLOCK, a FIFO with no writer included, and its type checked
    before any read)."""
    try:
        fd = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0))
        with open(fd, "rb") as f:
            if not stat.S_ISREG(os.fstat(f.fileno()).st_mode):
                raise ConfigError(path, "config path is not a regular file")
            data = f.read(MAX_CONFIG_BYTES + 1)
    except OSError as exc:
        raise ConfigError(path, f"cannot read config: {exc.strerror}") from None
    if len(data) > MAX_CONFIG_BYTES:
        raise ConfigError(path, f"config larger than {MAX_CONFIG_BYTES} bytes; refusing")
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError:
        raise ConfigError(path, "cannot read config: not UTF-8 text") from None


def _locate(name: str, relative_to: Path | None, owner: str = "") -> tuple[str, str]:
    """Return (text, source label) of a config given by path or embedded name.

    ``relative_to`` is the folder of the config that names it in ``extends``: then only
    an embedded name or a file in that folder or below it is accepted (no absolute
    path, no ``..`` out of it, no symlink pointing elsewhere); an embedded config
    (``relative_to`` None after an embedded one, see ``config_layers``) extends embedded
    names only."""
    embedded = name if name.endswith(".yaml") else f"{name}.yaml"
    p = Path(name)
    if relative_to is not None:
        c = relative_to / p
        if p.is_absolute() or not _is_below(c, relative_to):
            if embedded in embedded_names() and "/" not in name:
                return _embedded_text(embedded)
            raise ConfigError(
                owner or name,
                f"'extends: {clip(name, 80)}' must name an embedded config or a file beside "
                "this config or below its folder; refusing",
            )
        if c.is_file() or (c.exists() and not c.is_dir()):
            return _read_text(c), str(c)
    elif p.exists() and not p.is_dir():
        return _read_text(p), str(p)
    if embedded in embedded_names():
        return _embedded_text(embedded)
    # named by an ``extends``: the error names the config holding it, and the key
    label, what = clip(name, 200), ""
    if relative_to is not None:
        label, what, p = owner or label, f"extends {short(name, 80)}: ", relative_to / p
    if p.exists():
        raise ConfigError(label if what else p, f"{what}config path is not a file")
    raise ConfigError(
        label,
        f"{what}config not found (not a file, nor one of the embedded: "
        f"{', '.join(embedded_names())})",
    )


def _is_below(path: Path, folder: Path) -> bool:
    try:
        return path.resolve().is_relative_to(folder.resolve())
    except (OSError, RuntimeError):
        return False


def _embedded_text(embedded: str) -> tuple[str, str]:
    text = resources.files("fuzzyslam.configs").joinpath(embedded).read_text(encoding="utf-8")
    return text, f"<embedded {embedded}>"


def _merge(base: dict[str, Any], over: dict[str, Any]) -> dict[str, Any]:
    out = dict(base)
    for k, v in over.items():
        if isinstance(v, dict) and isinstance(out.get(k), dict):
            out[k] = _merge(out[k], v)
        else:
            out[k] = v
    return out


def config_layers(name: str) -> tuple[dict[str, Any], list[str]]:
    """The merged raw mapping of config ``name`` and its ``extends`` chain (followed
    iteratively, at most MAX_EXTENDS long, cycles refused), unchecked, and the chain.

    Parameters
    ----------
    name : str
        A config file's path or an embedded config's name.

    Returns
    -------
    dict
        The keys of every file of the chain, each file's over those of the one it
        extends (``extends`` removed).
    list of str
        The source labels of the chain: ``name``'s own first (its path as given), then
        each file it extends (``<embedded NAME.yaml>`` for an embedded config).
    """
    layers: list[dict] = []
    chain: list[str] = []
    relative_to: Path | None = None
    embedded_only = False
    while True:
        if embedded_only:
            embedded = name if name.endswith(".yaml") else f"{name}.yaml"
            if embedded not in embedded_names():
                raise ConfigError(
                    chain[-1], f"'extends' of an embedded config: unknown {short(name)}"
                )
            text, source = _embedded_text(embedded)
        else:
            text, source = _locate(name, relative_to, chain[-1] if chain else "")
        if source in chain:
            raise ConfigError(source, "'extends' forms a cycle")
        if len(chain) >= MAX_EXTENDS:
            raise ConfigError(chain[0], f"'extends' chain longer than {MAX_EXTENDS}; refusing")
        chain.append(source)
        data = _read_yaml(text, source)
        parent = data.pop("extends", None)
        layers.append(data)
        if parent is None:
            break
        if not isinstance(parent, str):
            raise ConfigError(source, "'extends' must be a config name or path")
        name = parent
        embedded_only = source.startswith("<")
        relative_to = None if embedded_only else Path(source).parent
    merged: dict = {}
    for data in reversed(layers):
        merged = _merge(merged, data)
    return merged, chain


def config_from_raw(data: dict[str, Any], source: str, seed: int | None = None) -> Config:
    """The checked Config of a raw mapping (:func:`config_layers`, possibly with keys
    merged over it): unknown keys, types, ranges and sizes refused (``data`` is not
    changed).

    Parameters
    ----------
    data : dict
        The raw mapping of sections.
    source : str
        What an error names: the config file, or what set the keys (``--set K=V``).
    seed : int or None
        Overrides the mapping's seed when given.

    Returns
    -------
    Config
    """
    cfg = from_dict(Config, data, source)
    if seed is not None:
        if seed < 0:
            raise ConfigError(source, f"seed must be >= 0, got {seed}")
        cfg.seed = seed
    check_sizes(cfg, source)
    return cfg


def load_config(path: str | Path | None = None, seed: int | None = None) -> Config:
    """Load a config by path or embedded name (default: the paper scenario).

    ``seed`` overrides the file's seed when given (the CLI's ``--seed``).
    """
    data, chain = config_layers(str(path) if path is not None else DEFAULT_CONFIG)
    return config_from_raw(data, chain[0], seed)


def check_sizes(cfg: Config, source: str) -> None:
    """Refuse configs whose sizes, within each field's range, would allocate or run
    too much together: camera samples per frame, the simulated drive's length."""
    cam = cfg.camera
    samples = cam.width * cam.height * cam.supersample**2
    if samples > MAX_CAMERA_SAMPLES:
        raise ConfigError(
            source,
            f"'camera' width x height x supersample^2 = {samples} samples per frame, over "
            f"{MAX_CAMERA_SAMPLES}; lower the size or the supersampling",
        )
    import numpy as np

    pts = np.asarray(cfg.world.centerline, dtype=float).reshape(-1, 2)
    loop = float(np.sum(np.hypot(*np.diff(np.vstack([pts, pts[:1]]), axis=0).T)))
    speed = min(cfg.robot.cruise_speed, cfg.robot.max_speed)
    drive = cfg.scenario.runs * loop * cfg.scenario.lap_fraction / speed
    if drive > MAX_DRIVE_SECONDS:
        raise ConfigError(
            source,
            f"the scenario drives about {drive:.3g} s (runs x lap x lap_fraction / "
            f"cruise_speed), over {MAX_DRIVE_SECONDS:g} s",
        )


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
            close = difflib.get_close_matches(str(key)[:100], list(fields), n=1)
            hint = f" (did you mean '{where}{close[0]}'?)" if close else ""
            raise ConfigError(source, f"unknown key {short(f'{where}{key}', 60)}{hint}")
        f = fields[key]
        kwargs[key] = _convert(hints[key], value, source, f"{where}{key}", f.metadata)
    try:
        return cls(**kwargs)
    except (TypeError, ValueError) as exc:
        what = where.rstrip(".") or "<top>"
        raise ConfigError(source, f"'{what}': {clip(str(exc), 200)}") from None


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
        meta = dict(meta or {})
        want, most = meta.pop("len", None), meta.pop("max_items", MAX_ITEMS)
        if want is not None and len(value) != want:
            raise ConfigError(source, f"'{key}' must have {want} items, got {len(value)}")
        if len(value) > most:
            raise ConfigError(source, f"'{key}' has {len(value)} items, more than {most}")
        if "item_len" in meta:
            meta["len"] = meta.pop("item_len")
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
            raise ConfigError(source, f"'{key}' must be true or false, got {short(value)}")
        return value
    if tp is int:
        if isinstance(value, bool) or not isinstance(value, int):
            if isinstance(value, float) and value.is_integer():
                value = int(value)
            else:
                raise ConfigError(source, f"'{key}' must be an integer, got {short(value)}")
        _check_range(value, source, key, meta)
        return value
    if tp is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ConfigError(source, f"'{key}' must be a number, got {short(value)}")
        try:
            value = float(value)
        except OverflowError:
            raise ConfigError(source, f"'{key}' is too large: {short(value)}") from None
        if not math.isfinite(value):
            raise ConfigError(source, f"'{key}' must be a finite number, got {value}")
        _check_range(value, source, key, meta)
        return value
    if tp is str:
        if not isinstance(value, str):
            raise ConfigError(source, f"'{key}' must be a string, got {short(value)}")
        choices = meta.get("choices") if meta else None
        if choices and value not in choices:
            raise ConfigError(
                source, f"'{key}' must be one of {', '.join(choices)}, got {short(value)}"
            )
        return value
    raise ConfigError(source, f"'{key}': unsupported type {_type_name(tp)}")


def _check_range(value: float, source: str, key: str, meta: Any) -> None:
    meta = meta or {}
    lo, hi = meta.get("min", -DEFAULT_BOUND), meta.get("max", DEFAULT_BOUND)
    if lo is not None and value < lo:
        raise ConfigError(source, f"'{key}' must be >= {lo}, got {value}")
    if hi is not None and value > hi:
        raise ConfigError(source, f"'{key}' must be <= {hi}, got {value}")
