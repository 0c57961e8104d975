"""Grid SLAM without lamps: pose fixes against the map of the keyframes before
(``fuzzyslam run --live-map``; docs/models.md sec. 10b).

A log without lamps and without a trajectory from elsewhere had only its dead reckoning
to place the readings by. Here the FGM is built while the robot localises on it: the
incremental scan-to-map scheme of Hector SLAM (Kohlbrecher, Meyer, von Stryk and
Klingauf, "A flexible and scalable SLAM system with full 3D motion estimation", SSRR
2011), with the fuzzy map's evidence and forgetting and the correlative match of the
pose fixes (:class:`fuzzyslam.fixes.pose_aid.PoseFixAid`: its windows, gate and
relocalisation). Per ring:

1. once the robot has moved ``pose_min_travel`` or turned ``pose_min_turn_deg`` since
   the last applied match, the ring is matched against the map around the filter's
   prediction. The template is a laser scan's echo end points within ``live_reach``
   (:func:`end_points`; its beams are narrow) or a sonar ring's FLM;
2. the ring is then fused into the map at the filter's pose after that match: a
   *keyframe*. A ring is never matched against itself, and a match refused as
   disagreeing with the map (``gated``, ``edge``, ``no_match``) is not fused.

Why keyframes only. Rings fused between matches sit at poses predicted by the odometry;
the next match then finds the odometry's own drift in the map and corrects nothing
(measured on Freiburg 079, laser: every scan fused, mean error 0.85-2.9 m by the match
covariance and a heading that drifted -30 deg over the log with the odometry's bias;
keyframes only: 0.30 m). A laser's match covariance is inflated by ``live_cov_scale``,
not by the frozen map's correlation model (``fixes/params.py``); a sonar ring's FLM match
keeps the latter (its own covariance is too small to build a map on).

The map grows with the robot (:class:`LiveFgm`: the grid re-allocated larger, its
cells kept, when a ring reaches past its edge), and the matcher reads it as it is at
each match (:class:`LiveMatcher`: the lookup maps of the searched patch only).

With ``live_right_angles`` a laser's heading is also fixed against the building's own
wall direction (:class:`LiveRightAngleHeading`), which bounds the heading's drift in a
building whose walls meet at right angles.

Loops (a laser's, ``live_close_loops``). Each keyframe is also a node of a pose graph
(:class:`KeyframeGraph`: odometry, scan-match and loop edges). With
``live_close_online`` a keyframe whose loop edge moves the graph's solution by a cell or
more closes the loop during the run: the keyframes take the solution's poses, the map is
fused again from them (:meth:`LiveFgm.refill`) and the filter is moved onto the newest
keyframe's (``LiveMapPoseAid._close_online``), so the walls the robot comes back to are
where they were first seen, not a second copy. After the run the graph is solved once
more and every ring's pose moved with its keyframes: trajectory_closed.tum. A loop that
comes back beyond the search windows is refused as a match (``gated``) and not fused, so
it adds no keyframe and closes nothing; the forgetting factor thins the second copy of
its walls where the two contradict. The filter's covariance is relative to the map, not
to the world: its NEES against a true trajectory grows with the drift.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from fuzzyslam.errors import FuzzyslamError
from fuzzyslam.fixes.params import FixParams
from fuzzyslam.fixes.pose_aid import PoseFixAid
from fuzzyslam.fixes.pose_graph import optimise
from fuzzyslam.fixes.pose_match import PoseMatch, PoseMatcher, lookup_channels
from fuzzyslam.fixes.scan_heading import ScanLineHeadingAid, scan_segments, search_window
from fuzzyslam.fixes.scan_lines import family_direction, scan_end_points
from fuzzyslam.fixes.summaries import HeadingSummary, PoseSummary
from fuzzyslam.maps.evidence import reading_kinds
from fuzzyslam.maps.fgm import FgmBuilder
from fuzzyslam.maps.grid import MAX_CELLS, BeliefMap, Grid
from fuzzyslam.maps.params import MapParams
from fuzzyslam.references import Reference
from fuzzyslam.se2 import between, compose, inverse, jacobians_compose, wrap_angle_scalar
from fuzzyslam.slam.events import FilterView

# the map grows by at least this much (m) on a side it outgrows (amortised copies), and
# the first grid reaches this far from the start
GROW_STEP_M = 16.0
# a ring whose cone is at most this wide (deg) has narrow beams (a laser): its end points
# are its template and its wall lines measure the heading
NARROW_BEAM_DEG = 5.0
# the building's wall direction is learnt from at least this many metres of wall
LEARN_MIN_WALL_M = 10.0
# the building's right angles checked (LiveRightAngleHeading._walls_seen): a scan whose
# wall family across the building's direction lies more than OFF_RIGHT_ANGLE_DEG from 90
# deg to its family along it, in more than OFF_SHARE of the scans seeing both (at least
# OFF_MIN of them), is a building some of whose corridors are off its right angles
OFF_RIGHT_ANGLE_DEG = 3.0
OFF_SHARE = 0.05
OFF_MIN = 10
# matches that leave the ring out of the map: they disagree with it
NOT_FUSED = frozenset({"gated", "edge", "no_match"})
# keyframes fused in one vectorised pass (an online loop closure's refill, a graph edge's map)
REFILL_BATCH = 64
# an online closure's map is fused again where it is next read (LiveFgm.fresh), this far
# around the cells read (m): the next reads nearby find them done
REFRESH_MARGIN_M = 16.0
# ... or all of it, when more than this fraction of the keyframes reach the cells read
# (their rings' evidence is most of a fusion's cost, whatever cells it is kept for)
REFRESH_ALL = 0.5

# the pose graph of the keyframes (KeyframeGraph). Odometry edges: 2 cm + 5 % of the
# distance, 0.5 deg + 1 deg per root metre (1 sigma), looser than the filter's white
# model to hold the systematic errors of real odometry (the development logs': 1 % of
# scale, 0.05 deg/m of bias, 2 % random)
ODO_SIGMA_M = (0.02, 0.05)
ODO_SIGMA_DEG = (0.5, 1.0)
# a keyframe is matched against the map of the SEQUENTIAL keyframes before it, and, as a
# loop, against the map of an old keyframe (at least LOOP_MIN_GAP keyframes before, the
# nearest within LOOP_RADIUS_M) and LOOP_SPAN on each side of it
SEQUENTIAL = 4
LOOP_MIN_GAP = 40
LOOP_RADIUS_M = 2.0
LOOP_SPAN = 2
# the prior window of those matches (1 sigma): the estimate's relative poses are this good
PAIR_SIGMA_M = 0.3
PAIR_SIGMA_DEG = 5.0
# with heading fixes against the building (live_right_angles), each keyframe's heading is
# held to the run's within this (1 sigma): those fixes are absolute, the graph's edges
# relative (measured heading error of the runs: 0.9-1.6 deg)
HEADING_PRIOR_DEG = 2.0
# the graph's solver stops when no pose moves by more than this (m, rad) in a step: a
# tenth of a millimetre, far below the 10 cm cells; from the keyframes' poses it takes
# 3-4 Gauss-Newton steps where 1e-8 took 8-12 (Freiburg 079: 206 solves in 2.6 s rather
# than 5.3 s, the trajectories' mean error the same to 0.3 mm)
SOLVE_TOL = 1e-4
# filter_health's finding live_map_inconsistent (LiveMapPoseAid.inconsistency): the
# graph's edges down-weighted by its robust kernel (beyond 3 sigmas at the solution)
# outnumber INCONSISTENT_SHARE of its loop edges, at least INCONSISTENT_MIN of them; or
# more than UNMATCHED_SHARE of the loop candidates (at least INCONSISTENT_MIN) found no
# match (a return to a mapped place whose scan does not fit the map there)
INCONSISTENT_SHARE = 0.5
UNMATCHED_SHARE = 0.4
INCONSISTENT_MIN = 10


def narrow_beams(fov: float) -> bool:
    """Whether a ring's cone is a narrow beam's (at most NARROW_BEAM_DEG): a laser's.

    Parameters
    ----------
    fov : float
        The cone's full angle (rad).

    Returns
    -------
    bool
    """
    return fov <= math.radians(NARROW_BEAM_DEG)


def grown_grid(grid: Grid, lo: np.ndarray, hi: np.ndarray, step: float) -> Grid:
    """The grid ``grid`` extended, by whole cells and at least ``step`` metres on each
    side that must grow, so that it covers the box [lo, hi]; ``grid`` itself when it
    does.

    Parameters
    ----------
    grid : Grid
        The current grid.
    lo, hi : ndarray, shape (2,)
        The box (x, y) to cover (m).
    step : float
        The least growth of a side that grows (m).

    Returns
    -------
    Grid
        Cells of the same size, its origin moved by whole cells: a cell of ``grid`` is a
        cell of the result.
    """
    res = grid.resolution
    ox, oy = grid.origin
    ny, nx = grid.shape
    g_lo = np.array([ox, oy])
    g_hi = g_lo + res * np.array([nx, ny])
    grow_lo = np.where(lo < g_lo, np.ceil((g_lo - lo + step) / res), 0).astype(int)
    grow_hi = np.where(hi > g_hi, np.ceil((hi - g_hi + step) / res), 0).astype(int)
    if not (grow_lo.any() or grow_hi.any()):
        return grid
    shape = (ny + int(grow_lo[1] + grow_hi[1]), nx + int(grow_lo[0] + grow_hi[0]))
    origin = (ox - res * int(grow_lo[0]), oy - res * int(grow_lo[1]))
    return Grid(origin, res, shape)


def end_points(
    ranges: np.ndarray, max_range: Any, mounts: np.ndarray, reach: float
) -> tuple[np.ndarray, np.ndarray]:
    """The echoes' end points of a ring of narrow beams, as a match template
    (``PoseMatcher.match_points``): each an occupied point, m(O) = 1, m(E) = 0.

    A laser's end point is where its beam met the wall, to a centimetre or two: matched
    as points, they carry that precision, where an FLM raster of the same scan moves each
    to its cell's centre (measured: a Freiburg scan matched against a map of itself at
    its own pose, 40 scans: the FLM's mean error -1.7 cm, +0.8 cm, +0.14 deg, its spread
    2.2 cm, 1.7 cm, 0.61 deg; the end points' -0.3 cm, -0.1 cm, +0.05 deg and 0.9 cm,
    0.9 cm, 0.39 deg).

    Parameters
    ----------
    ranges : ndarray, shape (M,)
        The readings (NaN: none; at or beyond the maximum range: no echo).
    max_range : ndarray, shape (M,), or float
        The maximum ranges.
    mounts : ndarray, shape (M, 3)
        The beams' poses (x, y, direction) in the robot's frame.
    reach : float
        End points farther than this from the robot are left out (m).

    Returns
    -------
    pts : ndarray, shape (N, 2)
        The end points, robot frame (m).
    masses : ndarray, shape (N, 2)
        (m(O), m(E)) = (1, 0) each.
    """
    pts = scan_end_points(ranges, max_range, mounts)  # NaN where a beam has no echo
    with np.errstate(invalid="ignore"):
        pts = pts[np.hypot(pts[:, 0], pts[:, 1]) <= reach]
    masses = np.zeros((len(pts), 2))
    masses[:, 0] = 1.0
    return pts, masses


class LiveFgm:
    """An FGM that grows with the robot: :class:`FgmBuilder` on a grid re-allocated
    larger (:func:`grown_grid`) when a ring reaches past its edge.

    After an online loop closure (:meth:`refill`) the map is fused again from its
    keyframes lazily, cell by cell, where it is next read or written (:meth:`fresh`):
    a matcher's patch, a new keyframe's cells, or all of it (:attr:`map`). A cell's
    masses are the fold of its own evidence, ring after ring in time order (sec. 6's
    discount-and-combine is per cell: m_c <- clip(discount(m_c, 1 - gamma m_c(empty))
    (conj) e_c)), so a cell fused again from every keyframe that reaches it, in time
    order, holds the same floats as a fusion of the whole map; what is never read again
    before the next closure is never fused (its keyframes moved once more).

    Parameters
    ----------
    start : ndarray, shape (2,) or (3,)
        The first position (m): the first grid reaches GROW_STEP_M around it.
    params : MapParams
        The evidence model and the cell size.
    """

    def __init__(self, start: np.ndarray, params: MapParams) -> None:
        self.params = params
        x, y = (float(v) for v in np.asarray(start, dtype=float)[:2])
        h = GROW_STEP_M
        self.builder = FgmBuilder(Grid.covering(x - h, y - h, x + h, y + h, params.resolution),
                                  params)  # fmt: skip
        self.grown = 0  # times the grid was re-allocated
        # the last refill's keyframes, their poses and reaches then, and the cells not yet
        # fused again from them (None: every cell is up to date)
        self._stale: np.ndarray | None = None
        self._n_stale = 0
        self._frames: list[Keyframe] = []
        self._poses = np.zeros((0, 3))
        self._reaches = np.zeros(0)
        self._grids: list[Grid] = []  # the grids the refill's keyframes are fused on
        self._grid_of = np.zeros(0, dtype=np.int64)  # each keyframe's, in self._grids
        self._reach_of: dict[int, tuple[Keyframe, float]] = {}  # id -> (keyframe, reach)

    @property
    def grid(self) -> Grid:
        """The map's grid as it is now (nothing fused for it)."""
        return self.builder.map.grid

    @property
    def map(self) -> BeliefMap:
        """The map as it is now, every cell up to date (:meth:`fresh` of the whole grid)."""
        ny, nx = self.grid.shape
        self.fresh(0, ny, 0, nx)
        return self.builder.map

    def _cover(self, lo: np.ndarray, hi: np.ndarray) -> None:
        """Grow the grid to cover [lo, hi], the masses (and which cells are up to date)
        kept cell for cell."""
        old = self.builder.map
        grid = grown_grid(old.grid, lo, hi, GROW_STEP_M)
        if grid is old.grid:
            return
        if float(grid.shape[0]) * grid.shape[1] > MAX_CELLS:
            raise FuzzyslamError(
                f"the live map would grow to {grid.shape[1]} x {grid.shape[0]} cells of "
                f"{grid.resolution} m, more than {MAX_CELLS}: a coarser fgm.resolution "
                "holds a path this long"
            )
        new = BeliefMap.vacuous(grid)
        r0 = round((old.grid.origin[1] - grid.origin[1]) / grid.resolution)
        c0 = round((old.grid.origin[0] - grid.origin[0]) / grid.resolution)
        ny, nx = old.grid.shape
        for a, b in zip((new.m_e, new.m_o, new.m_t, new.m_c),
                        (old.m_e, old.m_o, old.m_t, old.m_c), strict=True):  # fmt: skip
            a[r0 : r0 + ny, c0 : c0 + nx] = b
        if self._stale is not None:
            # the new cells: no keyframe of the last refill reaches them (it covered them)
            stale = np.zeros(grid.shape, dtype=bool)
            stale[r0 : r0 + ny, c0 : c0 + nx] = self._stale
            self._stale = stale
        self.builder.map = new
        self.grown += 1

    def add_ring(
        self, pose: np.ndarray, ranges: np.ndarray, max_range: Any, fov: float, mounts: np.ndarray
    ) -> None:
        """Fuse one ring at ``pose`` (:meth:`FgmBuilder.add_ring`), the grid first grown
        to hold every cell the ring's readings reach (an echo: its range plus the
        tolerance; no echo: ``no_echo_reach``; ``maps.evidence.reading_masses``) and
        those cells brought up to date (:meth:`fresh`).

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
        """
        xy = np.asarray(pose, dtype=float)[:2]
        reach = self._reach(ranges, max_range, mounts)
        self._cover(xy - reach, xy + reach)
        if self._stale is not None:
            self.fresh(*self._cells(xy - reach, xy + reach))
        self.builder.add_ring(pose, ranges, max_range, fov, mounts)

    def _reach(self, ranges: np.ndarray, max_range: Any, mounts: np.ndarray) -> float:
        """How far from the robot a ring's readings reach (m): add_ring's."""
        p = self.params
        ok, echo = reading_kinds(ranges, max_range)
        far = np.where(echo, np.asarray(ranges, dtype=float) + p.range_tolerance, p.no_echo_reach)
        mounts = np.asarray(mounts, dtype=float)
        reach = float(np.max(far[ok], initial=0.0))
        reach += float(np.max(np.hypot(mounts[..., 0], mounts[..., 1]), initial=0.0))
        return reach + 2.0 * p.resolution

    def _frame_reach(self, f: Keyframe) -> float:
        """:meth:`_reach` of a keyframe's ring, kept (it does not depend on the pose)."""
        got = self._reach_of.get(id(f))
        if got is None or got[0] is not f:
            got = (f, self._reach(f.ranges, f.max_range, f.mounts))
            self._reach_of[id(f)] = got
        return got[1]

    def _cells(self, lo: np.ndarray, hi: np.ndarray) -> tuple[int, int, int, int]:
        """The rows r0 .. r1 and columns c0 .. c1 (half-open, clipped to the grid) of
        the cells that meet the box [lo, hi] (m)."""
        g = self.grid
        ny, nx = g.shape
        res, (ox, oy) = g.resolution, g.origin
        c0 = min(max(math.floor((float(lo[0]) - ox) / res) - 1, 0), nx)
        c1 = min(max(math.floor((float(hi[0]) - ox) / res) + 2, 0), nx)
        r0 = min(max(math.floor((float(lo[1]) - oy) / res) - 1, 0), ny)
        r1 = min(max(math.floor((float(hi[1]) - oy) / res) + 2, 0), ny)
        return r0, r1, c0, c1

    def refill(self, frames: list[Keyframe]) -> None:
        """Fuse the map again from nothing: each keyframe's ring at its pose (an online
        loop closure moved them), on the grid as it is (grown where a ring needs it).

        The same map as :meth:`add_ring` of each in turn, fused where it is next read
        (:meth:`fresh`; class docstring). The grid grows now, as a fusion of the rings
        in time order, REFILL_BATCH at a time, would grow it: the same grid.

        Parameters
        ----------
        frames : list of Keyframe
            The keyframes, in time order.
        """
        # the masses are kept (no new map of the whole grid per closure): every cell is
        # stale after the covers below, and set vacuous when it is fused again (fresh)
        self._stale = None
        frames = list(frames)
        poses = np.array([f.pose for f in frames], dtype=float).reshape(-1, 3)
        reaches = np.array([self._frame_reach(f) for f in frames], dtype=float)
        # each keyframe's grid: the one its batch was fused on in a fusion in turn
        grids: list[Grid] = []
        grid_of = np.zeros(len(frames), dtype=np.int64)
        start = 0
        for batch in sensor_batches(frames, REFILL_BATCH):
            p, r = poses[start : start + len(batch)], reaches[start : start + len(batch)]
            self._cover((p[:, :2] - r[:, None]).min(axis=0), (p[:, :2] + r[:, None]).max(axis=0))
            if not grids or grids[-1] is not self.grid:
                grids.append(self.grid)
            grid_of[start : start + len(batch)] = len(grids) - 1
            start += len(batch)
        self._grids, self._grid_of = grids, grid_of
        self._frames, self._poses, self._reaches = frames, poses, reaches
        self._stale = np.ones(self.grid.shape, dtype=bool)
        self._n_stale = self._stale.size
        self.builder.rings = len(frames)
        live = {id(f) for f in frames}
        self._reach_of = {k: v for k, v in self._reach_of.items() if k in live}

    def _reaching(self, r0: int, r1: int, c0: int, c1: int) -> tuple[np.ndarray, np.ndarray]:
        """The refill's keyframes whose cells (within their reach of the pose) can meet
        the stale cells of rows r0 .. r1, columns c0 .. c1 (their indices, in time
        order), and those stale cells (a mask of the box)."""
        sub = self._stale[r0:r1, c0:c1].copy()
        rows, cols = np.flatnonzero(sub.any(axis=1)), np.flatnonzero(sub.any(axis=0))
        if rows.size == 0:
            return np.zeros(0, dtype=np.int64), sub
        g = self.grid
        res, (ox, oy) = g.resolution, g.origin
        lo = np.array([ox + res * (c0 + cols[0]), oy + res * (r0 + rows[0])])
        hi = np.array([ox + res * (c0 + cols[-1] + 1), oy + res * (r0 + rows[-1] + 1)])
        xy, r = self._poses[:, :2], self._reaches[:, None]
        return np.flatnonzero(np.all((xy + r >= lo) & (xy - r <= hi), axis=1)), sub

    def fresh(self, r0: int, r1: int, c0: int, c1: int) -> None:
        """Bring the cells of rows r0 .. r1, columns c0 .. c1 (half-open) up to date
        after a :meth:`refill`: the stale cells of that box grown by REFRESH_MARGIN_M
        (so that the next reads nearby find them done; all of them when more than
        REFRESH_ALL of the keyframes reach those) are set vacuous and fused from the
        refill's keyframes that reach them, in time order
        (``FgmBuilder.add_rings(only=...)``, REFILL_BATCH at a time).

        Parameters
        ----------
        r0, r1, c0, c1 : int
            The box (cells of the grid as it is).
        """
        if self._stale is None:
            return
        if r1 <= r0 or c1 <= c0 or not self._stale[r0:r1, c0:c1].any():
            return
        g = self.grid
        ny, nx = g.shape
        # the margin: the farthest a keyframe reaches (the next keyframe's cells, fused
        # after this read, are then done too) and at least REFRESH_MARGIN_M
        pad = math.ceil(max(REFRESH_MARGIN_M, float(np.max(self._reaches, initial=0.0)))
                        / g.resolution)  # fmt: skip
        box = (max(r0 - pad, 0), min(r1 + pad, ny), max(c0 - pad, 0), min(c1 + pad, nx))
        chosen, sub = self._reaching(*box)
        if len(chosen) > REFRESH_ALL * len(self._frames):
            # most keyframes' evidence is computed anyway: every stale cell at once
            box = (0, ny, 0, nx)
            chosen, sub = self._reaching(*box)
        r0, r1, c0, c1 = box
        m = self.builder.map
        for a, v in zip((m.m_e, m.m_o, m.m_t, m.m_c), (0.0, 0.0, 1.0, 0.0), strict=True):
            a[r0:r1, c0:c1][sub] = v  # from nothing: m(Theta) = 1
        need = np.zeros(g.shape, dtype=bool)
        need[r0:r1, c0:c1] = sub
        flat = need.reshape(-1)
        # runs of keyframes of one grid (their evidence computed on it: the same floats)
        cut = np.flatnonzero(np.diff(self._grid_of[chosen])) + 1
        for run in np.split(chosen, cut):
            frames = [self._frames[k] for k in run]
            start = 0
            for batch in sensor_batches(frames, REFILL_BATCH):
                poses = self._poses[run[start : start + len(batch)]]
                self.builder.add_rings(poses, *stacked_readings(batch), batch[0].fov,
                                       batch[0].mounts, only=flat,
                                       on=self._grids[self._grid_of[run[0]]])  # fmt: skip
                start += len(batch)
        self._stale[r0:r1, c0:c1] = False
        self._n_stale -= int(sub.sum())
        if self._n_stale == 0:
            self._stale = None
            self._frames, self._poses, self._reaches = [], np.zeros((0, 3)), np.zeros(0)
            self._grids, self._grid_of = [], np.zeros(0, dtype=np.int64)


class LiveMatcher(PoseMatcher):
    """:class:`PoseMatcher` on a map that changes between matches: the lookup maps are
    computed for each searched patch from the live masses (with the blur's margin),
    the same values as a PoseMatcher of a frozen copy of the map gives.

    Parameters
    ----------
    live : LiveFgm
        The map.
    params : FixParams
        The match's parameters.
    """

    def __init__(self, live: LiveFgm, params: FixParams) -> None:
        self.live = live
        self.params = params
        self.last_window = (math.nan, math.nan)
        self.last_peak = np.full(3, np.nan)

    @property
    def grid(self) -> Grid:  # type: ignore[override]
        """The live map's grid (it grows)."""
        return self.live.grid

    def _patch(self, row0: int, col0: int, size: int) -> np.ndarray:
        """PoseMatcher's lookup channels on rows row0 .. row0 + size and columns col0 ..
        col0 + size of the live map, zeros outside it."""
        p = self.params
        g = self.live.grid
        res = g.resolution
        sigma = p.pose_blur / res
        r = max(1, math.ceil(2.5 * sigma)) if sigma > 0 else 0
        ny, nx = g.shape
        out = np.zeros((size, size, 2), dtype=np.float32)
        r0, r1 = max(row0, 0), min(row0 + size, ny)
        c0, c1 = max(col0, 0), min(col0 + size, nx)
        if r1 <= r0 or c1 <= c0:
            return out
        # the patch within the map and the blur's margin around it
        a0, a1 = max(r0 - r, 0), min(r1 + r, ny)
        b0, b1 = max(c0 - r, 0), min(c1 + r, nx)
        self.live.fresh(a0, a1, b0, b1)  # after an online closure: fused where read
        m = self.live.builder.map
        lookup = lookup_channels(m.m_o[a0:a1, b0:b1], m.m_e[a0:a1, b0:b1], res, p)
        out[r0 - row0 : r1 - row0, c0 - col0 : c1 - col0] = lookup[
            r0 - a0 : r1 - a0, c0 - b0 : c1 - b0
        ]
        return out


@dataclass
class Keyframe:
    """A ring fused into the live map: its index among the rings decided, its time, the
    filter's pose after its match, the dead reckoning's pose, and the ring itself."""

    ring: int
    t: float
    pose: np.ndarray
    odometry: np.ndarray
    ranges: np.ndarray
    max_range: Any
    fov: float
    mounts: np.ndarray


def keyframes_map(frames: list[Keyframe], anchor: np.ndarray, params: MapParams, reach: float):
    """The FGM of ``frames`` placed at their poses relative to ``anchor`` (its frame), on
    a grid covering each pose with ``reach`` around it.

    Parameters
    ----------
    frames : list of Keyframe
        The keyframes.
    anchor : ndarray, shape (3,)
        The map's frame (a keyframe's pose).
    params : MapParams
        The evidence model.
    reach : float
        How far around each pose the grid reaches (m).

    Returns
    -------
    BeliefMap
    """
    rel = np.array([between(anchor, f.pose) for f in frames])
    lo, hi = rel[:, :2].min(axis=0) - reach, rel[:, :2].max(axis=0) + reach
    b = FgmBuilder(Grid.covering(lo[0], lo[1], hi[0], hi[1], params.resolution), params)
    start = 0
    for batch in sensor_batches(frames, REFILL_BATCH):
        b.add_rings(rel[start : start + len(batch)], *stacked_readings(batch), batch[0].fov,
                    batch[0].mounts)  # fmt: skip
        start += len(batch)
    return b.map


def sensor_batches(frames: list[Keyframe], most: int) -> Iterator[list[Keyframe]]:
    """Consecutive runs of keyframes taken by the same sensors (cone and mounts), at
    most ``most`` long: what ``FgmBuilder.add_rings`` fuses in one vectorised pass (the
    same masses as one ring after another, in time order).

    Parameters
    ----------
    frames : list of Keyframe
        The keyframes, in time order.
    most : int
        The longest batch (bounds the pass's memory).

    Yields
    ------
    list of Keyframe
    """
    start = 0
    while start < len(frames):
        f0 = frames[start]
        stop = start + 1
        while (stop < len(frames) and stop - start < most and frames[stop].fov == f0.fov
               and np.array_equal(frames[stop].mounts, f0.mounts)):  # fmt: skip
            stop += 1
        yield frames[start:stop]
        start = stop


def stacked_readings(batch: list[Keyframe]) -> tuple[np.ndarray, np.ndarray]:
    """A batch's readings and maximum ranges, stacked for ``FgmBuilder.add_rings``.

    Parameters
    ----------
    batch : list of Keyframe
        Keyframes of the same sensors (:func:`sensor_batches`).

    Returns
    -------
    ranges, max_range : ndarray, shape (K, M)
    """
    ranges = np.array([f.ranges for f in batch], dtype=float)
    rmax = np.array([np.broadcast_to(np.asarray(f.max_range, dtype=float), f.ranges.shape)
                     for f in batch])  # fmt: skip
    return ranges, rmax


class KeyframeGraph:
    """The pose graph of the keyframes, built as they come: each keyframe's edges are
    found when it is added (:meth:`add`), from the poses the keyframes have then, and the
    graph is solved whenever asked (:meth:`solve`: the live map's online closures
    during the run, ``LiveMapPoseAid.closed`` after it).

    Edges (i, j, z_ij, W_ij), W the Cholesky factor of the information:

    - odometry: consecutive keyframes, the dead reckoning's relative pose, sigmas
      ODO_SIGMA_M and ODO_SIGMA_DEG;
    - sequential: keyframe k's template matched against the map of the SEQUENTIAL before
      it, in the frame of k - 1, around the estimate's relative pose;
    - loop: against the map of the nearest old keyframe (LOOP_MIN_GAP before, within
      LOOP_RADIUS_M in the estimate) and LOOP_SPAN on each side of it;
    - heading priors (``solve(heading_prior=True)``): each keyframe's heading held to the
      estimate's within HEADING_PRIOR_DEG (an edge from the first keyframe, fixed).

    A match's W is from its covariance (PoseMatcher's, not inflated).

    Parameters
    ----------
    template : callable
        Keyframe -> (points (N, 2), masses (N, 2)), what is matched of it.
    map_params : MapParams
        The evidence model of the keyframes' maps.
    fix_params : FixParams
        The match's parameters.
    reach : float
        How far around each keyframe its map reaches (m).
    """

    def __init__(
        self,
        template: Callable[[Keyframe], tuple[np.ndarray, np.ndarray]],
        map_params: MapParams,
        fix_params: FixParams,
        reach: float,
    ) -> None:
        self.template = template
        self.map_params = map_params
        self.fix_params = fix_params
        self.reach = reach
        self.frames: list[Keyframe] = []
        # the odometry and sequential edges, and the loops' (kept apart: solved in that order)
        self.edges: list[tuple[int, int, np.ndarray, np.ndarray]] = []
        self.loop_edges: list[tuple[int, int, np.ndarray, np.ndarray]] = []
        self.counts = {"sequential": 0, "loops": 0, "loop_candidates": 0}
        self._stacks: dict[str, tuple] = {}  # the edge lists as arrays (_stacked)

    def _matched(self, idx: range, anchor: int, k: int) -> PoseMatch:
        """Keyframe k's template matched against the map of keyframes ``idx`` in the frame
        of keyframe ``anchor``, around their relative pose (prior PAIR_SIGMA_*)."""
        f = self.frames
        a = f[anchor].pose
        fgm = keyframes_map([f[i] for i in idx], a, self.map_params, self.reach)
        cov = np.diag([PAIR_SIGMA_M**2, PAIR_SIGMA_M**2, math.radians(PAIR_SIGMA_DEG) ** 2])
        guess = between(a, f[k].pose)
        return PoseMatcher(fgm, self.fix_params).match_points(*self.template(f[k]), guess, cov, 1.0)

    def _add(self, i: int, j: int, m: PoseMatch, key: str) -> bool:
        """An edge of the match ``m`` of keyframe j in the frame of i, if it is one."""
        if m.ok:
            w = np.linalg.cholesky(np.linalg.inv(m.cov)).T
            (self.loop_edges if key == "loops" else self.edges).append(
                (i, j, np.asarray(m.pose, dtype=float), w)
            )
            self.counts[key] += 1
        return bool(m.ok)

    def add(self, frame: Keyframe) -> int | None:
        """Add a keyframe and its edges (odometry, sequential, loop).

        Parameters
        ----------
        frame : Keyframe
            The newest keyframe (its pose: the estimate's now).

        Returns
        -------
        int or None
            The old keyframe its loop edge ties it to, or None (no loop edge).
        """
        f = self.frames
        f.append(frame)
        k = len(f) - 1
        if k == 0:
            return None
        z = between(f[k - 1].odometry, frame.odometry)
        d = float(np.hypot(z[0], z[1]))
        s_xy = ODO_SIGMA_M[0] + ODO_SIGMA_M[1] * d
        s_th = math.radians(ODO_SIGMA_DEG[0] + ODO_SIGMA_DEG[1] * math.sqrt(d))
        self.edges.append((k - 1, k, z, np.diag(1.0 / np.array([s_xy, s_xy, s_th]))))
        self._add(k - 1, k, self._matched(range(max(0, k - SEQUENTIAL), k), k - 1, k),
                  "sequential")  # fmt: skip
        if k < LOOP_MIN_GAP:
            return None
        old = np.array([o.pose[:2] for o in f[: k - LOOP_MIN_GAP + 1]], dtype=float)
        d_old = np.hypot(*(old - np.asarray(frame.pose, dtype=float)[:2]).T)
        j = int(np.argmin(d_old))
        if d_old[j] > LOOP_RADIUS_M:
            return None
        self.counts["loop_candidates"] += 1
        span = range(max(0, j - LOOP_SPAN), min(len(f), j + LOOP_SPAN + 1))
        return j if self._add(j, k, self._matched(span, j, k), "loops") else None

    def _stacked(
        self, edges: list[tuple[int, int, np.ndarray, np.ndarray]], key: str
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """A list of edges (only ever appended to) as arrays i, j (E,), z (E, 3) and
        W (E, 3, 3), kept between solves and extended by the edges added since."""
        have = self._stacks.get(key)
        n = 0 if have is None else len(have[0])
        if have is not None and n == len(edges):
            return have
        new = edges[n:]
        add = (np.array([e[0] for e in new], dtype=np.int64).reshape(-1),
               np.array([e[1] for e in new], dtype=np.int64).reshape(-1),
               np.array([e[2] for e in new], dtype=float).reshape(-1, 3),
               np.array([e[3] for e in new], dtype=float).reshape(-1, 3, 3))  # fmt: skip
        out = add if have is None else tuple(np.concatenate(p) for p in zip(have, add, strict=True))
        self._stacks[key] = out
        return out

    def move(self, poses: np.ndarray) -> None:
        """Set the keyframes' poses (an online closure's solution).

        Parameters
        ----------
        poses : ndarray, shape (K, 3)
            A pose per keyframe.
        """
        for f, p in zip(self.frames, poses, strict=True):
            f.pose = np.array(p, dtype=float)

    def solve(self, heading_prior: bool) -> tuple[np.ndarray, dict]:
        """The keyframes' poses that best explain the edges: robust least squares
        (:func:`fuzzyslam.fixes.pose_graph.optimise`, to SOLVE_TOL), the first keyframe
        held, from the keyframes' poses.

        Parameters
        ----------
        heading_prior : bool
            Hold the headings to the keyframes' (the run had absolute heading fixes).

        Returns
        -------
        poses : ndarray, shape (K, 3)
            The solution.
        info : dict
            The edges' counts, the solver's (``optimise``), and how far the keyframes
            moved (``moved_mean_m``, ``moved_max_m``).
        """
        x0 = np.array([f.pose for f in self.frames])
        parts = [self._stacked(self.edges, "edges"), self._stacked(self.loop_edges, "loops")]
        if heading_prior:
            # edge (0, k): z = (-)x_0 (+) x_k, W = diag(0, 0, 1 / sigma); only its heading
            # wrap(wrap(-theta_0) + theta_k) counts (W's zeros), the same floats as
            # se2.between's per pose
            k = len(x0) - 1
            w = np.diag([0.0, 0.0, 1.0 / math.radians(HEADING_PRIOR_DEG)])
            parts.append((np.zeros(k, dtype=np.int64), np.arange(1, k + 1),
                          between(x0[0], x0[1:]).reshape(-1, 3),
                          np.broadcast_to(w, (k, 3, 3))))  # fmt: skip
        i, j, z, w = (np.concatenate([p[n] for p in parts]) for n in range(4))
        poses, info = optimise(x0, i, j, z, w, tol=SOLVE_TOL)
        moved = np.hypot(*(poses[:, :2] - x0[:, :2]).T)
        return poses, {**self.counts, **info, "moved_mean_m": float(moved.mean()),
                       "moved_max_m": float(moved.max())}  # fmt: skip


def inconsistent(info: dict) -> bool:
    """Whether a keyframe graph's figures show it contradicting itself
    (``LiveMapPoseAid.inconsistency``): its down-weighted edges more than
    INCONSISTENT_SHARE of its loop edges, or its loop candidates without a match more
    than UNMATCHED_SHARE of them, at least INCONSISTENT_MIN either way.

    Parameters
    ----------
    info : dict
        ``loops`` and ``loop_candidates`` (KeyframeGraph.counts), and ``downweighted``
        when a solution's (KeyframeGraph.solve).

    Returns
    -------
    bool
    """
    down = int(info.get("downweighted", 0))
    unmatched = int(info["loop_candidates"]) - int(info["loops"])
    bent = down >= INCONSISTENT_MIN and down > INCONSISTENT_SHARE * int(info["loops"])
    lost = unmatched >= INCONSISTENT_MIN and unmatched > UNMATCHED_SHARE * int(
        info["loop_candidates"]
    )
    return bent or lost


def closure_jump(v: np.ndarray, p_rr: np.ndarray) -> tuple[float, float]:
    """How far an online loop closure moves the filter, and how surprising the move is
    to it: |v_xy| and the squared Mahalanobis distance d^2 = v^T P_rr^-1 v of the move
    v = x_k* - x_r under the filter's pose covariance before it (chi-square with 3
    degrees of freedom if the filter's covariance were its error's).

    Parameters
    ----------
    v : ndarray, shape (3,)
        The move (m, m, rad; heading wrapped).
    p_rr : ndarray, shape (3, 3)
        The filter's pose covariance.

    Returns
    -------
    (float, float)
        |v_xy| (m) and d^2.
    """
    v = np.asarray(v, dtype=float)
    d2 = float(v @ np.linalg.lstsq(np.asarray(p_rr, dtype=float), v, rcond=None)[0])
    return float(np.hypot(v[0], v[1])), d2


def corrected_path(t: np.ndarray, path: np.ndarray, t_key: np.ndarray, before: np.ndarray,
                   after: np.ndarray) -> np.ndarray:  # fmt: skip
    """A path moved with its keyframes: each pose p(t) becomes C(t) (+) p(t), with C the
    keyframes' corrections C_k = after_k (+) before_k^-1 interpolated in time (x, y and
    heading linearly between keyframes; the first's before it, the last's after it).

    Parameters
    ----------
    t : ndarray, shape (N,)
        The path's times.
    path : ndarray, shape (N, 3)
        Its poses.
    t_key : ndarray, shape (K,)
        The keyframes' times (increasing).
    before, after : ndarray, shape (K, 3)
        The keyframes' poses on the path and after the correction.

    Returns
    -------
    ndarray, shape (N, 3)
    """
    corr = compose(np.asarray(after, dtype=float), inverse(np.asarray(before, dtype=float)))
    corr = corr.reshape(-1, 3)
    corr[:, 2] = np.unwrap(corr[:, 2])
    c = np.stack([np.interp(t, t_key, corr[:, k]) for k in range(3)], axis=1)
    return compose(c, np.asarray(path, dtype=float).reshape(-1, 3))


class LiveMapPoseAid(PoseFixAid):
    """Plug-in of ``fuzzyslam run --live-map``: rings matched against the map of the
    keyframes before them, then fused into it (module docstring).

    Parameters
    ----------
    params : FixParams
        The ``fixes:`` section: the pose fixes' settings, with ``live_reach`` and, for a
        laser, ``live_cov_scale`` in place of ``pose_cov_scale`` and
        ``pose_corr_distance`` (``pose_map_sigma`` is not used: the filter's own error is
        in this map, so a filter surer than the map still matches).
    map_params : MapParams
        The ``fgm:`` section (the evidence model and the cell size).
    flm_source : callable
        (ring, mounts) -> the ring's FLM (a sonar ring's template).
    start_time : float
        Log time (s) from which rings are matched and fused.
    """

    def __init__(
        self, params: FixParams, map_params: MapParams, flm_source: Any, start_time: float = 0.0
    ) -> None:
        params = dataclasses.replace(params, pose_map_sigma=0.0)
        self.map_params = map_params
        self.live: LiveFgm | None = None
        super().__init__(BeliefMap.vacuous(Grid((0.0, 0.0), 1.0, (1, 1))), params, flm_source,
                         start_time)  # fmt: skip
        # every ring's time and the filter's pose after it (the path the loop closure
        # moves), and the keyframes (KeyframeGraph)
        self._t: list[float] = []
        self._path: list[np.ndarray] = []
        self._frames: list[Keyframe] = []
        # the run's heading fixes against the building (fixes/aids.py sets it with
        # live_right_angles): once they were applied, the graph holds the headings
        self.heading_aid: Any = None
        self._closed: tuple[np.ndarray, dict] | None = None
        # the keyframes' pose graph, built as they come with live_close_online (a laser's)
        self.graph: KeyframeGraph | None = None
        self.online_closures = 0  # loop edges that moved the keyframes, the map and the filter
        self.online_moved_max = 0.0  # the farthest a keyframe moved in one of them (m)
        # each online closure's (time, the filter's move (m), its Mahalanobis d^2 under
        # the filter's pose covariance before the move): closure_jump
        self.closure_jumps: list[tuple[float, float, float]] = []
        self.inconsistent_at: float | None = None  # when the graph first contradicted itself

    @property
    def keyframes(self) -> int:
        """The rings fused into the map."""
        return len(self._frames)

    def flm_every_ring(self) -> bool:
        """A ring's FLM is built here, for the rings matched only (not ahead).

        Returns
        -------
        bool
            False.
        """
        return False

    def template(self, ring: Any, mounts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """What is matched of a ring: a narrow-beam ring's echo end points within
        ``live_reach`` (:func:`end_points`), a sonar ring's FLM (PoseFixAid.template).

        Parameters
        ----------
        ring : Ring
            The ring.
        mounts : ndarray, shape (M, 3)
            The sensors' poses in base_link.

        Returns
        -------
        pts, masses : ndarray, shape (N, 2)
        """
        if not narrow_beams(ring.fov):
            return super().template(ring, mounts)
        return end_points(ring.ranges, ring.max_range, mounts, self.params.live_reach)

    def on_ring(self, t: float, ring: Any, mounts: np.ndarray, ekf: FilterView) -> None:
        """Match the ring against the map so far (PoseFixAid.on_ring); fuse a keyframe at
        the filter's pose (module docstring).

        Parameters
        ----------
        t : float
            The ring's log time (s).
        ring : Ring
            The ring (ranges (M,), max ranges (M,), fov).
        mounts : ndarray, shape (M, 3)
            The sensors' poses in base_link.
        ekf : FilterView
            The filter.
        """
        if not self.started(t):
            return
        try:
            self._decide(t, ring, mounts, ekf)
        finally:
            self._t.append(float(t))
            self._path.append(np.array(ekf.pose, dtype=float))

    def _decide(self, t: float, ring: Any, mounts: np.ndarray, ekf: FilterView) -> None:
        """on_ring's work: the match and the keyframe."""
        if self.live is None:  # the first ring starts the map
            if narrow_beams(ring.fov) and self.params.live_cov_scale > 0:
                # end points' matches: inflated by live_cov_scale whatever the travel
                self.params = dataclasses.replace(
                    self.params, pose_corr_distance=0.0, pose_cov_scale=self.params.live_cov_scale
                )
            self.live = LiveFgm(ekf.pose, self.map_params)
            self.matcher = LiveMatcher(self.live, self.params)
        else:
            n = len(self.decisions)
            super().on_ring(t, ring, mounts, ekf)
            if len(self.decisions) == n:
                return  # not matched (too near the last applied match): not a keyframe
            d = self.decisions[-1]
            if not d.accepted and d.reason in NOT_FUSED:
                return
        self.live.add_ring(ekf.pose, ring.ranges, ring.max_range, ring.fov, mounts)
        frame = Keyframe(len(self._t), float(t), np.array(ekf.pose, dtype=float),
                         np.array(ekf.odometry_pose, dtype=float),
                         np.array(ring.ranges, dtype=float), ring.max_range, float(ring.fov),
                         np.array(mounts, dtype=float))  # fmt: skip
        self._frames.append(frame)
        p = self.params
        if p.live_close_loops and p.live_close_online and narrow_beams(ring.fov):
            self._close_online(frame, ekf)

    def _graph(self) -> KeyframeGraph:
        """The keyframes' pose graph (made on first use), matching their rings'
        templates with the loop's reach."""
        if self.graph is None:

            def template(f: Keyframe) -> tuple[np.ndarray, np.ndarray]:
                ring = _RingView(f.t, f.ranges, f.max_range, f.fov)
                return self.template(ring, f.mounts)

            reach = self.params.live_reach + 1.0
            self.graph = KeyframeGraph(template, self.map_params, self.params, reach)
        return self.graph

    def _heading_held(self) -> bool:
        """Whether the run's heading fixes against the building were applied (the
        graph then holds the headings)."""
        h = self.heading_aid
        return h is not None and any(d.accepted for d in h.decisions)

    def _close_online(self, frame: Keyframe, ekf: FilterView) -> None:
        """Add the newest keyframe to the graph; if it closes a loop that moves the
        solution by a cell or more, move the keyframes there, fuse the map again from
        them and move the filter onto the newest keyframe's pose.

        The filter's move is a direct measurement of its pose, z = x_k* (the newest
        keyframe's solved pose), with R the loop edge's covariance in the map frame,
        after P_rr += diag(v^2) (v = z - x_r): the recovery of
        :class:`~fuzzyslam.fixes.pose_aid.PoseFixAid`, the closure being an error of the
        map the filter was relative to, not of the filter against it. The graph and its
        solution: Grisetti, Kuemmerle, Stachniss and Burgard, "A tutorial on
        graph-based SLAM", IEEE ITS Magazine 2010.
        """
        g = self._graph()
        j = g.add(frame)
        self._judge(frame.t, g.counts)
        if j is None:
            return
        poses, info = g.solve(self._heading_held())
        self._judge(frame.t, info)
        moved = info["moved_max_m"]
        if moved < self.map_params.resolution:
            return
        g.move(poses)
        self.live.refill(g.frames)
        _, _, z_jk, w = g.loop_edges[-1]
        _, jb = jacobians_compose(poses[j], z_jk)
        r = jb @ np.linalg.inv(w.T @ w) @ jb.T  # R = J_b Sigma_jk J_b^T, x_k = x_j (+) z_jk
        z = poses[-1]
        v = np.asarray(z, dtype=float) - np.asarray(ekf.pose, dtype=float)
        v[2] = wrap_angle_scalar(float(v[2]))
        self.closure_jumps.append((frame.t, *closure_jump(v, ekf.pose_cov)))
        ekf.inflate_robot(np.diag(v * v))  # P_rr += diag(v^2)
        ekf.update_robot(z, 0.5 * (r + r.T), [0, 1, 2], gate_chi2=None)  # z = x_r + noise(R)
        self.online_closures += 1
        self.online_moved_max = max(self.online_moved_max, moved)

    def _judge(self, t: float, info: dict) -> None:
        """Note the first time ``info`` (the graph's counts, or a solution's figures)
        shows the map inconsistent (:meth:`inconsistency`)."""
        if self.inconsistent_at is None and inconsistent(info):
            self.inconsistent_at = float(t)

    def inconsistency(self) -> tuple[str, float] | None:
        """("live_map_inconsistent", the time) when the keyframes' pose graph contradicts
        itself (:func:`inconsistent`: during the run, or in its solution after it), else
        None.

        A consistent live map closes its loops by small corrections the odometry and
        scan-match edges can take; a map that drifted (along a corridor a short laser
        cannot see the end of, on readings of the robot's own body) either bends the
        chain beyond its stated noise to take the loop edges, so that the robust kernel
        down-weights its edges, or does not match where the estimate says it is back on
        mapped ground. Measured (28 live-map runs: the CARMEN buildings with their own and
        4 other odometries, 11 re-recordings as other robots record them, synthetic
        buildings of 20 to 64 min): the runs at
        0.07-0.45 m of closed error (aligned) down-weighted at most 0.2 edges per loop
        edge and refused at most 20 % of the loop candidates; the ones flagged, 0.61-6.0
        m: ACES with a 3.5 m laser (0.67-1.15 edges per loop edge), with the robot's body
        in the scan (2.3; Freiburg 1.0 and 51 % refused), and a building whose corridors
        lie 6 deg off its right angles (48 % refused). Not seen: a drift along a 150 m
        corridor whose loops then close nowhere, and a corridor 6 deg off that is driven
        once (docs/models.md sec. 10b; a line on stderr now names such a building,
        :class:`LiveRightAngleHeading`).

        Returns
        -------
        (str, float) or None
        """
        found = self.closed()
        if found is not None and self.inconsistent_at is None and inconsistent(found[1]):
            self.inconsistent_at = float(self._frames[-1].t)
        if self.inconsistent_at is None:
            return None
        return "live_map_inconsistent", self.inconsistent_at

    def troubles(self) -> list[tuple[str, float]]:
        """PoseFixAid's findings and :meth:`inconsistency`'s, in time order.

        Returns
        -------
        list of (str, float)
        """
        found = [*super().troubles(), self.inconsistency()]
        return sorted((f for f in found if f is not None), key=lambda f: f[1])

    def closed(self) -> tuple[np.ndarray, dict] | None:
        """The keyframes' poses with the loops closed and the graph's figures
        (:class:`KeyframeGraph`, built during the run or now, solved once), or None
        (``live_close_loops`` off, fewer than two keyframes, or a sonar ring: measured
        on Freiburg's 9 sonars, 7 odometry variants, its FLM matches' edges moved the
        aligned error by -0.06 to +0.05 m and doubled the raw error of some runs, 0.32
        -> 0.67 m).

        Returns
        -------
        (ndarray (K, 3), dict) or None
        """
        if not self.params.live_close_loops or len(self._frames) < 2:
            return None
        if not narrow_beams(self._frames[0].fov):
            return None  # a sonar ring's matches are too loose for the graph (sec. 10b)
        if self._closed is None and self.graph is None:
            # built after the run (live_close_online off): each keyframe's edges in turn
            from fuzzyslam.progress import Progress

            g = self._graph()
            n = len(self._frames)
            with Progress(n, f"run: closing the live map's loops ({n} keyframes)") as bar:
                for k, f in enumerate(self._frames):
                    g.add(f)
                    bar.update_to(k + 1)
        if self._closed is None:
            self._closed = self.graph.solve(self._heading_held())
        return self._closed

    def closed_path(self) -> tuple[np.ndarray, np.ndarray] | None:
        """Every ring's time and the filter's pose there, moved with the keyframes by the
        loop closure (:func:`corrected_path`), or None without it.

        Returns
        -------
        (ndarray (N,), ndarray (N, 3)) or None
        """
        found = self.closed()
        if found is None:
            return None
        t = np.array(self._t)
        path = np.array(self._path)
        before = path[[f.ring for f in self._frames]]  # the keyframes' poses on the path
        t_key = t[[f.ring for f in self._frames]]
        return t, corrected_path(t, path, t_key, before, found[0])

    def run_note(self, lamps: bool) -> str:
        """One line for stderr: where the loops were closed and what to build the map
        from, and how many matches the run's gate refused (a loop that comes back beyond
        the search window is refused: filter_health's NIS findings of a live-map run
        come from such matches, sec. 10b).

        Parameters
        ----------
        lamps : bool
            Whether the log has lamps (unused: the live map says the same either way).

        Returns
        -------
        str
            '' without a loop closure.
        """
        found = self.closed()
        if found is None:
            return ""
        info = found[1]
        gated = sum(d.reason == "gated" for d in self.decisions)
        refused = (
            f"; the run's gate refused {gated} of its matches (a loop that comes back "
            "beyond the search window is refused there, and trajectory.tum and "
            "filter_health keep it: docs/models.md sec. 10b)"
            if gated
            else ""
        )
        online = (
            f"{self.online_closures} loops closed during the run (keyframes moved up to "
            f"{self.online_moved_max:.2f} m), "
            if self.online_closures
            else ""
        )
        return (
            f"live map: {online}trajectory_closed.tum has its loops closed ({info['loops']} "
            f"loop edges, keyframes moved up to {info['moved_max_m']:.2f} m after the run): "
            f"build the map from it (map --trajectory){refused}"
        )

    def write(self, outdir: Path) -> None:
        """pose_fixes.csv (PoseFixAid.write) and, with the loops closed,
        trajectory_closed.tum: every ring's pose moved with its keyframes.

        Parameters
        ----------
        outdir : Path
            The run's directory (being written).
        """
        from fuzzyslam.rundir import TRAJECTORY_CLOSED
        from fuzzyslam.streams.tum import write_tum

        super().write(outdir)
        path = self.closed_path()
        if path is not None:
            write_tum(Path(outdir) / TRAJECTORY_CLOSED, *path)

    def summary(self) -> PoseSummary:
        """PoseFixAid's entry with the map's: keyframes, grid shape, cell size, growths.

        Returns
        -------
        PoseSummary
        """
        s = super().summary()
        if self.live is None:
            return dataclasses.replace(s, keyframes=0)
        g = self.live.grid
        loops = None
        found = self.closed()
        if found is not None:
            info = found[1]
            loops = {
                "loops": info["loops"],
                "loop_candidates": info["loop_candidates"],
                "sequential": info["sequential"],
                "downweighted": info["downweighted"],
                "iterations": info["iterations"],
                "keyframes_moved_mean_m": round(info["moved_mean_m"], 4),
                "keyframes_moved_max_m": round(info["moved_max_m"], 4),
                "online_closures": self.online_closures,
                "online_moved_max_m": round(self.online_moved_max, 4),
                "closure_d2_max": round(max((j[2] for j in self.closure_jumps), default=0.0), 1),
            }
        return dataclasses.replace(
            s,
            keyframes=self.keyframes,
            map_shape=[int(v) for v in g.shape],
            map_resolution_m=float(g.resolution),
            map_grown=self.live.grown,
            loop_closure=loops,
        )

    def messages(self, topics: Any, start: float | None = None) -> list:
        """The pose matches for estimates.mcap and the live map as it ended, stamped at
        the last ring decided (PoseFixAid.messages).

        Parameters
        ----------
        topics : Topics
            The config's topics.
        start : float or None
            Unused: the map is stamped at its end.

        Returns
        -------
        list of (str, str, message, float)
        """
        from fuzzyslam.fixes.viewer import map_messages

        out = super().messages(topics, None)
        if self.live is not None and self.decisions:
            out = map_messages((self.live.map, []), topics, self.decisions[-1].t) + out
        return out


@dataclass(frozen=True)
class _RingView:
    """A keyframe's ring as ``template`` reads it (and an FLM source keys it)."""

    t: float
    ranges: np.ndarray
    max_range: Any
    fov: float


def building_direction(angles: np.ndarray, lengths: np.ndarray) -> float:
    """The direction of a building's walls, mod pi/2, from wall segments that meet at
    right angles: the length-weighted circular mean of 4 theta, divided by 4 (the
    four-fold symmetry taken out, as for any axial data of period pi/2: Mardia and
    Jupp, "Directional statistics", 2000, sec. 9.3.2).

    Parameters
    ----------
    angles : ndarray, shape (S,)
        The segments' directions (rad, map frame, any multiple of pi/2 apart).
    lengths : ndarray, shape (S,)
        Their lengths (m): the weights.

    Returns
    -------
    float
        The direction in [0, pi/2) (rad).
    """
    c = float(np.sum(lengths * np.cos(4.0 * angles)))
    s = float(np.sum(lengths * np.sin(4.0 * angles)))
    return float(np.mod(math.atan2(s, c) / 4.0, math.pi / 2))


class LiveRightAngleHeading(ScanLineHeadingAid):
    """Heading fixes of a live-map run from a laser scan's wall lines against the
    building's own wall direction (``fixes.live_right_angles``).

    Over the first ``live_reference_m`` of travel (dead reckoning) the scans' wall
    segments are gathered in the map frame (their direction plus the filter's heading);
    their direction mod 90 deg (:func:`building_direction`, at least LEARN_MIN_WALL_M of
    wall) becomes the one reference, covering the whole map, of the scan-line heading
    fixes (:class:`ScanLineHeadingAid` with right angles, its wall window at least
    ``live_gate_deg`` wide): from then on every scan's walls along or across it measure
    the heading, gated on the innovation (walls at other angles are not in the window).
    The heading's error then stays bounded instead of growing with the odometry's drift
    (measured on ACES, laser: mean heading error 0.9 deg against 3.1 deg without, mean
    position error 0.57 m against 1.90 m).

    The reference's own error (the scans' wall directions scatter by about 1.3 deg; the
    heading drifts over the first metres) turns the whole map after the learning by that
    much: a rotation of the map frame, which aligned errors (evo's ``-a``) do not see.
    Rings with wide cones (sonars) are left alone: their echoes are not wall points.

    The building's right angles are checked as it goes (:meth:`_walls_seen`). A corridor
    a few degrees off them has walls within the fixes' window, and one scan's fix (1.6
    deg of noise) cannot tell its skew from the heading's error: scan after scan the
    fixes turn the heading by the skew, and the map with it. But a scan that sees walls
    both along and across the building's direction measures the angle between them,
    which the heading's error does not enter: two families of one scan agree to 0.3-0.5
    deg on the development logs. More than OFF_SHARE of such scans (at least OFF_MIN)
    more than OFF_RIGHT_ANGLE_DEG off a right angle, and the building is not one whose
    walls all meet at right angles: the summary says when (``off_right_angles_at``) and
    a line on stderr names ``live_right_angles: false``. Measured (docs/models.md sec.
    10b): the CARMEN buildings with 7 odometries each, 0 such scans off; synthetic
    corridor rings with corridors 3-6 deg off, 10-35 % of theirs, 0.62-5.3 m of error
    (aligned) where 0.06-2.1 m without the fixes. The fixes are not stopped: in a
    right-angled building with one skewed dead-end wing they cost 0.39 m where 0.58 m
    without them (stopped at the wing: 2.2 m), the wing's walls turning the heading only
    while the robot is in it; which corridor is skewed is a question for a map of
    corridors, as the frozen map's references answer it.

    Parameters
    ----------
    params : FixParams
        The ``fixes:`` section (the scan-line constants; ``right_angles`` is taken on).
    start_time : float
        Log time (s) from which the aid acts.
    """

    def __init__(self, params: FixParams, start_time: float = 0.0) -> None:
        p = dataclasses.replace(params, right_angles=True, scan_line_gate_deg=params.live_gate_deg)
        super().__init__([], p, start_time)
        self._angles: list[np.ndarray] = []
        self._lengths: list[np.ndarray] = []
        self._start: np.ndarray | None = None
        self.reference_angle = math.nan
        self.learnt_at: float | None = None
        # scans seeing both wall families, those off the right angles, when first too many
        self.right_angle_scans = 0
        self.off_right_angle_scans = 0
        self.off_right_angles_at: float | None = None
        self._first_scan = math.nan

    def _learn(self, t: float, ring: Any, mounts: np.ndarray, ekf: FilterView) -> None:
        """Gather one scan's segments in the map frame; set the reference once the robot
        has travelled ``live_reference_m`` with enough wall seen."""
        odo = np.asarray(ekf.odometry_pose, dtype=float)
        if self._start is None:
            self._start = odo.copy()
        segs = scan_segments(ring, mounts, self.params)
        self._angles.append(np.asarray(segs.angle) + float(ekf.pose[2]))
        self._lengths.append(np.asarray(segs.length))
        if float(np.hypot(*(odo[:2] - self._start[:2]))) < self.params.live_reference_m:
            return
        a, w = np.concatenate(self._angles), np.concatenate(self._lengths)
        if float(w.sum()) < LEARN_MIN_WALL_M:
            return
        theta = building_direction(a, w)
        big = 1e7  # one region covering any map
        region = np.array([[-big, -big], [big, -big], [big, big], [-big, big]])
        self.refs = [Reference(0, "building", theta, float(w.sum()), region)]
        self.reference_angle, self.learnt_at = theta, t
        self._angles, self._lengths = [], []

    def _walls_seen(self, t: float, segs: Any, predicted: float, p_tt: float) -> None:
        """Count the scan (ScanLineHeadingAid._walls_seen's arguments) when it sees walls
        along and across the building's direction, each where a fix looks for it
        (:func:`~fuzzyslam.fixes.scan_heading.search_window`), and whether they meet off
        its right angles (class docstring)."""
        p = self.params
        gate, wall = search_window(p_tt, p)
        along, across = (
            family_direction(
                segs, self.reference_angle + off - predicted, gate, wall, p.scan_line_min_support
            )
            for off in (0.0, math.pi / 2)
        )
        if along is None or across is None:
            return
        # the angle between the two families less 90 deg: the heading's error cancels
        off = abs(wrap_angle_scalar(2.0 * (across.angle - along.angle - math.pi / 2))) / 2.0
        self.right_angle_scans += 1
        if off <= math.radians(OFF_RIGHT_ANGLE_DEG):
            return
        self.off_right_angle_scans += 1
        n, k = self.right_angle_scans, self.off_right_angle_scans
        if self.off_right_angles_at is None and k >= OFF_MIN and k > OFF_SHARE * n:
            self.off_right_angles_at = float(t)

    def on_ring(self, t: float, ring: Any, mounts: np.ndarray, ekf: FilterView) -> None:
        """Learn the building's direction, then fix the heading (class docstring).

        Parameters
        ----------
        t : float
            The ring's log time (s).
        ring : Ring
            The scan read as a ring of narrow beams.
        mounts : ndarray, shape (M, 3)
            The beams' mounts in base_link.
        ekf : FilterView
            The filter.
        """
        if not self.started(t) or not narrow_beams(ring.fov):
            return
        if math.isnan(self._first_scan):
            self._first_scan = float(t)
        if not self.refs:
            self._learn(t, ring, mounts, ekf)
            return
        super().on_ring(t, ring, mounts, ekf)

    def run_note(self, lamps: bool) -> str:
        """One line for stderr when the building's walls are off its right angles (class
        docstring), else ''.

        Parameters
        ----------
        lamps : bool
            Whether the log has lamps (unused).

        Returns
        -------
        str
        """
        if self.off_right_angles_at is None:
            return ""
        return (
            f"live map: {self.off_right_angle_scans} of {self.right_angle_scans} scans saw "
            f"walls more than {OFF_RIGHT_ANGLE_DEG:g} deg off the building's right angles "
            f"(from {self.off_right_angles_at - self._first_scan:.1f} s after its first "
            "scan): if some corridors are off them, its heading fixes against them turn "
            "the heading there; run with fixes.live_right_angles: false"
        )

    def summary(self) -> HeadingSummary:
        """ScanLineHeadingAid's entry with the reference learnt (deg, mod 90) and when,
        and the check of the building's right angles (scans, off, when first too many).

        Returns
        -------
        HeadingSummary
        """
        ref = None if math.isnan(self.reference_angle) else math.degrees(self.reference_angle)
        return dataclasses.replace(
            super().summary(),
            reference_angle_deg=ref,
            reference_learnt_at=self.learnt_at,
            right_angle_scans=self.right_angle_scans,
            off_right_angle_scans=self.off_right_angle_scans,
            off_right_angles_at=self.off_right_angles_at,
        )
