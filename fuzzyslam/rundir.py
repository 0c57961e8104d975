"""The run directory (``fuzzyslam run -o OUTDIR``, docs/contracts.md sec. 2): its file
names, and the one reader and writer of its landmarks.yaml.

Written by the run stage (:mod:`fuzzyslam.slam.outputs`, the aids' own files from
``fixes/``); read by ``map --landmarks``, ``evaluate`` and ``reproduce``.
"""

from __future__ import annotations

import os
from collections.abc import Iterable
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from fuzzyslam.errors import InputError
from fuzzyslam.fileio import check_input_file

TRAJECTORY = "trajectory.tum"
ODOMETRY = "odometry.tum"
COVARIANCE = "covariance.csv"
UPDATES = "updates.csv"
LANDMARKS = "landmarks.yaml"
ESTIMATES = "estimates.mcap"
SUMMARY = "summary.json"
HEADING_FIXES = "heading_fixes.csv"
POSE_FIXES = "pose_fixes.csv"
CHANGES = "changes.csv"
TRAJECTORY_CLOSED = "trajectory_closed.tum"  # run --live-map: its loops closed
# files a run writes only with some options: an old one would be mixed with a new run
OPTIONAL_OUTPUTS = (
    TRAJECTORY_CLOSED,
    HEADING_FIXES,
    POSE_FIXES,
    CHANGES,
    "changes.png",
    "calibration.csv",
    "calibration.yaml",
)

# every file a run may write into its directory
RUN_OUTPUTS = (
    TRAJECTORY,
    ODOMETRY,
    COVARIANCE,
    UPDATES,
    LANDMARKS,
    ESTIMATES,
    SUMMARY,
    *OPTIONAL_OUTPUTS,
)


def landmarks_dict(lamps: Iterable[Any]) -> dict:
    """The content of landmarks.yaml: ``{frame: map, landmarks: [{id, x, y, cov,
    first_seen, last_seen, observations}]}`` of lamp records (``slam.events.LampRecord``:
    ``cov`` (2, 2))."""
    return {
        "frame": "map",
        "landmarks": [
            {
                "id": int(lm.id),
                "x": float(lm.x),
                "y": float(lm.y),
                "cov": [[float(v) for v in row] for row in lm.cov],
                "first_seen": float(lm.first_seen),
                "last_seen": float(lm.last_seen),
                "observations": int(lm.observations),
            }
            for lm in lamps
        ],
    }


def write_landmarks(path: str | os.PathLike, lamps: Iterable[Any]) -> None:
    """Write landmarks.yaml (:func:`landmarks_dict`) at ``path``."""
    Path(path).write_text(yaml.safe_dump(landmarks_dict(lamps), sort_keys=False), encoding="utf-8")


def read_landmarks(path: str | os.PathLike, truth: bool = False) -> tuple[np.ndarray, list[int]]:
    """The lamps of a landmarks.yaml (this module's, or a real log's true landmarks:
    ``{landmarks: [{id, x, y}, ...]}``, ``id`` defaulting to the position in the list).

    Either must be a mapping with a ``landmarks`` list, else it is a bad input (a TUM file,
    a bare list, another YAML given by mistake); a run's landmarks.yaml may hold no lamp (a
    lamp-less run: ``landmarks: []``), a file of true landmarks (``truth``) must hold one.

    Parameters
    ----------
    path : path
        The YAML file.
    truth : bool
        The file is the truth's (``evaluate --landmarks-truth``): at least one landmark.

    Returns
    -------
    xy : ndarray, shape (M, 2)
        Positions (m).
    ids : list of int
        Their ids.
    """
    what = "landmarks truth" if truth else "landmarks"
    p = check_input_file(path, what)
    try:
        data = yaml.safe_load(p.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, yaml.YAMLError) as exc:
        raise InputError(p, f"cannot read {what} YAML: {str(exc).splitlines()[0]}") from None
    if not (isinstance(data, dict) and "landmarks" in data):
        held = {dict: "a mapping without it", list: "a bare list", str: "plain text",
                type(None): "nothing"}  # fmt: skip
        expected = "" if truth else "a run's landmarks.yaml, "
        raise InputError(
            p,
            f"not a {what} file: no 'landmarks' list (the YAML holds "
            f"{held.get(type(data), 'a ' + type(data).__name__)}; expected "
            f"{expected}'landmarks: [{{id, x, y}}, ...]')",
        )
    lms = data["landmarks"]
    if lms is None:
        lms = []
    if not isinstance(lms, list):
        raise InputError(p, "'landmarks' must be a list")
    if truth and not lms:
        raise InputError(p, "the landmarks truth holds no landmark ('landmarks' is empty)")
    try:
        xy = np.array([[float(d["x"]), float(d["y"])] for d in lms], dtype=float).reshape(-1, 2)
        ids = [int(d.get("id", i)) for i, d in enumerate(lms)]
    except (KeyError, TypeError, ValueError, AttributeError) as exc:
        raise InputError(p, f"malformed landmark entry: {exc}") from None
    return xy, ids


def split_label(spec: str | os.PathLike) -> tuple[str | None, str | os.PathLike]:
    """``LABEL=PATH`` -> (LABEL, PATH); a plain path (or one that exists as written, even
    with a '=' in it) -> (None, path). A label holds no path separator."""
    text = os.fspath(spec)
    label, sep, path = text.partition("=")
    if not sep or not label or not path or "/" in label or os.sep in label:
        return None, spec
    if os.path.exists(text):
        return None, spec
    return label, path
