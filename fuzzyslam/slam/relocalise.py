"""The relocalisation test: a pose that has left its covariance, found from one frame [ours].

When the best JCBB hypothesis (:mod:`fuzzyslam.slam.association`) leaves several of a
frame's detections unexplained, the frame is associated again under the hypothesis that
the robot suffered an unmodelled disturbance (its covariance inflated); the disturbance is
accepted when that explains clearly more detections (docs/models.md sec. 4c), JCBB
re-linearised at the pose the disturbance implies (:mod:`fuzzyslam.slam.iterated`). Frames with
too few detections for the test are pooled over a short window of odometry (a camera that
sees one or two landmarks at a time, frame after frame, while the pose is lost).
"""

from __future__ import annotations

import copy
from dataclasses import dataclass, field

import numpy as np

from fuzzyslam import se2
from fuzzyslam.slam.association import Association, candidates, jcbb, unique_hypothesis
from fuzzyslam.slam.ekf import EkfSlam, UpdateResult, mahalanobis_2x2
from fuzzyslam.slam.iterated import iterated_association
from fuzzyslam.slam.lamp_update import unique_update
from fuzzyslam.slam.params import SlamParams


@dataclass(frozen=True)
class Relocalisation:
    """One relocalisation test: pairings of the best hypothesis as the filter stood and
    with its robot covariance inflated, and whether the inflation was kept."""

    pairs_before: int
    pairs_after: int
    accepted: bool
    # JCBB's association of the frame as the filter stood (still valid when refused)
    before: Association | None = None
    tested: bool = True  # False: the frame did not call for the test (nothing unexplained)
    # JCBB's association under the inflated covariance, when accepted
    wide: Association | None = None
    # accepted by the iterated test: the pose to linearise the lamp model at (the iterate)
    lin: np.ndarray | None = None
    iterations: int = 0  # hypotheses iterated (0: the test linearised at x0 sufficed)


def relocalisation_test(
    ekf: EkfSlam,
    z: np.ndarray,
    r: np.ndarray,
    d2: np.ndarray,
    gate_chi2: float,
    ambiguity_margin: float,
    q: np.ndarray,
    min_gain: int = 2,
    min_pairs: int = 3,
    min_lamps: int = 0,
) -> tuple[np.ndarray, Relocalisation | None]:
    """Test whether an unmodelled disturbance explains a frame better [ours].

    A pose that has left its covariance (odometry that integrated a turn the wheels did
    not make, a slip, a bump) makes JCBB pair a frame's detections with the wrong
    landmarks, or with few of them: the landmarks that would explain the rest are
    outside their gates. The alternative hypothesis is a disturbance of covariance ``q``
    on the robot (the fault-detection counterpart of covariance inflation; Simon,
    "Optimal state estimation", sec. 7.4). Under it the gates widen and JCBB (the most
    jointly compatible pairings) is run again; when that is refused, it is run again
    re-linearised at the pose its hypothesis implies (:func:`iterated_association`: a
    disturbance whose linearisation error exceeds the detections' noise). The
    disturbance is accepted, and the robot block of ``ekf`` inflated by ``q``, when its
    best hypothesis pairs at least ``min_gain`` more detections than before and at least
    ``min_pairs`` (redundant pairings: two landmarks fix a pose, a third checks it; two
    check each other's distance and the prior ``q``). The test runs only on frames whose
    best hypothesis leaves ``min_gain`` detections unexplained and that have
    ``min_pairs`` detections, and only once the map holds ``min_lamps`` lamps (at least
    ``min_pairs``): on a map of just ``min_pairs`` lamps an accepted hypothesis must pair
    every lamp, so the test cannot tell a disturbance from ``min_pairs`` landmarks not
    yet mapped that stand like the mapped ones (the likelier explanation while the map
    holds few of the landmarks in view) [ours].

    Parameters
    ----------
    ekf : EkfSlam
        The filter (its robot covariance is inflated when the test accepts).
    z : ndarray, shape (m, 2)
        The frame's detections (robot frame).
    r : ndarray, shape (m, 2, 2)
        Their covariances.
    d2 : ndarray, shape (m, n)
        Their squared Mahalanobis distances to the n lamps, as the filter stands.
    gate_chi2 : float
        The 2-dof individual gate.
    ambiguity_margin : float
        JCBB's ambiguity margin.
    q : ndarray, shape (3, 3)
        Covariance of the disturbance (symmetric positive semi-definite).
    min_gain : int
        Extra pairings needed to accept.
    min_pairs : int
        Pairings needed to accept.
    min_lamps : int
        Lamps the map needs before the test runs (at least ``min_pairs`` in any case).

    Returns
    -------
    d2 : ndarray, shape (m, n)
        The distances to associate with: recomputed under the inflated covariance, and
        linearised at the test's ``lin``, when accepted, else the ``d2`` given.
    test : Relocalisation or None
        The test's outcome (``tested`` False when the best hypothesis explained the frame
        well enough, with ``before`` its JCBB association); None when the frame had too
        few detections or the map too few lamps (``min_pairs``, ``min_lamps``). Accepted,
        the filter's lamp update must be linearised at its ``lin``
        (``EkfSlam.linearised_at``): the iterated EKF's update.
    """
    m = len(z)
    if m < min_pairs or ekf.n_lamps < max(min_pairs, min_lamps):
        return d2, None
    assoc = jcbb(ekf, z, r, d2, gate_chi2, ambiguity_margin)
    before = len(assoc.best)
    if m - before < min_gain:
        return d2, Relocalisation(before, before, False, assoc, tested=False)
    trial = copy.deepcopy(ekf)
    trial.inflate_robot(q)
    need = max(before + min_gain, min_pairs)
    d2_wide = trial.individual_compatibility(z, r)
    wide = jcbb(trial, z, r, d2_wide, gate_chi2, ambiguity_margin)
    lin, its = None, 0
    if len(wide.best) < need:  # refused linearised at x0: at the hypothesis' own pose?
        d2_wide, wide, lin, its = iterated_association(
            trial, z, r, gate_chi2, ambiguity_margin, d2_wide
        )
    after = len(wide.best)
    if after < need:
        return d2, Relocalisation(before, after, False, assoc, iterations=its)
    ekf.inflate_robot(q)
    return d2_wide, Relocalisation(before, after, True, assoc, wide=wide, lin=lin, iterations=its)


@dataclass
class _Sighting:
    """Unexplained detections of one frame, with the odometry pose they were made from."""

    t: float
    odo: np.ndarray  # (3,) dead-reckoned pose (odometry only) at the frame
    z: np.ndarray  # (k, 2) robot frame
    r: np.ndarray  # (k, 2, 2)


def _same(v: np.ndarray, s: np.ndarray) -> float:
    return float(mahalanobis_2x2(s[0, 0], s[0, 1], s[1, 1], v[0], v[1]))


def pool_window(
    z: np.ndarray,
    r: np.ndarray,
    odo: np.ndarray,
    past: list[_Sighting],
    gate_chi2: float,
) -> tuple[np.ndarray, np.ndarray]:
    """A frame's detections with earlier frames' unexplained ones, in the frame's robot frame.

    An earlier detection z_a made at odometry pose o_a is seen from the odometry pose o
    now at z = o^-1 (+) o_a (+) z_a (the odometry's relative motion over a short window
    is precise even when the absolute pose is lost); its covariance is rotated with it.
    An earlier detection within ``gate_chi2`` (squared Mahalanobis, R_a + R_b) of one
    already pooled is the same landmark seen again and is left out, newest first: one
    frame does not see a landmark twice, a window does.

    Parameters
    ----------
    z : ndarray, shape (m, 2)
        The frame's detections (robot frame).
    r : ndarray, shape (m, 2, 2)
        Their covariances.
    odo : ndarray, shape (3,)
        The odometry pose at the frame.
    past : list of _Sighting
        Earlier frames' unexplained detections, oldest first.
    gate_chi2 : float
        The 2-dof gate of "the same landmark".

    Returns
    -------
    z : ndarray, shape (k, 2)
        The pooled detections, the frame's first.
    r : ndarray, shape (k, 2, 2)
        Their covariances.
    """
    zs, rs = list(z), list(r)
    for s in reversed(past):
        rel = se2.between(odo, s.odo)  # the earlier robot frame seen from this one
        c = se2.rot(rel[2])
        for za, ra in zip(se2.transform_points(rel, s.z), s.r, strict=True):
            ra = c @ ra @ c.T
            if all(_same(za - zb, ra + rb) > gate_chi2 for zb, rb in zip(zs, rs, strict=True)):
                zs.append(za)
                rs.append(ra)
    return np.asarray(zs, dtype=float).reshape(-1, 2), np.asarray(rs, dtype=float).reshape(-1, 2, 2)


@dataclass
class Relocaliser:
    """The test as the SLAM loop runs it, with its counts.

    Frames with fewer than ``min_pairs`` detections cannot call for the test on their own. With
    ``window_s`` > 0 the unexplained detections of the frames of the last ``window_s``
    seconds are pooled with the frame's (:func:`pool_window`) and the test is run on the
    pool; when it accepts, the filter's robot covariance is inflated and the frame's
    detections take the pairings that the pool's best hypothesis gives them. The earlier
    detections are evidence (for the test and the pairings), not measurements: their
    place in the frame rests on the odometry's motion over the window, which is what
    fails when a turn is commanded and not made.

    Parameters
    ----------
    q : ndarray, shape (3, 3)
        Covariance of the disturbance.
    gate_chi2, ambiguity_margin : float
        JCBB's gate and ambiguity margin.
    min_gain : int
        Extra pairings needed to accept.
    window_s : float
        The pooling window (s); 0: each frame on its own.
    min_pairs : int
        Pairings needed to accept (and detections to test a frame on its own).
    min_lamps : int
        Lamps the map needs before the test runs (:func:`relocalisation_test`).
    """

    q: np.ndarray
    gate_chi2: float
    ambiguity_margin: float
    min_gain: int = 2
    window_s: float = 0.0
    min_pairs: int = 3
    min_lamps: int = 0
    tests: int = 0
    accepted: int = 0
    # accepted on the last call: the frame's detections the filter explained as it stood.
    # The health monitor's association windows count these (a disturbance the model did
    # not admit), so a model that needs one frame after frame (a wrong wheel radius)
    # leaves them out of bounds as it did without the test
    explained_before: int | None = None
    _odo: np.ndarray = field(default_factory=lambda: np.zeros(3))
    _past: list[_Sighting] = field(default_factory=list)

    @classmethod
    def from_params(cls, p: SlamParams) -> Relocaliser | None:
        """The relocaliser of ``slam.relocalise_*`` (None when both sigmas are 0).

        Parameters
        ----------
        p : SlamParams
            The ``slam:`` section.

        Returns
        -------
        Relocaliser or None
        """
        if p.relocalise_sigma_m <= 0 and p.relocalise_sigma_heading_deg <= 0:
            return None
        sp, sh = p.relocalise_sigma_m, np.radians(p.relocalise_sigma_heading_deg)
        q = np.diag([sp * sp, sp * sp, sh * sh])
        return cls(
            q,
            p.gate_chi2,
            p.ambiguity_margin,
            p.relocalise_min_gain,
            p.relocalise_window_s,
            p.relocalise_min_pairs,
            p.relocalise_min_lamps,
        )

    def moved(self, delta: np.ndarray) -> None:
        """The odometry's relative motion since the last call (robot frame), for the window.

        Parameters
        ----------
        delta : ndarray, shape (3,)
            (dx, dy, dtheta) in the robot frame at the start of the motion.
        """
        if self.window_s > 0:
            self._odo = se2.compose(self._odo, delta)

    def _count(self, test: Relocalisation | None) -> None:
        if test is not None and test.tested:
            self.tests += 1
            self.accepted += test.accepted

    def update_if_explained(
        self, ekf: EkfSlam, z: np.ndarray, r: np.ndarray, d2: np.ndarray
    ) -> tuple[Association, UpdateResult | None] | None:
        """The frame's lamp update when it certainly leaves :func:`relocalisation_test`
        untested, without the test's own JCBB: its association has a unique hypothesis
        (``unique_hypothesis``) that leaves fewer than ``min_gain`` detections
        unexplained, and the update's joint test accepts it. JCBB's best is then that
        hypothesis (every candidate pair, jointly compatible), so the test would have
        found fewer than ``min_gain`` unexplained detections and the association would
        have made this same update (``lamp_update.associate_update``'s first step). None
        (the filter unchanged) otherwise: the frame goes through :meth:`__call__`.

        Parameters
        ----------
        ekf : EkfSlam
            The filter (updated in place when the update is made).
        z : ndarray, shape (m, 2)
            Detections (robot frame).
        r : ndarray, shape (m, 2, 2)
            Their covariances.
        d2 : ndarray, shape (m, n)
            Their squared Mahalanobis distances to the lamps.

        Returns
        -------
        (Association, UpdateResult or None) or None
        """
        m = len(z)
        if m < self.min_pairs or ekf.n_lamps < max(self.min_pairs, self.min_lamps):
            return None  # the test would not run on the frame alone: its window might
        pairs = unique_hypothesis(candidates(d2, self.gate_chi2))
        if pairs is None or m - len(pairs) >= self.min_gain:
            return None
        done = unique_update(ekf, z, r, pairs, self.gate_chi2)
        if done is not None:
            self.explained_before = None
        return done

    def __call__(
        self, ekf: EkfSlam, z: np.ndarray, r: np.ndarray, d2: np.ndarray, t: float
    ) -> tuple[np.ndarray, Association | None, np.ndarray | None]:
        """Run :func:`relocalisation_test` on one frame (or its window) and count it.

        Parameters
        ----------
        ekf : EkfSlam
            The filter.
        z : ndarray, shape (m, 2)
            Detections (robot frame).
        r : ndarray, shape (m, 2, 2)
            Their covariances.
        d2 : ndarray, shape (m, n)
            Their squared Mahalanobis distances to the lamps.
        t : float
            The frame's time (s), for the window.

        Returns
        -------
        d2 : ndarray, shape (m, n)
            The distances to associate with.
        known : Association or None
            JCBB's association on them, when the test computed it and left the filter as
            it was (for :func:`~fuzzyslam.slam.lamp_update.associate_update`).
        lin : ndarray, shape (3,), or None
            Accepted: the pose to linearise the frame's lamp update at
            (``EkfSlam.linearised_at``; the iterate of :func:`iterated_association`).
        """
        args = (
            self.gate_chi2,
            self.ambiguity_margin,
            self.q,
            self.min_gain,
            self.min_pairs,
            self.min_lamps,
        )
        self.explained_before = None
        d2_new, test = relocalisation_test(ekf, z, r, d2, *args)
        self._count(test)
        if test is not None or self.window_s <= 0:
            if test is not None and test.accepted:
                self._past.clear()
                self.explained_before = test.pairs_before
                return d2_new, None, test.lin
            return d2_new, None if test is None else test.before, None
        # too few detections on their own: pool the window's unexplained ones with them
        self._forget(t)
        if not self._past or ekf.n_lamps == 0:
            return d2, None, None
        zw, rw = pool_window(z, r, self._odo, self._past, self.gate_chi2)
        if len(zw) == len(z):
            return d2, None, None
        dw = ekf.individual_compatibility(zw, rw)
        dw, pooled = relocalisation_test(ekf, zw, rw, dw, *args)
        self._count(pooled)
        if pooled is None or not pooled.accepted:
            return d2, None, None
        self._past.clear()
        self.explained_before = sum(j < len(z) for j, _ in pooled.before.best)
        # the pool's association decides the frame's pairings (the frame's detections come
        # first in it); only the frame's own detections are measurements
        m, w = len(z), pooled.wide
        known = Association(
            [pr for pr in w.pairs if pr[0] < m],
            [j for j in w.ambiguous if j < m],
            [pr for pr in w.best if pr[0] < m],
        )
        return dw[:m], known, pooled.lin

    def unexplained(self, t: float, z: np.ndarray, r: np.ndarray, assoc: Association) -> None:
        """Keep the frame's detections that the best hypothesis left unexplained, for the
        window (nothing when ``window_s`` is 0).

        Parameters
        ----------
        t : float
            The frame's time (s).
        z : ndarray, shape (m, 2)
            Its detections (robot frame).
        r : ndarray, shape (m, 2, 2)
            Their covariances.
        assoc : Association
            The frame's association (``best``: the best hypothesis).
        """
        if self.window_s <= 0:
            return
        self._forget(t)
        explained = {j for j, _ in assoc.best}
        rest = [j for j in range(len(z)) if j not in explained]
        if rest:
            self._past.append(_Sighting(t, self._odo.copy(), z[rest].copy(), r[rest].copy()))

    def _forget(self, t: float) -> None:
        """Drop the unexplained detections older than the window at time ``t``."""
        self._past = [s for s in self._past if t - s.t <= self.window_s]

    def counts(self) -> dict[str, int]:
        """The summary's counts: tests run and disturbances accepted.

        Returns
        -------
        dict
            ``relocalisation_tests``, ``relocalisations``.
        """
        return {"relocalisation_tests": self.tests, "relocalisations": self.accepted}
