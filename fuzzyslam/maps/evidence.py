"""Per-reading sonar evidence on grid cells (models.md sec. 5), vectorised over a whole ring.

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
    """
    dr = params.range_tolerance
    a = np.clip(1.0 - np.abs(phi / half_angle) ** params.angular_exponent, 0.0, None)
    d = 1.0 / (1.0 + (rho / params.reliability_range) ** 2)
    d_e = 1.0 / (1.0 + (rho / params.empty_reliability_range) ** 2)
    ad = a * d
    u = (rho - r) / dr
    f_o = np.where(echo, params.k_occupied * np.clip(1.0 - u * u, 0.0, None), 0.0)
    ramp = np.clip((r - rho) / dr, 0.0, 1.0)
    f_e_echo = np.where(rho <= params.empty_reach, params.k_empty * ramp, 0.0)
    f_e_none = np.where(rho < params.no_echo_reach, params.no_echo_empty, 0.0)
    f_e = np.where(echo, f_e_echo, f_e_none)
    return a * d_e * f_e, ad * f_o


def cone_cells(
    grid: Grid, sensors: np.ndarray, reach: np.ndarray, half_angle: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(reading index, iy, ix) of every grid cell in the bounding box of each cone.

    The box of cone i spans the sensor origin and its arc of radius reach[i] (sampled
    at 9 bearings, padded by one cell), clipped to the grid. All boxes are enumerated at
    once with repeat/arange index arithmetic (no loop over readings or cells).
    """
    n = len(sensors)
    if n == 0:
        e = np.zeros(0, dtype=np.int64)
        return e, e, e
    bear = sensors[:, 2:3] + np.linspace(-half_angle, half_angle, 9)[None, :]
    ax = np.concatenate([sensors[:, 0:1], sensors[:, 0:1] + reach[:, None] * np.cos(bear)], 1)
    ay = np.concatenate([sensors[:, 1:2], sensors[:, 1:2] + reach[:, None] * np.sin(bear)], 1)
    res, (ox, oy) = grid.resolution, grid.origin
    ny, nx = grid.shape
    ix0 = np.clip(np.floor((ax.min(1) - ox) / res).astype(np.int64) - 1, 0, nx)
    ix1 = np.clip(np.floor((ax.max(1) - ox) / res).astype(np.int64) + 2, 0, nx)
    iy0 = np.clip(np.floor((ay.min(1) - oy) / res).astype(np.int64) - 1, 0, ny)
    iy1 = np.clip(np.floor((ay.max(1) - oy) / res).astype(np.int64) + 2, 0, ny)
    wx = ix1 - ix0
    wy = iy1 - iy0
    count = np.maximum(wx, 0) * np.maximum(wy, 0)
    total = int(count.sum())
    rid = np.repeat(np.arange(n), count)
    start = np.cumsum(count) - count
    k = np.arange(total) - np.repeat(start, count)
    w = wx[rid]
    return rid, iy0[rid] + k // w, ix0[rid] + k % w


def ring_evidence(
    grid: Grid,
    pose: np.ndarray,
    ranges: np.ndarray,
    max_range: np.ndarray | float,
    fov: float,
    mounts: np.ndarray,
    params: MapParams,
) -> RingEvidence:
    """Evidence of one ring of readings placed at robot ``pose`` (in ``grid``'s frame).

    Sensor i sits at compose(pose, mounts[i]). NaN ranges (missing, invalid) are skipped.
    Each reading's mass function is evaluated on the cells of its cone; the readings that
    reach a same cell (overlapping cones) are combined with the conjunctive rule
    (:func:`fuzzyslam.maps.tbm.conjunctive_grouped`). Returns the touched cells (flat
    indices into ``grid.shape``, unique) with their combined masses.
    """
    ranges = np.asarray(ranges, dtype=float).reshape(-1)
    rmax = np.broadcast_to(np.asarray(max_range, dtype=float), ranges.shape)
    mounts = np.asarray(mounts, dtype=float).reshape(-1, 3)
    if len(mounts) != len(ranges):
        raise ValueError(f"{len(ranges)} ranges but {len(mounts)} sonar mounts")
    ok = np.isfinite(ranges) & (ranges > 0)
    echo_all = ok & (~np.isfinite(rmax) | (ranges < rmax - 1e-6))
    half = 0.5 * float(fov)
    sensors = compose(np.asarray(pose, dtype=float), mounts[ok])
    r = ranges[ok]
    echo = echo_all[ok]
    reach = np.where(echo, r + params.range_tolerance, np.minimum(params.no_echo_reach, r))
    rid, iy, ix = cone_cells(grid, sensors, reach, half)
    res, (ox, oy) = grid.resolution, grid.origin
    dx = ox + (ix + 0.5) * res - sensors[rid, 0]
    dy = oy + (iy + 0.5) * res - sensors[rid, 1]
    rho = np.hypot(dx, dy)
    phi = np.mod(np.arctan2(dy, dx) - sensors[rid, 2] + np.pi, 2.0 * np.pi) - np.pi
    inside = (np.abs(phi) <= half) & (rho <= reach[rid])
    rid, iy, ix, rho, phi = rid[inside], iy[inside], ix[inside], rho[inside], phi[inside]
    m_e, m_o = reading_masses(rho, phi, r[rid], echo[rid], half, params)
    keep = (m_e > 0) | (m_o > 0)
    flat = (iy * grid.shape[1] + ix)[keep]
    m_e, m_o = m_e[keep], m_o[keep]
    cells, inv = np.unique(flat, return_inverse=True)
    zeros = np.zeros_like(m_e)
    masses = conjunctive_grouped((m_e, m_o, 1.0 - m_e - m_o, zeros), inv, len(cells))
    return RingEvidence(cells, masses, int(flat.size), int(ok.sum()))
