"""Per-reading sonar evidence on grid cells (docs/models.md sec. 5), vectorised over a whole ring.

For a reading of range r from a sensor with cone half-angle w, a cell at range rho and
bearing phi from the sensor receives (Oriolo, Ulivi & Vendittelli, "Real-time map
building and navigation for autonomous robots in unknown environments", IEEE SMC-B 28(3),
1998; Poloni, Ulivi & Vendittelli, "Fuzzy logic and autonomous vehicles", 1995)::

    angular weight     a(phi) = 1 - |phi / w|^p  (p = 2 in Oriolo) for |phi| <= w
    distance rel.      d(rho) = 1 / (1 + (rho / rho_h)^2), d_E likewise with rho_E
    occupied           f_O = k_O (1 - ((rho - r) / dr)^2)          for |rho - r| < dr
    empty              f_E = k_E                                   for rho <= r - dr
                       f_E = k_E (r - rho) / dr                    for r - dr < rho < r
                       f_E = 0                                     for rho > rho_max_E
    mass function      m(O) = a d f_O,  m(E) = a d_E f_E,  m(T) = 1 - m(E) - m(O)

A max-range (no echo) reading gives no occupied evidence and only the weak empty
evidence k = ``no_echo_empty`` up to ``no_echo_reach`` (specular walls do not echo; the
cone is not known to be empty far away). Constants and their justification:
:mod:`fuzzyslam.maps.params`. Cells are evaluated at their centres.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from fuzzyslam.maps.grid import Grid
from fuzzyslam.maps.params import MapParams
from fuzzyslam.maps.tbm import Masses, conjunctive_grouped
from fuzzyslam.se2 import compose


@dataclass
class RingEvidence:
    """The combined evidence of one ring: flat cell indices (unique) and their masses."""

    cells: np.ndarray
    masses: Masses
    pairs: int
    readings: int


def reading_kinds(ranges: np.ndarray, max_range) -> tuple[np.ndarray, np.ndarray]:
    """Which readings count and which of them are echoes: a reading is valid when finite
    and positive (NaN: missing or invalid), and an echo when also below its maximum range
    (by more than 1e-6 m; an infinite maximum: every valid reading); a valid reading at
    its maximum range is "no echo" (empty evidence up to ``no_echo_reach``).

    Parameters
    ----------
    ranges : ndarray, shape (...)
        The readings (m).
    max_range : ndarray or float
        The maximum ranges, broadcast to ``ranges``.

    Returns
    -------
    valid, echo : ndarray of bool, shape of ``ranges``
    """
    r = np.asarray(ranges, dtype=float)
    rmax = np.broadcast_to(np.asarray(max_range, dtype=float), r.shape)
    valid = np.isfinite(r) & (r > 0)
    return valid, valid & (~np.isfinite(rmax) | (r < rmax - 1e-6))


def reading_masses(
    rho: np.ndarray,
    phi: np.ndarray,
    r: np.ndarray,
    echo: np.ndarray,
    half_angle: float,
    params: MapParams,
) -> tuple[np.ndarray, np.ndarray]:
    """(m(E), m(O)) of cells at (rho, phi) from readings r (echo: bool), elementwise.

    The equations are in the module docstring.

    Parameters
    ----------
    rho, phi : ndarray, shape (...)
        Cells' range (m) and bearing (rad) from the sensor's axis.
    r : ndarray, shape (...)
        The readings (m).
    echo : ndarray of bool, shape (...)
        Whether each reading is an echo (else no echo up to the maximum range).
    half_angle : float
        The cone's half-angle (rad).
    params : MapParams
        The sonar model's constants.

    Returns
    -------
    m_e, m_o : ndarray, shape (...)
    """
    dr = params.range_tolerance
    # (np.maximum / np.minimum: np.clip's values here, no NaN nor -0 in these terms,
    # without its overhead)
    a = np.maximum(1.0 - np.abs(phi / half_angle) ** params.angular_exponent, 0.0)
    d = 1.0 / (1.0 + (rho / params.reliability_range) ** 2)
    d_e = 1.0 / (1.0 + (rho / params.empty_reliability_range) ** 2)
    ad = a * d
    u = (rho - r) / dr
    f_o = np.where(echo, params.k_occupied * np.maximum(1.0 - u * u, 0.0), 0.0)
    ramp = np.minimum(np.maximum((r - rho) / dr, 0.0), 1.0)
    f_e_echo = np.where(rho <= params.empty_reach, params.k_empty * ramp, 0.0)
    f_e_none = np.where(rho < params.no_echo_reach, params.no_echo_empty, 0.0)
    f_e = np.where(echo, f_e_echo, f_e_none)
    return a * d_e * f_e, ad * f_o


@lru_cache(maxsize=8)
def _arc_bearings(half_angle: float) -> np.ndarray:
    """The 9 bearings (rad) at which :func:`cone_cells` samples a sector's arcs, about the
    axis (read-only; one table per cone, not one per call)."""
    out = np.linspace(-half_angle, half_angle, 9)
    out.flags.writeable = False
    return out


def _bound(x: np.ndarray, lo, hi) -> np.ndarray:
    """min(max(x, lo), hi) elementwise: ``np.clip(x, lo, hi)`` for integers and whole
    numbers (no NaN) without np.clip's Python overhead."""
    return np.minimum(np.maximum(x, lo), hi)


def cone_cells(
    grid: Grid, sensors: np.ndarray, r0: np.ndarray, r1: np.ndarray, half_angle: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(piece index, iy, ix) of candidate cells of each annular sector r0[i] <= rho <=
    r1[i], |phi| <= half_angle about sensor i's axis: a superset of the cells whose
    CENTRES lie in the sector (the caller applies the exact test).

    Rows: those of the sector's bounding box (its two arcs sampled at 9 bearings, padded
    by r1 (1 - cos(w / 8)), the most an arc bulges between two samples). Per row, the
    x-interval of the centres inside the disc rho <= r1 + pad and between the cone's two
    edge rays (two half-planes: the wedge is convex for w < 90 deg); the inner radius is
    not used. Paper log: 1.6 candidates per kept cell (5.8 with the whole-cell padded
    boxes of the first version, 2.9 with tight boxes). All rows and cells are
    enumerated at once with repeat/arange index arithmetic (no loop over sectors, rows or
    cells; the loop is over the two edge rays).

    Parameters
    ----------
    grid : Grid
        The grid.
    sensors : ndarray, shape (P, 3)
        The sensors' poses in the grid's frame.
    r0, r1 : ndarray, shape (P,)
        The sectors' inner and outer radii (m).
    half_angle : float
        The cone's half-angle (rad).

    Returns
    -------
    piece, iy, ix : ndarray of int, shape (C,)
    """
    n = len(sensors)
    if n == 0:
        e = np.zeros(0, dtype=np.int64)
        return e, e, e
    # the two arcs' samples (rows: arc, bearing; columns: sector, so that the boxes'
    # bounds are reductions over rows, much faster than over a short last axis)
    bear = sensors[:, 2] + _arc_bearings(float(half_angle))[:, None]
    c, s = np.cos(bear), np.sin(bear)
    radii = np.stack([r0, r1])[:, None, :]
    ax = (sensors[:, 0] + radii * c).reshape(-1, n)
    ay = (sensors[:, 1] + radii * s).reshape(-1, n)
    res, (ox, oy) = grid.resolution, grid.origin
    ny, nx = grid.shape
    pad = np.asarray(r1, dtype=float) * (1.0 - np.cos(half_angle / 8.0)) + 1e-9
    # cell ix has its centre at ox + (ix + 0.5) res: centres in [xmin, xmax] are
    # ix in [ceil((xmin - ox) / res - 0.5), floor((xmax - ox) / res - 0.5)]
    # (integer bounds: np.minimum / np.maximum are np.clip's values, without its overhead)
    ix0 = _bound(np.ceil((ax.min(0) - pad - ox) / res - 0.5).astype(np.int64), 0, nx)
    ix1 = _bound(np.floor((ax.max(0) + pad - ox) / res - 0.5).astype(np.int64) + 1, 0, nx)
    iy0 = _bound(np.ceil((ay.min(0) - pad - oy) / res - 0.5).astype(np.int64), 0, ny)
    iy1 = _bound(np.floor((ay.max(0) + pad - oy) / res - 0.5).astype(np.int64) + 1, 0, ny)
    # rows of each box, then per row the x-interval of the cell centres that can lie in
    # the sector: inside the disc rho <= r1 and between the cone's two edge rays
    wy = np.maximum(iy1 - iy0, 0)
    nrow = int(wy.sum())
    rp = np.repeat(np.arange(n), wy)
    iy = iy0.take(rp) + np.arange(nrow) - np.repeat(np.cumsum(wy) - wy, wy)
    dy = oy + (iy + 0.5) * res - sensors[:, 1].take(rp)
    h2 = (r1 + pad).take(rp) ** 2 - dy * dy
    h = np.sqrt(np.maximum(h2, 0.0))
    lo, hi = -h, np.where(h2 >= 0.0, h, -np.inf)
    eps = 1e-6  # the cone test is exact; the interval only has to contain its cells
    if half_angle < np.pi / 2:  # (a wider cone is not convex)
        # edge rays at axis + w (sign 1: cells to its right) and axis - w (sign -1, left),
        # both at once (rows: sign); inside: sign * (ux dy - uy dx) <= 0, i.e.
        # sign * uy dx >= sign * ux dy. Each ray bounds lo from below (su > 0) or hi
        # from above (su < 0), or empties the row (su = 0, sv > eps): max, min and -inf
        # in either order, the same floats as one ray after the other
        # (the rays' cosines and sines per sector, then per row: the same floats)
        sign = np.array([[1.0], [-1.0]])
        b = sensors[:, 2] + sign * half_angle
        ux, uy = np.cos(b).take(rp, axis=1), np.sin(b).take(rp, axis=1)
        su, sv = sign * uy, sign * ux * dy
        with np.errstate(divide="ignore", invalid="ignore"):
            bound = sv / su
        lo = np.maximum(lo, np.where(su > 1e-12, bound - eps, -np.inf).max(0))
        cap = np.where(su < -1e-12, bound + eps, np.inf)
        cap[(np.abs(su) <= 1e-12) & (sv > eps)] = -np.inf
        hi = np.minimum(hi, cap.min(0))
    xs = sensors[:, 0].take(rp) - ox
    # whole numbers (finite or infinite: lo, hi and their sums are never NaN) clamped to the
    # row's box, then made integers (np.clip's values)
    box0, box1 = ix0.take(rp), ix1.take(rp)
    a = _bound(np.ceil((xs + lo) / res - 0.5), box0, box1).astype(np.int64)
    z = _bound(np.floor((xs + np.maximum(hi, lo - res)) / res - 0.5) + 1, box0, box1)
    count = np.maximum(z.astype(np.int64) - a, 0)
    total = int(count.sum())
    row = np.repeat(np.arange(nrow), count)
    k = np.arange(total) - np.repeat(np.cumsum(count) - count, count)
    return rp.take(row), iy.take(row), a.take(row) + k


@dataclass
class BatchEvidence:
    """Combined evidence of K rings: ring k's cells are ``cells[ptr[k]:ptr[k + 1]]`` (flat
    indices, unique and sorted within a ring) with ``masses`` sliced alike."""

    ptr: np.ndarray
    cells: np.ndarray
    masses: Masses
    pairs: int
    readings: int

    def ring(self, k: int) -> RingEvidence:
        """Ring ``k``'s evidence.

        Parameters
        ----------
        k : int
            The ring (0 <= k < K).

        Returns
        -------
        RingEvidence
        """
        a, b = int(self.ptr[k]), int(self.ptr[k + 1])
        return RingEvidence(
            self.cells[a:b],
            tuple(m[a:b] for m in self.masses),
            0,
            0,  # type: ignore[arg-type]
        )


def rings_evidence(
    grid: Grid,
    poses: np.ndarray,
    ranges: np.ndarray,
    max_range: np.ndarray | float,
    fov: float,
    mounts: np.ndarray,
    params: MapParams,
) -> BatchEvidence:
    """Evidence of K rings at robot poses (K, 3), ranges (K, M), in ``grid``'s frame.

    Sensor i of ring k sits at compose(poses[k], mounts[i]) (or mounts[k, i]: each ring
    its own, deskewed, :func:`fuzzyslam.streams.sonar.deskewed_mounts`). NaN ranges (missing,
    invalid) are skipped. Each reading's mass function (:func:`reading_masses`) is
    evaluated on the cells of its cone; readings of one ring that reach a same cell
    (overlapping cones) are combined with the conjunctive rule
    (:func:`fuzzyslam.maps.tbm.conjunctive_grouped`). All rings, readings and cells are
    processed in one vectorised pass (no loop).

    Parameters
    ----------
    grid : Grid
        The grid.
    poses : ndarray, shape (K, 3)
        The robot's poses.
    ranges : ndarray, shape (K, M)
        The readings (NaN: none).
    max_range : ndarray, shape (K, M), or float
        The maximum ranges.
    fov : float
        The cone's full angle (rad).
    mounts : ndarray, shape (M, 3) or (K, M, 3)
        The sensors' poses on the robot (the same for every ring, or each ring's).
    params : MapParams
        The sonar model's constants.

    Returns
    -------
    BatchEvidence
    """
    poses = np.asarray(poses, dtype=float).reshape(-1, 3)
    k_rings = len(poses)
    mounts = np.asarray(mounts, dtype=float)
    per_ring = mounts.ndim == 3
    mounts = mounts.reshape(k_rings, -1, 3) if per_ring else mounts.reshape(-1, 3)
    m = mounts.shape[-2]
    ranges = np.asarray(ranges, dtype=float).reshape(k_rings, -1)
    if ranges.shape[1] != m:
        raise ValueError(f"{ranges.shape[1]} ranges per ring but {m} sonar mounts")
    ok, echo_all = reading_kinds(ranges, max_range)
    half = 0.5 * float(fov)
    ring_of, sensor_of = np.nonzero(ok)
    sensors = compose(poses[ring_of], mounts[ring_of, sensor_of] if per_ring else mounts[sensor_of])
    rid, cell, m_e, m_o, _ = readings_cells(grid, sensors, ranges[ok], echo_all[ok], half, params)
    ncell = grid.shape[0] * grid.shape[1]
    return combine_cells(ring_of[rid] * ncell + cell, m_e, m_o, k_rings, ncell, int(ok.sum()))


def readings_cells(
    grid: Grid,
    sensors: np.ndarray,
    r: np.ndarray,
    echo: np.ndarray,
    half: float,
    params: MapParams,
) -> tuple[np.ndarray, ...]:
    """The cells that readings give evidence to and their masses, before combination.

    Each reading's cone is split in two annular sectors (the near one: empty evidence,
    and the arc when it is near; the far one: the arc), so that the cells between them
    are never enumerated. Entries come sector by sector, the near sectors of all readings
    first, then the far ones, each sector's cells row by row; every entry depends only on
    its own reading (so one reading alone gives its own entries, bit for bit).

    Parameters
    ----------
    grid : Grid
        The grid.
    sensors : ndarray, shape (R, 3)
        The readings' sensor poses in the grid's frame.
    r : ndarray, shape (R,)
        The ranges (m), finite and positive.
    echo : ndarray of bool, shape (R,)
        Whether each is an echo (else no echo up to the maximum range).
    half : float
        The cone's half-angle (rad).
    params : MapParams
        The sonar model's constants.

    Returns
    -------
    rid : ndarray of int, shape (C,)
        The reading of each entry.
    cell : ndarray of int, shape (C,)
        Its flat cell index (iy nx + ix).
    m_e, m_o : ndarray, shape (C,)
        Its masses (at least one positive).
    second : ndarray of bool, shape (C,)
        Whether it comes from a far sector.
    """
    # near: [0, n1] (empty evidence, and the arc when it is near); far: [r - dr, r + dr].
    dr = params.range_tolerance
    reach = np.where(echo, r + dr, np.minimum(params.no_echo_reach, r))
    near = np.where(echo & (r - dr > params.empty_reach), params.empty_reach, reach)
    far = echo & (r - dr > params.empty_reach)
    src = np.concatenate([np.arange(len(r)), np.flatnonzero(far)])
    lo = np.concatenate([np.zeros(len(r)), (r - dr)[far]])
    hi = np.concatenate([near, (r + dr)[far]])
    pid, iy, ix = cone_cells(grid, sensors[src], lo, hi, half)
    rid = src.take(pid)
    res, (ox, oy) = grid.resolution, grid.origin
    # (gathers by ``take`` and by index arrays: numpy's fancy and boolean indexing give
    # the same elements, more slowly)
    dx = ox + (ix + 0.5) * res - sensors[:, 0].take(rid)
    dy = oy + (iy + 0.5) * res - sensors[:, 1].take(rid)
    # along = rho cos(phi), across = rho sin(phi) in the sensor's frame: the cone test
    # |phi| <= w is across^2 <= tan(w)^2 along^2 with along > 0 (no arctan on every cell)
    ca, sa = np.cos(sensors[:, 2]).take(rid), np.sin(sensors[:, 2]).take(rid)
    along = dx * ca + dy * sa
    across = dy * ca - dx * sa
    rho2 = dx * dx + dy * dy
    inside = (
        (along > 0)
        & (across * across <= np.tan(half) ** 2 * along * along)
        & (rho2 >= (lo**2).take(pid))
        & (rho2 < (hi**2).take(pid))
    )
    sel = np.flatnonzero(inside)
    rid = rid.take(sel)
    rho = np.sqrt(rho2.take(sel))
    phi = np.arctan2(across.take(sel), along.take(sel))
    m_e, m_o = reading_masses(rho, phi, r.take(rid), echo.take(rid), half, params)
    keep = np.flatnonzero((m_e > 0) | (m_o > 0))
    sel = sel.take(keep)  # the candidates kept
    cell = iy.take(sel) * grid.shape[1] + ix.take(sel)
    second = pid.take(sel) >= len(r)
    return rid.take(keep), cell, m_e.take(keep), m_o.take(keep), second


def combine_cells(
    key: np.ndarray, m_e: np.ndarray, m_o: np.ndarray, k_rings: int, ncell: int, readings: int
) -> BatchEvidence:
    """The entries of :func:`readings_cells` combined per cell and ring (conjunctive rule,
    in the entries' order).

    Parameters
    ----------
    key : ndarray of int, shape (C,)
        Ring k's cell c is k ncell + c.
    m_e, m_o : ndarray, shape (C,)
        The entries' masses.
    k_rings : int
        Number of rings.
    ncell : int
        Cells of the grid.
    readings : int
        Readings used (for the summary).

    Returns
    -------
    BatchEvidence
    """
    ukey, inv = np.unique(key, return_inverse=True)
    masses = conjunctive_grouped((m_e, m_o, 1.0 - m_e - m_o, np.zeros_like(m_e)), inv, len(ukey))
    ptr = np.searchsorted(ukey, np.arange(k_rings + 1) * ncell)
    return BatchEvidence(ptr, ukey % ncell, masses, int(key.size), readings)


def ring_evidence(
    grid: Grid,
    pose: np.ndarray,
    ranges: np.ndarray,
    max_range: np.ndarray | float,
    fov: float,
    mounts: np.ndarray,
    params: MapParams,
) -> RingEvidence:
    """Evidence of one ring at robot ``pose``: :func:`rings_evidence` with K = 1.

    Parameters
    ----------
    grid : Grid
        The grid.
    pose : ndarray, shape (3,)
        The robot's pose.
    ranges : ndarray, shape (M,)
        The readings (NaN: none).
    max_range : ndarray, shape (M,), or float
        The maximum ranges.
    fov : float
        The cone's full angle (rad).
    mounts : ndarray, shape (M, 3)
        The sensors' poses on the robot.
    params : MapParams
        The sonar model's constants.

    Returns
    -------
    RingEvidence
    """
    ranges = np.asarray(ranges, dtype=float).reshape(1, -1)
    rmax = np.broadcast_to(np.asarray(max_range, dtype=float), ranges.shape[1:]).reshape(1, -1)
    b = rings_evidence(grid, np.asarray(pose, float)[None], ranges, rmax, fov, mounts, params)
    return RingEvidence(b.cells, b.masses, b.pairs, b.readings)
