"""The measurement updates of :class:`fuzzyslam.slam.ekf.EkfSlam` (docs/models.md sec. 4).

Kalman correction in Joseph form with H nonzero only on a few columns (the robot pose
and the lamps observed), O(n^2) per update (one rank-2k correction of P, applied by row
blocks to the upper triangle and mirrored); the lamps' stacked prediction; direct
measurements of the robot's state (heading and pose fixes). A mixin: ``EkfSlam`` holds
the state (``_x``, ``_p``, ``dim``, ``m0``, ``guards``, ``heading_frozen``,
``robot_updates``). Reference: Thrun, Burgard, Fox, *Probabilistic Robotics* (2005),
ch. 3 and 10; R. Labbe, *Kalman and Bayesian filters in Python* (filterpy), ch. 7
(Joseph form).
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from fuzzyslam.se2 import wrap_angle
from fuzzyslam.slam.health import repair_covariance, solve_spd


@dataclass
class UpdateResult:
    """Outcome of one measurement update: accepted, NIS = v^T S^-1 v, innovation v."""

    accepted: bool
    nis: float
    innovation: np.ndarray
    s: np.ndarray | None = None  # innovation covariance S = H P H^T + R (prior)


_BLOCK = 256
_POSE_COLS = np.arange(3)  # the robot pose's columns of H
_XY = np.arange(2)  # a lamp's x, y offsets in the state


@lru_cache(maxsize=16)
def _h_lamp_index(k: int) -> tuple[np.ndarray, slice, np.ndarray]:
    """Index of the k lamps' 2x2 blocks of H viewed (k, 2, 3 + 2k) in
    :meth:`EkfUpdates.predict_lamps`: ``hv[index]`` is (k, 2, 2), its [a, c, r] the entry
    of row r of lamp a's two rows in column 3 + 2a + c (the advanced indices first), so
    that ``hv[index] = R^T.T`` puts R^T in every lamp's block."""
    rows = np.arange(k)
    return rows[:, None], slice(None), 3 + 2 * rows[:, None] + _XY


def _add_symmetric_update(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> None:
    """P += A B^T for a symmetric A B^T, in place, keeping P exactly symmetric.

    Row blocks of the upper triangle are updated (one small GEMM each), diagonal blocks
    averaged with their transpose and the rest mirrored to the lower triangle: no
    n x n temporary and no full-matrix transpose, so the cost stays O(n^2) once P
    leaves the caches.
    """
    n = p.shape[0]
    for i0 in range(0, n, _BLOCK):
        i1 = min(i0 + _BLOCK, n)
        p[i0:i1, i0:] += a[i0:i1] @ b[i0:].T
        blk = p[i0:i1, i0:i1]
        blk[...] = 0.5 * (blk + blk.T)
        if i1 < n:
            p[i1:, i0:i1] = p[i0:i1, i1:].T


class EkfUpdates:
    """Measurement updates of the EKF-SLAM state (mixed into ``EkfSlam``)."""

    _x: np.ndarray
    _p: np.ndarray
    dim: int
    m0: int
    guards: dict
    heading_frozen: np.ndarray
    robot_updates: list
    P: np.ndarray  # the covariance's used part (EkfSlam.P)
    # the pose the lamp model is linearised at (None: the state's own; linearised_at)
    lin_pose: np.ndarray | None
    # first-estimates Jacobians (EkfSlam.first_estimate_motion): the lamps' first
    # estimates, laid out as _x
    first_estimates: bool
    _xf: np.ndarray

    @contextmanager
    def linearised_at(self, pose: np.ndarray | None) -> Iterator[None]:
        """Linearise the lamp model at ``pose`` instead of at the state's pose, within.

        The iterated EKF's step (Bell and Cathey, "The iterated Kalman filter update as
        a Gauss-Newton method", IEEE T-AC 38(2), 1993): h and H are taken at the iterate
        x_i (pose ``pose``, the lamps at their means) and the prediction is the
        first-order expansion about it, evaluated at the prior mean x:

            h_i(x) = h(x_i) + H_i (x - x_i),   v = z - h_i(x),   S = H_i P H_i^T + R

        so the innovations, S, the gates, JCBB's joint tests and the update
        x' = x + K v (K = P H_i^T S^-1) are those of the model linearised at x_i. With
        ``pose`` None (or the state's pose) everything is the plain EKF's.

        Parameters
        ----------
        pose : ndarray, shape (3,), or None
            The linearisation pose (x, y, theta).

        Returns
        -------
        contextmanager
            Restores the previous linearisation pose on leaving.
        """
        old = self.lin_pose
        self.lin_pose = None if pose is None else np.asarray(pose, dtype=float).copy()
        try:
            yield
        finally:
            self.lin_pose = old

    def _lin_offset(self) -> tuple[np.ndarray, np.ndarray | None]:
        """The linearisation pose x_i and x - x_i (pose part, heading wrapped; None when
        the model is linearised at the state's own pose)."""
        lin = self.lin_pose
        if lin is None:
            return self._x[:3], None
        dx = self._x[:3] - lin
        dx[2] = wrap_angle(dx[2])
        return lin, dx

    def _innovate(
        self, cols: np.ndarray, hc: np.ndarray, v: np.ndarray, r: np.ndarray
    ) -> tuple[float, np.ndarray, np.ndarray, np.ndarray]:
        """The gate's NIS and the gain's factors for H nonzero only on columns ``cols``,
        S factored once for both (filterpy's ``KalmanFilter.update`` order):

        P H^T,  S = H (P H^T) + R,  [w | K^T] = S^-1 [v | (P H^T)^T],  NIS = v^T w,

        a near-singular S regularised (``health.solve_spd``) and counted once.

        Returns
        -------
        nis : float
        s : ndarray, shape (d, d)
            S, symmetrised.
        pht : ndarray, shape (n, d)
            P H^T.
        kt : ndarray, shape (d, n)
            K^T = S^-1 (P H^T)^T.
        """
        n = self.dim
        pht = self._p[:n, cols] @ hc.T
        s = hc @ pht[cols] + r
        s = 0.5 * (s + s.T)
        sol, reg = solve_spd(s, np.concatenate((v[:, None], pht.T), axis=1))
        self.guards["s_regularised"] += reg
        return float(v @ sol[:, 0]), s, pht, sol[:, 1:]

    def _correct(
        self,
        v: np.ndarray,
        s: np.ndarray,
        pht: np.ndarray,
        kt: np.ndarray,
        frozen: np.ndarray | None = None,
    ) -> None:
        """Kalman correction from :meth:`_innovate`'s S, P H^T and K^T.

        K = P H^T S^-1,  x' = x + K v,
        P' = (I - K H) P (I - K H)^T + K R K^T      (Joseph form)
           = P - K (P H^T)^T - (P H^T) K^T + K S K^T (expanded, valid for any K)
           = P + X Y^T + Y X^T,  X = K, Y = K S / 2 - P H^T,
        one (n x 4k)(4k x n) matrix product: O(n^2 k), applied by row blocks to the upper
        triangle and mirrored, so P stays exactly symmetric (``_add_symmetric_update``).

        ``frozen`` (j, k): calibration directions this measurement cannot observe; the
        gain along them is projected out (``calibration.freeze_gain``; the Joseph form
        keeps P the covariance of the suboptimal gain, those directions unchanged).
        """
        n = self.dim
        p = self._p[:n, :n]
        k = kt.T
        if frozen is not None and len(frozen):
            from fuzzyslam.slam.calibration import freeze_gain

            k = freeze_gain(k, frozen, 3, self.m0)
        self._x[:n] += k @ v
        self._x[2] = wrap_angle(self._x[2])
        y = 0.5 * (k @ s) - pht
        _add_symmetric_update(p, np.concatenate((k, y), 1), np.concatenate((y, k), 1))
        d = np.diagonal(p)
        if not 0.0 < d.min() <= d.max() < np.inf:  # finite and > 0 (NaN fails): O(n)
            self.check_covariance()

    def check_covariance(self) -> bool:
        """Repair P if it is not symmetric positive definite (``health.repair_covariance``,
        the nearest such matrix); count it in ``guards['p_repaired']``. O(n^3): called
        after an update breaks the O(n) diagonal check, and periodically by the runner.

        Returns
        -------
        bool
            Whether P was repaired.
        """
        p, repaired = repair_covariance(self.P)
        if repaired:
            self._p[: self.dim, : self.dim] = p
            self.guards["p_repaired"] += 1
        return repaired

    def innovation_cov(self, cols: np.ndarray, hc: np.ndarray, r: np.ndarray) -> np.ndarray:
        """S = H P H^T + R for H nonzero only on ``cols``.

        Parameters
        ----------
        cols : ndarray, shape (c,)
            The state columns where H is nonzero.
        hc : ndarray, shape (d, c)
            H restricted to them.
        r : ndarray, shape (d, d)
            The measurement covariance.

        Returns
        -------
        ndarray, shape (d, d)
            S, symmetrised.
        """
        s = hc @ self._p[cols][:, cols] @ hc.T + r
        return 0.5 * (s + s.T)

    def predict_lamps(self, ids) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Stacked prediction of lamps ``ids``: h (2k,), columns, H restricted to columns.

        Columns are [0, 1, 2, l_i...]; H is (2k, 3 + 2k) with the blocks of
        ``lamp_measurement`` (vectorised over the k lamps). Within
        :meth:`linearised_at`, h and H of the model linearised at that pose.

        Parameters
        ----------
        ids : array_like of int, shape (k,)
            The lamps.

        Returns
        -------
        h : ndarray, shape (2k,)
            The lamps in the robot frame, stacked.
        cols : ndarray, shape (3 + 2k,)
            The state columns of H.
        hc : ndarray, shape (2k, 3 + 2k)
            H restricted to them.
        """
        ids = np.asarray(ids, dtype=int).reshape(-1)
        k = len(ids)
        x = self._x
        pose, dx = self._lin_offset()  # the linearisation pose (linearised_at)
        c, s = math.cos(pose[2]), math.sin(pose[2])
        rt = np.array([[c, s], [-s, c]])
        j = self.m0 + 2 * ids
        jj = j[:, None] + _XY  # the lamps' (x, y) indices (k, 2)
        h = (x[jj] - pose[:2]) @ rt.T  # (k, 2)
        hc = np.zeros((2 * k, 3 + 2 * k))
        hv = hc.reshape(k, 2, 3 + 2 * k)
        hv[:, :, :2] = -rt
        # dh/dtheta = (h_y, -h_x), with first estimates at the lamps' first positions:
        # H_FEJ (Huang, Mourikis and Roumeliotis, ICRA 2008; EkfSlam.first_estimate_motion)
        hf = (self._xf[jj] - pose[:2]) @ rt.T if self.first_estimates else h
        hv[:, 0, 2] = hf[:, 1]
        hv[:, 1, 2] = -hf[:, 0]
        hv[_h_lamp_index(k)] = rt.T  # dh_a / dl_a = R^T in columns 3 + 2a, 4 + 2a
        cols = np.concatenate([_POSE_COLS, jj.reshape(-1)])
        if dx is not None:  # h_i(x) = h(x_i) + H_i (x - x_i) (lamps at their means)
            h = h + hv[:, :, :3] @ dx
        return h.reshape(-1), cols, hc

    def update_lamps(
        self, ids, z: np.ndarray, r: np.ndarray, gate_chi2: float | None = None
    ) -> UpdateResult:
        """Joint update with lamps ``ids`` observed at robot-frame points z (k, 2).

        ``r`` is the (2k, 2k) measurement covariance (block-diagonal for independent
        detections). v = z - h(x); S = H P H^T + R; rejected if NIS > gate_chi2.

        Parameters
        ----------
        ids : array_like of int, shape (k,)
            The lamps observed.
        z : ndarray, shape (k, 2)
            Their detections in the robot frame.
        r : ndarray, shape (2k, 2k)
            The detections' covariance.
        gate_chi2 : float, optional
            NIS above which the update is refused (None: always applied).

        Returns
        -------
        UpdateResult
            Accepted, NIS, innovation (2k,) and S (2k, 2k).
        """
        h, cols, hc = self.predict_lamps(ids)
        v = np.asarray(z, dtype=float).reshape(-1) - h
        nis, s, pht, kt = self._innovate(cols, hc, v, r)
        if gate_chi2 is not None and not nis <= gate_chi2:
            return UpdateResult(False, nis, v, s)
        self._correct(v, s, pht, kt)
        return UpdateResult(True, nis, v, s)

    def update_lamp(self, i: int, z, r, gate_chi2: float | None = None) -> UpdateResult:
        """Update with one lamp ``i`` seen at robot-frame point z (2,), covariance r (2, 2).

        Parameters
        ----------
        i : int
            The lamp.
        z : array_like, shape (2,)
            The detection in the robot frame.
        r : array_like, shape (2, 2)
            Its covariance.
        gate_chi2 : float, optional
            NIS above which the update is refused.

        Returns
        -------
        UpdateResult
        """
        return self.update_lamps([i], np.asarray(z).reshape(1, 2), np.asarray(r), gate_chi2)

    def update_robot(self, z, r, idx, gate_chi2: float | None = None) -> UpdateResult:
        """Direct measurement of robot state components ``idx`` (e.g. [2] heading, [0, 1, 2]).

        h(x) = x[idx], H = rows of the identity; the heading component of the
        innovation is wrapped to (-pi, pi]. Rejected (no change) if NIS > gate_chi2.

        Parameters
        ----------
        z : array_like, shape (d,)
            The measured components.
        r : array_like, shape (d, d)
            Their covariance.
        idx : array_like of int, shape (d,)
            Which of x, y, theta (0, 1, 2) are measured.
        gate_chi2 : float, optional
            NIS above which the update is refused.

        Returns
        -------
        UpdateResult
            Also appended to ``robot_updates`` (the runner's updates.csv).
        """
        cols = np.asarray(idx, dtype=int).reshape(-1)
        if np.any((cols < 0) | (cols > 2)):
            raise ValueError("update_robot: idx must be robot components 0, 1, 2")
        z = np.asarray(z, dtype=float).reshape(-1)
        r = np.atleast_2d(np.asarray(r, dtype=float))
        v = z - self._x[cols]
        v[cols == 2] = wrap_angle(v[cols == 2])
        hc = np.eye(len(cols))
        nis, s, pht, kt = self._innovate(cols, hc, v, r)
        if gate_chi2 is not None and not nis <= gate_chi2:
            res = UpdateResult(False, nis, v)
        else:
            heading_only = bool(np.all(cols == 2))
            self._correct(v, s, pht, kt, self.heading_frozen if heading_only else None)
            res = UpdateResult(True, nis, v)
        self.robot_updates.append((tuple(int(c) for c in cols), res))
        return res
