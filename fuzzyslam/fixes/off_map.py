"""Is the estimate where the map says a robot can be? A heading aid's watch [ours].

Heading fixes correct the heading only. A filter whose position is wrong can lock its
heading onto the wrong walls and accept fix after fix with a small NIS: Freiburg 079 with
a start pose 5 m and 90 deg off had 433 fixes accepted, a 23 m mean error, and a healthy
summary. Its estimate was then mostly where the frozen map has never seen free space:
the mapping robot drove only through cells the range sensor saw empty.

:class:`OffMapWatch` keeps, per ring, whether the estimated position is farther from the
nearest free cell of the frozen map (m(E) > ``FREE_BELIEF``) than it can be wrong:
``max(MIN_DISTANCE_M, SIGMAS * sigma)``, sigma the square root of the largest
eigenvalue of the position's covariance (a filter that knows it is uncertain is not
flagged). When more than ``SHARE`` of the rings of the last ``SPAN_S`` seconds (at least
``MIN_RINGS`` of them) are off the map, the estimate is lost: ``pose_off_map`` in the
run's ``filter_health``.

Measured with the scan heading fixes on the CARMEN logs (maps from their truth): the
localised runs never have a ring off the map (ACES, whose position drifts 1.3 m mean with
a sigma of up to 1.4 m, and Freiburg), the lost Freiburg run 56 % of its rings, flagged
98 s after its start; the simulated paper scenario's heading runs (5 seeds, phases C and
D, and the paper log) none.
"""

from __future__ import annotations

import math
from collections import deque

import numpy as np

FREE_BELIEF = 0.5  # m(E) above this: a cell the map saw free
MIN_DISTANCE_M = 0.5  # within this of a free cell: on the map, however sure the filter is
SIGMAS = 3.0  # ... or within this many position sigmas
SPAN_S = 60.0  # s of rings the share is taken over
MIN_RINGS = 10  # rings needed in the span
SHARE = 0.5  # more rings off the map than this: lost


def free_distance(m_e: np.ndarray, resolution: float) -> np.ndarray:
    """The distance (m) from each cell's centre to the nearest free cell (m(E) >
    ``FREE_BELIEF``): the exact Euclidean distance transform (OpenCV ``DIST_L2`` with the
    precise mask; Felzenszwalb and Huttenlocher, "Distance transforms of sampled
    functions", Theory of Computing 8, 2012).

    Parameters
    ----------
    m_e : ndarray, shape (ny, nx)
        The frozen map's empty masses.
    resolution : float
        The cell size (m).

    Returns
    -------
    ndarray, shape (ny, nx)
        0 on free cells; inf everywhere when no cell is free.
    """
    import cv2

    free = np.asarray(m_e) > FREE_BELIEF
    if not free.any():
        return np.full(free.shape, np.inf)
    src = np.where(free, 0, 255).astype(np.uint8)  # the transform's zeros: the free cells
    return cv2.distanceTransform(src, cv2.DIST_L2, cv2.DIST_MASK_PRECISE) * resolution


class OffMapWatch:
    """The rings' share off the frozen map (module docstring).

    Parameters
    ----------
    fgm : BeliefMap
        The frozen map (its grid and m(E)).
    """

    def __init__(self, fgm) -> None:
        self.grid = fgm.grid
        self.distance = free_distance(fgm.m_e, fgm.grid.resolution)
        self._recent: deque[tuple[float, bool]] = deque()
        self._off = 0
        self.rings_off = 0
        self.found_at: float | None = None

    def observe(self, t: float, x: float, y: float, lam: float) -> None:
        """One ring's estimate: position (x, y) and the largest eigenvalue ``lam`` of its
        2x2 covariance.

        Parameters
        ----------
        t : float
            The ring's time (s).
        x, y : float
            The estimated position (m).
        lam : float
            lambda_max of the position's covariance (m^2).
        """
        g = self.grid
        ix = math.floor((x - g.origin[0]) / g.resolution)
        iy = math.floor((y - g.origin[1]) / g.resolution)
        ny, nx = self.distance.shape
        d = float(self.distance[iy, ix]) if 0 <= ix < nx and 0 <= iy < ny else math.inf
        off = d > max(MIN_DISTANCE_M, SIGMAS * math.sqrt(max(lam, 0.0)))
        self.rings_off += off
        self._recent.append((t, off))
        self._off += off
        while self._recent and self._recent[0][0] < t - SPAN_S:
            self._off -= self._recent.popleft()[1]
        n = len(self._recent)
        if self.found_at is None and n >= MIN_RINGS and self._off > SHARE * n:
            self.found_at = t
