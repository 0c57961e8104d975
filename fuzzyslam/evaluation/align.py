"""Least-squares alignment of two point sets (Umeyama 1991), as evo aligns trajectories for APE.

Reference: S. Umeyama, "Least-squares estimation of transformation parameters between two
point patterns", IEEE PAMI 13(4), 1991, eqs. (34)-(43).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from fuzzyslam.se2 import wrap_angle

Array = NDArray[np.float64]


@dataclass(frozen=True)
class Similarity:
    """p' = s R p + t: rotation R (d, d), translation t (d,), scale s."""

    rotation: Array
    translation: Array
    scale: float = 1.0

    @property
    def angle(self) -> float:
        """Rotation angle (rad) of a planar (2x2) rotation."""
        return float(np.arctan2(self.rotation[1, 0], self.rotation[0, 0]))

    def apply(self, points: ArrayLike) -> Array:
        """Map points (N, d) through the transform."""
        p = np.asarray(points, dtype=float)
        return self.scale * p @ self.rotation.T + self.translation

    def apply_poses(self, poses: ArrayLike) -> Array:
        """Map planar poses (N, 3) (x, y, theta): positions transformed, headings rotated."""
        p = np.asarray(poses, dtype=float).reshape(-1, 3)
        xy = self.apply(p[:, :2])
        th = np.asarray(wrap_angle(p[:, 2] + self.angle)).reshape(-1)
        return np.column_stack([xy, th])

    def inverse(self) -> Similarity:
        """The transform that undoes this one: p = (1/s) R^T (p' - t).

        Returns
        -------
        Similarity
            Rotation R^T, translation -(1/s) R^T t, scale 1/s.
        """
        r = self.rotation.T
        return Similarity(r, -(r @ self.translation) / self.scale, 1.0 / self.scale)


def umeyama(src: ArrayLike, dst: ArrayLike, with_scale: bool = False) -> Similarity:
    """Rotation, translation (and scale) minimising sum ||dst_i - (s R src_i + t)||^2.

    Umeyama (1991): with means mu_x, mu_y of src and dst, variance sigma_x^2 of src and the
    cross-covariance Sigma_xy = (1/n) sum (y_i - mu_y)(x_i - mu_x)^T = U D V^T (SVD),

        S = diag(1, .., 1, det(U) det(V))        (a proper rotation, eq. 39)
        R = U S V^T                              (eq. 40)
        s = trace(D S) / sigma_x^2               (eq. 42; s = 1 for a rigid fit)
        t = mu_y - s R mu_x                      (eq. 41)

    src and dst are (N, d) arrays of corresponding points, N >= 2.
    """
    x = np.asarray(src, dtype=float)
    y = np.asarray(dst, dtype=float)
    if x.shape != y.shape or x.ndim != 2:
        raise ValueError(f"umeyama: point sets must have the same (N, d) shape, got {x.shape}")
    n, d = x.shape
    if n < 2:
        raise ValueError("umeyama: need at least two corresponding points")
    mu_x = x.mean(axis=0)
    mu_y = y.mean(axis=0)
    xc = x - mu_x
    yc = y - mu_y
    sigma_x2 = float(np.mean(np.sum(xc * xc, axis=1)))
    cov = yc.T @ xc / n
    u, dvals, vt = np.linalg.svd(cov)
    s_mat = np.eye(d)
    if np.linalg.det(u) * np.linalg.det(vt) < 0.0:
        s_mat[d - 1, d - 1] = -1.0
    r = u @ s_mat @ vt
    scale = float(np.trace(np.diag(dvals) @ s_mat) / sigma_x2) if with_scale else 1.0
    if with_scale and not np.isfinite(scale):
        raise ValueError("umeyama: degenerate source points (zero variance)")
    t = mu_y - scale * r @ mu_x
    return Similarity(rotation=r, translation=t, scale=scale)


def anchor(est_pose: ArrayLike, truth_pose: ArrayLike) -> Similarity:
    """The rigid 2-D motion that takes one estimated pose onto the true pose at that time.

    A SLAM filter started with a (near) zero start covariance defines its map frame by the
    robot's first pose: its covariances are the uncertainty of the pose relative to that
    frame. Mapping the estimate by the motion that makes the first poses coincide puts
    estimate and truth in that frame, where ``e^T P^-1 e`` is the NEES the filter claims
    (Bar-Shalom et al. 2001, sec. 5.4). A least-squares alignment of the whole path
    (:func:`umeyama`) moves the start away from the truth's, where the filter claims
    millimetres, and spreads the late drift over the whole path.

    Parameters
    ----------
    est_pose : array_like, shape (3,)
        The estimated pose (x, y, theta).
    truth_pose : array_like, shape (3,)
        The true pose at the same time.

    Returns
    -------
    Similarity
        Rotation by theta_t - theta_e about the origin, then the translation that maps
        the estimated position onto the true one (scale 1).
    """
    e = np.asarray(est_pose, dtype=float).reshape(3)
    t = np.asarray(truth_pose, dtype=float).reshape(3)
    a = float(t[2] - e[2])
    r = np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])
    return Similarity(r, t[:2] - r @ e[:2])
