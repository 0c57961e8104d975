"""The relocalisation test: a pose that has left its covariance, found from one frame [ours].

When the best JCBB hypothesis (:mod:`fuzzyslam.slam.association`) leaves several of a
frame's detections unexplained, the frame is associated again under the hypothesis that
the robot suffered an unmodelled disturbance (its covariance inflated); the disturbance is
accepted when that explains clearly more detections (docs/models.md sec. 4c).
"""

from __future__ import annotations

import copy
from dataclasses import dataclass

import numpy as np

from fuzzyslam.slam.association import Association, jcbb
from fuzzyslam.slam.ekf import EkfSlam
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
) -> tuple[np.ndarray, Relocalisation | None]:
    """Test whether an unmodelled disturbance explains a frame better [ours].

    A pose that has left its covariance (odometry that integrated a turn the wheels did
    not make, a slip) makes JCBB pair a frame's detections with the wrong landmarks, or
    with few of them: the landmarks that would explain the rest are outside their gates.
    The alternative hypothesis is a disturbance of covariance ``q`` on the robot (the
    fault-detection counterpart of covariance inflation; Simon, "Optimal state
    estimation", sec. 7.4). Under it the gates widen and JCBB (the most jointly
    compatible pairings) is run again. The disturbance is accepted, and the robot block of
    ``ekf`` inflated by ``q``, when its best hypothesis pairs at least ``min_gain`` more
    detections than before and at least ``min_pairs`` (redundant pairings: two landmarks
    fix a pose, a third checks it). The test runs only on frames whose best hypothesis
    leaves ``min_gain`` detections unexplained and that have ``min_pairs`` detections.

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

    Returns
    -------
    d2 : ndarray, shape (m, n)
        The distances to associate with: recomputed under the inflated covariance when
        accepted, else the ``d2`` given.
    test : Relocalisation or None
        The test's outcome (``tested`` False when the best hypothesis explained the frame
        well enough, with ``before`` its JCBB association); None when the frame had too
        few detections or the map too few lamps.
    """
    m = len(z)
    if m < min_pairs or ekf.n_lamps < min_pairs:
        return d2, None
    assoc = jcbb(ekf, z, r, d2, gate_chi2, ambiguity_margin)
    before = len(assoc.best)
    if m - before < min_gain:
        return d2, Relocalisation(before, before, False, assoc, tested=False)
    trial = copy.deepcopy(ekf)
    trial.inflate_robot(q)
    d2_wide = trial.individual_compatibility(z, r)
    after = len(jcbb(trial, z, r, d2_wide, gate_chi2, ambiguity_margin).best)
    if after < max(before + min_gain, min_pairs):
        return d2, Relocalisation(before, after, False, assoc)
    ekf.inflate_robot(q)
    return ekf.individual_compatibility(z, r), Relocalisation(before, after, True)


@dataclass
class Relocaliser:
    """The test as the SLAM loop runs it, with its counts.

    Parameters
    ----------
    q : ndarray, shape (3, 3)
        Covariance of the disturbance.
    gate_chi2, ambiguity_margin : float
        JCBB's gate and ambiguity margin.
    min_gain : int
        Extra pairings needed to accept.
    """

    q: np.ndarray
    gate_chi2: float
    ambiguity_margin: float
    min_gain: int = 2
    tests: int = 0
    accepted: int = 0

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
        return cls(q, p.gate_chi2, p.ambiguity_margin, p.relocalise_min_gain)

    def __call__(
        self, ekf: EkfSlam, z: np.ndarray, r: np.ndarray, d2: np.ndarray
    ) -> tuple[np.ndarray, Association | None]:
        """Run :func:`relocalisation_test` on one frame and count it.

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

        Returns
        -------
        d2 : ndarray, shape (m, n)
            The distances to associate with.
        known : Association or None
            JCBB's association on them, when the test computed it and left the filter as
            it was (for :func:`~fuzzyslam.slam.lamp_update.associate_update`).
        """
        d2, test = relocalisation_test(
            ekf, z, r, d2, self.gate_chi2, self.ambiguity_margin, self.q, self.min_gain
        )
        if test is None:
            return d2, None
        if test.tested:
            self.tests += 1
            self.accepted += test.accepted
        return d2, None if test.accepted else test.before

    def counts(self) -> dict[str, int]:
        """The summary's counts: tests run and disturbances accepted.

        Returns
        -------
        dict
            ``relocalisation_tests``, ``relocalisations``.
        """
        return {"relocalisation_tests": self.tests, "relocalisations": self.accepted}
