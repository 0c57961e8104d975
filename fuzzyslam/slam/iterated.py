"""The iterated relocalisation: JCBB with the lamp model re-linearised at the pose a
hypothesis implies (the iterated EKF; docs/models.md sec. 4c) [the issue 18 extension].

:func:`iterated_association` is what the relocalisation test
(:func:`fuzzyslam.slam.relocalise.relocalisation_test`) associates a frame with under the
inflated covariance; :func:`pose_iterate` and :func:`converge` are the iterated EKF's
Gauss-Newton steps (Bell and Cathey, "The iterated Kalman filter update as a Gauss-Newton
method", IEEE T-AC 38(2), 1993), on the model of ``EkfSlam.linearised_at``.
"""

from __future__ import annotations

import numpy as np

from fuzzyslam import se2
from fuzzyslam.slam.association import Association, block_diag_cov, jcbb
from fuzzyslam.slam.ekf import EkfSlam

# the iterated test's Gauss-Newton iterations: at most, and the step (m, rad) below
# which the iterate has converged (far below the detections' 0.7 mm and 0.02 deg)
MAX_ITERATIONS = 10
STEP_TOL = 1e-7


def pose_iterate(
    ekf: EkfSlam, z: np.ndarray, r: np.ndarray, pairs: list[tuple[int, int]]
) -> np.ndarray:
    """The iterated EKF's next pose for ``pairs`` (detection j, lamp i) [Bell and Cathey 1993].

    One Gauss-Newton step of the MAP problem min (x - x0)^T P^-1 (x - x0) + |z - h(x)|^2_R,
    taken from the linearisation pose of ``ekf`` (``EkfSlam.linearised_at``; its state's
    own pose when there is none):

        x_(i+1) = x0 + K_i (z - h(x_i) - H_i (x0 - x_i)),   K_i = P H_i^T S_i^-1

    (the pose rows; the lamps stay at their means, their errors of a few mm times the
    heading's step are second order).

    Parameters
    ----------
    ekf : EkfSlam
        The filter (prior mean x0, covariance P), linearised at x_i.
    z : ndarray, shape (m, 2)
        Detections (robot frame).
    r : ndarray, shape (m, 2, 2)
        Their covariances.
    pairs : list of (int, int)
        The hypothesis (at least one pair).

    Returns
    -------
    ndarray, shape (3,)
        x_(i+1)'s pose.
    """
    det = [j for j, _ in pairs]
    h, cols, hc = ekf.predict_lamps([i for _, i in pairs])  # h_i(x0), H_i
    v = z[det].reshape(-1) - h
    s = ekf.innovation_cov(cols, hc, block_diag_cov(r[det]))
    pose = ekf.pose + ekf.P[:3, cols] @ hc.T @ np.linalg.solve(s, v)
    pose[2] = se2.wrap_angle(pose[2])
    return pose


def nearest_pairs(d2: np.ndarray, gate_chi2: float) -> list[tuple[int, int]]:
    """Each detection with its nearest individually compatible lamp, nearest pairs first,
    a lamp taken once: the hypothesis the iterated test starts from.

    Parameters
    ----------
    d2 : ndarray, shape (m, n)
        Squared Mahalanobis distances.
    gate_chi2 : float
        The individual gate.

    Returns
    -------
    list of (int, int)
        (detection, lamp) pairs, sorted by detection.
    """
    jj, ii = np.nonzero(d2 <= gate_chi2)
    pairs: list[tuple[int, int]] = []
    for k in np.argsort(d2[jj, ii], kind="stable"):
        j, i = int(jj[k]), int(ii[k])
        if all(j != a and i != b for a, b in pairs):
            pairs.append((j, i))
    return sorted(pairs)


def converge(
    ekf: EkfSlam,
    z: np.ndarray,
    r: np.ndarray,
    pairs: list[tuple[int, int]],
    lin: np.ndarray | None = None,
) -> np.ndarray:
    """Iterate :func:`pose_iterate` on one hypothesis until the step is below ``STEP_TOL``
    (at most ``MAX_ITERATIONS`` steps): the iterated EKF's pose for ``pairs``.

    Parameters
    ----------
    ekf : EkfSlam
        The filter (not changed).
    z : ndarray, shape (m, 2)
        Detections (robot frame).
    r : ndarray, shape (m, 2, 2)
        Their covariances.
    pairs : list of (int, int)
        The hypothesis (at least one pair).
    lin : ndarray, shape (3,), optional
        The first linearisation pose (default: the filter's).

    Returns
    -------
    ndarray, shape (3,)
        The last iterate.
    """
    for _ in range(MAX_ITERATIONS):
        with ekf.linearised_at(lin):
            new = pose_iterate(ekf, z, r, pairs)
        step = new - (ekf.pose if lin is None else lin)
        step[2] = se2.wrap_angle(step[2])
        lin = new
        if np.all(np.abs(step) < STEP_TOL):
            break
    return lin


def iterated_association(
    ekf: EkfSlam,
    z: np.ndarray,
    r: np.ndarray,
    gate_chi2: float,
    ambiguity_margin: float,
    d2: np.ndarray | None = None,
) -> tuple[np.ndarray, Association, np.ndarray | None, int]:
    """JCBB with the lamp model re-linearised at the hypothesis' own pose (iterated EKF).

    JCBB's gates and joint test are linearised at the filter's pose. When that pose is
    off by an angle dtheta, a lamp at range rho is predicted with a second-order error
    of about rho dtheta^2 / 2 (1.5 cm per metre at 10 deg), which no linearised
    covariance holds: with mm detections the pairs pass their individual gates under a
    wide covariance but not the joint test. So: take the hypothesis of each detection's
    nearest individually compatible lamp (:func:`nearest_pairs`), find its iterated-EKF
    pose x* (:func:`converge`), and run JCBB linearised there; while JCBB's best
    hypothesis differs from the one iterated, iterate JCBB's instead and associate
    again. At x* the joint test is the chi-square test (2k dof) of the hypothesis' MAP
    cost, (x* - x0)^T P^-1 (x* - x0) + |z - h(x*)|^2_R to first order, not of a
    linearisation's error.

    Parameters
    ----------
    ekf : EkfSlam
        The filter (not changed).
    z : ndarray, shape (m, 2)
        Detections (robot frame).
    r : ndarray, shape (m, 2, 2)
        Their covariances.
    gate_chi2, ambiguity_margin : float
        JCBB's gate and margin.
    d2 : ndarray, shape (m, n), optional
        The individual distances linearised at the filter's pose, when computed.

    Returns
    -------
    d2 : ndarray, shape (m, n)
        The individual distances linearised at ``lin``.
    assoc : Association
        JCBB's association linearised at ``lin``.
    lin : ndarray, shape (3,), or None
        The linearisation pose (None: the filter's own; no lamp was compatible).
    iterations : int
        The hypotheses iterated.
    """
    if d2 is None:
        d2 = ekf.individual_compatibility(z, r)
    hyp = nearest_pairs(d2, gate_chi2)
    if not hyp:
        return d2, Association([]), None, 0
    lin, its = None, 0
    while its < MAX_ITERATIONS:
        its += 1
        lin = converge(ekf, z, r, hyp, lin)
        with ekf.linearised_at(lin):
            d2 = ekf.individual_compatibility(z, r)
            assoc = jcbb(ekf, z, r, d2, gate_chi2, ambiguity_margin)
        best = sorted(assoc.best)
        if not best or best == hyp:
            break
        hyp = best
    return d2, assoc, lin, its
