"""Map quality against the true walls: precision and recall of wall cells within one cell.

A map cell is a wall cell when it is occupied in the nav2 picture's sense (BetP(O) >
0.65 and something is known, :func:`fuzzyslam.maps.mapio.occupancy_image`). True wall
cells are the cells the world's wall segments pass through. Precision: the fraction of
map wall cells within ``tolerance`` cells (Chebyshev distance) of a true wall cell;
recall: the fraction of true wall cells within ``tolerance`` of a map wall cell.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from fuzzyslam.maps.grid import BeliefMap, Grid
from fuzzyslam.maps.mapio import PGM_OCCUPIED, occupancy_image


@dataclass
class WallQuality:
    precision: float
    recall: float
    map_cells: int
    true_cells: int


def wall_mask(grid: Grid, walls: np.ndarray) -> np.ndarray:
    """Cells crossed by wall segments (N, 4) x0 y0 x1 y1, sampled every resolution/4.

    Parameters
    ----------
    grid : Grid
        The map's grid (ny, nx).
    walls : ndarray, shape (N, 4)
        Wall segments.

    Returns
    -------
    ndarray of bool, shape (ny, nx)
    """
    walls = np.asarray(walls, dtype=float).reshape(-1, 4)
    mask = np.zeros(grid.shape, dtype=bool)
    if len(walls) == 0:
        return mask
    length = np.hypot(walls[:, 2] - walls[:, 0], walls[:, 3] - walls[:, 1])
    n = np.maximum(np.ceil(length / (grid.resolution / 4)).astype(int), 1) + 1
    seg = np.repeat(np.arange(len(walls)), n)
    u = np.concatenate([np.linspace(0.0, 1.0, k) for k in n])
    pts = walls[seg, 0:2] + u[:, None] * (walls[seg, 2:4] - walls[seg, 0:2])
    iy, ix = grid.cell_of(pts)
    ok = grid.inside(iy, ix)
    mask[iy[ok], ix[ok]] = True
    return mask


def map_wall_mask(bm: BeliefMap) -> np.ndarray:
    """Occupied cells of the map (row 0 at the origin's y, like the masses).

    Parameters
    ----------
    bm : BeliefMap
        The FGM (masses (ny, nx)).

    Returns
    -------
    ndarray of bool, shape (ny, nx)
    """
    return np.flipud(occupancy_image(bm)) == PGM_OCCUPIED


def wall_quality(bm: BeliefMap, walls: np.ndarray, tolerance: int = 1) -> WallQuality:
    """Precision/recall of the map's wall cells against true walls (module docstring).

    Parameters
    ----------
    bm : BeliefMap
        The FGM (masses (ny, nx)).
    walls : ndarray, shape (N, 4)
        True wall segments.
    tolerance : int
        Cells a wall may be off.

    Returns
    -------
    WallQuality
    """
    truth = wall_mask(bm.grid, walls)
    found = map_wall_mask(bm)
    k = np.ones((2 * tolerance + 1, 2 * tolerance + 1), np.uint8)
    near_truth = cv2.dilate(truth.astype(np.uint8), k).astype(bool)
    near_found = cv2.dilate(found.astype(np.uint8), k).astype(bool)
    nf, nt = int(found.sum()), int(truth.sum())
    precision = float((found & near_truth).sum() / nf) if nf else 0.0
    recall = float((truth & near_found).sum() / nt) if nt else 0.0
    return WallQuality(precision, recall, nf, nt)
