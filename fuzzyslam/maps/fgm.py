"""The fuzzy global map (FGM): sonar rings placed along a trajectory, fused per cell.

Per ring (docs/models.md sec. 6; the paper's sec. 3):

1. the ring's evidence on the cells of its cones (:func:`evidence.ring_evidence`);
2. forgetting: each touched cell's stored masses are discounted with reliability
   alpha = 1 - gamma * m_stored(emptyset), so contradicted cells (placed by wrong poses)
   forget their old evidence;
3. Smets' unnormalised conjunctive combination of the discounted masses with the ring's.

After :meth:`FgmBuilder.freeze` the map is read-only (the paper suspends the update once
SLAM has converged and uses the map as a reference).
"""

from __future__ import annotations

import numpy as np

from fuzzyslam.maps.evidence import rings_evidence
from fuzzyslam.maps.grid import MAX_CELLS, BeliefMap, Grid
from fuzzyslam.maps.params import MapParams
from fuzzyslam.maps.tbm import Masses, clip_masses, conjunctive, discount, forgetting_factor


class FrozenMapError(RuntimeError):
    """An update was attempted on a frozen FGM."""


def grid_for_path(xy: np.ndarray, params: MapParams) -> Grid:
    """Grid covering the path's extent plus ``params.margin`` on every side.

    Parameters
    ----------
    xy : ndarray, shape (N, 2)
        The path's positions (finite).
    params : MapParams
        ``resolution`` and ``margin`` (ValueError beyond MAX_CELLS cells).

    Returns
    -------
    Grid
    """
    xy = np.asarray(xy, dtype=float).reshape(-1, 2)
    if len(xy) == 0 or not np.all(np.isfinite(xy)):
        raise ValueError("the path is empty or not finite")
    lo = xy.min(0) - params.margin
    hi = xy.max(0) + params.margin
    cells = float(np.prod(np.ceil((hi - lo) / params.resolution) + 1.0))
    if cells > MAX_CELLS:
        span = hi - lo
        raise ValueError(
            f"the path spans {span[0]:.3g} x {span[1]:.3g} m: {cells:.3g} cells of "
            f"{params.resolution} m, more than {MAX_CELLS}"
        )
    return Grid.covering(lo[0], lo[1], hi[0], hi[1], params.resolution)


def _step(stored: np.ndarray, ev: Masses, gamma: float) -> np.ndarray:
    """One FGM step on the stored masses (4, n) of n distinct cells:
    m <- clip(discount(m, 1 - gamma m(emptyset)) (conj) ev) (module docstring); float64
    arithmetic, returned as (4, n) to be stored in the map's float32."""
    m = tuple(stored.astype(float))
    return np.array(clip_masses(conjunctive(discount(m, forgetting_factor(m[3], gamma)), ev)))


class FgmBuilder:
    """Accumulates sonar rings into a :class:`BeliefMap` with contradiction-driven forgetting.

    Attributes: ``map`` (the BeliefMap), ``frozen``, ``freeze_time``, ``rings`` (rings
    added), ``readings`` (readings used), ``cell_updates`` (reading x cell evidence terms).
    """

    def __init__(self, grid: Grid, params: MapParams) -> None:
        self.params = params
        self.map = BeliefMap.vacuous(grid)
        self.frozen = False
        self.freeze_time: float | None = None
        self.rings = 0
        self.readings = 0
        self.cell_updates = 0

    @classmethod
    def for_path(cls, xy: np.ndarray, params: MapParams) -> FgmBuilder:
        return cls(grid_for_path(xy, params), params)

    @property
    def grid(self) -> Grid:
        return self.map.grid

    def add_ring(
        self,
        pose: np.ndarray,
        ranges: np.ndarray,
        max_range: np.ndarray | float,
        fov: float,
        mounts: np.ndarray,
    ) -> int:
        """Fuse one ring taken at robot ``pose`` (map frame); returns the cells touched.

        Parameters
        ----------
        pose : ndarray, shape (3,)
            The robot's pose (map frame).
        ranges : ndarray, shape (M,)
            The readings (NaN: none).
        max_range : ndarray, shape (M,), or float
            The maximum ranges.
        fov : float
            The cone's full angle (rad).
        mounts : ndarray, shape (M, 3)
            The sensors' poses on the robot.

        Returns
        -------
        int
            The cells touched.
        """
        ranges = np.asarray(ranges, dtype=float).reshape(1, -1)
        rmax = np.broadcast_to(np.asarray(max_range, dtype=float), ranges.shape[1:])
        return self.add_rings(np.asarray(pose, float)[None], ranges, rmax[None], fov, mounts)

    def add_rings(
        self,
        poses: np.ndarray,
        ranges: np.ndarray,
        max_range: np.ndarray | float,
        fov: float,
        mounts: np.ndarray,
        only: np.ndarray | None = None,
        on: Grid | None = None,
    ) -> int:
        """Fuse K rings in time order: poses (K, 3), ranges and max ranges (K, M).

        The evidence of all K rings is computed in one vectorised pass
        (:func:`fuzzyslam.maps.evidence.rings_evidence`); the per-cell
        discount-and-combine then runs ring after ring, each step vectorised over the
        ring's cells. Returns the number of (ring, cell) updates.

        Why not combine a cell's evidence across rings at once: the forgetting factor
        alpha = 1 - gamma m(emptyset) depends on the cell's running conflict, so unlike
        the plain conjunctive rule the sequence has no closed-form product. Exact
        grouping is still possible (step j updates every cell with its j-th piece of
        evidence: cells are independent), but wall cells are seen by most rings of a
        batch, so the steps fell only from 2003 to 1796 / 1097 / 626 (batches of 64 /
        256 / 1024 rings, paper log) while scattered gathers replaced contiguous slices:
        measured 1.1-1.6x SLOWER than this loop (paper log: 0.16 s of combination in all,
        against ~0.25 s of evidence).

        Parameters
        ----------
        poses : ndarray, shape (K, 3)
            The robot's poses (map frame), in time order.
        ranges : ndarray, shape (K, M)
            The readings (NaN: none).
        max_range : ndarray, shape (K, M), or float
            The maximum ranges.
        fov : float
            The cone's full angle (rad).
        mounts : ndarray, shape (M, 3)
            The sensors' poses on the robot.
        only : ndarray of bool, shape (ny nx,), or None
            Fuse into these cells only (flat index iy nx + ix), the others left as they
            are: a cell's masses are the fold of its own evidence in time order, so the
            cells kept get the same floats as a fusion of the whole rings (the live
            map's partial refill, ``fixes.live_map.LiveFgm``). None: every cell.
        on : Grid or None
            The grid to compute the evidence on, when the map's grid grew since the
            rings were meant for it: its cells are the map's, offset by whole cells
            (``fixes.live_map.grown_grid``), and its cell centres' floats those of that
            grid. None: the map's grid.

        Returns
        -------
        int
            The cell updates (a cell touched by two rings counts twice).
        """
        if self.frozen:
            raise FrozenMapError("the FGM is frozen; it accepts no more readings")
        on = self.grid if on is None else on
        ev = rings_evidence(on, poses, ranges, max_range, fov, mounts, self.params)
        m = self.map
        # cell (iy, ix) of ``on`` is (iy + dr, ix + dc) of the map's grid
        res, nx0, nx = on.resolution, on.shape[1], self.grid.shape[1]
        dr = round((on.origin[1] - self.grid.origin[1]) / res)
        dc = round((on.origin[0] - self.grid.origin[0]) / res)
        moved = on is not self.grid and (dr, dc, nx0) != (0, 0, nx)
        # flat views of the four mass arrays: only the cells a ring touches are read and
        # written (no copy of the whole map: the live map of fixes/live_map.py adds its
        # rings one by one to a grid of a building)
        arrays = (m.m_e, m.m_o, m.m_t, m.m_c)
        flat = [a.reshape(-1) for a in arrays]
        if any(not np.may_share_memory(f, a) for f, a in zip(flat, arrays, strict=True)):
            raise ValueError("the map's mass arrays must be contiguous")
        gamma = self.params.forgetting_gamma
        for k in range(len(ev.ptr) - 1):  # sequential over rings, vectorised over cells
            a, b = int(ev.ptr[k]), int(ev.ptr[k + 1])
            if a < b:
                idx = ev.cells[a:b]
                if moved:
                    idx = (idx // nx0 + dr) * nx + (idx % nx0 + dc)
                piece = tuple(x[a:b] for x in ev.masses)
                if only is not None:
                    keep = np.flatnonzero(only[idx])
                    if keep.size == 0:
                        continue
                    idx = idx.take(keep)
                    piece = tuple(x.take(keep) for x in piece)
                stored = np.stack([f[idx] for f in flat])
                new = _step(stored, piece, gamma)
                for f, row in zip(flat, new, strict=True):
                    f[idx] = row
        self.rings += len(ev.ptr) - 1
        self.readings += ev.readings
        self.cell_updates += ev.pairs
        return int(ev.cells.size)

    def freeze(self, t: float | None = None) -> BeliefMap:
        """Stop updating; returns the map (further :meth:`add_ring` calls raise).

        Parameters
        ----------
        t : float or None
            The freeze time (s), kept with the map.

        Returns
        -------
        BeliefMap
            The frozen FGM.
        """
        self.frozen = True
        self.freeze_time = t
        return self.map
