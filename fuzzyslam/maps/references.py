"""Corridor reference angles from the frozen FGM (docs/models.md sec. 8; the paper's sec. 4).

The paper cut the FGM into corridor segments by hand. Here the segments come from the
path the map was built along (the robot drives the corridors' centre lines):

1. resample the path every ``step`` metres of arc length;
2. its direction mod pi at each sample (doubled-angle vectors, so back-and-forth runs
   agree), from the chord over +-``window`` metres;
3. samples where the direction changes by less than ``segment_turn_deg`` across the
   window are straight; runs of straight samples at least ``segment_min_length`` long
   are stretches, each fitted with a line (total least squares);
4. stretches of the same corridor (direction within ``segment_turn_deg`` mod pi,
   centroid within ``segment_merge_distance`` of the line) are merged;
5. each corridor's region is the rectangle along its line over the stretch's extent
   less ``segment_end_trim`` at both ends (junctions carry the next corridor's walls),
   ``segment_band`` metres either side; its wall evidence (bel(O)) goes to the Hough
   transform (:func:`fuzzyslam.maps.hough.dominant_direction`);
6. a reference is flagged ambiguous (no heading fix uses it) when its Hough finds two
   directions alike, or when its strongest wall line is shorter than
   ``reference_min_strength`` metres of wall (a room, a stub, a doorway beside the path).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fuzzyslam.maps.grid import BeliefMap
from fuzzyslam.maps.hough import dominant_direction, wall_weights
from fuzzyslam.maps.params import MapParams
from fuzzyslam.references import Reference
from fuzzyslam.se2 import direction_mod_pi, wrap_angle_period


@dataclass
class Stretch:
    """A straight piece of corridor: a point on its line, unit direction, extent [s0, s1]."""

    point: np.ndarray
    direction: np.ndarray
    s0: float
    s1: float

    @property
    def angle(self) -> float:
        """Direction mod pi in [0, pi)."""
        return direction_mod_pi(np.arctan2(self.direction[1], self.direction[0]))

    @property
    def length(self) -> float:
        return self.s1 - self.s0

    def polygon(self, band: float) -> np.ndarray:
        """(4, 2) rectangle along the line, ``band`` either side.

        Parameters
        ----------
        band : float
            Half-width (m).

        Returns
        -------
        ndarray, shape (4, 2)
        """
        d = self.direction
        n = np.array([-d[1], d[0]])
        a = self.point + self.s0 * d
        b = self.point + self.s1 * d
        return np.array([a - band * n, b - band * n, b + band * n, a + band * n])


def _fit_line(p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Centroid and unit direction (principal axis) of points (N, 2): total least squares."""
    c = p.mean(axis=0)
    _u, _s, vt = np.linalg.svd(p - c, full_matrices=False)
    d = vt[0]
    if d[0] < 0 or (d[0] == 0 and d[1] < 0):
        d = -d
    return c, d


def resample_path(xy: np.ndarray, step: float) -> np.ndarray:
    """Points every ``step`` metres of arc length along a polyline (N, 2).

    Parameters
    ----------
    xy : ndarray, shape (N, 2)
        The polyline.
    step : float
        Spacing (m).

    Returns
    -------
    ndarray, shape (K, 2)
    """
    xy = np.asarray(xy, dtype=float).reshape(-1, 2)
    seg = np.hypot(*np.diff(xy, axis=0).T)
    s = np.concatenate([[0.0], np.cumsum(seg)])
    if s[-1] <= 0:
        return xy[:1]
    keep = np.concatenate([[True], seg > 1e-9])
    s, xy = s[keep], xy[keep]
    q = np.arange(0.0, s[-1], step)
    return np.column_stack([np.interp(q, s, xy[:, 0]), np.interp(q, s, xy[:, 1])])


def straight_stretches(
    xy: np.ndarray, params: MapParams, step: float = 0.1, window: float = 0.5
) -> list[Stretch]:
    """Straight stretches of a path (steps 1-3 of the module docstring).

    Parameters
    ----------
    xy : ndarray, shape (N, 2)
        The path.
    params : MapParams
        The stretches' thresholds.
    step : float
        Resampling step (m).
    window : float
        Half-window (m) of the local direction.

    Returns
    -------
    list of Stretch
    """
    p = resample_path(xy, step)
    k = max(round(window / step), 1)
    if len(p) < 2 * k + 2:
        return []
    chord = p[2 * k :] - p[: -2 * k]
    ang2 = 2.0 * np.arctan2(chord[:, 1], chord[:, 0])  # doubled: direction mod pi
    dang = np.abs(wrap_angle_period(ang2[2 * k :] - ang2[: -2 * k], 2 * np.pi)) / 2.0
    straight = np.zeros(len(p), dtype=bool)
    straight[2 * k : 2 * k + len(dang)] = dang < np.deg2rad(params.segment_turn_deg)
    edges = np.flatnonzero(np.diff(np.concatenate([[0], straight.astype(np.int8), [0]])))
    out = []
    for a, b in zip(edges[::2], edges[1::2], strict=True):  # one per stretch
        pts = p[a:b]
        if len(pts) * step < params.segment_min_length:
            continue
        c, d = _fit_line(pts)
        s = (pts - c) @ d
        out.append(Stretch(c, d, float(s.min()), float(s.max())))
    return out


def merge_stretches(stretches: list[Stretch], params: MapParams) -> list[Stretch]:
    """Merge stretches of the same corridor (step 4 of the module docstring).

    Parameters
    ----------
    stretches : list of Stretch
        :func:`straight_stretches`.
    params : MapParams
        The merge thresholds.

    Returns
    -------
    list of Stretch
    """
    merged: list[list[Stretch]] = []
    tol = np.deg2rad(params.segment_turn_deg)
    for st in stretches:  # a few dozen stretches at most
        home = None
        for group in merged:
            g = group[0]
            same_dir = abs(wrap_angle_period(st.angle - g.angle, np.pi)) < tol
            n = np.array([-g.direction[1], g.direction[0]])
            near = abs((st.point - g.point) @ n) < params.segment_merge_distance
            if same_dir and near:
                home = group
                break
        if home is None:
            merged.append([st])
        else:
            home.append(st)
    out = []
    for group in merged:
        ends = np.concatenate(
            [[s.point + s.s0 * s.direction, s.point + s.s1 * s.direction] for s in group]
        )
        w = np.repeat([s.length for s in group], 2)
        c = np.average(ends, axis=0, weights=w)
        # the longest stretch's direction, flipped to agree
        best = max(group, key=lambda s: s.length)
        d = best.direction
        s = (ends - c) @ d
        out.append(Stretch(c, d, float(s.min()), float(s.max())))
    return out


def extract_references(fgm: BeliefMap, path_xy: np.ndarray, params: MapParams) -> list[Reference]:
    """Corridor references of a (frozen) FGM built along ``path_xy`` (module docstring).

    Parameters
    ----------
    fgm : BeliefMap
        The frozen FGM.
    path_xy : ndarray, shape (N, 2)
        The path it was built along.
    params : MapParams
        The ``fgm:`` section.

    Returns
    -------
    list of Reference
    """
    stretches = merge_stretches(straight_stretches(path_xy, params), params)
    X, Y = fgm.grid.centres()
    w_all = wall_weights(fgm, params.wall_threshold)
    refs = []
    trim = params.segment_end_trim
    stretches = [
        Stretch(st.point, st.direction, st.s0 + trim, st.s1 - trim)
        for st in stretches
        if st.length - 2 * trim >= params.segment_min_length / 2
    ]
    for i, st in enumerate(stretches):  # one Hough per corridor
        d = st.direction
        n = np.array([-d[1], d[0]])
        s = (X - st.point[0]) * d[0] + (Y - st.point[1]) * d[1]
        q = (X - st.point[0]) * n[0] + (Y - st.point[1]) * n[1]
        mask = (s >= st.s0) & (s <= st.s1) & (np.abs(q) <= params.segment_band)
        w = np.where(mask, w_all, 0.0)
        wd = dominant_direction(X, Y, w, params, rho_step=fgm.grid.resolution)
        refs.append(
            Reference(
                i,
                f"corridor_{i}",
                wd.angle,
                wd.strength,
                st.polygon(params.segment_band),
                bool(wd.ambiguous or wd.strength < params.reference_min_strength),
                wd.cells,
                wd,
                st,
            )
        )
    return refs
