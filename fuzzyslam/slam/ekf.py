"""Augmented-state EKF-SLAM with point landmarks (ceiling lamps) in the plane.

State ``x = (x, y, theta, c_1..c_k, l1x, l1y, ..., lnx, lny)`` and covariance ``P``
(docs/models.md sec. 4; Thrun, Burgard, Fox, Probabilistic Robotics (2005), ch. 10;
the paper sec. 2). ``c`` are the k odometry calibration factors (k = 0 without
self-calibration; slam/calibration.py, docs/models.md sec. 4b). Costs: ``predict``
O(n) (robot block and robot-map rows only), ``update_*`` O(n^2) (one rank-2k
correction of P), ``add_lamp`` O(n).

Storage is preallocated and grows by doubling, so adding a lamp does not copy
the whole matrix each time; ``x`` and ``P`` are views of the used part.
"""

from __future__ import annotations

import math

import numpy as np

from fuzzyslam.robot import motion_step
from fuzzyslam.se2 import compose, compose_with_jacobians, rot, wrap_angle
from fuzzyslam.slam.ekf_update import EkfUpdates, UpdateResult  # updates; re-exported
from fuzzyslam.slam.motion import (  # the motion model's home; re-exported here
    Preintegrator,
    motion_jacobians,
    motion_noise,
    odometry_noise_tuple,
)

__all__ = ["EkfSlam", "Preintegrator", "UpdateResult", "lamp_init", "lamp_measurement",
           "motion_jacobians", "motion_noise", "odometry_noise_tuple"]  # fmt: skip


_PERP = np.array([1.0, -1.0])  # (d_y, d_x) * _PERP = d^perp


def lamp_measurement(pose: np.ndarray, lamp: np.ndarray) -> tuple[np.ndarray, ...]:
    """Predicted lamp position in the robot frame and its Jacobians (docs/models.md sec. 3).

    h = R(theta)^T (l - p);  dh/dp = -R^T;  dh/dl = R^T;  dh/dtheta = (h_y, -h_x).

    Parameters
    ----------
    pose : ndarray, shape (3,)
        The robot pose (x, y, theta).
    lamp : array_like, shape (2,)
        The lamp (x, y) in the map frame.

    Returns
    -------
    h : ndarray, shape (2,)
        The lamp in the robot frame.
    h_r : ndarray, shape (2, 3)
        dh / d pose.
    h_l : ndarray, shape (2, 2)
        dh / d lamp.
    """
    rt = rot(pose[2]).T
    h = rt @ (np.asarray(lamp, dtype=float) - pose[:2])
    hr = np.empty((2, 3))
    hr[:, :2] = -rt
    hr[:, 2] = (h[1], -h[0])
    return h, hr, rt


def mahalanobis_2x2(a, b, d, v0, v1):
    """Squared Mahalanobis distance v^T S^-1 v for symmetric 2x2 S = [[a, b], [b, d]],
    in closed form (S^-1 = [[d, -b], [-b, a]] / (a d - b^2)), element-wise over arrays.

    Parameters
    ----------
    a, b, d : ndarray or float, one shape (...)
        The entries of S.
    v0, v1 : ndarray or float, shape (...)
        The entries of v.

    Returns
    -------
    ndarray or float, shape (...)
        (d v0^2 - 2 b v0 v1 + a v1^2) / (a d - b^2).
    """
    det = a * d - b * b
    return (d * v0**2 - 2 * b * v0 * v1 + a * v1**2) / det


def lamp_init(pose: np.ndarray, z: np.ndarray) -> tuple[np.ndarray, ...]:
    """Inverse model: lamp l = p + R(theta) z, with Jacobians J_r (2, 3) and J_z (2, 2).

    J_r = [[1, 0, -s zx - c zy], [0, 1, c zx - s zy]],  J_z = R(theta).

    Parameters
    ----------
    pose : ndarray, shape (3,)
        The robot pose (x, y, theta).
    z : array_like, shape (2,)
        The detection in the robot frame.

    Returns
    -------
    lamp : ndarray, shape (2,)
        The lamp in the map frame.
    j_r : ndarray, shape (2, 3)
        d lamp / d pose.
    j_z : ndarray, shape (2, 2)
        d lamp / d z.
    """
    r = rot(pose[2])
    d = r @ np.asarray(z, dtype=float)
    jr = np.array([[1.0, 0.0, -d[1]], [0.0, 1.0, d[0]]])
    return pose[:2] + d, jr, r


class EkfSlam(EkfUpdates):
    """EKF-SLAM state and covariance with O(n) prediction and Joseph-form updates."""

    def __init__(
        self,
        pose,
        pose_cov,
        noise,
        capacity: int = 16,
        calib=None,
        calib_cov=None,
        first_estimates: bool = False,
    ) -> None:
        k = 0 if calib is None else len(calib)
        self.k = k  # calibration factors, right after the pose
        self.m0 = 3 + k  # index of the first lamp
        cap = self.m0 + 2 * max(int(capacity), 1)
        self._x = np.zeros(cap)
        self._p = np.zeros((cap, cap))
        self._x[:3] = np.asarray(pose, dtype=float)
        self._x[2] = wrap_angle(self._x[2])
        self._p[:3, :3] = np.asarray(pose_cov, dtype=float)
        if k:
            self._x[3 : self.m0] = np.asarray(calib, dtype=float)
            self._p[3 : self.m0, 3 : self.m0] = np.asarray(calib_cov, dtype=float).reshape(k, k)
        # directions (j, k) of calibration space that a heading-only update cannot inform:
        # its gain along them is projected out (calibration.freeze_gain)
        self.heading_frozen = np.zeros((0, k))
        self.noise = odometry_noise_tuple(noise)
        self.dim = self.m0
        # (idx, UpdateResult) of every update_robot call, drained by the runner (updates.csv)
        self.robot_updates: list[tuple[tuple[int, ...], UpdateResult]] = []
        # numerical guards (slam/health.py): near-singular S regularised, P repaired
        self.guards = {"s_regularised": 0, "p_repaired": 0}
        self.lin_pose = None  # the lamp model's linearisation pose (linearised_at)
        # dead reckoning of the same odometry, never corrected by updates: a smooth pose
        # whose differences are the robot's relative motion (multi-ring FLMs, fixes.heading)
        self.odometry_pose = self._x[:3].copy()
        # first-estimates Jacobians (FEJ, :meth:`first_estimate_motion`): the lamps'
        # positions when they were added, and the robot's position as last predicted,
        # kept in a vector laid out as ``_x`` (its pose entries: the prior position)
        self.first_estimates = bool(first_estimates)
        self._xf = self._x.copy()
        self._fej_restart = False

    # -- views ------------------------------------------------------------------------

    @property
    def x(self) -> np.ndarray:
        return self._x[: self.dim]

    @property
    def P(self) -> np.ndarray:
        return self._p[: self.dim, : self.dim]

    @property
    def pose(self) -> np.ndarray:
        """Robot pose (x, y, theta), a copy."""
        return self._x[:3].copy()

    @property
    def pose_cov(self) -> np.ndarray:
        """Robot pose covariance (3, 3), a copy."""
        return self._p[:3, :3].copy()

    @property
    def calib(self) -> np.ndarray:
        """Calibration factors (k,), a copy."""
        return self._x[3 : self.m0].copy()

    @property
    def calib_cov(self) -> np.ndarray:
        """Calibration covariance (k, k), a copy."""
        return self._p[3 : self.m0, 3 : self.m0].copy()

    @property
    def n_lamps(self) -> int:
        return (self.dim - self.m0) // 2

    @property
    def lamps(self) -> np.ndarray:
        """(n, 2) lamp positions (a view)."""
        return self._x[self.m0 : self.dim].reshape(-1, 2)

    def lamp_cov(self, i: int) -> np.ndarray:
        """The marginal covariance of lamp ``i``.

        Parameters
        ----------
        i : int
            The lamp's index.

        Returns
        -------
        ndarray, shape (2, 2)
            A copy of its diagonal block of P.
        """
        j = self.m0 + 2 * i
        return self._p[j : j + 2, j : j + 2].copy()

    def lamp_covs(self) -> np.ndarray:
        """(n, 2, 2) marginal covariances of all lamps (O(n), no loop in Python): a copy of
        the 2x2 diagonal blocks of the lamp block, read through a (n, 2, n, 2) view.

        Returns
        -------
        ndarray, shape (n, 2, 2)
        """
        return self._lamp_blocks().copy()

    def _lamp_blocks(self) -> np.ndarray:
        """A read-only (n, 2, 2) view of the lamps' 2x2 diagonal blocks of P."""
        n, m0 = self.n_lamps, self.m0
        blocks = self._p[m0 : self.dim, m0 : self.dim].reshape(n, 2, n, 2)
        return np.diagonal(blocks, axis1=0, axis2=2).transpose(2, 0, 1)

    # -- prediction ---------------------------------------------------------------------

    def predict(self, d_trans: float, d_rot: float) -> None:
        """Odometry prediction (Probabilistic Robotics, EKF-SLAM prediction, Table 10.1):

        x_r' = g(x_r, u);   P_rr' = G_x P_rr G_x^T + G_u M G_u^T;   P_rm' = G_x P_rm.

        Only the robot block and the robot-map cross rows change: O(n).

        Parameters
        ----------
        d_trans, d_rot : float
            The odometry increment: distance (m) and turn (rad).
        """
        pose = self._x[:3]
        gx, gu = motion_jacobians(pose, d_trans, d_rot)
        m = motion_noise(d_trans, d_rot, self.noise)
        self._x[:3] = motion_step(pose, d_trans, d_rot)
        self.odometry_pose = motion_step(self.odometry_pose, d_trans, d_rot)
        self._propagate(self.first_estimate_motion(gx), gu, m)

    def _propagate(self, a: np.ndarray, b: np.ndarray, q: np.ndarray) -> None:
        """P_rr' = A P_rr A^T + B Q B^T;  P_rm' = A P_rm: the prediction's covariance, the
        robot block and the robot-map cross rows only (O(n))."""
        n = self.dim
        p = self._p
        prr = a @ p[:3, :3] @ a.T + b @ q @ b.T
        p[:3, :3] = 0.5 * (prr + prr.T)
        if n > 3:
            cross = a @ p[:3, 3:n]
            p[:3, 3:n] = cross
            p[3:n, :3] = cross.T

    def predict_relative(
        self, delta: np.ndarray, q_delta: np.ndarray, d_calib: np.ndarray | None = None
    ) -> None:
        """Prediction with a preintegrated relative motion delta (robot frame) of covariance Q:

        x_r' = x_r (+) delta;  P_rr' = J_a P_rr J_a^T + J_b Q J_b^T;  P_rm' = J_a P_rm,
        with J_a, J_b the Jacobians of SE(2) composition (se2.jacobians_compose). Equal
        to a sequence of ``predict`` calls (the midpoint step is the composition with
        (dt cos(dr/2), dt sin(dr/2), dr), and these Jacobians compose), but O(n) once.

        With calibration factors c, ``d_calib`` (3, k) is d delta / d c and the pose rows
        take T = [J_a, J_b D] over (pose, c) (``calibration.predict_calibrated``).

        Parameters
        ----------
        delta : ndarray, shape (3,)
            The relative motion (x, y, theta) in the robot frame.
        q_delta : ndarray, shape (3, 3)
            Its covariance.
        d_calib : ndarray, shape (3, k), optional
            d delta / d c (with self-calibration).
        """
        if self.k and d_calib is not None:
            from fuzzyslam.slam.calibration import predict_calibrated

            predict_calibrated(self, delta, q_delta, d_calib)
            return
        self._x[:3], ja, jb = compose_with_jacobians(self._x[:3], delta)
        self.odometry_pose = compose(self.odometry_pose, delta)
        self._propagate(self.first_estimate_motion(ja), jb, q_delta)

    def first_estimate_motion(self, a: np.ndarray) -> np.ndarray:
        """The motion's pose Jacobian with first estimates (FEJ), called once the state
        holds the predicted pose p_(k+1|k).

        A prediction x' = x (+) delta has the pose Jacobian A = [[I, J (p' - p)], [0, 1]]
        (J the rotation by +90 deg) with p = p_(k|k), the pose the last update left. With
        ``first_estimates`` its heading column is taken between the two predicted
        positions instead (Huang, Mourikis and Roumeliotis, "Analysis and improvement of
        the consistency of extended Kalman filter based SLAM", ICRA 2008):

            A_FEJ = [[I, J (p_(k+1|k) - p_(k|k-1))], [0, 1]]

        so that the products of these Jacobians and the lamps' first-estimate measurement
        Jacobians (:meth:`predict_lamps`) keep the three unobservable directions of
        SLAM (a translation and a rotation of the whole map and the robot) unobservable:
        the standard EKF gains spurious heading information from every update and
        becomes overconfident. Without an update since the last prediction p_(k|k) =
        p_(k|k-1) and A is unchanged. After :meth:`inflate_robot` (an unmodelled
        disturbance, whose update moves the pose by far more than its motion) the next
        prediction takes the standard A and the lamps' current estimates become their
        first ones: the linearisation restarts from there.

        Parameters
        ----------
        a : ndarray, shape (3, 3)
            The standard pose Jacobian (at p_(k|k)).

        Returns
        -------
        ndarray, shape (3, 3)
            ``a`` itself without ``first_estimates``, else the FEJ Jacobian (a copy).
        """
        if not self.first_estimates:
            return a
        p_new = self._x[:2]
        if self._fej_restart:  # the lamps' linearisation restarts with the pose's
            self._fej_restart = False
            self._xf[self.m0 : self.dim] = self._x[self.m0 : self.dim]
        else:
            d = p_new - self._xf[:2]  # p_(k+1|k) - p_(k|k-1)
            a = a.copy()
            a[0, 2] = -d[1]
            a[1, 2] = d[0]
        self._xf[:2] = p_new
        return a

    def restart_linearisation(self) -> None:
        """Take the state's position as the last predicted one (FEJ: the state was set
        from outside, e.g. rewound to a snapshot taken with no update since)."""
        self._xf[:2] = self._x[:2]
        self._fej_restart = False

    def inflate_robot(self, q) -> None:
        """Add ``q`` (3, 3, symmetric PSD) to the robot block: P_rr' = P_rr + Q.

        Covariance inflation (fading memory; Simon, "Optimal state estimation", sec. 7.4)
        after an unseen disturbance (a bump): the pose keeps its mean and its
        correlations with the lamps, but admits the disturbance. P stays symmetric PSD.

        Parameters
        ----------
        q : array_like, shape (3, 3)
            Symmetric positive semi-definite; ValueError otherwise.
        """
        q = np.asarray(q, dtype=float).reshape(3, 3)
        if not np.allclose(q, q.T) or np.linalg.eigvalsh(0.5 * (q + q.T)).min() < -1e-12:
            raise ValueError("inflate_robot: q must be symmetric positive semi-definite")
        self._p[:3, :3] += 0.5 * (q + q.T)
        self._fej_restart = True  # FEJ: the next prediction's Jacobian restarts

    # -- augmentation -------------------------------------------------------------------

    def _grow(self, need: int) -> None:
        cap = self._x.size
        if need <= cap:
            return
        new = max(need, 2 * cap)
        x = np.zeros(new)
        p = np.zeros((new, new))
        xf = np.zeros(new)
        x[:cap] = self._x
        p[:cap, :cap] = self._p
        xf[:cap] = self._xf
        self._x, self._p, self._xf = x, p, xf

    def add_lamp(self, z, r) -> int:
        """Append a lamp seen at robot-frame point z with covariance r; return its index.

        l = p + R(theta) z;  P_ll = J_r P_rr J_r^T + J_z R J_z^T;  P_lx = J_r P_rx
        (Probabilistic Robotics sec. 10.2; O(n)).

        Parameters
        ----------
        z : array_like, shape (2,)
            The detection in the robot frame.
        r : array_like, shape (2, 2)
            Its covariance.

        Returns
        -------
        int
            The new lamp's index.
        """
        n = self.dim
        self._grow(n + 2)
        pose = self._x[:3]
        lamp, jr, jz = lamp_init(pose, z)
        p = self._p
        plx = jr @ p[:3, :n]
        p[n : n + 2, :n] = plx
        p[:n, n : n + 2] = plx.T
        pll = jr @ p[:3, :3] @ jr.T + jz @ np.asarray(r, dtype=float) @ jz.T
        p[n : n + 2, n : n + 2] = 0.5 * (pll + pll.T)
        self._x[n : n + 2] = lamp
        self._xf[n : n + 2] = lamp  # its first estimate (FEJ)
        self.dim = n + 2
        return self.n_lamps - 1

    def individual_compatibility(self, z: np.ndarray, r: np.ndarray) -> np.ndarray:
        """(m, n) squared Mahalanobis distances of detections z (m, 2) to every lamp.

        D2_ij = v_ij^T S_ij^-1 v_ij,  S_ij = H_i P H_i^T + R_j,  v_ij = z_j - h_i.
        Computed in the map frame (O(n m), vectorised): with d_i = l_i - p,
        H_i = R^T [-I, d_i^perp | I] (d^perp = (d_y, -d_x)), so S_ij = R^T (W_i + R R_j R^T) R
        with W_i = G_i P_rr G_i^T + G_i P_rl_i + P_rl_i^T G_i^T + P_ll_i, G_i = [-I, d_i^perp],
        and D2_ij = (R v_ij)^T (W_i + R R_j R^T)^-1 (R v_ij). Within ``linearised_at``,
        of the model linearised at that pose (R, d_i and G_i at it, h_i its expansion).

        Parameters
        ----------
        z : ndarray, shape (m, 2)
            The detections in the robot frame.
        r : ndarray, shape (m, 2, 2) or (2, 2)
            Their covariances (one for all).

        Returns
        -------
        ndarray, shape (m, n)
            D2_ij (inf everywhere when there is no lamp or no detection).
        """
        z = np.asarray(z, dtype=float).reshape(-1, 2)
        n = self.n_lamps
        if n == 0 or len(z) == 0:
            return np.full((len(z), n), np.inf)
        p = self._p
        x = self._x
        pose, dx = self._lin_offset()  # the linearisation pose (linearised_at)
        c, s = math.cos(pose[2]), math.sin(pose[2])
        rmat = np.array([[c, -s], [s, c]])
        m0, end = self.m0, self.dim
        d = x[m0:end].reshape(n, 2) - pose[:2]  # d_i = l_i - p  (n, 2)
        # H's heading column: at the lamps' first estimates with ``first_estimates``
        df = self._xf[m0:end].reshape(n, 2) - pose[:2] if self.first_estimates else d
        dp = df[:, ::-1] * _PERP  # d^perp = (d_y, -d_x)
        dpc = dp[:, :, None]  # (n, 2, 1)
        # G P_rr G^T = Pxx - (p_t dp^T + dp p_t^T) + q_tt dp dp^T
        pxx, pt, qtt = p[:2, :2], p[:2, 2], p[2, 2]
        ptdp = pt[:, None] * dp[:, None, :]  # p_t dp^T (n, 2, 2); dp p_t^T is its transpose
        w = pxx - (ptdp + ptdp.transpose(0, 2, 1))
        w += qtt * dpc * dp[:, None, :]
        # G P_rl = dp P_rl[2] - P_rl[:2]  (each 2x2); P_rl rows 0..2, lamp columns
        prl = p[:3, m0:end].reshape(3, n, 2)  # [row, lamp, col]
        gpl = dpc * prl[2][:, None, :] - prl[:2].transpose(1, 0, 2)  # (n, 2, 2)
        w += gpl + gpl.transpose(0, 2, 1)
        w += self._lamp_blocks()
        r = np.asarray(r, dtype=float).reshape(-1, 2, 2)
        rw = rmat @ r @ rmat.T  # (m or 1, 2, 2): one R for all broadcasts below
        zw = z @ rmat.T  # R z_j
        # R h_i: d_i, and linearised at x_i (linearised_at) R h(x_i) + R H_i (x - x_i)
        # = d_i - dp + dtheta d_i^perp, (dp, dtheta) = x - x_i
        dh = d if dx is None else d - dx[:2] + dx[2] * dp
        v = zw[:, None, :] - dh[None, :, :]  # R (z_j - h_i) = R z_j - R h_i
        # the entries (a, b; b, dd) of S_ij = W_i + R R_j R^T, each (m, n)
        a = w[:, 0, 0] + rw[:, None, 0, 0]
        b = w[:, 0, 1] + rw[:, None, 0, 1]
        dd = w[:, 1, 1] + rw[:, None, 1, 1]
        return mahalanobis_2x2(a, b, dd, v[..., 0], v[..., 1])
