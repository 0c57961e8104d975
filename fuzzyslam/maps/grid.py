"""Grid geometry and per-cell belief masses: the data contract of every fuzzy map.

A :class:`Grid` maps world (or robot-frame) coordinates to cells: cell (iy, ix)
covers x in [ox + ix*res, ox + (ix+1)*res) and y in [oy + iy*res, oy + (iy+1)*res),
so row 0 is at the origin's y (as in nav2's OccupancyGrid; flip rows for a picture).

A :class:`BeliefMap` holds, per cell, the masses of Smets' transferable belief
model on the frame {E (empty), O (occupied)}: m(E), m(O), m(Theta) (don't know)
and m(emptyset) (conflict), which always sum to 1 (docs/models.md sec. 6).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

MAX_CELLS = 100_000_000  # cells a map may have (4 float32 masses each: 1.6 GB)


@dataclass(frozen=True)
class Grid:
    """Regular grid: origin (lower-left corner of cell (0, 0)), cell size, (ny, nx)."""

    origin: tuple[float, float]
    resolution: float
    shape: tuple[int, int]

    @classmethod
    def centred(cls, cells: int, resolution: float) -> Grid:
        """Square grid of ``cells`` x ``cells`` centred on (0, 0) (the FLM's frame)."""
        half = cells * resolution / 2.0
        return cls((-half, -half), float(resolution), (int(cells), int(cells)))

    @classmethod
    def covering(
        cls, xmin: float, ymin: float, xmax: float, ymax: float, resolution: float
    ) -> Grid:
        """Smallest grid with cells aligned to multiples of ``resolution`` covering a box."""
        ox = np.floor(xmin / resolution) * resolution
        oy = np.floor(ymin / resolution) * resolution
        nx = int(np.ceil((xmax - ox) / resolution))
        ny = int(np.ceil((ymax - oy) / resolution))
        return cls((float(ox), float(oy)), float(resolution), (max(ny, 1), max(nx, 1)))

    def cell_of(self, pts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(iy, ix) integer indices of points (N, 2); may be out of range.

        Parameters
        ----------
        pts : ndarray, shape (N, 2)
            Points (m).

        Returns
        -------
        iy, ix : ndarray of int, shape (N,)
        """
        p = np.asarray(pts, dtype=float).reshape(-1, 2)
        ix = np.floor((p[:, 0] - self.origin[0]) / self.resolution).astype(np.int64)
        iy = np.floor((p[:, 1] - self.origin[1]) / self.resolution).astype(np.int64)
        return iy, ix

    def inside(self, iy: np.ndarray, ix: np.ndarray) -> np.ndarray:
        """Whether cell indices lie on the grid.

        Parameters
        ----------
        iy, ix : ndarray of int, shape (N,)
            Cell indices.

        Returns
        -------
        ndarray of bool, shape (N,)
        """
        return (iy >= 0) & (iy < self.shape[0]) & (ix >= 0) & (ix < self.shape[1])

    def centres(self) -> tuple[np.ndarray, np.ndarray]:
        """(ny, nx) arrays X, Y of cell-centre coordinates (read-only, computed once per
        grid: the heading aid asks for the FLM grid's at every ring).

        Returns
        -------
        X, Y : ndarray, shape (ny, nx)
        """
        return _centres(self)

    def box_centres(self, box: tuple[slice, slice]) -> tuple[np.ndarray, np.ndarray]:
        """X, Y of the cell centres in ``box`` (rows, columns), equal to
        ``centres()`` sliced by it to the last bit, without the whole grid's arrays.

        Parameters
        ----------
        box : tuple of slice
            Rows and columns (steps of 1, within the grid).

        Returns
        -------
        X, Y : ndarray, shape (rows, columns)
        """
        rows, cols = (range(*b.indices(n)) for b, n in zip(box, self.shape, strict=True))
        return np.meshgrid(_cell_centres(self.origin[0], cols, self.resolution),
                           _cell_centres(self.origin[1], rows, self.resolution))  # fmt: skip

    @property
    def extent(self) -> tuple[float, float, float, float]:
        """(xmin, xmax, ymin, ymax), for matplotlib's imshow(origin='lower')."""
        ox, oy = self.origin
        return (ox, ox + self.shape[1] * self.resolution, oy, oy + self.shape[0] * self.resolution)


def _cell_centres(origin: float, cells: range, resolution: float) -> np.ndarray:
    """Centres of the cells ``cells`` along one axis (one formula for every caller)."""
    return origin + (np.arange(cells.start, cells.stop) + 0.5) * resolution


@lru_cache(maxsize=16)
def _centres(grid: Grid) -> tuple[np.ndarray, np.ndarray]:
    """:meth:`Grid.centres`, read-only (shared by every caller of the same grid)."""
    xs = _cell_centres(grid.origin[0], range(grid.shape[1]), grid.resolution)
    ys = _cell_centres(grid.origin[1], range(grid.shape[0]), grid.resolution)
    out = np.meshgrid(xs, ys)
    for a in out:
        a.flags.writeable = False
    return out[0], out[1]


@dataclass
class BeliefMap:
    """Per-cell masses m(E), m(O), m(Theta), m(conflict) (float32, each ``grid.shape``)."""

    grid: Grid
    m_e: np.ndarray
    m_o: np.ndarray
    m_t: np.ndarray
    m_c: np.ndarray

    @classmethod
    def vacuous(cls, grid: Grid) -> BeliefMap:
        """Total ignorance: m(Theta) = 1 everywhere."""
        z = np.zeros(grid.shape, dtype=np.float32)
        return cls(grid, z.copy(), z.copy(), np.ones(grid.shape, dtype=np.float32), z.copy())

    def copy(self) -> BeliefMap:
        """An independent copy (the grid shared).

        Returns
        -------
        BeliefMap
        """
        return BeliefMap(
            self.grid, self.m_e.copy(), self.m_o.copy(), self.m_t.copy(), self.m_c.copy()
        )

    def belief_occupied(self) -> np.ndarray:
        """bel(O) = m(O).

        Returns
        -------
        ndarray, shape (ny, nx)
        """
        return self.m_o

    def plausibility_occupied(self) -> np.ndarray:
        """pl(O) = m(O) + m(Theta).

        Returns
        -------
        ndarray, shape (ny, nx)
        """
        return self.m_o + self.m_t

    def pignistic_occupied(self) -> np.ndarray:
        """BetP(O) = (m(O) + m(Theta)/2) / (1 - m(emptyset)) (Smets & Kennes 1994).

        Returns
        -------
        ndarray, shape (ny, nx)
        """
        denom = np.maximum(1.0 - self.m_c, 1e-6)
        return (self.m_o + 0.5 * self.m_t) / denom
