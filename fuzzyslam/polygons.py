"""Planar polygons: the point-in-polygon test and the distance to a polygon.

A polygon is its corners (K, 2) in order (either sense), K >= 3, the last joined to the
first. Inside is the crossing-number rule (W. R. Franklin, PNPOLY): a point is inside
when a ray towards +x crosses the polygon's edges an odd number of times.
"""

from __future__ import annotations

import math

import numpy as np


def points_in_polygon(pts: np.ndarray, poly: np.ndarray) -> np.ndarray:
    """Crossing-number point-in-polygon test, vectorised over points and edges.

    Parameters
    ----------
    pts : ndarray, shape (N, 2)
        Points.
    poly : ndarray, shape (K, 2)
        The polygon's corners.

    Returns
    -------
    ndarray of bool, shape (N,)
        Whether each point is inside.
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


def distance_to_polygon(pts: np.ndarray, poly: np.ndarray) -> np.ndarray:
    """Euclidean distance from points to a polygon's boundary, 0 inside.

    Parameters
    ----------
    pts : ndarray, shape (N, 2)
        Points.
    poly : ndarray, shape (K, 2)
        The polygon's corners.

    Returns
    -------
    ndarray, shape (N,)
        Distances (0 for the points inside).
    """
    p = np.asarray(pts, dtype=float).reshape(-1, 2)
    a = np.asarray(poly, dtype=float).reshape(-1, 2)
    e = np.roll(a, -1, axis=0) - a
    u = np.sum((p[:, None] - a[None]) * e[None], axis=2) / np.maximum(np.sum(e * e, axis=1), 1e-300)
    q = a[None] + np.clip(u, 0.0, 1.0)[..., None] * e[None]
    d = np.hypot(*np.moveaxis(q - p[:, None], 2, 0)).min(axis=1)
    return np.where(points_in_polygon(p, a), 0.0, d)


Edges = list[tuple[float, float, float, float]]


def polygon_edges(poly: np.ndarray) -> Edges:
    """A polygon's edges as Python floats, for one-point tests in a hot loop.

    Parameters
    ----------
    poly : ndarray, shape (K, 2)
        The corners, in order (the last joined to the first).

    Returns
    -------
    list of (ax, ay, bx, by)
        Edge k from corner k to corner k + 1.
    """
    a = np.asarray(poly, dtype=float).reshape(-1, 2).tolist()
    return [(ax, ay, bx, by) for (ax, ay), (bx, by) in zip(a, a[1:] + a[:1], strict=True)]


def edges_contain(edges: Edges, x: float, y: float) -> bool:
    """:func:`points_in_polygon` for one point on :func:`polygon_edges`: the same
    crossing-number test, its operations on Python floats (IEEE doubles, the same
    roundings, so the same answer; a straddling edge never has dy = 0), without arrays.

    Parameters
    ----------
    edges : list of (ax, ay, bx, by)
        The polygon's edges.
    x, y : float
        The point.

    Returns
    -------
    bool
    """
    odd = False
    for ax, ay, bx, by in edges:
        if (ay > y) != (by > y) and x < ax + (y - ay) * (bx - ax) / (by - ay):
            odd = not odd
    return odd


def edges_within(edges: Edges, x: float, y: float, margin: float) -> bool | None:
    """Whether the point (x, y) lies within ``margin`` of the polygon of ``edges``
    (inside counts as 0), as ``distance_to_polygon(p, poly) <= margin`` answers; None when
    the distance is within 1e-9 (relative) of the margin, where the caller asks
    :func:`distance_to_polygon` itself.

    The nearest point of each edge is :func:`distance_to_polygon`'s (the projection
    parameter clipped to [0, 1], the same operations on Python floats); only its length
    is taken as sqrt(dx^2 + dy^2) instead of ``np.hypot``, which may differ in the last
    bit: the tolerance leaves every such difference to the array code.

    Parameters
    ----------
    edges : list of (ax, ay, bx, by)
        The polygon's edges (:func:`polygon_edges`).
    x, y : float
        The point (m).
    margin : float
        The distance (m).

    Returns
    -------
    bool or None
    """
    if edges_contain(edges, x, y):
        return 0.0 <= margin
    d2 = math.inf
    for ax, ay, bx, by in edges:
        ex, ey = bx - ax, by - ay
        u = ((x - ax) * ex + (y - ay) * ey) / max(ex * ex + ey * ey, 1e-300)
        u = min(max(u, 0.0), 1.0)
        dx, dy = ax + u * ex - x, ay + u * ey - y
        d2 = min(d2, dx * dx + dy * dy)
    d = math.sqrt(d2)
    if abs(d - margin) <= 1e-9 * max(d, margin) or not math.isfinite(d):
        return None
    return d < margin
