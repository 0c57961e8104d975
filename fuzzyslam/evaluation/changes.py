"""Change detection against the simulator's truth: precision and recall (issue 8).

Truth: the log's ``fuzzyslam.obstacles`` record (``sim.obstacles.obstacles_record``):
per object its kind, presence interval [t_start, t_end], box polygon or disc radius,
and its track [[t, x, y], ...]. Detections: ``changes.csv`` rows (t, x, y).

- A detection is a true positive when an object present at its time lies within
  ``tol`` (m) of it: distance to the box's polygon (0 inside), or to the disc's edge
  at its position interpolated in the track. Precision = true positives / detections.
- An encounter is a stretch of time (gaps under ``gap`` s) during which an object is
  present and within ``reach`` (m, the FLM's half-size) of the true robot. It is
  found when a true positive on that object falls inside it (+- gap / 2).
  Recall = found encounters / encounters.
"""

from __future__ import annotations

import csv
import os
from pathlib import Path
from typing import Any

import numpy as np

from fuzzyslam.errors import InputError
from fuzzyslam.polygons import distance_to_polygon
from fuzzyslam.streams.reader import LogReader

OBSTACLES_KEY = "fuzzyslam.obstacles"  # written by sim.record (sim.obstacles)


def object_distance(obj: dict[str, Any], t: np.ndarray, xy: np.ndarray) -> np.ndarray:
    """Distance (N,) from points xy (N, 2) at times t (N,) to the object; inf when absent."""
    t = np.asarray(t, dtype=float).reshape(-1)
    xy = np.asarray(xy, dtype=float).reshape(-1, 2)
    present = (t >= obj["t_start"]) & (t <= obj["t_end"])
    if obj["kind"] == "box":
        d = distance_to_polygon(xy, np.asarray(obj["polygon"], float))
    else:
        tr = np.asarray(obj["track"], dtype=float).reshape(-1, 3)
        if len(tr) == 0:
            return np.full(len(t), np.inf)
        c = np.column_stack([np.interp(t, tr[:, 0], tr[:, 1]), np.interp(t, tr[:, 0], tr[:, 2])])
        d = np.maximum(np.linalg.norm(xy - c, axis=1) - float(obj["radius"]), 0.0)
    return np.where(present, d, np.inf)


def _runs(mask: np.ndarray, t: np.ndarray, gap: float) -> list[tuple[float, float]]:
    """Stretches [t_a, t_b] of consecutive True samples (a gap over ``gap`` s splits)."""
    ts = t[mask]
    if ts.size == 0:
        return []
    cut = np.flatnonzero(np.diff(ts) > gap)
    starts = np.concatenate([[0], cut + 1])
    ends = np.concatenate([cut, [ts.size - 1]])
    return [(float(ts[a]), float(ts[b])) for a, b in zip(starts, ends, strict=True)]


def change_detection_scores(
    detections: np.ndarray,
    obstacles: list[dict[str, Any]],
    robot_t: np.ndarray,
    robot_xy: np.ndarray,
    tol: float = 0.3,
    reach: float = 1.5,
    gap: float = 2.0,
) -> dict[str, Any]:
    """Precision and recall of change detections (t, x, y) (N, 3) (module docstring)."""
    det = np.asarray(detections, dtype=float).reshape(-1, 3)
    n = len(det)
    dist = np.full((n, len(obstacles)), np.inf)
    for k, obj in enumerate(obstacles):
        dist[:, k] = object_distance(obj, det[:, 0], det[:, 1:])
    tp = dist.min(axis=1) <= tol if len(obstacles) else np.zeros(n, bool)
    owner = np.where(tp, dist.argmin(axis=1) if len(obstacles) else -1, -1)
    enc_total = enc_found = 0
    per_object = []
    for k, obj in enumerate(obstacles):
        near = object_distance(obj, robot_t, robot_xy) <= reach
        stretches = _runs(near, np.asarray(robot_t, float), gap)
        hits = det[owner == k, 0]
        found = sum(
            bool(np.any((hits >= a - gap / 2) & (hits <= b + gap / 2))) for a, b in stretches
        )
        enc_total += len(stretches)
        enc_found += found
        per_object.append(
            {"id": obj["id"], "kind": obj["kind"], "encounters": len(stretches),
             "found": found, "detections": int(np.count_nonzero(owner == k))}
        )  # fmt: skip
    return {
        "detections": n,
        "true_positives": int(np.count_nonzero(tp)),
        "precision": float(np.count_nonzero(tp) / n) if n else None,
        "encounters": enc_total,
        "encounters_found": enc_found,
        "recall": float(enc_found / enc_total) if enc_total else None,
        "tolerance_m": tol,
        "reach_m": reach,
        "objects": per_object,
    }


def read_changes_csv(path: Path) -> np.ndarray:
    """(t, x, y) rows (N, 3) of a run's changes.csv (header ``t,x,y,size,cells``)."""
    with open(path, newline="", encoding="utf-8") as fh:
        rows = list(csv.DictReader(fh))
    try:
        return np.array([[float(r["t"]), float(r["x"]), float(r["y"])] for r in rows]).reshape(
            -1, 3
        )
    except (KeyError, TypeError, ValueError):
        raise InputError(path, "not a changes.csv (t,x,y,size,cells)") from None


def change_metrics(
    truth_path: str | os.PathLike, estimate_path: str | os.PathLike, robot_t, robot_xy
) -> dict[str, Any] | None:
    """Scores of the estimate's changes.csv against the truth log's obstacle record, or
    None when either is missing (a run without --fix pose, a log without obstacles)."""
    est = Path(estimate_path)
    if not (est.is_dir() and (est / "changes.csv").is_file()):
        return None
    try:
        record = LogReader(truth_path).json_metadata(OBSTACLES_KEY)
    except InputError:
        return None
    if not record:
        return None
    det = read_changes_csv(est / "changes.csv")
    return change_detection_scores(det, record.get("obstacles", []), robot_t, robot_xy)
