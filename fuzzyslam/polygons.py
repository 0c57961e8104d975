"""Planar polygons: the point-in-polygon test and the distance to a polygon.

A polygon is its corners (K, 2) in order (either sense), K >= 3, the last joined to the
first. Inside is the crossing-number rule (W. R. Franklin, PNPOLY): a point is inside
when a ray towards +x crosses the polygon's edges an odd number of times.
"""

from __future__ import annotations

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
