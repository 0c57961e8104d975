"""The odometry motion model of the EKF (docs/models.md sec. 2): the noise of one
increment as random walks per metre and per radian (rate invariant; Thrun, Burgard, Fox,
Probabilistic Robotics (2005), ch. 5, applied to increments of any size), its Jacobians,
and the preintegration of many increments into one relative motion between updates.
"""

from __future__ import annotations

import math

import numpy as np


def motion_noise(d_trans: float, d_rot: float, noise) -> np.ndarray:
    """Covariance M of the odometry increment (d_trans, d_rot): a random walk per metre
    of travel and per radian of turn (``SlamParams`` docstring), so that the covariance
    of a motion does not depend on how many increments it is split into:

        M = diag(k_tt |dt| + k_tr |dr|,  k_rr |dr| + k_rt |dt|),
        noise = (k_tt [m^2/m], k_tr [m^2/rad], k_rr [rad^2/rad], k_rt [rad^2/m]).

    Parameters
    ----------
    d_trans : float
        Translation increment (m).
    d_rot : float
        Rotation increment (rad).
    noise : tuple of 4 float
        (k_tt, k_tr, k_rr, k_rt).

    Returns
    -------
    ndarray, shape (2, 2)
        M.
    """
    k_tt, k_tr, k_rr, k_rt = noise
    adt, adr = abs(d_trans), abs(d_rot)
    return np.diag([k_tt * adt + k_tr * adr, k_rr * adr + k_rt * adt])


def motion_jacobians(pose: np.ndarray, d_trans: float, d_rot: float) -> tuple[np.ndarray, ...]:
    """Jacobians of ``robot.motion_step`` (midpoint rule) w.r.t. the pose (G_x) and (dt, dr) (G_u).

    With m = theta + dr/2:  x' = x + dt cos m,  y' = y + dt sin m,  theta' = theta + dr.
    G_x = [[1, 0, -dt sin m], [0, 1, dt cos m], [0, 0, 1]],
    G_u = [[cos m, -dt sin m / 2], [sin m, dt cos m / 2], [0, 1]].

    Parameters
    ----------
    pose : ndarray, shape (3,)
        The pose before the step.
    d_trans : float
        Translation increment (m).
    d_rot : float
        Rotation increment (rad).

    Returns
    -------
    g_x : ndarray, shape (3, 3)
    g_u : ndarray, shape (3, 2)
    """
    m = pose[2] + 0.5 * d_rot
    c, s = np.cos(m), np.sin(m)
    gx = np.array([[1.0, 0.0, -d_trans * s], [0.0, 1.0, d_trans * c], [0.0, 0.0, 1.0]])
    gu = np.array([[c, -0.5 * d_trans * s], [s, 0.5 * d_trans * c], [0.0, 1.0]])
    return gx, gu


def odometry_noise_tuple(noise) -> tuple[float, float, float, float]:
    """The four random-walk coefficients (k_tt, k_tr, k_rr, k_rt) of :func:`motion_noise`,
    checked: finite and non-negative.

    Parameters
    ----------
    noise : sequence of 4 float
        The coefficients.

    Returns
    -------
    tuple of 4 float
        (k_tt, k_tr, k_rr, k_rt); ValueError when one is negative or not finite.
    """
    k = tuple(float(a) for a in noise)
    if len(k) != 4 or not all(math.isfinite(a) and a >= 0.0 for a in k):
        raise ValueError(f"odometry noise needs 4 finite coefficients >= 0, got {noise!r}")
    return k  # type: ignore[return-value]


class Preintegrator:
    """Odometry increments composed into one relative motion and its covariance.

    delta' = delta (+) m(u),  m(u) = (dt cos(dr/2), dt sin(dr/2), dr)  (the midpoint step);
    Q' = A Q A^T + B G_u M G_u^T B^T,  A, B the composition Jacobians at (delta, m(u)),
    G_u the motion Jacobian at the origin. Plain floats: it runs at the odometry rate.
    """

    def __init__(self, noise) -> None:
        self.noise = odometry_noise_tuple(noise)
        self.reset()

    def reset(self) -> None:
        """Start a new relative motion (identity, zero covariance)."""
        self.dx = self.dy = self.dth = 0.0
        self._q = [0.0] * 6  # q00 q01 q02 q11 q12 q22
        self.steps = 0

    def add(self, d_trans: float, d_rot: float) -> None:
        """Compose one increment (the matrix products written out on the 6 unique entries).

        Parameters
        ----------
        d_trans : float
            Translation increment (m).
        d_rot : float
            Rotation increment (rad).
        """
        h = 0.5 * d_rot
        mx, my = d_trans * math.cos(h), d_trans * math.sin(h)
        dth = self.dth
        c, s = math.cos(dth), math.sin(dth)
        # A = [[1, 0, a], [0, 1, b], [0, 0, 1]]
        a = -s * mx - c * my
        b = c * mx - s * my
        self._compose(d_trans, d_rot, mx, my, c, s, a, b, math.cos(dth + h), math.sin(dth + h))

    def _compose(
        self,
        d_trans: float,
        d_rot: float,
        mx: float,
        my: float,
        c: float,
        s: float,
        a: float,
        b: float,
        ch: float,
        sh: float,
    ) -> None:
        """:meth:`add` given the step's geometry (the calibrated subclass has it already):
        m(u) = (mx, my, d_rot), (c, s) of the heading so far, A's (a, b), and (ch, sh) of
        the heading at the step's midpoint."""
        k_tt, k_tr, k_rr, k_rt = self.noise
        adt, adr = abs(d_trans), abs(d_rot)
        mt = k_tt * adt + k_tr * adr  # motion_noise, written out
        mr = k_rr * adr + k_rt * adt
        # A Q A^T
        q00, q01, q02, q11, q12, q22 = self._q
        q00, q01, q02, q11, q12 = (
            q00 + 2 * a * q02 + a * a * q22,
            q01 + a * q12 + b * q02 + a * b * q22,
            q02 + a * q22,
            q11 + 2 * b * q12 + b * b * q22,
            q12 + b * q22,
        )
        # B G_u = [[ch, -k sh], [sh, k ch], [0, 1]], k = dt / 2: + B G_u diag(mt, mr) (B G_u)^T
        k = 0.5 * d_trans
        kk = k * k * mr
        self._q = [
            q00 + ch * ch * mt + kk * sh * sh,
            q01 + ch * sh * (mt - kk),
            q02 - k * sh * mr,
            q11 + sh * sh * mt + kk * ch * ch,
            q12 + k * ch * mr,
            q22 + mr,
        ]
        self.dx += c * mx - s * my
        self.dy += s * mx + c * my
        self.dth += d_rot
        self.steps += 1

    @property
    def q(self) -> np.ndarray:
        """Covariance (3, 3) of the preintegrated motion."""
        q00, q01, q02, q11, q12, q22 = self._q
        return np.array([[q00, q01, q02], [q01, q11, q12], [q02, q12, q22]])

    @property
    def delta(self) -> np.ndarray:
        return np.array([self.dx, self.dy, self.dth])
