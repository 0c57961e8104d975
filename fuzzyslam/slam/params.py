"""Parameters of the EKF-SLAM filter and the lamp detector (config section ``slam``)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass
class SlamParams:
    """EKF-SLAM on ceiling lamps (docs/models.md sec. 2-4).

    Odometry noise of an increment (dt, dr) (the odometry motion model of Probabilistic
    Robotics, sec. 5.4, with the variances linear in the motion, i.e. a random walk per
    metre of travel and per radian of turn, so that the covariance of a motion does not
    depend on the odometry's message rate)::

        var_trans = trans_var_per_m |dt| + trans_var_per_rad |dr|
        var_rot   = rot_var_per_rad |dr| + rot_var_per_m |dt|

    Detections given as points (PoseArray) are range-bearing measurements::

        sigma_r = detection_sigma_range + detection_sigma_range_per_m * r
        sigma_b = detection_sigma_bearing_deg
        R = J diag(sigma_r^2, sigma_b^2) J^T,  J = d(x, y) / d(r, b)
    """

    # odometry random walks (docstring). Simulator values: the encoders' random walks
    # measured against ground truth on quick.yaml (translation 2.5e-6 m^2/m, heading
    # 6.1e-5 rad^2/m) plus what covers the 1 % wheel-base error on turns (3e-5 rad^2/rad:
    # 1.6 mrad of systematic error between two frames of a turn)
    trans_var_per_m: float = field(default=4.5e-6, metadata={"min": 0.0, "max": 1.0})
    trans_var_per_rad: float = field(default=3e-6, metadata={"min": 0.0, "max": 1.0})
    rot_var_per_rad: float = field(default=3e-5, metadata={"min": 0.0, "max": 1.0})
    rot_var_per_m: float = field(default=6.65e-5, metadata={"min": 0.0, "max": 1.0})
    use_encoders: bool = True
    # odometry self-calibration (slam/calibration.py, docs/models.md sec. 4b): scale factors
    # in the filter state, wheels (left, right, base) for encoders, (translation,
    # rotation) for Odometry poses; prior sigmas around 1 and a random walk of each
    # factor per metre and per radian of motion (factor^2/m, factor^2/rad)
    calibrate: bool = False
    # (wheel radii measured to 0.1 mm on a 5 cm wheel: 0.2 %; a wider prior on each wheel is
    # a prior heading drift of sqrt(2) sigma / b per metre, 35 mrad/m at 1 % on a 40 cm base,
    # that the EKF's linearisation does not survive: tests/test_calibration.py, NEES)
    calib_wheel_sigma: float = field(default=0.002, metadata={"min": 1e-6, "max": 0.5})
    calib_base_sigma: float = field(default=0.02, metadata={"min": 1e-6, "max": 0.5})
    calib_trans_sigma: float = field(default=0.05, metadata={"min": 1e-6, "max": 0.5})
    calib_rot_sigma: float = field(default=0.05, metadata={"min": 1e-6, "max": 0.5})
    calib_var_per_m: float = field(default=1e-9, metadata={"min": 0.0, "max": 1e-2})
    calib_var_per_rad: float = field(default=1e-9, metadata={"min": 0.0, "max": 1e-2})
    # first-estimates Jacobians (FEJ; EkfSlam.first_estimate_motion): the motion's and the
    # lamps' Jacobians taken at the first estimates, so that updates cannot make the
    # unobservable global heading look observable (the standard EKF-SLAM grows
    # overconfident in heading on a young map)
    first_estimates: bool = False
    # start pose (x, y, theta) when the log carries none, and its standard deviation
    start_pose: list[float] = field(
        default_factory=lambda: [0.0, 0.0, 0.0], metadata={"min": -1e6, "max": 1e6, "len": 3}
    )
    start_sigma: list[float] = field(
        default_factory=lambda: [1e-3, 1e-3, 1e-3], metadata={"min": 1e-9, "max": 1e3, "len": 3}
    )
    # lamp detector
    threshold: int = field(default=200, metadata={"min": 1, "max": 255})
    min_area: int = field(default=4, metadata={"min": 1})
    max_area: int = field(default=2000, metadata={"min": 1})
    min_fill: float = field(default=0.5, metadata={"min": 0.0, "max": 1.0})
    max_aspect: float = field(default=2.0, metadata={"min": 1.0})
    border: int = field(default=1, metadata={"min": 0, "max": 100})
    # centroid standard deviation (px): measured 0.007 px on simulated frames against the
    # true projections; 0.02 leaves room for what the simulator does not model
    pixel_sigma: float = field(default=0.02, metadata={"min": 0.001, "max": 100.0})
    # noise of a detection given as a PoseArray point (logs without frames; docstring):
    # range sigma (m) at zero range, its growth per metre of range, bearing sigma (deg)
    detection_sigma_range: float = field(default=0.02, metadata={"min": 1e-4, "max": 10.0})
    detection_sigma_range_per_m: float = field(default=0.0, metadata={"min": 0.0, "max": 1.0})
    detection_sigma_bearing_deg: float = field(default=0.6, metadata={"min": 1e-3, "max": 45.0})
    # a detection's own covariance (vision_msgs/Detection3DArray): ``floor``: taken, but
    # no smaller than the model above along and across the line of sight (a detector's
    # covariance is its Gaussian core, the model's margin holds its tails); ``use``: taken
    # as it is; ``model``: ignored (detection_cov_floored)
    detection_own_covariance: str = field(
        default="floor", metadata={"choices": ["floor", "use", "model"]}
    )
    # data association
    gate_chi2: float = field(default=9.21, metadata={"min": 0.1})
    new_lamp_chi2: float = field(default=40.0, metadata={"min": 0.1})
    # JCBB alternatives: a hypothesis with as many pairings whose joint NIS is within this
    # margin of the best makes the pairings it changes ambiguous (not applied; a
    # log-likelihood ratio: 4 = alternatives at least e^-2 = 14 % as likely); 0: off
    ambiguity_margin: float = field(default=4.0, metadata={"min": 0.0, "max": 100.0})
    # relocalisation test (slam/relocalise.py ``relocalisation_test``): a frame that the
    # best hypothesis leaves >= relocalise_min_gain detections unexplained is associated
    # again with the robot's covariance inflated by an unmodelled disturbance of these
    # sigmas (m, deg), re-linearised at the pose it implies when that is refused (the
    # iterated EKF); kept when it then pairs that many more, and at least
    # relocalise_min_pairs. 0: off
    relocalise_sigma_m: float = field(default=0.0, metadata={"min": 0.0, "max": 100.0})
    relocalise_sigma_heading_deg: float = field(default=0.0, metadata={"min": 0.0, "max": 180.0})
    relocalise_min_gain: int = field(default=2, metadata={"min": 1, "max": 100})
    # pairings the disturbed hypothesis needs (and detections a frame needs to be tested on
    # its own): 3 (two landmarks fix a pose, a third checks it); 2 where the disturbance's
    # sigmas are small against the landmarks' spacing, so the prior tells them apart
    relocalise_min_pairs: int = field(default=3, metadata={"min": 2, "max": 100})
    # lamps the map must hold before the test runs (at least relocalise_min_pairs): with
    # just relocalise_min_pairs lamps an accepted hypothesis pairs the whole map, and
    # landmarks not yet mapped that stand like the mapped ones pass it; 0: min_pairs
    relocalise_min_lamps: int = field(default=0, metadata={"min": 0, "max": 1000})
    # frames with fewer than relocalise_min_pairs detections: their unexplained ones are
    # pooled over this window (s) of odometry and the test run on the pool; 0: each
    # frame on its own
    relocalise_window_s: float = field(default=0.0, metadata={"min": 0.0, "max": 60.0})
    tentative_hits: int = field(default=3, metadata={"min": 1})
    tentative_radius: float = field(default=0.3, metadata={"min": 0.01, "max": 10.0})
    tentative_timeout: float = field(default=2.0, metadata={"min": 0.0})
    # a frame arriving after the odometry has been silent for longer than this (s) is not
    # used (counted: frames_stale_odometry): the robot may have moved since the last
    # increment, so its detections would be compared with a stale pose (duplicates)
    odometry_stale_s: float = field(default=1.0, metadata={"min": 0.01, "max": 1000.0})
    # odometry latency (s): the motion of an increment stamped t happens at t + this
    # (commanded or filtered wheel velocities lead the wheels; slam/latency.py)
    odometry_delay_s: float = field(default=0.0, metadata={"min": 0.0, "max": 5.0})
    # outputs: trajectory rows at least this far apart (s) between camera updates
    record_period: float = field(default=0.2, metadata={"min": 0.0})
    # /slam/landmarks MarkerArray period in estimates.mcap (s)
    landmarks_period: float = field(default=10.0, metadata={"min": 0.01})

    @property
    def odometry_noise(self) -> tuple[float, float, float, float]:
        """(k_tt, k_tr, k_rr, k_rt) of ``ekf.motion_noise``."""
        return (
            self.trans_var_per_m,
            self.trans_var_per_rad,
            self.rot_var_per_rad,
            self.rot_var_per_m,
        )

    def detection_cov(self, z: np.ndarray) -> np.ndarray:
        """(m, 2, 2) covariances of detections z (m, 2) in the robot frame (docstring):
        R = J diag(sigma_r^2, sigma_b^2) J^T with J = [[cos b, -r sin b], [sin b, r cos b]],
        i.e. sigma_r^2 along the line of sight and (r sigma_b)^2 across it.

        Parameters
        ----------
        z : ndarray, shape (m, 2)
            Detections (robot frame, m).

        Returns
        -------
        ndarray, shape (m, 2, 2)
        """
        r, u = _line_of_sight(z)
        sr = self.detection_sigma_range + self.detection_sigma_range_per_m * r
        st = r * np.deg2rad(self.detection_sigma_bearing_deg)
        along = u[:, :, None] * u[:, None, :]
        return sr[:, None, None] ** 2 * along + st[:, None, None] ** 2 * (np.eye(2) - along)

    def detection_cov_floored(self, z: np.ndarray, own: np.ndarray) -> tuple[np.ndarray, int]:
        """Covariances of detections some of which carry their own
        (``detection_own_covariance``): with ``floor``, each own C is raised to at least
        the model's variance along the line of sight u and across it n,

            C' = C + max(0, sigma_r^2 - u^T C u) u u^T + max(0, (r sigma_b)^2 - n^T C n) n n^T,

        which adds positive semidefinite terms only (C' >= C, and C' = C where C already
        holds the model's); with ``use`` C as it is; with ``model`` the model's
        (:meth:`detection_cov`). Without an own covariance (NaN), the model's.

        Parameters
        ----------
        z : ndarray, shape (m, 2)
            Detections (robot frame, m).
        own : ndarray, shape (m, 2, 2)
            Their own covariances, NaN where they carry none.

        Returns
        -------
        cov : ndarray, shape (m, 2, 2)
        floored : int
            How many own covariances were raised.
        """
        cov = self.detection_cov(z)
        has = np.all(np.isfinite(own), axis=(1, 2))
        if self.detection_own_covariance == "model" or not np.any(has):
            return cov, 0
        c = np.array(own[has], dtype=float)
        if self.detection_own_covariance == "floor":
            u = _line_of_sight(z)[1][has]
            n = np.stack([-u[:, 1], u[:, 0]], axis=1)
            model = cov[has]
            raised = 0
            for d in (u, n):
                short = np.maximum(0.0, _quad(model, d) - _quad(c, d))
                c += short[:, None, None] * (d[:, :, None] * d[:, None, :])
                raised = raised | (short > 0)
            floored = int(np.count_nonzero(raised))
        else:
            floored = 0
        cov[has] = c
        return cov, floored


def _line_of_sight(z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Ranges (m,) and unit lines of sight (m, 2) of detections z (m, 2); (1, 0) at 0."""
    z = np.asarray(z, dtype=float).reshape(-1, 2)
    r = np.hypot(z[:, 0], z[:, 1])
    with np.errstate(invalid="ignore", divide="ignore"):
        u = np.where(r[:, None] > 0, z / r[:, None], np.array([1.0, 0.0]))
    return r, u


def _quad(c: np.ndarray, d: np.ndarray) -> np.ndarray:
    """d_k^T C_k d_k for (m, 2, 2) C and (m, 2) d."""
    return np.einsum("ki,kij,kj->k", d, c, d)
