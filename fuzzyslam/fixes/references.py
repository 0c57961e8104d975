"""Corridor references of a frozen FGM: reference angle (mod pi) and region, as plain data.

``references.yaml`` (docs/contracts.md sec. 3) holds ``{references: [{id, name, angle,
angle_deg, strength, region}]}`` where ``region`` is a polygon ``[[x, y], ...]`` or a
bounding box (``[xmin, ymin, xmax, ymax]`` or ``{bbox: [...]}``). This module turns
those dicts into :class:`Reference` objects and answers "which corridors contain this
point" (crossing-number test, vectorised over the polygon's edges).
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from functools import cached_property
from typing import Any

import numpy as np

from fuzzyslam.errors import InputError
from fuzzyslam.se2 import wrap_angle_period


@dataclass(frozen=True)
class Reference:
    """One corridor: id, name, reference angle (rad, mod pi), Hough strength, region polygon."""

    id: int
    name: str
    angle: float
    strength: float
    polygon: np.ndarray  # (K, 2), K >= 3
    ambiguous: bool = False  # the map stage found no single dominant direction

    @cached_property
    def _box(self) -> tuple[float, float, float, float]:
        """The polygon's bounding box grown by 1 um: a point beyond it is outside (no
        edge straddles its y, or all cross on one side), so ``contains`` skips the test."""
        lo, hi = self.polygon.min(axis=0), self.polygon.max(axis=0)
        return float(lo[0]) - 1e-6, float(lo[1]) - 1e-6, float(hi[0]) + 1e-6, float(hi[1]) + 1e-6

    def contains(self, xy: Sequence[float]) -> bool:
        p = np.asarray(xy, float).reshape(1, 2)
        x0, y0, x1, y1 = self._box
        if not (x0 <= p[0, 0] <= x1 and y0 <= p[0, 1] <= y1):
            return False
        return bool(points_in_polygon(p, self.polygon)[0])


def points_in_polygon(pts: np.ndarray, poly: np.ndarray) -> np.ndarray:
    """Crossing-number point-in-polygon test (W. R. Franklin, PNPOLY), (N,) bool.

    A point is inside when a ray towards +x crosses the polygon's edges an odd number
    of times. Vectorised over points and edges: (N, K) arrays.
    """
    p = np.asarray(pts, dtype=float).reshape(-1, 2)
    a = np.asarray(poly, dtype=float).reshape(-1, 2)
    b = np.roll(a, -1, axis=0)
    x, y = p[:, :1], p[:, 1:]
    straddles = (a[None, :, 1] > y) != (b[None, :, 1] > y)
    dy = b[:, 1] - a[:, 1]
    dy = np.where(dy == 0.0, np.inf, dy)
    x_cross = a[:, 0] + (y - a[:, 1]) * (b[:, 0] - a[:, 0]) / dy
    crossings = straddles & (x < x_cross)
    return (np.count_nonzero(crossings, axis=1) % 2) == 1


def _region_polygon(region: Any, source: str, where: str) -> np.ndarray:
    if isinstance(region, dict):
        if "bbox" in region:
            region = region["bbox"]
        elif "polygon" in region:
            region = region["polygon"]
        else:
            raise InputError(source, f"{where}: region needs 'bbox' or 'polygon'")
    try:
        arr = np.asarray(region, dtype=float)
    except (TypeError, ValueError):
        raise InputError(source, f"{where}: region is not numeric") from None
    if arr.ndim == 1 and arr.size == 4:
        x0, y0, x1, y1 = arr
        if not (x1 > x0 and y1 > y0):
            raise InputError(source, f"{where}: bbox must be [xmin, ymin, xmax, ymax]")
        arr = np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]])
    if arr.ndim != 2 or arr.shape[1] != 2 or arr.shape[0] < 3:
        raise InputError(source, f"{where}: region must be a polygon of >= 3 [x, y] points")
    if not np.all(np.isfinite(arr)):
        raise InputError(source, f"{where}: region has non-finite coordinates")
    return arr


def references_from_dicts(items: Iterable[dict[str, Any]], source: str) -> list[Reference]:
    """Parse the ``references`` list of references.yaml; ``source`` names the file in errors."""
    out: list[Reference] = []
    for i, d in enumerate(items):
        where = f"references[{i}]"
        if not isinstance(d, dict):
            raise InputError(source, f"{where} must be a mapping")
        for key in ("angle", "region"):
            if key not in d:
                raise InputError(source, f"{where}: missing '{key}'")
        try:
            angle = float(d["angle"])
            strength = float(d.get("strength", 1.0))
            rid = int(d.get("id", i))
        except (TypeError, ValueError):
            raise InputError(source, f"{where}: id/angle/strength must be numbers") from None
        if not np.isfinite(angle):
            raise InputError(source, f"{where}: angle is not finite")
        poly = _region_polygon(d["region"], source, where)
        name = str(d.get("name", f"corridor{rid}"))
        amb = bool(d.get("ambiguous", False))
        out.append(
            Reference(rid, name, float(wrap_angle_period(angle, np.pi)), strength, poly, amb)
        )
    ids = [r.id for r in out]
    if len(set(ids)) != len(ids):
        raise InputError(source, "corridor ids are not unique")
    return out


def corridors_at(xy: Sequence[float], refs: Sequence[Reference]) -> list[Reference]:
    """The corridors whose region contains the point ``xy``."""
    return [r for r in refs if r.contains(xy)]


def distance_to_polygon(xy: Sequence[float], poly: np.ndarray) -> float:
    """Euclidean distance from ``xy`` to the polygon (0 inside), vectorised over its edges."""
    p = np.asarray(xy, dtype=float).reshape(2)
    a = np.asarray(poly, dtype=float).reshape(-1, 2)
    if points_in_polygon(p[None], a)[0]:
        return 0.0
    e = np.roll(a, -1, axis=0) - a
    u = np.clip(np.sum((p - a) * e, axis=1) / np.maximum(np.sum(e * e, axis=1), 1e-300), 0, 1)
    return float(np.min(np.hypot(*(a + u[:, None] * e - p).T)))


def corridors_near(xy: Sequence[float], refs: Sequence[Reference], margin: float) -> list:
    """The corridors whose region lies within ``margin`` (m) of ``xy`` (junctions, corners)."""
    return [r for r in refs if distance_to_polygon(xy, r.polygon) <= margin]
