"""Which corridors contain a point, or lie near it (the heading fixes' corridor choice);
the :class:`Reference` type and its reader are :mod:`fuzzyslam.references` (re-exported)."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from fuzzyslam.polygons import (
    Edges,
    distance_to_polygon,
    edges_contain,
    edges_within,
    points_in_polygon,
    polygon_edges,
)
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
    x, y = float(xy[0]), float(xy[1])
    return [r for r in refs if edges_contain(_corners(r.region), x, y)]


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
        near = edges_within(_corners(r.polygon), x, y, margin)
        if near is None:  # within rounding of the margin: the plain distance decides
            near = bool(distance_to_polygon(p, r.polygon)[0] <= margin)
        if near:
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


_CORNERS: dict[int, tuple[np.ndarray, Edges]] = {}


def _corners(poly: np.ndarray) -> Edges:
    """The polygon's edges (ax, ay, bx, by) as Python floats, b the next corner (the last
    joined to the first), cached per array like :func:`_box`."""
    hit = _CORNERS.get(id(poly))
    if hit is not None and hit[0] is poly:
        return hit[1]
    edges = polygon_edges(poly)
    if len(_CORNERS) > 256:
        _CORNERS.clear()
    _CORNERS[id(poly)] = (poly, edges)
    return edges
