"""TUM trajectory files: ``timestamp x y z qx qy qz qw`` (what evo reads)."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from fuzzyslam.errors import InputError
from fuzzyslam.fileio import atomic_path, check_input_file
from fuzzyslam.se2 import quaternion_to_yaw, yaw_to_quaternion


def format_tum(t: np.ndarray, poses: np.ndarray) -> str:
    """TUM text of times (N,) and planar poses (N, 3), z = 0, yaw-only quaternion."""
    t = np.asarray(t, dtype=float)
    poses = np.asarray(poses, dtype=float).reshape(-1, 3)
    q = yaw_to_quaternion(poses[:, 2]).reshape(-1, 4)
    rows = np.column_stack([t, poses[:, 0], poses[:, 1], np.zeros(len(t)), q])
    # Python floats (tolist) format as the numpy rows do, 3x faster; one format per line
    fmt = TUM_LINE.__mod__
    return "\n".join(["# timestamp x y z qx qy qz qw", *map(fmt, map(tuple, rows.tolist()))]) + "\n"


TUM_LINE = "%.9f %.6f %.6f %.6f %.9f %.9f %.9f %.9f"  # one pose, fixed layout


def write_tum(path: str | os.PathLike, t: np.ndarray, poses: np.ndarray) -> None:
    """Write a TUM file atomically."""
    with atomic_path(path) as tmp:
        Path(tmp).write_text(format_tum(t, poses), encoding="utf-8")


def read_tum(path: str | os.PathLike, sort: bool = False, report: bool = False):
    """Read a TUM file: times (N,) and planar poses (N, 3) (yaw from the quaternion).

    Stamps must increase strictly: the first line whose stamp is not after the previous
    one's is an error naming it (``FILE: line N: ...``), unless ``sort``, which sorts the
    poses by time (stable) and drops every repeat of a stamp but its first line. With
    ``report`` a third value is returned: ``{"out_of_order": lines that went back in
    time, "repeats_dropped": lines dropped}`` (zeros when nothing was sorted).
    """
    t, poses, _planar, fixes = read_tum_planar(path, sort, report=True)
    return (t, poses, fixes) if report else (t, poses)


def read_tum_planar(path: str | os.PathLike, sort: bool = False, report: bool = False):
    """:func:`read_tum` and whether the file is planar (z = 0 and a yaw-only quaternion,
    within 1 mm and 1e-3); a 3-D trajectory is read as its projection on the plane.
    With ``report``, the sorting counts of :func:`read_tum` come fourth."""
    p = check_input_file(path, "trajectory")
    try:
        text = p.read_text(encoding="utf-8")
    except UnicodeDecodeError:
        raise InputError(p, "not a TUM trajectory (not text)") from None
    a, linenos = _regular_rows(text), None
    if a is None:
        a, linenos = _parse_lines(p, text)
    t = a[:, 0]
    step = np.diff(t)
    bad = np.flatnonzero(step <= 0)
    fixes = {"out_of_order": int(np.count_nonzero(step < 0)), "repeats_dropped": 0}
    if len(bad) and not sort:
        if linenos is None:
            linenos = _parse_lines(p, text)[1]
        k = int(bad[0]) + 1
        what = "repeats" if step[bad[0]] == 0 else "goes back before"
        raise InputError(
            p,
            f"line {linenos[k]}: timestamp {t[k]:.9f} {what} the previous pose's "
            f"{t[k - 1]:.9f} (line {linenos[k - 1]}); stamps must increase "
            "(map --sort sorts them and drops repeats)",
        )
    if len(bad):
        order = np.argsort(t, kind="stable")
        a = a[order]
        keep = np.concatenate([[True], np.diff(a[:, 0]) > 0])
        fixes["repeats_dropped"] = int(np.count_nonzero(~keep))
        a = a[keep]
        t = a[:, 0]
    yaw = np.asarray(quaternion_to_yaw(a[:, 4:8])).reshape(-1)
    q = a[:, 4:8] / np.linalg.norm(a[:, 4:8], axis=1, keepdims=True)
    planar = bool(np.all(np.abs(a[:, 3]) <= 1e-3) and np.all(np.abs(q[:, :2]) <= 1e-3))
    poses = np.column_stack([a[:, 1], a[:, 2], yaw])
    return (t, poses, planar, fixes) if report else (t, poses, planar)


def _parse_lines(p: Path, text: str) -> tuple[np.ndarray, list[int]]:
    """The rows (N, 8) of a TUM text read line by line and their line numbers; the first
    malformed line is an InputError naming it."""
    rows, linenos = [], []
    for lineno, line in enumerate(text.splitlines(), 1):
        s = line.strip()
        if not s or s.startswith("#"):
            continue
        parts = s.replace(",", " ").split()
        if len(parts) != 8:
            raise InputError(p, f"line {lineno}: expected 8 columns (TUM), got {len(parts)}")
        try:
            vals = [float(v) for v in parts]
        except ValueError:
            raise InputError(p, f"line {lineno}: non-numeric value") from None
        if not np.all(np.isfinite(vals)):
            raise InputError(p, f"line {lineno}: NaN or infinite value")
        rows.append(vals)
        linenos.append(lineno)
    if not rows:
        raise InputError(p, "trajectory holds no poses")
    return np.array(rows), linenos


def _regular_rows(text: str) -> np.ndarray | None:
    """The rows (N, 8) of a TUM text whose every line is a comment (``#`` first), blank or
    eight finite numbers separated by blanks, parsed at once (``np.loadtxt``: each number
    by ``PyOS_string_to_double``, as ``float``); None for any other text (commas, a ``#``
    within a line, a wrong column count, a value float() reads but loadtxt does not, NaN),
    which :func:`_parse_lines` then reads, naming the faulty line."""
    if "," in text:
        return None
    lines = text.splitlines()
    if "#" in text:
        lines = [ln for ln in lines if not ln.lstrip().startswith("#")]
    if not "".join(lines).strip():
        return None  # no poses (loadtxt would warn)
    try:
        a = np.loadtxt(lines, dtype=np.float64, comments=None, ndmin=2)
    except ValueError:
        return None
    if a.ndim != 2 or a.shape[0] == 0 or a.shape[1] != 8 or not np.isfinite(a).all():
        return None
    return a
