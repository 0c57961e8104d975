"""Config keys set on the command line (``--set KEY=VALUE``): ``sweep`` and ``reproduce``.

A set of keys becomes a config file that ``extends`` the base config (a path or an
embedded name) and sets them (:func:`override_text`), so that every step's command names
a plain config file and ``commands.sh`` replays it. ``sweep`` takes a list of values
per key (a grid, reproduce/sweep.py); ``reproduce`` one value per key
(:func:`parse_one`), applied to every config of its suite (:func:`suite_with`).
"""

from __future__ import annotations

import dataclasses
import itertools
from pathlib import Path
from typing import Any

import yaml

from fuzzyslam.config import Config, _merge, clip, config_from_raw, config_layers, yaml_value
from fuzzyslam.errors import ConfigError, InputError

GRID_SYNTAX = "KEY=V1,V2,... (e.g. fgm.freeze_run=1,2)"  # sweep's --set
ONE_SYNTAX = "KEY=VALUE (e.g. slam.calibrate=true)"  # reproduce's --set


def parse_set(text: str, syntax: str = GRID_SYNTAX) -> tuple[str, list[Any]]:
    """``KEY=V1,V2,...`` -> (KEY, [values]); each value is read as YAML (0.5, 1e-3, true,
    text) by the configs' loader (``config.yaml_value``); an empty value is refused.

    Parameters
    ----------
    text : str
        The option's text, e.g. ``fgm.freeze_run=1,2``.
    syntax : str
        The option's form, for the error of a malformed one.

    Returns
    -------
    (str, list)
        The dotted key and its values. A malformed option is an InputError naming it
        (``--set TEXT``).
    """
    label = f"--set {text}"
    key, sep, values = text.partition("=")
    key = key.strip()
    if not sep or not key or not values.strip():
        raise InputError(label, f"--set must be {syntax}")
    if key.split(".")[0] == "extends":
        raise InputError(label, "'extends' cannot be set; give the config to extend as CONFIG")
    refuse_seed(key, label, syntax)
    parts = values.split(",")
    if any(not v.strip() for v in parts):
        raise InputError(label, f"an empty value; --set must be {syntax}")
    try:
        return key, [yaml_value(v, label) for v in parts]
    except yaml.YAMLError as exc:
        problem = getattr(exc, "problem", None) or "syntax error"
        raise InputError(label, f"a value is not YAML: {clip(problem, 80)}") from None


# The options that choose the seeds, by the command (its --set form): every simulate
# step is given its seed (``--seed S``), which overrides a config's ``seed``
SEED_OPTIONS = {GRID_SYNTAX: "--seeds N", ONE_SYNTAX: "--seeds N and --first-seed S"}


def refuse_seed(key: str, label: str, syntax: str = GRID_SYNTAX) -> None:
    """Refuse ``seed`` as a ``--set`` key (an InputError, one line naming ``label``): each
    simulate step of a sweep or reproduce passes its own ``--seed``, which overrides the
    config's, so a set ``seed`` would be recorded (commands.sh, results.json, the
    ``gI.yaml`` and ``set_*.yaml`` files, sweep.md's rows) and silently ignored.

    Parameters
    ----------
    key : str
        The dotted key.
    label : str
        What the error names (the ``--set`` option).
    syntax : str
        The command's ``--set`` form (:data:`GRID_SYNTAX`: sweep, :data:`ONE_SYNTAX`:
        reproduce), which tells the seed options to point to.
    """
    if key.split(".")[0] == "seed":
        options = SEED_OPTIONS.get(syntax, "--seeds N")
        raise InputError(
            label,
            "'seed' cannot be set: every simulate step passes its own --seed, which "
            f"overrides the config's; choose the seeds with {options}",
        )


def parse_one(text: str) -> tuple[str, Any]:
    """``KEY=VALUE`` -> (KEY, value) (:func:`parse_set` with exactly one value).

    Parameters
    ----------
    text : str
        The option's text, e.g. ``slam.calibrate=true``.

    Returns
    -------
    (str, object)
        The dotted key and its value read as YAML.
    """
    key, values = parse_set(text, ONE_SYNTAX)
    if len(values) != 1:
        raise InputError(
            f"--set {text}", "--set takes one value (KEY=VALUE); a grid is 'fuzzyslam sweep'"
        )
    return key, values[0]


def nested(key: str, value: Any) -> dict[str, Any]:
    """``a.b.c``, v -> {a: {b: {c: v}}}."""
    out: Any = value
    for part in reversed(key.split(".")):
        out = {part: out}
    return out


def override_text(base: str, overrides: dict[str, Any], comment: str) -> str:
    """The YAML text of a config that ``extends`` ``base`` and sets ``overrides`` (dotted
    keys), after a ``# comment`` line.

    Parameters
    ----------
    base : str
        The config it extends (a file beside it or an embedded name).
    overrides : dict
        Dotted key -> value.
    comment : str
        The first line's text.

    Returns
    -------
    str
    """
    doc: dict[str, Any] = {"extends": base}
    for k, v in overrides.items():
        doc = _merge(doc, nested(k, v))
    return f"# {comment}\n" + yaml.safe_dump(doc, sort_keys=True)


def overridden(raw: dict[str, Any], overrides: dict[str, Any]) -> dict[str, Any]:
    """The raw mapping of a config (:func:`~fuzzyslam.config.config_layers`) with
    ``overrides`` set, as the file of :func:`override_text` loads (``raw`` unchanged).

    Parameters
    ----------
    raw : dict
        The base config's merged keys.
    overrides : dict
        Dotted key -> value.

    Returns
    -------
    dict
    """
    doc: dict[str, Any] = {}
    for k, v in overrides.items():
        doc = _merge(doc, nested(k, v))
    return _merge(raw, doc)


def set_label(key: str, values: list[Any]) -> str:
    """The ``--set`` option of ``key`` and its ``values`` as a command line's text, what
    an error caused by it names: ``--set robot.wheel_noise=0.1,0.2``.

    Parameters
    ----------
    key : str
        The dotted key.
    values : list
        Its values.

    Returns
    -------
    str
    """
    return f"--set {key}={','.join(_scalar(v) for v in values)}"


def _checked(
    raw: dict[str, Any], source: str, overrides: dict[str, Any], labels: dict[str, str]
) -> Config:
    """The Config of ``raw`` (from config ``source``) with ``overrides`` set; an error is
    told to what caused it: the config alone (naming ``source``), else the first key
    whose value alone is refused (naming ``labels[key]``, its ``--set`` option), else the
    combination (naming every option)."""
    try:
        return config_from_raw(overridden(raw, overrides), source)
    except ConfigError:
        config_from_raw(raw, source)
        for k, v in overrides.items():
            config_from_raw(overridden(raw, {k: v}), labels[k])
        config_from_raw(overridden(raw, overrides), " ".join(dict.fromkeys(labels.values())))
        raise


def check_grid(base: str, sets: list[tuple[str, list[Any]]]) -> list[Config]:
    """Check, in memory and before any file is written, each grid point of ``sets`` (the
    product of their values) set over the config ``base``. An error names what causes
    it: ``base``'s file (its own keys or values), a value's ``--set KEY=V1,V2`` option,
    or every ``--set`` option (a combination: sizes). A key given twice is refused.

    Parameters
    ----------
    base : str
        The config: a path or an embedded name.
    sets : list of (str, list)
        Dotted keys and their values.

    Returns
    -------
    list of Config
        The config of each grid point, in the order of ``itertools.product``.
    """
    keys = [k for k, _ in sets]
    labels = {k: set_label(k, vs) for k, vs in sets}
    for key in keys:
        refuse_seed(key, labels[key])
        if keys.count(key) > 1:
            raise InputError(labels[key], f"'{clip(key, 80)}' is given in more than one --set")
    raw, chain = config_layers(base)
    return [
        _checked(raw, chain[0], dict(zip(keys, point, strict=True)), labels)
        for point in itertools.product(*(vs for _, vs in sets))
    ]


def check_suite(suite, overrides: dict[str, Any]) -> None:
    """Check, in memory, every config of ``suite`` with ``overrides`` set (what
    :func:`suite_with` writes): an error names the ``--set KEY=VALUE`` option causing it
    (every option: a combination's).

    Parameters
    ----------
    suite : Suite
        The embedded configs (reproduce/plan.py).
    overrides : dict
        Dotted key -> value (:func:`parse_one`).
    """
    labels = {k: set_label(k, [v]) for k, v in overrides.items()}
    for k in overrides:
        refuse_seed(k, labels[k], ONE_SYNTAX)
    for field in dataclasses.fields(suite):
        raw, chain = config_layers(getattr(suite, field.name))
        _checked(raw, chain[0], overrides, labels)


def suite_with(suite, overrides: dict[str, Any], root: Path):
    """``suite`` (reproduce/plan.py ``Suite``) with ``overrides`` set in each of its
    configs: ``set_NAME`` files in ``root`` (the plan's directory, where the steps run),
    written after every one is checked (:func:`check_suite`: an unknown key or a bad
    value is one line naming the ``--set`` option, and nothing is written). The suite
    itself without overrides.

    Parameters
    ----------
    suite : Suite
        The embedded configs.
    overrides : dict
        Dotted key -> value (:func:`parse_one`).
    root : Path
        The directory the files are written into.

    Returns
    -------
    Suite
        The same fields, naming the files.
    """
    if not overrides:
        return suite
    check_suite(suite, overrides)
    names = {}
    for field in dataclasses.fields(suite):
        base = getattr(suite, field.name)
        name = f"set_{base}"
        (root / name).write_text(
            override_text(base, overrides, f"reproduce{set_options(overrides)}"), encoding="utf-8"
        )
        names[field.name] = name
    return dataclasses.replace(suite, **names)


def _scalar(v: Any) -> str:
    """``v`` as one line of YAML (true, 0.5, [1, 2])."""
    return yaml.safe_dump(v, default_flow_style=True).removesuffix("...\n").strip()


def set_options(overrides: dict[str, Any]) -> str:
    """The ``--set`` options of ``overrides`` as a command line's text (' --set k=v' ...)."""
    return "".join(f" --set {k}={_scalar(v)}" for k, v in overrides.items())
