"""The fuzzy global map (FGM): sonar rings placed along a trajectory, fused per cell.

Per ring (models.md sec. 6; the paper's sec. 3):

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
from fuzzyslam.maps.grid import BeliefMap, Grid
from fuzzyslam.maps.params import MapParams
from fuzzyslam.maps.tbm import Masses, clip_masses, conjunctive, discount, forgetting_factor


class FrozenMapError(RuntimeError):
    """An update was attempted on a frozen FGM."""


def grid_for_path(xy: np.ndarray, params: MapParams) -> Grid:
    """Grid covering the path's extent plus ``params.margin`` on every side."""
    xy = np.asarray(xy, dtype=float).reshape(-1, 2)
    if len(xy) == 0 or not np.all(np.isfinite(xy)):
        raise ValueError("the path is empty or not finite")
    lo = xy.min(0) - params.margin
    hi = xy.max(0) + params.margin
    return Grid.covering(lo[0], lo[1], hi[0], hi[1], params.resolution)


def _flat(m: BeliefMap) -> tuple[np.ndarray, ...]:
    """Flat views of a BeliefMap's four mass arrays (writes go to the map)."""
    return (m.m_e.reshape(-1), m.m_o.reshape(-1), m.m_t.reshape(-1), m.m_c.reshape(-1))


def _update(flat: tuple[np.ndarray, ...], idx: np.ndarray, ev: Masses, gamma: float) -> None:
    """One FGM step on distinct cells ``idx``: m <- clip(discount(m, 1 - gamma m(emptyset))
    (conj) ev) (module docstring)."""
    stored = tuple(f[idx].astype(float) for f in flat)
    alpha = forgetting_factor(stored[3], gamma)
    new = clip_masses(conjunctive(discount(stored, alpha), ev))
    for f, val in zip(flat, new, strict=True):
        f[idx] = val


def fuse_ranked(
    bm: BeliefMap, ring_of: np.ndarray, cells: np.ndarray, masses: Masses, gamma: float
) -> int:
    """Fuse the evidence of a batch of rings into ``bm`` in time order, exactly as ring
    after ring, in as many vectorised steps as the most-seen cell has rings (not one per
    ring). Returns that number of steps.

    Cells are independent: the forgetting factor of a cell depends only on its own
    conflict, so the discount-and-combine sequence of each cell needs only its OWN
    evidence in ring order. The pairs (ring ``ring_of``, cell ``cells``; cells distinct
    within a ring) are ranked within their cell by ring (a lexicographic sort);
    step j updates every cell with its j-th piece of evidence at once. Each cell sees the
    same operations in the same order as in the ring-by-ring path, so the result is the
    same to the last bit (a state-dependent discount admits no closed-form product over a
    cell's evidence, unlike the plain conjunctive rule, so the sequence is kept).
    """
    n = cells.size
    if n == 0:
        return 0
    by_cell = np.lexsort((ring_of, cells))  # by cell, then by ring
    sc = cells[by_cell]
    first = np.flatnonzero(np.concatenate([[True], sc[1:] != sc[:-1]]))
    size = np.diff(np.append(first, n))
    rank = np.arange(n) - np.repeat(first, size)
    order = by_cell[np.argsort(rank, kind="stable")]
    counts = np.bincount(rank)
    flat = _flat(bm)
    ends = np.cumsum(counts)
    for a, b in zip(ends - counts, ends, strict=True):  # one step per rank, not per cell
        sel = order[a:b]
        _update(flat, cells[sel], tuple(x[sel] for x in masses), gamma)
    return len(counts)


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
        """Fuse one ring taken at robot ``pose`` (map frame); returns the cells touched."""
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
    ) -> int:
        """Fuse K rings in time order: poses (K, 3), ranges and max ranges (K, M).

        The evidence of all K rings is computed in one vectorised pass
        (:func:`fuzzyslam.maps.evidence.rings_evidence`), then fused by :func:`fuse_ranked`
        (exactly the ring-by-ring result, in far fewer vectorised steps). Returns the number
        of (ring, cell) updates.
        """
        if self.frozen:
            raise FrozenMapError("the FGM is frozen; it accepts no more readings")
        ev = rings_evidence(self.grid, poses, ranges, max_range, fov, mounts, self.params)
        ring_of = np.repeat(np.arange(len(ev.ptr) - 1), np.diff(ev.ptr))
        fuse_ranked(self.map, ring_of, ev.cells, ev.masses, self.params.forgetting_gamma)
        self.rings += len(ev.ptr) - 1
        self.readings += ev.readings
        self.cell_updates += ev.pairs
        return int(ev.cells.size)

    def add_rings_reference(
        self,
        poses: np.ndarray,
        ranges: np.ndarray,
        max_range: np.ndarray | float,
        fov: float,
        mounts: np.ndarray,
    ) -> int:
        """The reference path of :meth:`add_rings`: discount-and-combine ring after ring,
        each step vectorised over the ring's cells (kept for tests and benchmarks)."""
        if self.frozen:
            raise FrozenMapError("the FGM is frozen; it accepts no more readings")
        ev = rings_evidence(self.grid, poses, ranges, max_range, fov, mounts, self.params)
        flat = _flat(self.map)
        gamma = self.params.forgetting_gamma
        for k in range(len(ev.ptr) - 1):  # sequential over rings, vectorised over cells
            a, b = int(ev.ptr[k]), int(ev.ptr[k + 1])
            if a < b:
                _update(flat, ev.cells[a:b], tuple(x[a:b] for x in ev.masses), gamma)
        self.rings += len(ev.ptr) - 1
        self.readings += ev.readings
        self.cell_updates += ev.pairs
        return int(ev.cells.size)

    def freeze(self, t: float | None = None) -> BeliefMap:
        """Stop updating; returns the map (further :meth:`add_ring` calls raise)."""
        self.frozen = True
        self.freeze_time = t
        return self.map
