"""Data association of lamp detections with unknown correspondences (docs/models.md sec. 4).

- Individual compatibility: squared Mahalanobis distance D2_ij of detection j to
  lamp i against a chi-square gate with 2 dof (``EkfSlam.individual_compatibility``).
- Joint compatibility branch and bound (JCBB; J. Neira, J. D. Tardos, "Data
  association in stochastic mapping using the joint compatibility test", IEEE
  T-RA 17(6), 2001): the hypothesis (detection -> lamp or none) with the most
  pairings whose stacked innovation passes the chi-square test with 2k dof at the
  same confidence as the individual gate; ties go to the smaller joint NIS. A lamp
  takes at most one detection, so two lamps closer than the gate is wide each
  keep their own detection when both are seen.
- Relocalisation test: :mod:`fuzzyslam.slam.relocalise`.
- New lamps: a detection paired with no lamp becomes a tentative lamp; it is
  promoted into the state after ``hits`` sightings within ``radius`` of each other
  (the paper: "once those features become reliable, they are included into the
  map"), but only if it is far, D2 > ``new_lamp_chi2``, from every lamp already
  mapped: the guard against the paper's duplicate-lamp failure.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import lru_cache

import numpy as np

from fuzzyslam.slam.ekf import EkfSlam
from fuzzyslam.slam.health import chi2_quantile, gate_level


@lru_cache(maxsize=256)
def joint_threshold(gate_chi2: float, dof: int) -> float:
    """Chi-square threshold with ``dof`` degrees of freedom at the confidence of a 2-dof gate.

    chi2.cdf(x, k) = P(k/2, x/2) (regularised lower incomplete gamma), so
    chi2.ppf(p, k) = 2 P^-1(k/2, p); scipy.special avoids importing scipy.stats (1.5 s).
    """
    return chi2_quantile(gate_level(gate_chi2), dof)


def block_diag_cov(r: np.ndarray) -> np.ndarray:
    """(2k, 2k) block-diagonal matrix of k (2, 2) covariances.

    Parameters
    ----------
    r : ndarray, shape (k, 2, 2)
        The covariances.

    Returns
    -------
    ndarray, shape (2k, 2k)
    """
    r = np.asarray(r, dtype=float).reshape(-1, 2, 2)
    k = len(r)
    out = np.zeros((2 * k, 2 * k))
    for a in range(k):
        out[2 * a : 2 * a + 2, 2 * a : 2 * a + 2] = r[a]
    return out


def joint_nis(ekf: EkfSlam, pairs: list[tuple[int, int]], z: np.ndarray, r: np.ndarray) -> float:
    """NIS of the stacked innovation of ``pairs`` (detection j, lamp i).

    Parameters
    ----------
    ekf : EkfSlam
        The filter.
    pairs : list of (int, int)
        (detection, lamp) pairs.
    z : ndarray, shape (m, 2)
        Detections (robot frame).
    r : ndarray, shape (m, 2, 2)
        Their covariances.

    Returns
    -------
    float
    """
    if not pairs:
        return 0.0
    det = [j for j, _ in pairs]
    h, cols, hc = ekf.predict_lamps([i for _, i in pairs])
    v = z[det].reshape(-1) - h
    s = ekf.innovation_cov(cols, hc, block_diag_cov(r[det]))
    return float(v @ np.linalg.solve(s, v))


class JointTable:
    """The stacked innovation v and covariance S of every individually compatible
    (detection, lamp) pair of a frame, computed once, so that the joint NIS of any
    hypothesis (a set of pairs with distinct detections and lamps) is a slice of them:

        v_H = (v_p)_{p in H},  S_H = (S_all)_{H, H},  NIS_H = v_H^T S_H^-1 v_H

    (S_all = H_all P H_all^T + R_all with R_all block-diagonal per pair: pairs of one
    hypothesis have distinct detections, whose noises are independent, so the slice is
    exactly the joint S of :func:`joint_nis`). One prediction per frame instead of one
    per node of the JCBB search.
    """

    def __init__(self, ekf: EkfSlam, z: np.ndarray, r: np.ndarray, cands: list[list[int]]):
        self.index = {
            (j, i): k for k, (j, i) in enumerate((j, i) for j, c in enumerate(cands) for i in c)
        }
        pairs = list(self.index)
        if not pairs:
            self.v = np.zeros(0)
            self.s = np.zeros((0, 0))
            return
        det = [j for j, _ in pairs]
        h, cols, hc = ekf.predict_lamps([i for _, i in pairs])
        self.v = z[det].reshape(-1) - h
        self.s = ekf.innovation_cov(cols, hc, block_diag_cov(r[det]))

    def nis(self, pairs: list[tuple[int, int]]) -> float:
        """Joint NIS of ``pairs`` (all in the table).

        Parameters
        ----------
        pairs : list of (int, int)
            (detection, lamp) pairs.

        Returns
        -------
        float
        """
        rows = []  # the two rows of each pair in v and S
        for p in pairs:
            k = 2 * self.index[p]
            rows += (k, k + 1)
        idx = np.array(rows)
        v = self.v[idx]
        return float(v @ np.linalg.solve(self.s[idx[:, None], idx], v))  # S_H = S[H, H]


def candidates(d2: np.ndarray, gate_chi2: float) -> list[list[int]]:
    """Per detection, the individually compatible lamps, nearest first.

    Parameters
    ----------
    d2 : ndarray, shape (m, n)
        Squared Mahalanobis distances of detections to lamps.
    gate_chi2 : float
        The individual gate.

    Returns
    -------
    list of list of int
        Per detection, lamp indices.
    """
    return [
        sorted(np.nonzero(d2[j] <= gate_chi2)[0].tolist(), key=lambda i, j=j: d2[j, i])
        for j in range(len(d2))
    ]


def unique_hypothesis(cands: list[list[int]]) -> list[tuple[int, int]] | None:
    """The pairing of every detection with its candidate when no detection has two
    candidates and no lamp two detections (then it is the only hypothesis with the most
    pairings, and JCBB reduces to one joint test); else None.

    Parameters
    ----------
    cands : list of list of int
        :func:`candidates`.

    Returns
    -------
    list of (int, int) or None
    """
    flat = [c[0] for c in cands if c]
    if all(len(c) <= 1 for c in cands) and len(set(flat)) == len(flat):
        return [(j, c[0]) for j, c in enumerate(cands) if c]
    return None


@dataclass
class Association:
    """The outcome of JCBB on one frame: the pairings to apply, and the detections whose
    pairing is ambiguous (another hypothesis with as many pairings fits nearly as well)."""

    pairs: list[tuple[int, int]]
    ambiguous: list[int] = field(default_factory=list)
    # the best hypothesis before the ambiguous pairings were taken out of it
    best: list[tuple[int, int]] = field(default_factory=list)


def jcbb(
    ekf: EkfSlam,
    z: np.ndarray,
    r: np.ndarray,
    d2: np.ndarray,
    gate_chi2: float,
    ambiguity_margin: float = 0.0,
) -> Association:
    """Joint-compatibility branch and bound: the best list of (detection, lamp) pairs.

    ``d2`` (m, n) are the individual squared Mahalanobis distances. The best hypothesis
    has the most jointly compatible pairings, then the smallest joint NIS (Neira and
    Tardos 2001). With ``ambiguity_margin`` > 0 [ours]: every hypothesis with as many
    pairings and a joint NIS within the margin of the best is an alternative, and only
    the pairings common to all of them are returned; the detections paired differently
    by some alternative are ``ambiguous`` (neither applied nor new landmarks). The margin
    is a log-likelihood ratio: an alternative within it is at least exp(-margin / 2) as
    likely as the best, so choosing between them is a guess (e.g. landmarks closer
    together than the detection noise, seen from afar).

    Parameters
    ----------
    ekf : EkfSlam
        The filter.
    z : ndarray, shape (m, 2)
        Detections (robot frame).
    r : ndarray, shape (m, 2, 2)
        Their covariances.
    d2 : ndarray, shape (m, n)
        Individual squared Mahalanobis distances.
    gate_chi2 : float
        The 2-dof gate.
    ambiguity_margin : float
        Joint NIS margin of an alternative hypothesis.

    Returns
    -------
    Association
    """
    m = len(z)
    cands = candidates(d2, gate_chi2)
    pairs = unique_hypothesis(cands)
    if pairs is not None and (
        not pairs or joint_nis(ekf, pairs, z, r) <= joint_threshold(gate_chi2, 2 * len(pairs))
    ):
        return Association(pairs, [], pairs)
    table = JointTable(ekf, z, r, cands)
    hyps: list[tuple[list[tuple[int, int]], float]] = []  # (pairs, nis) with the best count
    best_n, best_nis = 0, np.inf

    def recurse(j: int, pairs: list[tuple[int, int]], used: set[int], nis: float) -> None:
        nonlocal best_n, best_nis
        if j == m:
            if len(pairs) > best_n:
                best_n, best_nis = len(pairs), nis
                hyps.clear()
            if len(pairs) == best_n:
                best_nis = min(best_nis, nis)
                hyps.append((list(pairs), nis))
            return
        # bound: even pairing every remaining detection cannot reach the best count
        remaining = sum(1 for jj in range(j, m) if cands[jj])
        if len(pairs) + remaining < best_n:
            return
        for i in cands[j]:
            if i in used:
                continue
            trial = [*pairs, (j, i)]
            jn = table.nis(trial)
            if jn <= joint_threshold(gate_chi2, 2 * len(trial)):
                used.add(i)
                recurse(j + 1, trial, used, jn)
                used.discard(i)
        if len(pairs) + remaining - (1 if cands[j] else 0) >= best_n:
            recurse(j + 1, pairs, used, nis)

    recurse(0, [], set(), 0.0)
    if not hyps or best_n == 0:
        return Association([])
    best = min(hyps, key=lambda h: h[1])[0]
    if ambiguity_margin <= 0:
        return Association(best, [], best)
    alts = [set(h) for h, nis in hyps if nis <= best_nis + ambiguity_margin]
    common = set.intersection(*alts)
    keep = [pr for pr in best if pr in common]
    ambiguous = sorted({j for alt in alts for j, _ in alt} - {j for j, _ in keep})
    return Association(keep, ambiguous, best)


@dataclass
class Tentative:
    """A candidate lamp: mean world position of its sightings, count, first/last time."""

    pos: np.ndarray
    hits: int
    first_t: float
    last_t: float
    cov: np.ndarray | None = None  # world covariance (2, 2) of the latest sighting


@dataclass
class TentativeLamps:
    """Candidate lamps awaiting ``hits`` consistent sightings (module docstring)."""

    hits: int = 3
    radius: float = 0.3
    timeout: float = 2.0
    gate_chi2: float = 9.21
    items: list[Tentative] = field(default_factory=list)
    expired: int = 0

    def expire(self, t: float) -> None:
        """Drop candidates not seen for longer than ``timeout``.

        Parameters
        ----------
        t : float
            Log time (s).
        """
        keep = [c for c in self.items if t - c.last_t <= self.timeout]
        self.expired += len(self.items) - len(keep)
        self.items = keep

    def observe(
        self, t: float, world: np.ndarray, taken: set[int], cov: np.ndarray | None = None
    ) -> bool:
        """Add a sighting at world point ``world``; True when it promotes a candidate.

        ``taken`` holds candidates already sighted in this frame (one sighting per frame).
        A sighting joins the nearest candidate within ``radius``; with ``cov`` (the
        sighting's world covariance, (2, 2)) also only one whose squared Mahalanobis
        distance (w - c)^T (C_w + C_c)^-1 (w - c) is within ``gate_chi2``, so that
        landmarks closer together than ``radius`` but far apart in units of the
        detection noise keep their own candidates.

        Parameters
        ----------
        t : float
            Log time (s).
        world : ndarray, shape (2,)
            The sighting (world frame).
        taken : set of int
            Candidates sighted in this frame.
        cov : ndarray, shape (2, 2), optional
            The sighting's world covariance.

        Returns
        -------
        bool
        """
        world = np.asarray(world, dtype=float)
        best, best_d = -1, np.inf
        for a, c in enumerate(self.items):  # a handful of candidates at a time
            if a in taken:
                continue
            diff = c.pos - world
            d = float(np.hypot(*diff))
            if d > self.radius:
                continue
            if cov is not None and c.cov is not None:
                s = cov + c.cov
                det = s[0, 0] * s[1, 1] - s[0, 1] * s[1, 0]
                m2 = (
                    s[1, 1] * diff[0] ** 2
                    - 2 * s[0, 1] * diff[0] * diff[1]
                    + s[0, 0] * diff[1] ** 2
                ) / det
                if not m2 <= self.gate_chi2:
                    continue
                d = m2
            if d < best_d:
                best, best_d = a, d
        if best < 0:
            if self.hits <= 1:
                return True
            self.items.append(Tentative(world.copy(), 1, t, t, cov))
            taken.add(len(self.items) - 1)
            return False
        c = self.items[best]
        c.pos = c.pos + (world - c.pos) / (c.hits + 1)
        c.hits += 1
        c.last_t = t
        if cov is not None:
            c.cov = cov
        taken.add(best)
        if c.hits >= self.hits:
            del self.items[best]
            # indices after ``best`` shift down by one
            shifted = {a - 1 if a > best else a for a in taken if a != best}
            taken.clear()
            taken.update(shifted)
            return True
        return False
