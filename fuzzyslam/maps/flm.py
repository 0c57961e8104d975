"""The fuzzy local map (FLM): one sonar ring on a small grid in the robot frame.

41 x 41 cells of 10 cm centred on the robot (base_link), from a single ring, with no
odometry dependency (the paper's sec. 3, docs/models.md sec. 7). The evidence and its
combination are the FGM's own (:func:`fuzzyslam.maps.evidence.ring_evidence`): combining
a ring into the vacuous map is the identity, so the FLM holds the ring's combined masses.

An FLM is a :class:`LocalMap`: a BeliefMap that also keeps the echoes it was built from
(in the robot frame), so that :func:`fuzzyslam.maps.hough.flm_wall_direction` can refine
the Hough direction with the tangent-line model (:mod:`fuzzyslam.maps.tangent`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fuzzyslam.maps.evidence import (
    BatchEvidence,
    RingEvidence,
    combine_cells,
    reading_kinds,
    readings_cells,
    ring_evidence,
    rings_evidence,
)
from fuzzyslam.maps.grid import BeliefMap, Grid
from fuzzyslam.maps.params import MapParams
from fuzzyslam.maps.tangent import RingReadings, readings_in_frame
from fuzzyslam.maps.tbm import clip_masses
from fuzzyslam.se2 import between, compose

# the bits of the vacuous masses m(E), m(O), m(Theta), m(emptyset) = 0, 0, 1, 0 (float32)
_VACUOUS_BITS = np.array([0.0, 0.0, 1.0, 0.0], dtype=np.float32).view(np.uint32)[:, None]


@dataclass
class LocalMap(BeliefMap):
    """An FLM: the BeliefMap of one or a few rings plus their echoes (robot frame).

    Pickled sparse: only the cells whose masses differ from the vacuous ones, bit for
    bit (a ring touches a few hundred of the 1681 cells); slam/prefetch.py sends every
    ring's FLM through a pipe (28 KB each dense, about 6 KB sparse with its echoes)."""

    readings: RingReadings | None = None

    @classmethod
    def of(cls, bm: BeliefMap, readings: RingReadings | None) -> LocalMap:
        return cls(bm.grid, bm.m_e, bm.m_o, bm.m_t, bm.m_c, readings)

    def __reduce__(self):
        arrays = (self.m_e, self.m_o, self.m_t, self.m_c)
        if any(a.dtype != np.float32 or a.shape != self.grid.shape for a in arrays):
            return super().__reduce__()  # not the grid's float32 masses: pickled whole
        bits = np.stack(arrays).reshape(4, -1).view(np.uint32)
        cells = np.flatnonzero((bits != _VACUOUS_BITS).any(axis=0))
        return _sparse_local_map, (self.grid, cells, bits[:, cells], self.readings)


def _sparse_local_map(
    grid: Grid, cells: np.ndarray, bits: np.ndarray, readings: RingReadings | None
) -> LocalMap:
    """The LocalMap that ``LocalMap.__reduce__`` pickled: the vacuous map with the masses'
    bits ``bits`` (4, n) (uint32 of float32) at the flat ``cells`` (n,); its four masses
    are the rows of one (4, ny, nx) block, as ``build_flm_rings`` makes them."""
    out = np.empty((4, grid.shape[0] * grid.shape[1]), dtype=np.uint32)
    out[:] = _VACUOUS_BITS
    out[:, cells] = bits
    m = out.view(np.float32).reshape(4, *grid.shape)
    return LocalMap(grid, m[0], m[1], m[2], m[3], readings)


def flm_grid(params: MapParams) -> Grid:
    """The FLM's grid: ``Grid.centred(flm_cells, resolution)`` in base_link.

    Parameters
    ----------
    params : MapParams
        ``flm_cells`` and ``resolution``.

    Returns
    -------
    Grid
    """
    return Grid.centred(params.flm_cells, params.resolution)


def build_flm(
    ranges: np.ndarray,
    max_range: np.ndarray | float,
    fov: float,
    mounts: np.ndarray,
    params: MapParams | None = None,
) -> LocalMap:
    """FLM of one ring: ranges (16,) (NaN = missing), max ranges, cone fov (rad), sonar
    mounts (16, 3) in base_link. Returns a BeliefMap on :func:`flm_grid` (robot frame).

    Parameters
    ----------
    ranges : ndarray, shape (M,)
        The readings (NaN: missing).
    max_range : ndarray, shape (M,), or float
        The maximum ranges.
    fov : float
        The cone's full angle (rad).
    mounts : ndarray, shape (M, 3)
        The sonars' poses in base_link.
    params : MapParams, optional
        The ``fgm:`` section (default values without it).

    Returns
    -------
    LocalMap
        The FLM (masses on :func:`flm_grid`) and its echoes.
    """
    params = params if params is not None else MapParams()
    grid = flm_grid(params)
    bm = BeliefMap.vacuous(grid)
    cached = _READINGS.evidence(grid, ranges, max_range, fov, mounts, params)
    if cached is None:  # a ring the cache does not take (not one range per mount)
        ev = ring_evidence(grid, np.zeros(3), ranges, max_range, fov, mounts, params)
        ranges = np.asarray(ranges, dtype=float).reshape(1, -1)
        echoes = readings_in_frame(np.zeros((1, 3)), ranges, max_range, fov, mounts)
    else:
        ev, echoes = cached
    for arr, val in zip((bm.m_e, bm.m_o, bm.m_t, bm.m_c), clip_masses(ev.masses), strict=True):
        arr.ravel()[ev.cells] = val
    return LocalMap.of(bm, echoes)


class _ReadingCells:
    """The FLM's evidence of one ring (the robot at the grid's origin) assembled from each
    reading's own cells and masses (:func:`fuzzyslam.maps.evidence.readings_cells` of that
    reading alone), remembered per (sensor, range, echo): a sonar's ranges are quantised,
    so the same readings come back ring after ring. The entries are concatenated in
    ``readings_cells``' order (near sectors, then far ones) and combined by
    ``combine_cells``: the same evidence as ``ring_evidence``, bit for bit
    (tests/test_fast_paths_aid.py). The ring's echoes come with it, their sensor poses
    taken from the mounts composed once at the origin (``readings_in_frame``'s floats)."""

    def __init__(self) -> None:
        self.setup: tuple | None = None
        self.sensors = np.zeros((0, 3))
        self.pieces: dict[tuple[int, float, bool], tuple] = {}

    def evidence(
        self, grid, ranges, max_range, fov, mounts, params
    ) -> tuple[RingEvidence, RingReadings] | None:
        """:func:`ring_evidence` at the origin and the ring's echoes (:func:`readings_in_frame`
        at the origin), or None when the ring does not fit the mounts or has no reading."""
        mounts = np.asarray(mounts, dtype=float).reshape(-1, 3)
        r_all = np.asarray(ranges, dtype=float).reshape(-1)
        if len(r_all) != len(mounts):
            return None
        half = 0.5 * float(fov)
        setup = (grid, half, mounts.tobytes(), tuple(vars(params).values()))
        if setup != self.setup:
            self.setup, self.pieces = setup, {}
            self.sensors = compose(np.zeros((len(mounts), 3)), mounts)
        ok, echo_all = reading_kinds(r_all, max_range)
        keys = [(i, float(r_all[i]), bool(echo_all[i])) for i in np.flatnonzero(ok).tolist()]
        if len(self.pieces) > 50000:  # bounded (a quantised sonar stays far below)
            self.pieces.clear()
        missing = [k for k in keys if k not in self.pieces]
        if missing:  # computed together (each entry depends on its own reading only)
            self._add(grid, missing, half, params)
        if not keys:  # no reading: the plain path
            return None
        got = [self.pieces[k] for k in keys]
        # rows cell, m(E), m(O): the near sectors' entries, then the far ones'
        entries = np.concatenate([g[0] for g in got] + [g[1] for g in got], axis=1)
        ncell = grid.shape[0] * grid.shape[1]
        b = combine_cells(entries[0].astype(np.int64), entries[1], entries[2], 1, ncell, len(keys))
        echoes = RingReadings(self.sensors[echo_all], r_all[echo_all], half)
        return RingEvidence(b.cells, b.masses, b.pairs, b.readings), echoes

    def _add(self, grid, keys: list, half: float, params) -> None:
        """Remember the entries of the near and of the far sector of each reading (sensor,
        range, echo) in ``keys``: (3, n) arrays of rows cell (a float: exact below 2^53),
        m(E), m(O), so that a ring's entries are one concatenation."""
        idx = [k[0] for k in keys]
        r = np.array([k[1] for k in keys])
        echo = np.array([k[2] for k in keys])
        rid, cell, m_e, m_o, second = readings_cells(grid, self.sensors[idx], r, echo, half, params)
        rows = np.array([cell, m_e, m_o])
        for j, key in enumerate(keys):
            mine = rid == j
            self.pieces[key] = (rows[:, mine & ~second], rows[:, mine & second])


_READINGS = _ReadingCells()


def build_flm_rings(
    poses: np.ndarray,
    ranges: np.ndarray,
    max_range: np.ndarray | float,
    fov: float,
    mounts: np.ndarray,
    params: MapParams | None = None,
) -> LocalMap:
    """FLM of several recent rings (beyond the paper): rings (K, M) taken at ``poses``
    (K, 3) expressed in the CURRENT robot frame (e.g. odometry increments composed back
    from now; the last ring is usually at the identity). The rings are fused exactly as in
    the FGM (:class:`fuzzyslam.maps.fgm.FgmBuilder` on :func:`flm_grid`). Odometry over a
    second or two is accurate to a fraction of a degree, while the per-ring noise of the
    wall direction averages down; with K = 1 at the identity this is :func:`build_flm`.
    The echoes of all K rings are kept (placed by ``poses``) for the tangent refinement:
    on the simulated paper log, 8 rings placed by dead reckoning give a wall direction
    within 0.35 deg mean |error| (std 0.44) against 1.18 / 1.57 for one ring.

    Parameters
    ----------
    poses : ndarray, shape (K, 3)
        The rings' poses in the newest ring's robot frame.
    ranges : ndarray, shape (K, M)
        The readings (NaN: missing).
    max_range : ndarray, shape (K, M), or float
        The maximum ranges.
    fov : float
        The cone's full angle (rad).
    mounts : ndarray, shape (M, 3) or (K, M, 3)
        The sonars' poses in base_link (each ring's, deskewed, for sonars fired in
        sequence).
    params : MapParams, optional
        The ``fgm:`` section.

    Returns
    -------
    LocalMap
    """
    params = params if params is not None else MapParams()
    grid = flm_grid(params)
    ev = rings_evidence(grid, poses, ranges, max_range, fov, mounts, params)
    work = _fuse_rings(ev, grid.shape[0] * grid.shape[1], params.forgetting_gamma)
    bm = BeliefMap(grid, *(row.reshape(grid.shape) for row in work))
    return LocalMap.of(bm, readings_in_frame(poses, ranges, max_range, fov, mounts))


def _fuse_rings(ev: BatchEvidence, ncell: int, gamma: float) -> np.ndarray:
    """The masses (4, ncell) (float32, rows m(E), m(O), m(T), m(emptyset)) of the vacuous
    map into which the K rings of ``ev`` are fused in order: the steps of
    :meth:`fuzzyslam.maps.fgm.FgmBuilder.add_rings` (``fgm._step``: forgetting, discount,
    conjunctive rule, ``clip_masses``), with the same float64 operations in the same
    order on each cell, bit for bit (tests/test_multi_ring.py), but each on a (2, n) or
    (3, n) block where the formulas repeat for m(E) and m(O) (fewer, larger numpy calls:
    the FLM's rings touch a few hundred cells each)."""
    work = np.zeros((4, ncell), dtype=np.float32)
    work[2] = 1.0
    evm = np.array(ev.masses)  # (4, entries)
    ptr = ev.ptr.tolist()
    for k in range(len(ptr) - 1):  # sequential over rings, vectorised over cells
        a, b = ptr[k], ptr[k + 1]
        if a >= b:
            continue
        idx = ev.cells[a:b]
        m = work.take(idx, axis=1).astype(float)
        e2 = evm[:, a:b]
        # forgetting_factor then discount: alpha m(A) for A != Theta, 1 - alpha + alpha m(T)
        # (forgetting_factor clips the stored m(emptyset) to [0, 1]: it is there already,
        # clip_masses' own, never -0)
        alpha = 1.0 - gamma * m[3]
        d = alpha * m[:3]
        t1 = 1.0 - alpha + d[2]
        eo1, eo2, t2 = d[:2], e2[:2], e2[2]
        out = np.empty_like(m)
        # conjunctive: m(E), m(O) = x1 x2 + x1 t2 + t1 x2 (x = E, O); m(T) = t1 t2; its
        # m(emptyset) is not formed: clip_masses replaces it by 1 - m(E) - m(O) - m(T);
        # clip_masses' np.clip as np.maximum / np.minimum (no NaN: the same floats)
        out[:2] = eo1 * eo2 + eo1 * t2 + t1 * eo2
        np.multiply(t1, t2, out=out[2])
        np.maximum(out[:3], 0.0, out=out[:3])
        np.minimum(out[:3], 1.0, out=out[:3])
        c = 1.0 - out[0] - out[1] - out[2]
        np.minimum(np.maximum(c, 0.0, out=c), 1.0, out=out[3])
        work[:, idx] = out
    return work


class RecentRings:
    """The last few rings with the robot's poses when they were taken, for multi-ring FLMs
    (beyond the paper; see :func:`build_flm_rings`).

    ``push`` one ring per firing with a pose from a smooth source (dead reckoning: its
    relative error over 2 s is far below a ring's own noise; a filter estimate jumps at
    its updates); ``flm()`` is the FLM of the rings of the last ``window`` seconds (at most
    ``count``) placed in the newest ring's frame. Successive multi-ring FLMs share rings,
    so their wall directions are correlated: feed a filter one of them every ``count``
    rings, or inflate its noise accordingly. With ``distance`` > 0 the rings also lie
    within that much travel (m, the path through the kept poses) of the newest: what a
    window sees of the walls grows with the travel, not with the number of rings.
    """

    def __init__(self, count: int = 8, window: float = 2.5, distance: float = 0.0) -> None:
        if count < 1:
            raise ValueError(f"count must be >= 1, got {count}")
        self.count = int(count)
        self.window = float(window)
        self.distance = float(distance)
        self._s: list[float] = []  # travel (m) along the kept poses, from the first pushed
        self._t: list[float] = []
        self._poses: list[np.ndarray] = []
        self._ranges: list[np.ndarray] = []
        self._rmax: list[np.ndarray] = []
        self._mounts: list[np.ndarray | None] = []  # a ring's own (deskewed) mounts
        self.fov = 0.0

    def __len__(self) -> int:
        return len(self._t)

    def push(
        self,
        t: float,
        pose: np.ndarray,
        ranges: np.ndarray,
        max_range: np.ndarray | float,
        fov: float,
        mounts: np.ndarray | None = None,
    ) -> float:
        """Keep a ring (the oldest dropped beyond ``count`` rings or ``window`` s; a ring back in

        time or of another size starts afresh).

        Parameters
        ----------
        t : float
            Log time (s).
        pose : ndarray, shape (3,)
            Its dead-reckoning pose.
        ranges : ndarray, shape (M,)
            The readings (NaN: missing).
        max_range : ndarray, shape (M,), or float
            The maximum ranges.
        fov : float
            The cone's full angle (rad).
        mounts : ndarray, shape (M, 3), optional
            The ring's own (deskewed) mounts; None: those given to :meth:`flm`.

        Returns
        -------
        float
            The travel (m) from the previous ring's pose to this one's (0 for the first).
        """
        ranges = np.asarray(ranges, dtype=float).ravel()
        if self._t and (t < self._t[-1] or len(ranges) != len(self._ranges[-1])):
            self.clear()  # time went back or the ring changed: start afresh
        pose = np.asarray(pose, dtype=float).reshape(3)
        step = float(np.hypot(*(pose[:2] - self._poses[-1][:2]))) if self._poses else 0.0
        self._s.append(self._s[-1] + step if self._s else 0.0)
        self._t.append(float(t))
        self._poses.append(pose)
        self._ranges.append(ranges)
        rmax = np.asarray(max_range, dtype=float)  # a ring's own (M,) array: as it is
        self._rmax.append(
            rmax if rmax.shape == ranges.shape else np.broadcast_to(rmax, ranges.shape)
        )
        self._mounts.append(mounts)
        self.fov = float(fov)
        while (
            len(self._t) > self.count
            or self._t[-1] - self._t[0] > self.window
            or (self.distance > 0 and self._s[-1] - self._s[0] > self.distance)
        ):
            for buf in (self._s, self._t, self._poses, self._ranges, self._rmax, self._mounts):
                buf.pop(0)
        return step

    @property
    def span(self) -> float:
        """The travel (m) from the oldest kept ring's pose to the newest's."""
        return self._s[-1] - self._s[0] if self._s else 0.0

    def clear(self) -> None:
        """Forget every ring."""
        for buf in (self._s, self._t, self._poses, self._ranges, self._rmax, self._mounts):
            buf.clear()

    def flm(self, mounts: np.ndarray, params: MapParams | None = None) -> LocalMap:
        """FLM of the kept rings in the newest ring's robot frame.

        Parameters
        ----------
        mounts : ndarray, shape (M, 3)
            The sonars' poses in base_link (for the rings pushed without their own).
        params : MapParams, optional
            The ``fgm:`` section.

        Returns
        -------
        LocalMap
        """
        if not self._t:
            raise ValueError("no rings pushed")
        poses = np.array(self._poses)
        rel = between(poses[-1], poses)
        if any(m is not None for m in self._mounts):  # deskewed rings: each its mounts
            mounts = np.stack([mounts if m is None else m for m in self._mounts])
        return build_flm_rings(
            rel, np.array(self._ranges), np.array(self._rmax), self.fov, mounts, params
        )
