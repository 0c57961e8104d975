"""Config keys set on the command line (``--set KEY=VALUE``): ``sweep`` and ``reproduce``.

A set of keys becomes a config file that ``extends`` the base config (a path or an
embedded name) and sets them (:func:`override_text`), so that every step's command names
a plain config file and ``commands.sh`` replays it. ``sweep`` takes a list of values
per key (a grid, reproduce/sweep.py); ``reproduce`` one value per key
(:func:`parse_one`), applied to every config of its suite (:func:`suite_with`).
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any

import yaml

from fuzzyslam.config import _merge, load_config
from fuzzyslam.errors import InputError


def parse_set(text: str) -> tuple[str, list[Any]]:
    """``KEY=V1,V2,...`` -> (KEY, [values]); each value is read as YAML (0.5, true, text)."""
    key, sep, values = text.partition("=")
    if not sep or not key.strip() or not values.strip():
        raise InputError(text, "--set must be KEY=V1,V2,... (e.g. fgm.freeze_run=1,2)")
    return key.strip(), [yaml.safe_load(v) for v in values.split(",")]


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
    key, values = parse_set(text)
    if len(values) != 1:
        raise InputError(text, "--set takes one value (KEY=VALUE); a grid is 'fuzzyslam sweep'")
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


def suite_with(suite, overrides: dict[str, Any], root: Path):
    """``suite`` (reproduce/plan.py ``Suite``) with ``overrides`` set in each of its
    configs: ``set_NAME`` files in ``root`` (the plan's directory, where the steps run),
    each loaded once to check it (an unknown key or a bad value: one line, before any
    step). The suite itself without overrides.

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
    names = {}
    for field in dataclasses.fields(suite):
        base = getattr(suite, field.name)
        name = f"set_{base}"
        (root / name).write_text(
            override_text(base, overrides, f"reproduce{set_options(overrides)}"), encoding="utf-8"
        )
        load_config(str(root / name))
        names[field.name] = name
    return dataclasses.replace(suite, **names)


def _scalar(v: Any) -> str:
    """``v`` as one line of YAML (true, 0.5, [1, 2])."""
    return yaml.safe_dump(v, default_flow_style=True).removesuffix("...\n").strip()


def set_options(overrides: dict[str, Any]) -> str:
    """The ``--set`` options of ``overrides`` as a command line's text (' --set k=v' ...)."""
    return "".join(f" --set {k}={_scalar(v)}" for k, v in overrides.items())
