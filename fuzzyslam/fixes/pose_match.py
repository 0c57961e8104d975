"""Full-pose fixes: correlative matching of the FLM against the frozen FGM (docs/models.md sec. 10).

Beyond the paper (its "future work"). Following E. Olson, "Real-time correlative scan
matching", ICRA 2009, and K. Konolige, K. Chou, "Markov localization using
correlation", IJCAI 1999: the pose likelihood is evaluated exhaustively on a lattice
(dx, dy, dtheta) around the prediction, and its mean and covariance are the moments
of that surface (Olson sec. IV-C):

    mu = sum_i L_i x_i / sum_i L_i,   Sigma = sum_i L_i (x_i - mu)(x_i - mu)^T / sum_i L_i.

Score [ours]. Each evidence cell of the FLM carries masses (o, e) = (m(O), m(E)); placed
at a candidate pose it meets the FGM's masses (O, E). The unnormalised conjunctive
combination of the two (Smets 1990) puts o O + e E on the agreeing focal sets and
K = o E + e O on the empty set (the conflict). The score is agreement minus conflict:

    s(pose) = sum_cells [ o * Ob + mu * e * E ] - lambda * [ o * E + e * O ]  /  sum_cells o

where Ob is Olson's blurred occupancy Ob(x) = max_c O(c) exp(-|x - c|^2 / 2 sigma_b^2)
(a grey dilation in the log domain): it widens the basin by the sonar's range/bearing
scatter so that a wall seen 5 cm off still scores, without thickening the conflict.

Vectorisation: for one rotation the score at every integer-cell translation is a
cross-correlation of the rotated FLM (splatted bilinearly onto a template, so each
translation's score is exactly the bilinear interpolation of the maps at the points)
with a patch of the 2-channel map (O-channel Ob - lambda E, E-channel E - lambda O):
one ``cv2.matchTemplate`` per rotation. Rotations: coarse steps over the window, then
fine steps within one coarse step of the coarse peak (skipped when the coarse surface
already leaves the heading free); the moments integrate the resulting non-uniform
lattice with per-sample rotation weights (trapezoid rule).

The agreement of empty with empty (mu, small by default) hardly depends on the pose
(most of an FLM's free cone lies in the FGM's free space wherever it is put) and would
only flatten the surface; the conflicts carry the information of the empty evidence.
Dividing by the FLM's occupied mass makes s the fraction of the ring's wall evidence
that the map explains, comparable from ring to ring.

Successive rings see the same walls from nearly the same place, so their match errors
are correlated (measured: biases of 5-20 cm persisting over several rings); treating them
as independent makes the EKF overconfident. The covariance is therefore multiplied by
``pose_cov_scale`` (at least the number of rings over which the errors stay correlated;
Bar-Shalom et al., "Estimation with applications to tracking", sec. 8.2, on correlated
measurement noise) [ours]. Measured on the paper scenario against truth: per-ring errors
4.5 cm RMS, autocorrelation 0.7 / 0.5 / 0.3 / 0.0 at lags 1 / 2 / 4 / 8 rings, plus a slow
map bias; the run's NEES chose the scale (``FixParams.pose_cov_scale``). The heading is
left free in almost every ring (echo arcs are centred on the robot), so ``run --fix pose``
also applies the Hough heading fixes (``fixes.pose_with_heading``). Part of a match's
error is the frozen map's own error, identical ring after ring, which no scale turns
into independent noise: while the filter's position sigma is below the map's accuracy
``pose_map_sigma`` the ring is not matched (``prior_better``), so fixes bound the
position uncertainty from above instead of averaging the map's error in (measured:
the run's NEES falls from 2-19 to 1.2-3.7 over the paper scenarios).

Likelihood [ours]: L = exp((s - s_max) / tau); tau, the loss of explained fraction per
e-fold of likelihood, is calibrated on synthetic scans (benchmarks/bench_fixes.py).
Directions whose variance nears that of a uniform distribution over the window are
unconstrained by the scan (a straight corridor along its axis; the heading of a ring
whose echo arcs are all centred on the robot): the eigen-directions of the xy block and
the heading are tested separately, and a free one is given a huge variance and no
correlation, so the EKF takes no information from it. A flat surface (all
directions unconstrained), a peak on the window's edge, or a second separate mode
(connected components of the L > e^-3 L_max region) are rejected.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from fuzzyslam.fixes.params import FixParams
from fuzzyslam.maps.grid import BeliefMap
from fuzzyslam.se2 import wrap_angle

UNCONSTRAINED_VAR = 1.0e4  # variance given to a direction the scan does not constrain


@dataclass(frozen=True)
class PoseMatch:
    """Result of one match: ``ok`` or why not, the measured pose and its covariance."""

    ok: bool
    reason: str
    pose: np.ndarray  # (3,)
    cov: np.ndarray  # (3, 3)
    score: float = math.nan
    degenerate: int = 0  # number of unconstrained eigen-directions
    candidates: int = 0


def olson_blur(m_o: np.ndarray, sigma_cells: float) -> np.ndarray:
    """Ob(x) = max_c m_o(c) exp(-|x - c|^2 / (2 sigma^2)) (Olson 2009, rasterised cost table).

    Computed as exp of a grey dilation of log m_o with the non-flat structuring element
    s(d) = -|d|^2 / (2 sigma^2), |d_x|, |d_y| <= r = ceil(2.5 sigma): the maximum over the
    (2r + 1)^2 offsets d of log m_o(x + d) + s(d), log m_o taken as -30 off the map (the
    definition of ``scipy.ndimage.grey_dilation(..., mode="constant", cval=-30)``). The
    element is the dilation of a row element by a column one, s(d) = s1(d_y) + s1(d_x),
    so the dilation is a row pass then a column pass (the chain rule of dilations,
    dil(f, dil(B1, B2)) = dil(dil(f, B1), B2): Soille, "Morphological Image Analysis",
    2nd ed., Springer 2003, ch. 3); the sums are taken in another order
    than scipy's, so a value may differ from it in the last bit of the float64 log,
    which the float32 result almost never keeps.

    Parameters
    ----------
    m_o : ndarray, shape (H, W)
        The FGM's occupied mass.
    sigma_cells : float
        The blur's sigma (cells); 0 or less: none.

    Returns
    -------
    ndarray of float32, shape (H, W)
        Ob.
    """
    m = np.asarray(m_o, dtype=np.float64)
    if sigma_cells <= 0:
        return m.astype(np.float32)
    r = max(1, math.ceil(2.5 * sigma_cells))
    d = np.arange(-r, r + 1, dtype=np.float64)
    s1 = -(d**2) / (2.0 * sigma_cells**2)  # s(d) = s1(d_y) + s1(d_x)
    logm = np.pad(np.log(np.maximum(m, 1e-9)), r, mode="constant", constant_values=-30.0)
    h, w = m.shape
    # s is separable and max distributes over +: max_dy [s1(dy) + max_dx (f + s1(dx))],
    # 2 (2r + 1) passes over the map instead of (2r + 1)^2 (over the element's offsets,
    # not the cells)
    rows = np.full((h + 2 * r, w), -np.inf)
    for j in range(2 * r + 1):
        np.maximum(rows, logm[:, j : j + w] + s1[j], out=rows)
    out = np.full((h, w), -np.inf)
    for i in range(2 * r + 1):
        np.maximum(out, rows[i : i + h] + s1[i], out=out)
    return np.exp(out).astype(np.float32)


def label_26(mask: np.ndarray) -> tuple[np.ndarray, int]:
    """Connected components of a 3-D mask, 26-connectivity (every voxel of the 3x3x3
    neighbourhood), as ``scipy.ndimage.label(mask, structure=np.ones((3, 3, 3)))`` up to
    the numbering of the components.

    Each slice is labelled 8-connected (``cv2.connectedComponents``); a component of
    slice k and one of slice k + 1 join when one of their voxels lies within one cell
    (rows and columns) of the other's, and the joined labels are merged by union-find
    (Tarjan, "Efficiency of a good but not linear set union algorithm", JACM 1975) over
    the distinct pairs.

    Parameters
    ----------
    mask : ndarray of bool, shape (K, H, W)
        The voxels.

    Returns
    -------
    labels : ndarray of int, shape (K, H, W)
        0 off the mask, 1..n on its components.
    n : int
        The number of components.
    """
    k, h, w = mask.shape
    labels = np.zeros(mask.shape, dtype=np.int32)
    count = 0
    m8 = np.asarray(mask, dtype=bool).view(np.uint8)
    for i in range(k):  # over the slices
        n, lab = cv2.connectedComponents(m8[i], connectivity=8, ltype=cv2.CV_32S)
        labels[i] = np.where(lab > 0, lab + count, 0) if count else lab
        count += n - 1
    if k == 1 or count <= 1:
        return labels, count
    # (lower, upper) label pairs of voxels of slices i and i + 1 within one row and column
    codes = []
    for dy in (-1, 0, 1):
        for dx in (-1, 0, 1):
            lo = labels[:-1, max(dy, 0) : h + min(dy, 0), max(dx, 0) : w + min(dx, 0)]
            up = labels[1:, max(-dy, 0) : h + min(-dy, 0), max(-dx, 0) : w + min(-dx, 0)]
            on = (lo > 0) & (up > 0)
            codes.append(lo[on].astype(np.int64) * (count + 1) + up[on])
    links = np.unique(np.concatenate(codes))
    if links.size == 0:
        return labels, count
    parent = list(range(count + 1))

    def root(x: int) -> int:
        while parent[x] != x:
            parent[x] = parent[parent[x]]
            x = parent[x]
        return x

    for code in links.tolist():  # over the distinct pairs of touching components
        ra, rb = root(code // (count + 1)), root(code % (count + 1))
        if ra != rb:
            parent[max(ra, rb)] = min(ra, rb)
    roots = np.array([root(x) for x in range(count + 1)])
    _, compact = np.unique(roots, return_inverse=True)  # roots[0] = 0: the background
    return compact[labels], int(compact.max())


def flm_evidence(flm: BeliefMap, min_mass: float) -> tuple[np.ndarray, np.ndarray]:
    """Robot-frame centres (N, 2) and masses (N, 2) = (m(O), m(E)) of the FLM's evidence cells.

    Parameters
    ----------
    flm : BeliefMap
        The ring's FLM (robot frame).
    min_mass : float
        Cells with m(O) or m(E) above it count.

    Returns
    -------
    pts : ndarray, shape (N, 2)
    masses : ndarray, shape (N, 2)
    """
    xs, ys = flm.grid.centres()
    mask = (flm.m_o > min_mass) | (flm.m_e > min_mass)
    pts = np.stack([xs[mask], ys[mask]], axis=1)
    masses = np.stack([flm.m_o[mask], flm.m_e[mask]], axis=1).astype(np.float64)
    return pts, masses


def lookup_channels(
    m_o: np.ndarray, m_e: np.ndarray, resolution: float, params: FixParams
) -> np.ndarray:
    """The map's two lookup channels of the score (module docstring): channel 0, met by
    the template's m(O), Olson's blurred m(O) minus ``pose_arc_conflict_weight`` m(E);
    channel 1, met by its m(E), ``pose_empty_weight`` m(E) minus ``pose_conflict_weight``
    m(O).

    Parameters
    ----------
    m_o, m_e : ndarray, shape (H, W)
        The map's (or a window's) occupied and empty masses.
    resolution : float
        The cell size (m): the blur ``pose_blur`` in cells.
    params : FixParams
        The weights and the blur.

    Returns
    -------
    ndarray of float32, shape (H, W, 2)
    """
    occ = olson_blur(m_o, params.pose_blur / resolution)
    e, o = m_e.astype(np.float32), m_o.astype(np.float32)
    return np.stack(
        [occ - params.pose_arc_conflict_weight * e,
         params.pose_empty_weight * e - params.pose_conflict_weight * o],
        axis=-1,
    )  # fmt: skip


def _extents(dth: np.ndarray) -> np.ndarray:
    """The rotation extent each sorted sample stands for (trapezoid rule weights)."""
    edges = np.concatenate([[dth[0]], 0.5 * (dth[1:] + dth[:-1]), [dth[-1]]])
    return np.diff(edges)


class PoseMatcher:
    """Correlative FLM-to-FGM matcher; the FGM's lookup maps are built once (it is frozen)."""

    def __init__(self, fgm: BeliefMap, params: FixParams) -> None:
        self.grid = fgm.grid
        self.params = params
        self.last_window = (math.nan, math.nan)  # (xy m, heading rad) of the last search
        self.last_peak = np.full(3, np.nan)  # the lattice's best pose of the last "edge"
        self.lookup = np.ascontiguousarray(
            lookup_channels(fgm.m_o, fgm.m_e, fgm.grid.resolution, params)
        )

    # -- lattice scores ---------------------------------------------------------------------

    def _patch(self, row0: int, col0: int, size: int) -> np.ndarray:
        """lookup[row0 : row0 + size, col0 : col0 + size] with zeros outside the map."""
        ny, nx = self.grid.shape
        out = np.zeros((size, size, 2), dtype=np.float32)
        r0, r1 = max(row0, 0), min(row0 + size, ny)
        c0, c1 = max(col0, 0), min(col0 + size, nx)
        if r1 > r0 and c1 > c0:
            out[r0 - row0 : r1 - row0, c0 - col0 : c1 - col0] = self.lookup[r0:r1, c0:c1]
        return out

    def scores(
        self, pts: np.ndarray, masses: np.ndarray, pose0: np.ndarray, thetas: np.ndarray, w: int
    ) -> np.ndarray:
        """Scores (n_theta, 2w+1, 2w+1): [k, ty+w, tx+w] is s(x0 + tx res, y0 + ty res, theta_k).

        Parameters
        ----------
        pts : ndarray, shape (N, 2)
            FLM cell centres (robot frame).
        masses : ndarray, shape (N, 2)
            Their (m(O), m(E)).
        pose0 : ndarray, shape (3,)
            The search's centre.
        thetas : ndarray, shape (n_theta,)
            The headings searched (rad).
        w : int
            Half-width of the window (cells).

        Returns
        -------
        ndarray, shape (n_theta, 2w+1, 2w+1)
        """
        res = self.grid.resolution
        c = (np.asarray(pose0[:2], float) - np.asarray(self.grid.origin)) / res - 0.5
        base = np.floor(c).astype(int)
        frac = c - base
        half = math.ceil(np.sqrt(np.max(np.sum(pts**2, axis=1))) / res) + 2 if len(pts) else 2
        size = 2 * half + 1
        n = len(thetas)
        cs, sn = np.cos(thetas)[:, None], np.sin(thetas)[:, None]
        px, py = pts[None, :, 0] / res, pts[None, :, 1] / res
        u = cs * px - sn * py + (frac[0] + half)  # template column (continuous), (n, N)
        v = sn * px + cs * py + (frac[1] + half)  # template row
        iu, iv = np.floor(u), np.floor(v)
        au, av = u - iu, v - iv
        # bilinear splat: 4 corners, one bincount per channel (the same sums, in the same
        # order, as one bincount over interleaved channels; half the index arithmetic)
        corner = (np.arange(n)[:, None] * size + iv.astype(np.int64)) * size + iu.astype(np.int64)
        offs = np.array([0, 1, size, size + 1])
        flat = (corner[..., None] + offs).ravel()  # (n, N, 4)
        wb = np.stack([(1 - av) * (1 - au), (1 - av) * au, av * (1 - au), av * au], axis=-1)
        cells = n * size * size
        # a channel the template has no mass in (a laser's end points: m(E) = 0) adds
        # exactly zero to every score: it is neither splatted nor correlated
        chans = [ch for ch in (0, 1) if np.any(masses[:, ch])] or [0]
        tmpl = np.stack(
            [
                np.bincount(flat, weights=(wb * masses[None, :, None, ch]).ravel(), minlength=cells)
                for ch in chans
            ],
            axis=-1,
        )
        tmpl = tmpl.astype(np.float32).reshape(n, size, size, len(chans))
        patch = self._patch(base[1] - half - w, base[0] - half - w, size + 2 * w)
        if len(chans) == 1:
            patch = np.ascontiguousarray(patch[..., chans[0] : chans[0] + 1])
        shifts = (2 * w + 1) ** 2
        if shifts <= self.params.pose_direct_shifts:
            # few translations: every rotation's correlation at once, one matrix product
            # of the templates (n, K) with the patch's windows (K, shifts), K = size^2 x
            # the channels correlated
            # (cv2.matchTemplate's DFT costs the same ~1 ms per rotation for any window)
            win = np.lib.stride_tricks.sliding_window_view(patch, (size, size, len(chans)))
            win = win.reshape(shifts, -1)
            out = tmpl.reshape(n, -1) @ win.T
            return out.reshape(n, 2 * w + 1, 2 * w + 1)
        if len(chans) == 1:  # cv2 takes (H, W) for one channel
            patch, tmpl = patch[..., 0], tmpl[..., 0]
        # each rotation's template cut to its points' box (corners included) and the patch
        # to that box plus the window: the cells cut are zeros, so the sums are the same,
        # and a corridor's scan (long and narrow) costs a fraction of the square's DFT
        r0, r1 = iv.min(axis=1).astype(int), iv.max(axis=1).astype(int) + 2
        c0, c1 = iu.min(axis=1).astype(int), iu.max(axis=1).astype(int) + 2
        return np.stack([
            cv2.matchTemplate(patch[r0[k] : r1[k] + 2 * w, c0[k] : c1[k] + 2 * w],
                              np.ascontiguousarray(tmpl[k, r0[k] : r1[k], c0[k] : c1[k]]),
                              cv2.TM_CCORR)
            for k in range(n)
        ])  # fmt: skip

    # -- the match ------------------------------------------------------------------------

    def match(
        self,
        flm: BeliefMap,
        pose0: np.ndarray,
        cov0: np.ndarray,
        scale: float | None = None,
        widen: float = 1.0,
    ) -> PoseMatch:
        """Measure the pose of ``flm`` in the FGM around ``pose0`` (module docstring).

        Parameters
        ----------
        flm : BeliefMap
            The ring's FLM (robot frame).
        pose0, cov0 : ndarray
            The prediction (3,) and its covariance (3, 3): the search window is 3 sigma
            of it, clipped to ``pose_window_min``..``pose_window_max`` (and in degrees).
        scale : float, optional
            The covariance inflation (default ``pose_cov_scale``).
        widen : float
            Factor on the windows (at most ``pose_window_max``, ``pose_window_max_deg``):
            a search again when the mode lay on the window's edge (fixes.pose_aid).
            The windows searched are left in :attr:`last_window` (m, rad).

        Returns
        -------
        PoseMatch
        """
        pts, masses = flm_evidence(flm, self.params.pose_min_mass)
        return self.match_points(pts, masses, pose0, cov0, scale, widen)

    def match_points(
        self,
        pts: np.ndarray,
        masses: np.ndarray,
        pose0: np.ndarray,
        cov0: np.ndarray,
        scale: float | None = None,
        widen: float = 1.0,
    ) -> PoseMatch:
        """:meth:`match` of a template given as points with masses (an FLM's cells,
        :func:`flm_evidence`, or a laser scan's end points, ``fixes.live_map``).

        Parameters
        ----------
        pts : ndarray, shape (N, 2)
            The template's points (robot frame, m).
        masses : ndarray, shape (N, 2)
            Their (m(O), m(E)).
        pose0, cov0 : ndarray
            The prediction (3,) and its covariance (3, 3) (:meth:`match`).
        scale : float, optional
            The covariance inflation (default ``pose_cov_scale``).
        widen : float
            Factor on the windows (:meth:`match`).

        Returns
        -------
        PoseMatch
        """
        p = self.params
        scale = p.pose_cov_scale if scale is None else float(scale)
        pose0 = np.asarray(pose0, dtype=float)
        res = self.grid.resolution
        nan3 = np.full(3, np.nan)
        if np.count_nonzero(masses[:, 0] > p.pose_min_mass) < p.pose_min_occupied_cells:
            return PoseMatch(False, "no_evidence", nan3, np.full((3, 3), np.nan))
        sig = np.sqrt(np.maximum(np.diag(np.asarray(cov0, float)), 0.0))
        wxy = float(np.clip(3.0 * max(sig[0], sig[1]), p.pose_window_min, p.pose_window_max))
        wxy = min(wxy * widen, p.pose_window_max)
        w = max(1, math.ceil(wxy / res - 1e-9))
        th_max = math.radians(p.pose_window_max_deg)
        wth = float(np.clip(3.0 * sig[2], math.radians(p.pose_window_min_deg), th_max))
        wth = min(wth * widen, th_max)
        self.last_window = (wxy, wth)
        cstep, fstep = math.radians(p.pose_coarse_deg), math.radians(p.pose_fine_deg)
        nc = max(1, math.ceil(wth / cstep - 1e-9))
        coarse = np.arange(-nc, nc + 1) * cstep
        # normalised by the FLM's occupied mass: the score is the fraction of its wall
        # evidence that the map explains (minus conflict), whatever the ring saw
        s_coarse = self.scores(pts, masses, pose0, pose0[2] + coarse, w) / masses[:, 0].sum()
        kc = int(np.argmax(s_coarse.max(axis=(1, 2))))
        # a heading the coarse surface leaves free (echo arcs centred on the robot) gains
        # nothing from finer steps: skip them
        lk = np.exp((s_coarse - s_coarse.max()) / p.pose_temperature).sum(axis=(1, 2))
        pk = lk / lk.sum()
        var_th = float(pk @ (coarse - pk @ coarse) ** 2)
        if nc > 1 and var_th > p.pose_degenerate_fraction * (coarse[-1] - coarse[0]) ** 2 / 12:
            return self._moments(pose0, coarse, _extents(coarse), s_coarse, w, res, scale)
        # fine rotations within one coarse step of the coarse peak, trapezoid weights
        nf = max(1, round(cstep / fstep))
        fine = coarse[kc] + np.arange(-nf, nf + 1) * (cstep / nf)
        fine = fine[(fine >= coarse[0] - 1e-12) & (fine <= coarse[-1] + 1e-12)]
        s_fine = np.empty((len(fine), *s_coarse.shape[1:]), dtype=s_coarse.dtype)
        same = np.abs((fine - coarse[0]) / cstep - np.round((fine - coarse[0]) / cstep)) < 1e-6
        s_fine[same] = s_coarse[np.round((fine[same] - coarse[0]) / cstep).astype(int)]
        s_fine[~same] = (
            self.scores(pts, masses, pose0, pose0[2] + fine[~same], w) / masses[:, 0].sum()
        )
        keep = np.abs(coarse - coarse[kc]) > cstep * (1 + 1e-9)
        dth = np.concatenate([coarse[keep], fine])
        s = np.concatenate([s_coarse[keep], s_fine])
        order = np.argsort(dth)
        dth, s = dth[order], s[order]
        return self._moments(pose0, dth, _extents(dth), s, w, res, scale)

    def _moments(
        self,
        pose0: np.ndarray,
        dth: np.ndarray,
        wrot: np.ndarray,
        s: np.ndarray,
        w: int,
        res: float,
        scale: float,
    ) -> PoseMatch:
        p = self.params
        smax = float(s.max())
        ncand = int(s.size)
        nan3, nan33 = np.full(3, np.nan), np.full((3, 3), np.nan)
        if not smax > 0:
            return PoseMatch(False, "no_match", nan3, nan33, smax, 0, ncand)
        ll = (s - smax) / p.pose_temperature
        lik = np.exp(ll) * wrot[:, None, None]
        total = lik.sum()
        t = np.arange(-w, w + 1) * res
        gth, gy, gx = np.meshgrid(dth, t, t, indexing="ij")
        xs = np.stack([gx.ravel(), gy.ravel(), gth.ravel()], axis=1)
        pw = lik.ravel() / total
        mu = pw @ xs
        d = xs - mu
        cov = (d * pw[:, None]).T @ d
        # modes: connected components of the high-likelihood region
        labels, nlab = label_26(ll > -3.0)
        if nlab > 1:
            mass = np.bincount(labels.ravel(), weights=lik.ravel())[1:] / total
            if np.sort(mass)[-2] > p.pose_max_second_mode:
                return PoseMatch(False, "multimodal", nan3, nan33, smax, 0, ncand)
        # unconstrained directions: variance near that of a uniform over the window. The
        # xy block is analysed in its own eigen-basis (a corridor leaves one translation
        # free), the heading alone; a free direction gets a huge variance and no
        # correlation with the others (its truncated-window moments mean nothing).
        span = np.array([2 * w * res, dth[-1] - dth[0]])
        uni = np.maximum(span**2 / 12.0, 1e-12)
        exy, vxy = np.linalg.eigh(0.5 * (cov[:2, :2] + cov[:2, :2].T))
        basis = np.eye(3)
        basis[:2, :2] = vxy
        degenerate = np.array([*(exy > p.pose_degenerate_fraction * uni[0]),
                               cov[2, 2] > p.pose_degenerate_fraction * uni[1]])  # fmt: skip
        ndeg = int(np.count_nonzero(degenerate))
        if ndeg == 3:
            return PoseMatch(False, "flat", nan3, nan33, smax, ndeg, ncand)
        kb, iy, ix = np.unravel_index(int(np.argmax(s)), s.shape)
        if ndeg == 0 and (kb in (0, len(dth) - 1) or iy in (0, 2 * w) or ix in (0, 2 * w)):
            # where the surface peaked: a search centred there may contain the mode
            self.last_peak = pose0 + np.array([(ix - w) * res, (iy - w) * res, dth[kb]])
            return PoseMatch(False, "edge", nan3, nan33, smax, ndeg, ncand)
        cb = basis.T @ cov @ basis
        cb[degenerate, :] = 0.0
        cb[:, degenerate] = 0.0
        cb[degenerate, degenerate] = UNCONSTRAINED_VAR
        cov = basis @ cb @ basis.T
        floor = np.array([p.pose_min_sigma, p.pose_min_sigma, math.radians(p.pose_min_sigma_deg)])
        cov = scale * (0.5 * (cov + cov.T)) + np.diag(floor**2)
        pose = pose0 + mu
        pose[2] = wrap_angle(pose[2])
        return PoseMatch(True, "ok", pose, cov, smax, ndeg, ncand)
