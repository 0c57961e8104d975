"""The simulated world: corridor walls, corridors and ceiling lamps from WorldParams (pure).

The corridors are the edges of a closed centre-line polygon. Walls are the polygon
offset by +-w/2 with mitred corners: for a vertex P with unit left normals n1, n2
of its incoming and outgoing edges, the offset vertex is

    P + d (n1 + n2) / (1 + n1 . n2)

(the intersection of the two offset lines). Corridor i is the quadrilateral between
the offset vertices of its two ends, so the corridors tile the loop.
"""

from __future__ import annotations

from bisect import bisect_right

import numpy as np

from fuzzyslam.errors import ConfigError
from fuzzyslam.se2 import direction_mod_pi
from fuzzyslam.sim.params import CameraParams, WorldParams
from fuzzyslam.streams.logmeta import Corridor, World


def centreline_array(params: WorldParams, source: str = "config") -> np.ndarray:
    """(N, 2) centre-line vertices, validated (>= 3 distinct vertices, no zero-length edge).

    Parameters
    ----------
    params : WorldParams
        The config's ``world:`` section.
    source : str
        The config's name (for error messages).

    Returns
    -------
    ndarray, shape (N, 2)
    """
    pts = np.asarray(params.centerline, dtype=float)
    if pts.ndim != 2 or pts.shape[1] != 2 or len(pts) < 3:
        raise ConfigError(source, "'world.centerline' must be a list of >= 3 [x, y] points")
    if np.any(np.linalg.norm(np.roll(pts, -1, axis=0) - pts, axis=1) < 1e-6):
        raise ConfigError(source, "'world.centerline' has two equal consecutive points")
    return pts


def offset_loop(pts: np.ndarray, d: float) -> np.ndarray:
    """Closed polygon offset by ``d`` to the left of its direction (mitred corners).

    Parameters
    ----------
    pts : ndarray, shape (N, 2)
        The closed polygon.
    d : float
        The offset (m; negative: to the right).

    Returns
    -------
    ndarray, shape (N, 2)
    """
    e_in = pts - np.roll(pts, 1, axis=0)
    e_out = np.roll(pts, -1, axis=0) - pts
    n_in = np.column_stack([-e_in[:, 1], e_in[:, 0]]) / np.linalg.norm(e_in, axis=1)[:, None]
    n_out = np.column_stack([-e_out[:, 1], e_out[:, 0]]) / np.linalg.norm(e_out, axis=1)[:, None]
    denom = 1.0 + np.sum(n_in * n_out, axis=1)
    return pts + d * (n_in + n_out) / denom[:, None]


def loop_length(pts: np.ndarray) -> float:
    """The perimeter of a closed polyline.

    Parameters
    ----------
    pts : ndarray, shape (N, 2)
        Its vertices.

    Returns
    -------
    float
        The length (m).
    """
    return float(np.sum(np.linalg.norm(np.roll(pts, -1, axis=0) - pts, axis=1)))


class Loop:
    """A closed polyline (N, 2) with its edges, their lengths and the cumulative arc
    length at each vertex, computed once for many ``at`` queries (the drive)."""

    def __init__(self, pts: np.ndarray) -> None:
        self.pts = pts
        self.edges = np.roll(pts, -1, axis=0) - pts
        self.lens = np.linalg.norm(self.edges, axis=1)
        self.cum = np.concatenate([[0.0], np.cumsum(self.lens)])
        # the same numbers as Python floats, for the one-point queries of the drive
        self._rows = list(zip(pts.tolist(), self.edges.tolist(), self.lens.tolist(), strict=True))
        self._cum = self.cum.tolist()

    def at(self, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Points (N, 2) and unit tangents (N, 2) at arc lengths ``s`` (mod the length).

        Parameters
        ----------
        s : ndarray, shape (N,)
            Arc lengths (m).

        Returns
        -------
        points, tangents : ndarray, shape (N, 2)
        """
        cum = self.cum
        s = np.mod(np.asarray(s, dtype=float), cum[-1])
        # integer indices: minimum(maximum()) is np.clip without its call overhead
        i = np.minimum(np.maximum(np.searchsorted(cum, s, side="right") - 1, 0), len(self.pts) - 1)
        tang = self.edges[i] / self.lens[i, None]
        return self.pts[i] + tang * (s - cum[i])[:, None], tang

    def at1(self, s: float) -> tuple[float, float, float, float]:
        """:meth:`at` of one arc length on Python floats (the drive's hot path; the same
        operations, so the same floats: float % is np.mod, bisect_right is searchsorted).

        Parameters
        ----------
        s : float
            Arc length (m).

        Returns
        -------
        tuple of 4 float
            The point (x, y) and the unit tangent (tx, ty).
        """
        cum = self._cum
        s = float(s) % cum[-1]
        i = min(max(bisect_right(cum, s) - 1, 0), len(self._rows) - 1)
        (px, py), (ex, ey), ln = self._rows[i]
        tx, ty = ex / ln, ey / ln
        d = s - cum[i]
        return px + tx * d, py + ty * d, tx, ty


def point_at(pts: np.ndarray, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Points (N, 2) and unit tangents (N, 2) at arc lengths ``s`` (mod the loop length).

    Parameters
    ----------
    pts : ndarray, shape (K, 2)
        The closed polyline.
    s : ndarray, shape (N,)
        Arc lengths (m).

    Returns
    -------
    points, tangents : ndarray, shape (N, 2)
    """
    return Loop(pts).at(s)


def even_lamps(pts: np.ndarray, count: int) -> np.ndarray:
    """``count`` lamps evenly along the loop, the first half a spacing from vertex 0.

    Parameters
    ----------
    pts : ndarray, shape (K, 2)
        The centre-line loop.
    count : int
        Number of lamps.

    Returns
    -------
    ndarray, shape (count, 2)
    """
    if count == 0:
        return np.zeros((0, 2))
    spacing = loop_length(pts) / count
    return point_at(pts, (np.arange(count) + 0.5) * spacing)[0]


def _check_offsets(pts: np.ndarray, left: np.ndarray, right: np.ndarray, source: str) -> None:
    """Each wall must run the same way as its centre-line edge (else the width is too large)."""
    edges = np.roll(pts, -1, axis=0) - pts
    for poly in (left, right):
        walls = np.roll(poly, -1, axis=0) - poly
        if np.any(np.sum(walls * edges, axis=1) <= 0.0):
            raise ConfigError(
                source, "'world.corridor_width' is too large for the centre line (walls fold over)"
            )


def build_world(params: WorldParams, camera: CameraParams, source: str = "config") -> World:
    """The World (logmeta contract) of the config: walls, lamps, corridors, ceiling height.

    Parameters
    ----------
    params : WorldParams
        The config's ``world:`` section.
    camera : CameraParams
        The ceiling height.
    source : str
        The config's name (for error messages).

    Returns
    -------
    World
    """
    pts = centreline_array(params, source)
    half = params.corridor_width / 2.0
    left = offset_loop(pts, half)
    right = offset_loop(pts, -half)
    _check_offsets(pts, left, right, source)
    walls = [
        [*poly[i], *poly[(i + 1) % len(poly)]] for poly in (left, right) for i in range(len(poly))
    ]
    if params.lamps:
        lamps = np.asarray(params.lamps, dtype=float)
        if lamps.ndim != 2 or lamps.shape[1] != 2:
            raise ConfigError(source, "'world.lamps' must be a list of [x, y] points")
    else:
        lamps = even_lamps(pts, params.lamp_count)
    corridors = []
    n = len(pts)
    for i in range(n):
        j = (i + 1) % n
        a, b = pts[i], pts[j]
        axis = direction_mod_pi(np.arctan2(b[1] - a[1], b[0] - a[0]))
        poly = [left[i], left[j], right[j], right[i]]
        corridors.append(
            Corridor(
                name=f"corridor_{i}",
                a=[float(a[0]), float(a[1])],
                b=[float(b[0]), float(b[1])],
                width=float(params.corridor_width),
                axis=axis,
                polygon=[[float(p[0]), float(p[1])] for p in poly],
            )
        )
    return World(
        walls=[[float(v) for v in w] for w in walls],
        lamps=[[float(x), float(y)] for x, y in lamps],
        lamp_radius=float(params.lamp_radius),
        corridors=corridors,
        centerline=[[float(x), float(y)] for x, y in pts],
        ceiling_height=float(camera.ceiling_height),
    )
