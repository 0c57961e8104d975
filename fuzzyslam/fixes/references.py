"""Which corridors contain a point, or lie near it (the heading fixes' corridor choice);
the :class:`Reference` type and its reader are :mod:`fuzzyslam.references` (re-exported)."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from fuzzyslam.polygons import distance_to_polygon, points_in_polygon
from fuzzyslam.references import Reference, references_from_dicts

__all__ = [
    "Reference",
    "corridors_at",
    "corridors_near",
    "distance_to_polygon",
    "points_in_polygon",
    "references_from_dicts",
]


def corridors_at(xy: Sequence[float], refs: Sequence[Reference]) -> list[Reference]:
    """The corridors whose region contains the point ``xy``.

    Parameters
    ----------
    xy : sequence of float, length 2
        The point (m).
    refs : sequence of Reference
        The map's corridor references.

    Returns
    -------
    list of Reference
    """
    return [r for r in refs if r.contains(xy)]


def corridors_near(xy: Sequence[float], refs: Sequence[Reference], margin: float) -> list:
    """The corridors whose region lies within ``margin`` (m) of ``xy`` (junctions, corners).

    Parameters
    ----------
    xy : sequence of float, length 2
        The point (m).
    refs : sequence of Reference
        The map's corridor references.
    margin : float
        The distance (m).

    Returns
    -------
    list of Reference
    """
    p = np.asarray(xy, dtype=float).reshape(1, 2)
    x, y = float(p[0, 0]), float(p[0, 1])
    out = []
    for r in refs:
        # a region whose bounding box is farther than the margin (1 um to spare: the
        # exact distance is computed to 1e-15) is not near: skip the polygon distance
        x0, y0, x1, y1 = _box(r.polygon)
        dx, dy = max(x0 - x, 0.0, x - x1), max(y0 - y, 0.0, y - y1)
        if dx * dx + dy * dy > (margin + 1e-6) ** 2:
            continue
        if distance_to_polygon(p, r.polygon)[0] <= margin:
            out.append(r)
    return out


_BOXES: dict[int, tuple[np.ndarray, tuple[float, float, float, float]]] = {}


def _box(poly: np.ndarray) -> tuple[float, float, float, float]:
    """The bounding box (xmin, ymin, xmax, ymax) of a polygon (K, 2), cached per array
    (the cache keeps the array, so its id is not reused while cached)."""
    hit = _BOXES.get(id(poly))
    if hit is not None and hit[0] is poly:
        return hit[1]
    lo, hi = np.min(poly, axis=0), np.max(poly, axis=0)
    box = (float(lo[0]), float(lo[1]), float(hi[0]), float(hi[1]))
    if len(_BOXES) > 256:
        _BOXES.clear()
    _BOXES[id(poly)] = (poly, box)
    return box
