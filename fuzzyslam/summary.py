"""The JSON summaries and result files of the stages: typed on the producing side,
one text on the consuming side.

Each stage builds its summary as a dataclass (``slam.summary.RunSummary``,
``maps.summary.MapSummary``, ``evaluation.results.Metrics``, ``reproduce.report.Results``;
nested dataclasses for their sections), so that a metric renamed or left out is a
``TypeError`` where it is made, not a blank where it is read. :func:`as_json` turns
such a tree into the JSON object every file and stdout carry (``summary_text``).

A path (or any text the system gave: a command-line argument, a file's name) enters the
text outputs (the JSON summaries, report.md, figure titles, stderr lines) as
:func:`path_text` has it: its bytes read as UTF-8, whatever the locale."""

from __future__ import annotations

import json
import math
import os
from dataclasses import fields, is_dataclass
from pathlib import Path
from typing import Any


class _Omitted:
    """The type of :data:`OMIT`."""

    _one: _Omitted | None = None

    def __new__(cls) -> _Omitted:
        if cls._one is None:
            cls._one = super().__new__(cls)
        return cls._one

    def __repr__(self) -> str:
        return "OMIT"

    def __bool__(self) -> bool:
        return False


OMIT: Any = _Omitted()
"""The value of a dataclass field whose key is absent from the JSON (an optional
section the stage did not compute), as opposed to None (the key, written as null)."""


def key(name: str) -> dict[str, str]:
    """Field metadata giving the JSON key of a field whose key is not a Python name
    (``field(metadata=key("true_within_0.5_m"))``).

    Parameters
    ----------
    name : str
        The key in the JSON.

    Returns
    -------
    dict
        ``{"key": name}``, for ``dataclasses.field(metadata=...)``.
    """
    return {"key": name}


def path_text(path: str | bytes | os.PathLike) -> str:
    """A path as the text outputs show it (JSON summaries, report.md, CSV and YAML
    headers, figure titles, stderr lines): valid text unchanged; a name the locale could
    not decode, its bytes on the file system decoded as UTF-8, a byte sequence that is
    not UTF-8 as U+FFFD.

    Python gives a path or command-line argument that its locale's encoding cannot
    decode (``é/lög.mcap`` under ``LC_ALL=C`` without UTF-8 mode, or a Latin-1 name under
    a UTF-8 locale) as lone surrogates (``"\\udcc3\\udca9"``), which no UTF-8 file can hold
    and matplotlib cannot draw; here they become the characters they encode (or U+FFFD).
    Also for any text the system gave (a command-line ``--label``).

    Parameters
    ----------
    path : str, bytes or path-like
        The path, as given or as ``os.fsdecode`` made it.

    Returns
    -------
    str
        Valid Unicode text (``path`` itself for a UTF-8 path under a UTF-8 locale).
    """
    raw = os.fspath(path)
    if isinstance(raw, str):
        if raw.isascii():
            return raw
        try:
            raw.encode("utf-8")
            return raw  # valid text (whatever the locale: a Latin-1 one decoded it right)
        except UnicodeEncodeError:  # lone surrogates: bytes the locale could not decode
            pass
        try:
            raw = os.fsencode(raw)  # the bytes the system gave
        except UnicodeEncodeError:  # characters the locale's encoding lacks beside them
            try:
                raw = raw.encode("utf-8", "surrogateescape")
            except UnicodeEncodeError:
                raw = raw.encode("utf-8", "surrogatepass")
    return raw.decode("utf-8", "replace")


def valid_text(text: str) -> str:
    """``text`` unchanged when it is valid Unicode (it encodes as UTF-8), else as
    :func:`path_text` has it (lone surrogates: bytes the system gave that its locale's
    encoding could not decode).

    Parameters
    ----------
    text : str
        Any text.

    Returns
    -------
    str
        Text that UTF-8 can hold.
    """
    if text.isascii():  # also bytes, returned as they are: a text stream refuses them,
        return text  # which is how click tells a text stream from a binary one
    return path_text(text)


def as_json(obj: Any) -> Any:
    """The JSON value of a summary: a dataclass as an object of its fields (in field
    order, each under its name or its ``key`` metadata, :data:`OMIT` ones left out),
    dicts, lists and tuples element by element, text as :func:`valid_text` has it (a path
    the locale could not decode, as :func:`path_text`), anything else unchanged (numbers
    keep their type: the writers choose how to print numpy scalars and NaN).

    Parameters
    ----------
    obj : Any
        A dataclass instance (a summary), or any value inside one.

    Returns
    -------
    Any
        dicts, lists and tuples of the leaves of ``obj``.
    """
    if is_dataclass(obj) and not isinstance(obj, type):
        out = {}
        for f in fields(obj):
            v = getattr(obj, f.name)
            if v is not OMIT:
                out[f.metadata.get("key", f.name)] = as_json(v)
        return out
    if isinstance(obj, dict):
        return {k: as_json(v) for k, v in obj.items() if v is not OMIT}
    if isinstance(obj, list):
        return [as_json(v) for v in obj]
    if isinstance(obj, tuple):
        return tuple(as_json(v) for v in obj)
    if isinstance(obj, str):
        return valid_text(obj)
    return obj


def jsonable(obj: Any) -> Any:
    """``json.dumps``'s ``default``: numpy scalars and arrays as Python values, the rest
    as text.

    Parameters
    ----------
    obj : Any
        A value ``json`` cannot write.

    Returns
    -------
    Any
        A Python number or list (numpy), else ``str(obj)``.
    """
    try:
        import numpy as np

        if isinstance(obj, np.generic):
            return obj.item()
        if isinstance(obj, np.ndarray):
            return obj.tolist()
    except ImportError:  # pragma: no cover
        pass
    return str(obj)


def strict(obj: Any) -> Any:
    """A JSON tree (:func:`as_json`'s) that strict JSON can hold: NaN and infinities as
    None (null, as metrics.json writes them), numpy scalars and arrays as Python numbers
    and lists, tuples as lists; other leaves unchanged.

    Parameters
    ----------
    obj : Any
        dicts, lists, tuples and leaves.

    Returns
    -------
    Any
        The same tree with every float finite or None.
    """
    if isinstance(obj, dict):
        return {k: strict(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [strict(v) for v in obj]
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if type(obj).__module__ == "numpy" and hasattr(obj, "tolist"):
        return strict(obj.tolist())  # a numpy scalar (a Python number) or array (a list)
    return obj


def summary_text(summary: dict[str, Any]) -> str:
    """The summary as the CLI prints it: indented strict JSON (non-finite numbers as
    null), keys sorted.

    Parameters
    ----------
    summary : dict or dataclass
        A stage's summary (a dataclass is turned into JSON by :func:`as_json`).

    Returns
    -------
    str
        The JSON text (no final newline).
    """
    return json.dumps(
        strict(as_json(summary)), indent=2, sort_keys=True, default=jsonable, allow_nan=False
    )


def log_name(path: str | os.PathLike | None) -> str:
    """A log's or run's short name for a title: its file name, with its folder's name when
    the file's name alone says little (``mrclam6-robot2/log.mcap``, ``trajectory.tum``'s
    run directory).

    Parameters
    ----------
    path : path or None
        The file or directory.

    Returns
    -------
    str
        The name, as :func:`path_text` shows it (valid Unicode under
        any locale: matplotlib cannot draw the lone surrogates of a name the locale
        could not decode); empty for None or an empty path.
    """
    if path is None or str(path) == "":
        return ""
    p = Path(path)
    generic = {"log.mcap", "truth.tum", "trajectory.tum", "estimates.mcap", "."}
    if p.name in generic and p.parent.name:
        return path_text(f"{p.parent.name}/{p.name}")
    return path_text(p.name)
