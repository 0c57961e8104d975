"""Corridor reference angles from the frozen FGM (docs/models.md sec. 8; the paper's sec. 4).

The paper cut the FGM into corridor segments by hand. Here the segments come from the
path the map was built along (the robot drives the corridors' centre lines):

1. resample the path every ``step`` metres of arc length;
2. split it into pieces along which it stays within tol = ``segment_min_length`` *
   sin(``segment_turn_deg``) of a line: split-and-merge (Ramer 1972; Douglas and
   Peucker 1973), the merge step against each joint piece's total-least-squares line.
   A path that bends by ``segment_turn_deg`` departs from its first leg's line by tol
   within ``segment_min_length`` of the bend; a weave about a straight line (the
   simulated robot's 0.1 m across over 3-4 m, +-7 deg of direction) stays within it
   (a test of the path's direction over a metre or two cuts it into pieces shorter
   than a corridor);
3. a piece ends where the path turns, judged from its direction mod pi at each sample
   (doubled-angle vectors, so back-and-forth runs agree; the chord over +-``window``
   metres): a sample is straight when that direction changes by less than
   ``segment_turn_deg`` across the window. Where two pieces meet in a corner (their
   lines, fitted to their straight samples, differ by ``segment_turn_deg`` or more, or
   the path turns back), each piece keeps the samples from its first straight one to
   its last (the weave's own non-straight samples between them included) and ends no
   nearer the crossing of the two lines than the test's reach, 2 ``window`` (where a
   sharp corner's straight samples end: the weave may make samples nearer the corner
   straight); at the path's own ends, and where two pieces meet at less than
   ``segment_turn_deg`` (the same corridor), it is not cut. Pieces at least
   ``segment_min_length`` long are stretches, each fitted with a line (total least
   squares);
4. stretches of the same corridor (direction within ``segment_turn_deg`` mod pi,
   centroid within ``segment_merge_distance`` of the line) are merged;
5. each corridor's region is the rectangle along its line over the stretch's extent
   less ``segment_end_trim`` at both ends (junctions carry the next corridor's walls),
   ``segment_band`` metres either side; its wall evidence (bel(O)) goes to the Hough
   transform (:func:`fuzzyslam.maps.hough.dominant_direction`);
6. a reference is flagged ambiguous (no heading fix uses it) when its Hough finds two
   directions alike, or when its strongest wall line is shorter than
   ``reference_min_strength`` metres of wall (a room, a stub, a doorway beside the path).
   A region with no wall cells at all (a drive across a hall, into a big room) has no
   Hough direction: its reference takes the path's direction (mod pi) with strength 0,
   ambiguous, so that it still marks "no corridor here" for the fixes.

Each Hough reads only the cells of its region's bounding box, so the memory of a map's
references grows with its corridors' areas, not with the map's.
"""

from __future__ import annotations

import itertools
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


def straight_samples(p: np.ndarray, k: int, turn: float) -> np.ndarray:
    """Which samples of a resampled path are straight: the chord from the sample 2k back
    to it and the chord from it to the sample 2k on differ in direction (mod pi) by less
    than ``turn`` (rad); the first and last 2k samples, where the chords do not fit, take
    the nearest sample's answer.

    Parameters
    ----------
    p : ndarray, shape (K, 2)
        Path samples, evenly spaced (none is straight when K < 4k + 1).
    k : int
        Half-window (samples).
    turn : float
        Bound on the direction change (rad).

    Returns
    -------
    ndarray of bool, shape (K,)
    """
    if len(p) < 4 * k + 1:
        return np.zeros(len(p), dtype=bool)
    chord = p[2 * k :] - p[: -2 * k]
    ang2 = 2.0 * np.arctan2(chord[:, 1], chord[:, 0])  # doubled: direction mod pi
    dang = np.abs(wrap_angle_period(ang2[2 * k :] - ang2[: -2 * k], 2 * np.pi)) / 2.0
    ok = dang < turn
    return np.concatenate([np.full(2 * k, ok[0]), ok, np.full(2 * k, ok[-1])])


def split_path(p: np.ndarray, tol: float) -> np.ndarray:
    """The split step of split-and-merge (Ramer 1972, Douglas and Peucker 1973): vertex
    indices such that every point between two consecutive vertices lies within ``tol``
    of the chord (segment) joining them, each piece split at its point farthest from it.

    Parameters
    ----------
    p : ndarray, shape (K, 2)
        The polyline.
    tol : float
        Across-track tolerance (m).

    Returns
    -------
    ndarray of int, shape (V,)
        Vertex indices, ascending, first 0 and last K - 1.
    """
    keep = np.zeros(len(p), dtype=bool)
    keep[[0, -1]] = True
    stack = [(0, len(p) - 1)]
    while stack:  # one split per iteration: a few per corridor
        a, b = stack.pop()
        if b - a < 2:
            continue
        q = p[a + 1 : b] - p[a]
        e = p[b] - p[a]
        u = np.clip(q @ e / max(float(e @ e), 1e-18), 0.0, 1.0)  # the segment, not its line:
        d = np.hypot(*(q - u[:, None] * e).T)  # a path that turns back is split there
        j = int(np.argmax(d))
        if d[j] > tol:
            m = a + 1 + j
            keep[m] = True
            stack += [(a, m), (m, b)]
    return np.flatnonzero(keep)


def merge_pieces(p: np.ndarray, vertices: np.ndarray, tol: float) -> np.ndarray:
    """The merge step of split-and-merge: a vertex is dropped when the path from the
    previous kept vertex to the next vertex lies within ``tol`` of its total-least-squares
    line and does not turn back there (the chords of :func:`split_path` end on the path's
    own weave, a line fitted to all of it does not).

    Parameters
    ----------
    p : ndarray, shape (K, 2)
        The polyline.
    vertices : ndarray of int, shape (V,)
        Vertex indices, ascending, first 0 and last K - 1.
    tol : float
        Across-track tolerance (m).

    Returns
    -------
    ndarray of int, shape (V',)
        The kept vertices.
    """
    out = [int(vertices[0])]
    for j in range(1, len(vertices) - 1):  # one line fit per vertex
        a, v, b = out[-1], int(vertices[j]), int(vertices[j + 1])
        q = p[a : b + 1]
        c, d = _fit_line(q)
        back = (p[v] - p[a]) @ (p[b] - p[v]) < 0
        if back or np.abs((q - c) @ np.array([-d[1], d[0]])).max() > tol:
            out.append(v)
    out.append(int(vertices[-1]))
    return np.array(out)


def _corner(
    p: np.ndarray, a: int, v: int, b: int, straight: np.ndarray, turn: float
) -> np.ndarray | None:
    """Where the pieces a-v and v-b of the path meet in a corner: the crossing of their
    lines (each fitted to its straight samples) when they differ by ``turn`` or more
    (mod pi), the vertex itself when the path turns back there, else None (one corridor).
    """
    lines = []
    for i, j in ((a, v), (v, b)):
        idx = i + np.flatnonzero(straight[i : j + 1])
        lines.append(_fit_line(p[idx] if len(idx) >= 2 else p[i : j + 1]))
    (c1, d1), (c2, d2) = lines
    cross = d1[0] * d2[1] - d1[1] * d2[0]
    if abs(cross) >= np.sin(turn):  # |sin| of the angle between the lines
        t = ((c2 - c1)[0] * d2[1] - (c2 - c1)[1] * d2[0]) / cross
        return c1 + t * d1
    if (p[v] - p[a]) @ (p[b] - p[v]) < 0:
        return p[v]
    return None


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
    if len(p) < 2:
        return []
    k = max(round(window / step), 1)
    turn = np.deg2rad(params.segment_turn_deg)
    straight = straight_samples(p, k, turn)
    tol = params.segment_min_length * np.sin(turn)
    v = merge_pieces(p, split_path(p, tol), tol)
    corners = [None, *(_corner(p, *v[j - 1 : j + 2], straight, turn) for j in range(1, len(v) - 1))]
    corners.append(None)  # the path's ends are no corners
    reach = 2 * k * step  # the chord test's: a sharp corner's straight samples end there
    out = []
    for j, (a, b) in enumerate(itertools.pairwise(v)):  # one per piece
        idx = a + np.flatnonzero(straight[a : b + 1])
        ends = corners[j], corners[j + 1]
        if len(idx) == 0 and (ends[0] is not None or ends[1] is not None):
            continue
        pts = p[idx[0] if ends[0] is not None else a : (idx[-1] if ends[1] is not None else b) + 1]
        c, d = _fit_line(pts)
        s = (pts - c) @ d
        s0, s1 = float(s.min()), float(s.max())
        ahead = 1.0 if (p[b] - p[a]) @ d >= 0 else -1.0  # travel along +d or -d
        for corner, side in zip(ends, (-ahead, ahead), strict=True):  # no nearer a corner
            if corner is not None:  # than the chord test's reach, weave or not
                sc = float((corner - c) @ d)
                s0, s1 = (max(s0, sc + reach), s1) if side < 0 else (s0, min(s1, sc - reach))
        if s1 - s0 < params.segment_min_length:
            continue
        out.append(Stretch(c, d, s0, s1))
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
    grid = fgm.grid
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
        region = st.polygon(params.segment_band)
        # the region's bounding box in cells: a cell whose centre lies in the region
        # has its index in the box (row-major order kept, so the Hough's points and
        # their order are those of the whole grid's)
        iy, ix = grid.cell_of(region)
        box = (
            slice(max(int(iy.min()), 0), max(min(int(iy.max()) + 1, grid.shape[0]), 0)),
            slice(max(int(ix.min()), 0), max(min(int(ix.max()) + 1, grid.shape[1]), 0)),
        )
        x, y = grid.box_centres(box)
        s = (x - st.point[0]) * d[0] + (y - st.point[1]) * d[1]
        q = (x - st.point[0]) * n[0] + (y - st.point[1]) * n[1]
        mask = (s >= st.s0) & (s <= st.s1) & (np.abs(q) <= params.segment_band)
        w = np.where(mask, wall_weights(fgm, params.wall_threshold, box), 0.0)
        wd = dominant_direction(x, y, w, params, rho_step=grid.resolution)
        walls = bool(np.isfinite(wd.angle))  # else no wall cells: the path's direction
        refs.append(
            Reference(
                i,
                f"corridor_{i}",
                wd.angle if walls else st.angle,
                wd.strength,
                region,
                bool(not walls or wd.ambiguous or wd.strength < params.reference_min_strength),
                wd.cells,
                wd,
                st,
            )
        )
    return refs
