"""Odometry self-calibration: scale factors of the odometry in the EKF state.

The filter state carries k calibration factors ``c`` right after the pose
(slam/ekf.py; docs/models.md sec. 4b), after Roy and Thrun, "Online self-calibration
for mobile robots" (ICRA 1999) and Martinelli, Tomatis and Siegwart, "Simultaneous
localization and odometry self calibration for mobile robot" (Autonomous Robots 22,
2007). Two models:

- ``wheels`` (wheel encoders; c = (s_L, s_R, s_B)): true wheel radii r s_L, r s_R and
  base b s_B. From the nominal increment (dt_n, dr_n) (nominal r and b) the nominal
  wheel arcs are a_L = dt_n - b dr_n / 2, a_R = dt_n + b dr_n / 2, and::

      dt = (s_L a_L + s_R a_R) / 2,    dr = (s_R a_R - s_L a_L) / (b s_B)

- ``odom`` (nav_msgs/Odometry pose increments; c = (s_T, s_W)): dt = s_T dt_n,
  dr = s_W dr_n.

Observability (docs/models.md sec. 4b): a lamp sighting or a pose fix measures position
and heading, so every factor; a heading fix measures heading only, which the
translation scale does not enter on a straight line and which on turns cannot
separate it from the base (or rotation) factor. The heading-only update's gain along the
translation direction (s_L + s_R for ``wheels``, s_T for ``odom``) is therefore projected
out (:func:`freeze_gain`), so the translation scale keeps its value and variance through
a dark stretch corrected by heading fixes alone. Each factor also takes a random walk
per metre and per radian of motion (``slam.calib_var_per_m``, ``calib_var_per_rad``).

The files (calibration.csv, calibration.yaml) are :mod:`fuzzyslam.slam.calibration_files`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from fuzzyslam.se2 import compose, compose_with_jacobians
from fuzzyslam.slam.ekf import Preintegrator

NAMES = {
    "wheels": ("left_scale", "right_scale", "base_scale"),
    "odom": ("trans_scale", "rot_scale"),
}
# directions of calibration space that a heading-only measurement cannot inform (module doc)
HEADING_FROZEN = {"wheels": np.array([[1.0, 1.0, 0.0]]), "odom": np.array([[1.0, 0.0]])}


@dataclass
class Calibration:
    """The calibration model of a run, its prior (or starting) factors and covariance."""

    kind: str  # "wheels" | "odom"
    wheel_base: float  # nominal b (m), ``wheels`` only
    factors: np.ndarray  # (k,)
    cov: np.ndarray  # (k, k)
    var_per_m: float = 0.0  # random walk of each factor, factor^2 per metre
    var_per_rad: float = 0.0  # and per radian
    source: str = "prior"

    @property
    def names(self) -> tuple[str, ...]:
        return NAMES[self.kind]

    @property
    def k(self) -> int:
        return len(self.names)


@dataclass(frozen=True, kw_only=True)
class CalibrationEntry:
    """The summary's ``calibration``: the odometry self-calibration's model, where it
    started (``start``: the prior or a file) and its final factors (slam/stage.py)."""

    model: str
    start: str
    start_factors: list[float]
    names: list[str]
    factors: list[float]
    sigma: list[float]


def prior(kind: str, slam, wheel_base: float) -> Calibration:
    """The config's prior: factors 1, sigmas ``slam.calib_*_sigma`` (independent).

    Parameters
    ----------
    kind : str
        wheels or odom.
    slam : SlamParams
        ``calib_*_sigma`` and the random walk.
    wheel_base : float
        The nominal wheel base (m).

    Returns
    -------
    Calibration
    """
    if kind == "wheels":
        s = [slam.calib_wheel_sigma, slam.calib_wheel_sigma, slam.calib_base_sigma]
    else:
        s = [slam.calib_trans_sigma, slam.calib_rot_sigma]
    return Calibration(
        kind,
        float(wheel_base),
        np.ones(len(s)),
        np.diag(np.square(s)),
        slam.calib_var_per_m,
        slam.calib_var_per_rad,
    )


def true_factors(robot) -> np.ndarray:
    """The simulator's true wheel factors (s_L, s_R, s_B), in the order of
    ``NAMES["wheels"]``: the config's ``robot.left_scale``, ``right_scale``,
    ``base_scale`` (sim/encoders.py: true radii r s_L, r s_R and base b s_B, as the
    ``wheels`` model has them).

    Parameters
    ----------
    robot : RobotParams
        The ``robot`` section of the config the log was simulated from.

    Returns
    -------
    ndarray, shape (3,)
    """
    return np.array([float(getattr(robot, n)) for n in NAMES["wheels"]])


def errors_in_sigma(factors, sigma, truth) -> np.ndarray:
    """Each factor's error against the truth in its own standard deviations,
    (c - c_true) / sigma_c: within 2 sigma when its magnitude is at most 2.

    Parameters
    ----------
    factors, sigma, truth : sequence of float, length k
        The estimated factors, their standard deviations and the true factors.

    Returns
    -------
    ndarray, shape (k,)
    """
    c, s, t = (np.asarray(v, dtype=float) for v in (factors, sigma, truth))
    return (c - t) / s


def calibrated_increment(kind: str, b: float, c, dt_n: float, dr_n: float):
    """Calibrated increment (dt, dr) and its Jacobian F = d(dt, dr)/dc as two row tuples.

    wheels: F = [[a_L/2, a_R/2, 0], [-a_L/(b s_B), a_R/(b s_B), -dr/s_B]];
    odom:   F = [[dt_n, 0], [0, dr_n]] (module docstring).

    Parameters
    ----------
    kind : str
        wheels or odom.
    b : float
        The nominal wheel base (m).
    c : sequence of float, length k
        The factors.
    dt_n : float
        Nominal translation increment (m).
    dr_n : float
        Nominal rotation increment (rad).
    """
    if kind == "wheels":
        sl, sr, sb = c
        al, ar = dt_n - 0.5 * b * dr_n, dt_n + 0.5 * b * dr_n
        dt = 0.5 * (sl * al + sr * ar)
        bs = b * sb
        dr = (sr * ar - sl * al) / bs
        return dt, dr, (0.5 * al, 0.5 * ar, 0.0), (-al / bs, ar / bs, -dr / sb)
    st, sw = c
    return st * dt_n, sw * dr_n, (dt_n, 0.0), (0.0, dr_n)


class CalibratedPreintegrator(Preintegrator):
    """:class:`Preintegrator` of calibrated increments, with D = d delta / d c (3, k).

    delta' = delta (+) m(u(c)):  D' = A D + B G_u F,  A, B G_u as in ``Preintegrator.add``
    and F the Jacobian of :func:`calibrated_increment` (the chain rule through the
    composition). The factors are those of the filter at the last ``reset``.

    F is evaluated at an instrument, not at the measured increment (``instrumented``,
    docs/models.md sec. 4b): at the mean increment per step between the last two
    updates (:meth:`mark`, called by the runner after each update). The measured increment
    carries the encoders' noise n, and the rotation column of F (d dr / d s_B = -dr /
    s_B, or dr_n for the rotation scale) with it; the next update's innovation carries
    -n / s_B, so the factor's correction (gain times innovation, the gain through D
    proportional to F) has a mean in E[n^2]: the errors-in-variables bias of a
    regression on a noisy regressor. On a straight line (true rotation 0, measured
    rotation n) every update shrinks the measured rotation by raising s_B; in all, s_B
    comes out high by about sum n^2 / sum dr^2 over the update intervals (0.2-0.4 % on
    the paper scenario: 2-3 sigma). The previous interval's increments are independent
    of this interval's noise, and equal to the current ones at a steady motion, so F
    keeps its value where the motion is steady and loses the bias. Before the first
    update, and past twice the instrument's steps without one, F is the exact one. What
    the instrument leaves out of F, E (3, k) (chained like D), enters the motion noise:
    :meth:`q_calib`. ``instrumented = False`` gives the exact derivative at the measured
    increments (D then equals the finite difference of delta in c).
    """

    instrumented = True

    def __init__(self, noise, model: Calibration) -> None:
        self.kind, self.b = model.kind, model.wheel_base
        self.c = tuple(float(v) for v in model.factors)
        self.inst = (0.0, 0.0)  # F's increment: the mean step between the last two updates
        self.inst_steps = 0  # the steps it is the mean of (0: no instrument yet)
        # the nominal increments since the last update, and their steps
        self._sum_t = self._sum_r = 0.0
        self._n = 0
        self._f_inst = None  # F at the instrument for the factors c (cached: both fixed)
        super().__init__(noise)

    def mark(self) -> None:
        """An update was made: the steps since the previous one give the instrument (their
        mean step), and a new interval begins."""
        n = self._n
        if n:
            self.inst = (self._sum_t / n, self._sum_r / n)
            self.inst_steps = n
            self._f_inst = None
        self._sum_t = self._sum_r = 0.0
        self._n = 0

    @property
    def instrument_valid(self) -> bool:
        """The instrument stands for this step: there is one, and the steps since the last
        update are at most twice those it was measured on (past that, with no update, the
        motion may have changed and the exact F is used: the bias it brings grows with the
        updates, which are then rare)."""
        return self.instrumented and 0 < self._n <= 2 * self.inst_steps

    def reset(self, factors=None) -> None:
        """Start a new preintegration (delta = 0, D = 0) from the filter's factors.

        Parameters
        ----------
        factors : sequence of float, length k, optional
            The filter's current factors (None: keep the last).
        """
        if factors is not None:
            c = tuple(factors.tolist() if isinstance(factors, np.ndarray) else map(float, factors))
            if c != self.c:
                self.c = c
                self._f_inst = None  # F at the instrument: for the new factors
        if hasattr(self, "_de") and self.steps == 0:
            return  # nothing added since the last reset: delta, Q, D, E are zero already
        super().reset()
        # D and E (D's error: F's error, chained) column by column, a column of each per
        # factor: (D_0j, D_1j, D_2j, E_0j, E_1j, E_2j)
        self._de = [(0.0,) * 6] * len(self.c)
        self._arrays = None  # D and E as arrays (_matrices), until the next add
        self.dist = self.turn = 0.0  # |dt| and |dr| summed: the random walk's clock

    def add(self, d_trans: float, d_rot: float) -> None:
        """Compose one nominal increment, calibrated with the factors c; D and E chained.

        Parameters
        ----------
        d_trans : float
            Nominal translation increment (m).
        d_rot : float
            Nominal rotation increment (rad).
        """
        dt, dr, f0, f1 = calibrated_increment(self.kind, self.b, self.c, d_trans, d_rot)
        self._sum_t += d_trans
        self._sum_r += d_rot
        self._n += 1
        h = 0.5 * dr
        mx, my = dt * math.cos(h), dt * math.sin(h)
        dth = self.dth
        c, s = math.cos(dth), math.sin(dth)
        a = -s * mx - c * my  # A = [[1, 0, a], [0, 1, b], [0, 0, 1]]
        b = c * mx - s * my
        ch, sh, kk = math.cos(dth + h), math.sin(dth + h), 0.5 * dt
        ks, kc = kk * sh, kk * ch
        # D' = A D + B G_u F, B G_u = [[ch, -kk sh], [sh, kk ch], [0, 1]], a column (x, y,
        # z) per factor; with the instrument (instrument_valid, written out) F is taken at
        # it (u, v) and E' = A E + B G_u G (p, q, r) with G = F_exact - F_inst (gu, gv)
        if self.instrumented and self._n <= 2 * self.inst_steps:
            if self._f_inst is None:
                self._f_inst = calibrated_increment(self.kind, self.b, self.c, *self.inst)[2:]
            e0, e1 = self._f_inst
            self._de = [
                (x + a * z + ch * u - ks * v, y + b * z + sh * u + kc * v, z + v,
                 p + a * r + ch * (gu := fu - u) - ks * (gv := fv - v),
                 q + b * r + sh * gu + kc * gv, r + gv)
                for (x, y, z, p, q, r), u, v, fu, fv in zip(self._de, e0, e1, f0, f1, strict=True)
            ]  # fmt: skip
        else:  # the exact F; E unchanged
            self._de = [
                (x + a * z + ch * u - ks * v, y + b * z + sh * u + kc * v, z + v, p, q, r)
                for (x, y, z, p, q, r), u, v in zip(self._de, f0, f1, strict=True)
            ]
        self._arrays = None
        self.dist += abs(dt)
        self.turn += abs(dr)
        self._compose(dt, dr, mx, my, c, s, a, b, ch, sh)  # Preintegrator.add of (dt, dr)

    def _matrices(self) -> tuple[np.ndarray, np.ndarray]:
        """D and E (3, k) each, from their columns (built once per preintegration)."""
        if self._arrays is None:
            de = np.array(self._de).T  # (6, k)
            self._arrays = (de[:3].copy(), de[3:].copy())
        return self._arrays

    @property
    def d_calib(self) -> np.ndarray:
        """D = d delta / d c, (3, k)."""
        return self._matrices()[0]

    def q_calib(self, p_cc: np.ndarray) -> np.ndarray:
        """The covariance (3, 3) of delta with what the instrument leaves out: Q + E P_cc E^T,
        E (3, k) the chain rule of F's error (exact F minus F at the instrument; zero
        when not ``instrumented``), P_cc the factors' covariance.

        Parameters
        ----------
        p_cc : ndarray, shape (k, k)
            The filter's covariance of the factors.

        Returns
        -------
        ndarray, shape (3, 3)
        """
        e = self._matrices()[1]
        return self.q + e @ p_cc @ e.T


def predict_calibrated(ekf, delta: np.ndarray, q: np.ndarray, d: np.ndarray) -> None:
    """Prediction over (pose, c) with the preintegrated delta(c) (Jacobian D = d delta/dc).

    x_r' = x_r (+) delta;  T = [J_a, J_b D] (3, 3 + k) on the rows of (pose, c):
    P_r,x' = T P_(r,c),x for every column x but the pose's;  P_rr' = T P_(r,c),(r,c) T^T
    + J_b Q J_b^T; c and its covariance unchanged (the random walk is added by the
    runner, ``EkfSlam.diffuse``). O(n).

    Parameters
    ----------
    ekf : EkfSlam
        The filter (pose, factors and landmarks; updated in place).
    delta : ndarray, shape (3,)
        The preintegrated motion.
    q : ndarray, shape (3, 3)
        Its covariance.
    d : ndarray, shape (3, k)
        d delta / d c.
    """
    m0, n = ekf.m0, ekf.dim
    p = ekf.P  # views of the filter's arrays: updated in place
    x = ekf.x
    x[:3], ja, jb = compose_with_jacobians(x[:3], delta)
    ja = ekf.first_estimate_motion(ja)  # J_a with first estimates (EkfSlam, FEJ)
    t = np.concatenate((ja, jb @ d), axis=1)  # (3, m0)
    ekf.odometry_pose = compose(ekf.odometry_pose, delta)
    rows = t @ p[:m0, :n]  # (3, n)
    prr = rows[:, :m0] @ t.T + jb @ q @ jb.T
    rows[:, :3] = 0.5 * (prr + prr.T)
    p[:3, :n] = rows
    p[3:n, :3] = rows[:, 3:].T


def diffuse(ekf, var: float) -> None:
    """Random walk of the factors: P_cc' = P_cc + var I.

    Parameters
    ----------
    ekf : EkfSlam
        The filter (updated in place).
    var : float
        The variance added to each factor.
    """
    if var > 0.0:
        p = ekf.P
        for i in range(3, ekf.m0):  # k scalars: cheaper than an index array
            p[i, i] += var


def freeze_gain(k: np.ndarray, frozen: np.ndarray, c0: int, c1: int) -> np.ndarray:
    """The gain K (n, m) with the calibration rows c0:c1 projected so that u^T K_c = 0
    for every frozen direction u (rows of ``frozen``, (j, k)): K_c' = (I - U (U^T U)^-1
    U^T) K_c, U = frozen^T. Then u^T c and u^T P_cc u are unchanged by the update (the
    Joseph form holds for any gain).

    Parameters
    ----------
    k : ndarray, shape (n, m)
        The gain.
    frozen : ndarray, shape (j, k)
        The frozen directions.
    c0, c1 : int
        The calibration rows of the state.

    Returns
    -------
    ndarray, shape (n, m)
    """
    u = np.asarray(frozen, dtype=float).T  # (k, j)
    k = k.copy()
    kc = k[c0:c1]
    k[c0:c1] = kc - u @ np.linalg.solve(u.T @ u, u.T @ kc)
    return k
