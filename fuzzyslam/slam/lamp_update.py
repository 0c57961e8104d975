"""A frame's lamp update in the EKF-SLAM loop (:mod:`fuzzyslam.slam.runner`): JCBB data
association of the frame's detections with the mapped lamps, then one joint update of
the paired lamps (the association itself is :mod:`fuzzyslam.slam.association`)."""

from __future__ import annotations

import numpy as np

from fuzzyslam.slam.association import (
    Association,
    block_diag_cov,
    candidates,
    jcbb,
    joint_threshold,
    unique_hypothesis,
)
from fuzzyslam.slam.ekf import EkfSlam, UpdateResult


def associate_update(
    ekf: EkfSlam,
    z: np.ndarray,
    r: np.ndarray,
    d2: np.ndarray,
    gate_chi2: float,
    ambiguity_margin: float,
    known: Association | None = None,
) -> tuple[Association, UpdateResult | None]:
    """JCBB association and the joint update of the paired lamps.

    Fast path: when the hypothesis is unique (``unique_hypothesis``) the update's own
    joint NIS test (chi-square of 2 x pairs dof at ``gate_chi2``'s level) is the joint
    compatibility test; JCBB runs only otherwise (or when that update is refused).

    Parameters
    ----------
    ekf : EkfSlam
        The filter (updated in place).
    z : ndarray, shape (m, 2)
        The frame's detections in base_link (m).
    r : ndarray, shape (m, 2, 2)
        Their covariances.
    d2 : ndarray, shape (m, n)
        Squared Mahalanobis distances of detections to the n mapped lamps
        (``EkfSlam.individual_compatibility``).
    gate_chi2 : float
        The individual gate (chi-square, 2 dof).
    ambiguity_margin : float
        JCBB's margin below which another hypothesis makes a detection ambiguous.
    known : Association, optional
        JCBB's result on these ``d2`` and this filter state, when already computed (the
        relocalisation test's): used instead of running JCBB again.

    Returns
    -------
    assoc : Association
        The pairs (detection j, lamp i) and the ambiguous detections.
    res : UpdateResult or None
        The joint update of the pairs (None: no pair, or no lamp mapped).
    """
    if ekf.n_lamps == 0:
        return Association([]), None
    pairs = unique_hypothesis(candidates(d2, gate_chi2))
    if pairs is not None:
        done = unique_update(ekf, z, r, pairs, gate_chi2)
        if done is not None:
            return done
    assoc = known if known is not None else jcbb(ekf, z, r, d2, gate_chi2, ambiguity_margin)
    if not assoc.pairs:
        return assoc, None
    det = [j for j, _ in assoc.pairs]
    res = ekf.update_lamps([i for _, i in assoc.pairs], z[det], block_diag_cov(r[det]))
    return assoc, res


def unique_update(
    ekf: EkfSlam,
    z: np.ndarray,
    r: np.ndarray,
    pairs: list[tuple[int, int]],
    gate_chi2: float,
) -> tuple[Association, UpdateResult | None] | None:
    """The joint update of a unique hypothesis (``unique_hypothesis``), gated by its own
    joint NIS: chi-square of 2 x pairs dof at ``gate_chi2``'s level, JCBB's joint
    compatibility test of those pairs (Neira and Tardos 2001). No pairs: nothing to update.

    Parameters
    ----------
    ekf : EkfSlam
        The filter (updated in place when the test accepts).
    z : ndarray, shape (m, 2)
        The frame's detections in base_link (m).
    r : ndarray, shape (m, 2, 2)
        Their covariances.
    pairs : list of (int, int)
        The unique hypothesis: (detection j, lamp i), every candidate pair of the frame.
    gate_chi2 : float
        The individual gate (chi-square, 2 dof).

    Returns
    -------
    (Association, UpdateResult or None) or None
        The pairs and their update; None when the joint test refused them (the filter
        unchanged: JCBB decides).
    """
    if not pairs:
        return Association([]), None
    det = [j for j, _ in pairs]
    res = ekf.update_lamps(
        [i for _, i in pairs],
        z[det],
        block_diag_cov(r[det]),
        gate_chi2=joint_threshold(gate_chi2, 2 * len(pairs)),
    )
    return (Association(pairs, [], pairs), res) if res.accepted else None
