"""Wall directions measured from a laser scan's end points (beyond the paper; docs/models.md
sec. 9, ``fixes.heading_source: scan_lines``).

The paper measures the wall direction in the robot frame as the Hough peak of the fuzzy
local map (10 cm cells). A laser's end points are centimetre-accurate and ordered by
beam, so the walls can be fitted directly:

1. end points in the robot frame: p_i = m_i + r_i (cos a_i, sin a_i), (x, y, a) the
   mount of kept beam i (the laser's mount composed with its beam angle), echoes only;
2. a point is *straight* when the ``scan_line_points`` consecutive linked end points
   centred on it (neighbours closer than ``scan_line_gap`` m) have a principal axis
   whose spread across, sqrt(lambda_min), is below ``scan_line_tolerance`` m; runs of
   straight points whose local directions change by less than 5 deg are one segment
   (15 deg merged walls meeting at a shallow angle: 0.83 -> 1.17 deg mean heading error
   on a development log);
3. each segment is fitted by total least squares (principal axis of its points,
   Pearson 1901): direction phi_j, residual variance across
   s2_j = n lambda_min / (n - 2), and the direction's variance
   var(phi_j) = s2_j / (n lambda_max) (the slope of an orthogonal regression, the
   points spread n lambda_max along the line); segments shorter than
   ``scan_line_min_length`` m are dropped;
4. the wall family expected at t_e = t_ref - theta_pred (mod pi): the segments within
   ``gate`` of t_e, weighted by w_j = 1 / (var(phi_j) + sigma_wall^2) (sigma_wall =
   ``scan_line_wall_sigma_deg``: a real wall, cupboard or door frame is straight to
   about that; the fit's own noise alone would trust a 3 m wall to 0.1 deg), give
   t_local = t_e + sum w_j d_j / sum w_j (d_j = phi_j - t_e mod pi) with variance
   1 / sum w_j, scaled up by the Birge ratio chi2 / (S - 1) when the segments scatter
   more than their weights say (chi2 = sum w_j (d_j - mean)^2).

Functions take arrays, no filter: :func:`scan_end_points`, :func:`fit_segments`,
:func:`family_direction`. The heading fix that uses them is
:class:`fuzzyslam.fixes.scan_heading.ScanLineHeadingAid`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from fuzzyslam.maps.evidence import reading_kinds


@dataclass(frozen=True)
class Segments:
    """Straight pieces of one scan, robot frame: direction mod pi in [0, pi) (S,), its
    standard deviation (S,) (rad), length (S,) (m) and number of points (S,)."""

    angle: np.ndarray
    sigma: np.ndarray
    length: np.ndarray
    points: np.ndarray

    def __len__(self) -> int:
        return len(self.angle)


@dataclass(frozen=True)
class FamilyDirection:
    """The direction (mod pi, rad) of a family of walls in the robot frame and its
    standard deviation (rad), with the segments and metres of wall it rests on."""

    angle: float
    sigma: float
    segments: int
    support: float


def scan_end_points(
    ranges: np.ndarray, max_range: np.ndarray | float, mounts: np.ndarray
) -> np.ndarray:
    """End points of one scan in the robot frame (module docstring, step 1).

    Parameters
    ----------
    ranges : (M,) ranges of the kept beams (m; NaN: invalid)
    max_range : scalar or (M,) the beams' max ranges (m): a range there is no echo
    mounts : (M, 3) the beams' poses (x, y, angle) in base_link

    Returns
    -------
    (M, 2) end points in beam order, NaN where a beam has no echo.
    """
    _, echo = reading_kinds(ranges, max_range)  # the evidence's rule (maps/evidence.py)
    r = np.where(echo, np.asarray(ranges, dtype=float), np.nan)
    m = np.asarray(mounts, dtype=float)
    return np.column_stack([m[:, 0] + r * np.cos(m[:, 2]), m[:, 1] + r * np.sin(m[:, 2])])


def _moments(x: np.ndarray, y: np.ndarray, axis: int = -1):
    """Centred second moments (sxx, syy, sxy) along ``axis``."""
    dx = x - x.mean(axis=axis, keepdims=True)
    dy = y - y.mean(axis=axis, keepdims=True)
    return (dx * dx).mean(axis=axis), (dy * dy).mean(axis=axis), (dx * dy).mean(axis=axis)


def _principal(sxx, syy, sxy):
    """Direction mod pi of the principal axis, and the larger and smaller eigenvalues."""
    half = 0.5 * (sxx + syy)
    root = np.sqrt(np.maximum(0.25 * (sxx - syy) ** 2 + sxy * sxy, 0.0))
    return np.mod(0.5 * np.arctan2(2 * sxy, sxx - syy), np.pi), half + root, half - root


def fit_segments(
    points: np.ndarray,
    window: int = 5,
    tolerance: float = 0.03,
    gap: float = 0.5,
    min_length: float = 0.5,
    turn_deg: float = 5.0,
) -> Segments:
    """Straight segments of one scan's ordered end points (module docstring, steps 2-3).

    Parameters
    ----------
    points : (M, 2) end points in beam order (NaN: no echo)
    window : points per local straightness test (``scan_line_points``)
    tolerance : largest spread across (m) of a straight window (``scan_line_tolerance``)
    gap : largest step (m) between linked neighbours (``scan_line_gap``)
    min_length : shortest segment kept (m) (``scan_line_min_length``)
    turn_deg : largest turn (deg) between successive straight points of one segment

    Returns
    -------
    :class:`Segments` with S entries: direction (S,) mod pi, its sigma (S,), length (S,),
    points (S,).
    """
    p = np.asarray(points, dtype=float)
    m = len(p)
    empty = Segments(*(np.zeros(0) for _ in range(4)))
    if m < window:
        return empty
    h = window // 2
    ok = np.all(np.isfinite(p), axis=1)
    step = np.hypot(*np.diff(p, axis=0).T)
    link = ok[:-1] & ok[1:] & (np.nan_to_num(step, nan=np.inf) < gap)  # (M-1,)
    # windows of `window` consecutive points, all linked: centred on point j + h
    wl = np.lib.stride_tricks.sliding_window_view(link, window - 1).all(axis=1)
    wx = np.lib.stride_tricks.sliding_window_view(p[:, 0], window)
    wy = np.lib.stride_tricks.sliding_window_view(p[:, 1], window)
    with np.errstate(invalid="ignore"):
        phi, _, lam_min = _principal(*_moments(wx, wy))
    straight = np.zeros(m, dtype=bool)
    straight[h : m - window + 1 + h] = wl & (np.sqrt(np.maximum(lam_min, 0.0)) < tolerance)
    local = np.full(m, np.nan)
    local[h : m - window + 1 + h] = phi
    # a new segment starts at a straight point whose predecessor is not straight, is not
    # linked to it, or turns by more than turn_deg (directions mod pi)
    turn = np.abs(np.mod(np.diff(local) + np.pi / 2, np.pi) - np.pi / 2)
    cont = straight[1:] & straight[:-1] & link & (turn < math.radians(turn_deg))
    start = straight & ~np.concatenate([[False], cont])
    label = np.cumsum(start) - 1
    idx = np.flatnonzero(straight)
    if not len(idx):
        return empty
    lab = label[idx]
    s = int(lab.max()) + 1
    x, y = p[idx, 0], p[idx, 1]
    ang, n, lam_max, lam_min, across = _fit_labels(lab, x, y, s)
    # one refit without the points beyond 3 robust sigmas of their line (a corner's
    # points: the windows centred next to it can still pass the straightness test)
    scale = 1.4826 * _median_by_label(np.abs(across), lab, s)
    good = np.abs(across) <= np.maximum(3.0 * scale[lab], 1e-3)
    lab, x, y = lab[good], x[good], y[good]
    ang, n, lam_max, lam_min, across = _fit_labels(lab, x, y, s)
    # extent along the line: max - min of the projections
    c, sn = np.cos(ang[lab]), np.sin(ang[lab])
    u = x * c + y * sn
    lo = np.full(s, np.inf)
    hi = np.full(s, -np.inf)
    np.minimum.at(lo, lab, u)
    np.maximum.at(hi, lab, u)
    length = hi - lo
    keep = (n >= 3) & (length >= min_length)
    with np.errstate(divide="ignore", invalid="ignore"):
        s2 = n * np.maximum(lam_min, 0.0) / np.maximum(n - 2, 1.0)
        var = s2 / (n * lam_max)
    return Segments(ang[keep], np.sqrt(var[keep]), length[keep], n[keep])


def _fit_labels(lab: np.ndarray, x: np.ndarray, y: np.ndarray, s: int):
    """Per label (s labels): TLS direction, point count, eigenvalues of the scatter, and
    each point's signed distance across its label's line."""
    n = np.bincount(lab, minlength=s).astype(float)
    with np.errstate(invalid="ignore", divide="ignore"):
        mx, my = np.bincount(lab, x, s) / n, np.bincount(lab, y, s) / n
        dx, dy = x - mx[lab], y - my[lab]
        sxx = np.bincount(lab, dx * dx, s) / n
        syy = np.bincount(lab, dy * dy, s) / n
        sxy = np.bincount(lab, dx * dy, s) / n
    ang, lam_max, lam_min = _principal(sxx, syy, sxy)
    across = -dx * np.sin(ang[lab]) + dy * np.cos(ang[lab])
    return ang, n, lam_max, lam_min, across


def _median_by_label(v: np.ndarray, lab: np.ndarray, s: int) -> np.ndarray:
    """The median of ``v`` per label (s,) (0 for a label without values)."""
    order = np.lexsort((v, lab))
    v, lab = v[order], lab[order]
    n = np.bincount(lab, minlength=s)
    first = np.concatenate([[0], np.cumsum(n)[:-1]])
    out = np.zeros(s)
    has = n > 0
    lo = first[has] + (n[has] - 1) // 2
    hi = first[has] + n[has] // 2
    out[has] = 0.5 * (v[lo] + v[hi])
    return out


def family_direction(
    segs: Segments, expected: float, gate: float, wall_sigma: float, min_support: float = 1.0
) -> FamilyDirection | None:
    """The direction of one family of walls (module docstring, step 4).

    Parameters
    ----------
    segs : the scan's segments (S,)
    expected : expected wall direction (rad, mod pi), t_ref - theta_pred
    gate : half-width (rad) of the window around ``expected``
    wall_sigma : straightness of a real wall (rad), added to each segment's variance
    min_support : least metres of wall in the window

    Returns
    -------
    :class:`FamilyDirection` (direction mod pi in [0, pi), sigma, segments, support), or
    None when the window holds less than ``min_support`` m of wall.
    """
    if not len(segs):
        return None
    d = np.mod(segs.angle - expected + np.pi / 2, np.pi) - np.pi / 2
    sel = np.abs(d) <= gate
    if not sel.any() or float(segs.length[sel].sum()) < min_support:
        return None
    d = d[sel]
    w = 1.0 / (segs.sigma[sel] ** 2 + wall_sigma**2)
    mean = float(np.sum(w * d) / np.sum(w))
    var = 1.0 / float(np.sum(w))
    k = int(sel.sum())
    if k > 1:
        chi2 = float(np.sum(w * (d - mean) ** 2))
        var *= max(1.0, chi2 / (k - 1))
    angle = float(np.mod(expected + mean, np.pi))
    return FamilyDirection(angle, math.sqrt(var), k, float(segs.length[sel].sum()))
