"""Analytic sonar ranges for the map tests (no simulator): the nearest echo within a cone.

For an infinite wall line and a sensor on its free side, the nearest point of the line
seen within the cone [axis - w, axis + w] is the foot of the perpendicular when the
wall's inward normal direction lies in the cone, else the point on the cone's edge ray
nearest to that direction, at distance p / cos(delta) (p the perpendicular distance,
delta the angle between the edge ray and the normal). In a convex room (or a strip) the
first echo of a cone is the minimum of this over the walls' lines.
"""

from __future__ import annotations

import numpy as np

from fuzzyslam.se2 import compose, wrap_angle


def cone_ranges(sensors: np.ndarray, lines: np.ndarray, half: float, rmax: float) -> np.ndarray:
    """Ranges (N,) of sensors (N, 3) to wall lines (L, 3) given as (nx, ny, c) with
    n . p = c on the line and n . p < c on the free side (unit n)."""
    s = np.asarray(sensors, float)[:, None, :]
    n = np.asarray(lines, float)[None, :, 0:2]
    c = np.asarray(lines, float)[None, :, 2]
    p = c - (n[..., 0] * s[..., 0] + n[..., 1] * s[..., 1])  # perpendicular distance
    normal_dir = np.arctan2(n[..., 1], n[..., 0])
    off = np.abs(wrap_angle(normal_dir - s[..., 2]))
    delta = np.maximum(off - half, 0.0)
    with np.errstate(divide="ignore"):
        d = np.where(delta < np.pi / 2 - 1e-9, p / np.cos(delta), np.inf)
    d = np.where(p > 0, d, np.inf)
    return np.minimum(d.min(axis=1), rmax)


def ring_in_lines(
    pose: np.ndarray, mounts: np.ndarray, lines: np.ndarray, fov: float, rmax: float
) -> np.ndarray:
    """One ring of analytic ranges from a robot at ``pose``."""
    return cone_ranges(compose(np.asarray(pose, float), mounts), lines, fov / 2, rmax)


def room_lines(xmin: float, ymin: float, xmax: float, ymax: float) -> np.ndarray:
    """The four wall lines of an axis-aligned rectangular room (free side inside)."""
    return np.array([[1, 0, xmax], [-1, 0, -xmin], [0, 1, ymax], [0, -1, -ymin]], float)


def corridor_lines(angle: float, half_width: float, centre=(0.0, 0.0)) -> np.ndarray:
    """The two wall lines of an infinite corridor along ``angle`` through ``centre``."""
    n = np.array([-np.sin(angle), np.cos(angle)])
    c0 = float(n @ np.asarray(centre, float))
    return np.array([[n[0], n[1], c0 + half_width], [-n[0], -n[1], -c0 + half_width]])
