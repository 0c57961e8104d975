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
    return [r for r in refs if distance_to_polygon(p, r.polygon)[0] <= margin]
