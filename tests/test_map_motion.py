"""Landmark motion against the landmarks' covariances (slam/map_motion.py)."""

from __future__ import annotations

import numpy as np

from fuzzyslam.se2 import inverse_transform_points
from fuzzyslam.slam.ekf import EkfSlam
from fuzzyslam.slam.map_motion import MapMotionMonitor, landmark_motion

NOISE = (0.01, 0.005, 0.01, 0.02)


def test_landmark_motion_is_the_mahalanobis_distance():
    rng = np.random.default_rng(0)
    n = 50
    a = rng.normal(size=(n, 2, 2))
    cb = a @ np.swapaxes(a, 1, 2) * 0.01
    g = rng.normal(size=(n, 2, 2))
    ca = cb + g @ np.swapaxes(g, 1, 2) * 0.02  # P_a - P_b positive definite
    la, lb = rng.normal(size=(n, 2)), rng.normal(size=(n, 2))
    got = landmark_motion(la, ca, lb, cb, 0.01)
    c = ca - cb + np.eye(2) * 1e-4
    want = np.einsum("ki,kij,kj->k", lb - la, np.linalg.inv(c), lb - la)
    assert np.allclose(got, want, rtol=1e-9)
    # a covariance that grew (P_b > P_a beyond the floor): impossible for a static state
    assert np.isinf(landmark_motion(la[:1], cb[:1], lb[:1], ca[:1], 0.0))[0]


def _ekf_with_lamps(rng, lamps):
    ekf = EkfSlam(np.zeros(3), np.diag([1e-6, 1e-6, 1e-6]), NOISE, capacity=8)
    r = np.diag([0.1**2, 0.05**2])
    for lm in lamps:
        z = inverse_transform_points(ekf.pose, lm[None])[0] + rng.normal(size=2) * [0.1, 0.05]
        ekf.add_lamp(z, r)
    return ekf, r


def test_a_consistent_filter_keeps_its_map_within_bounds_and_a_dragged_map_is_flagged():
    """The real filter, a robot that drives a little and re-observes 6 static landmarks
    with noise drawn from its own model: no window out of bounds in 60; the same map then
    moved as a whole by 5 of its sigmas twice: divergence at the second window."""
    rng = np.random.default_rng(7)
    lamps = np.array([[3.0, 0.0], [3.0, 0.2], [2.0, 2.5], [-1.0, 3.0], [-2.0, -2.0], [1.0, -3]])
    ekf, r = _ekf_with_lamps(rng, lamps)
    truth = np.zeros(3)
    mon = MapMotionMonitor(window_s=1.0)
    t = 0.0
    for _ in range(600):
        ds, dr = 0.01, 0.02 * np.sin(t)
        ekf.predict(ds, dr)
        step = [ds * np.cos(truth[2] + dr / 2), ds * np.sin(truth[2] + dr / 2), dr]
        truth = truth + np.array(step)
        z = inverse_transform_points(truth, lamps) + rng.normal(size=lamps.shape) * [0.1, 0.05]
        ekf.update_lamps(np.arange(6), z, np.kron(np.eye(6), r))
        t += 0.1
        if mon.due(t):
            mon.observe(t, ekf.lamps, ekf.lamp_covs())
    assert mon.windows >= 55 and mon.out_of_bounds == 0 and mon.diverged_at is None
    lamps_now, covs = ekf.lamps, ekf.lamp_covs()
    sigma = np.sqrt(covs[:, 0, 0])[:, None]
    mon.observe(t + 1, lamps_now + 5 * sigma, covs)
    assert mon.out_of_bounds == 1 and mon.diverged_at is None
    mon.observe(t + 2, lamps_now + 10 * sigma, covs)
    assert mon.out_of_bounds == 2 and mon.diverged_at == t + 2
