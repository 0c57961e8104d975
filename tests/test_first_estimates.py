"""First-estimates Jacobians (FEJ, ``slam.first_estimates``): the EKF-SLAM's global heading
stays unobservable, so the filter is not overconfident (``EkfSlam.first_estimate_motion``).

The simulated world: a robot driving a circle of radius 2 m among point landmarks on a
circle of radius 3.5 m, seen (as points in the robot frame, with white noise) within 3 m,
its true motion the odometry plus the filter's own motion noise (``motion_noise``), the
landmarks' correspondences known: whatever the filters do differently comes from their
Jacobians alone.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import chi2

from fuzzyslam.robot import motion_step
from fuzzyslam.se2 import wrap_angle
from fuzzyslam.slam.ekf import EkfSlam, lamp_measurement
from fuzzyslam.slam.motion import motion_noise


def _drive(ekf, rng, steps, noise, sz, n_lamps=6, truth=None):
    """Drive the circle; yield (true pose, filter) after each step's updates."""
    ang = np.linspace(0.0, 2.0 * np.pi, n_lamps, endpoint=False)
    lamps = np.c_[3.5 * np.cos(ang), 3.5 * np.sin(ang)]
    xt = np.array([2.0, 0.0, np.pi / 2]) if truth is None else truth
    ids: dict[int, int] = {}
    for _ in range(steps):
        dt, dr = 0.05, 0.025
        sd = np.sqrt(np.diag(motion_noise(dt, dr, noise)))
        xt = motion_step(xt, *(np.array([dt, dr]) + sd * rng.standard_normal(2)))
        ekf.predict(dt, dr)
        c, s = np.cos(xt[2]), np.sin(xt[2])
        z = (lamps - xt[:2]) @ np.array([[c, -s], [s, c]])  # R^T (l - p)
        z += sz * rng.standard_normal(z.shape)
        seen = np.flatnonzero(np.hypot(z[:, 0], z[:, 1]) < 3.0)
        known = [j for j in seen if j in ids]
        if known:
            r = np.kron(np.eye(len(known)), sz**2 * np.eye(2))
            ekf.update_lamps([ids[j] for j in known], z[known], r)
        for j in seen:
            if j not in ids:
                ids[j] = ekf.add_lamp(z[j], sz**2 * np.eye(2))
        yield xt, ekf


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_the_heading_variance_never_falls_below_its_prior_with_first_estimates(seed):
    """Nothing the robot measures (odometry, landmarks relative to it) tells the map's
    global heading, so the heading's variance cannot fall below the start pose's: the FEJ
    filter's never does; the standard EKF's falls to a third to a half of it, information
    that its linearisation made up (Huang, Mourikis and Roumeliotis, ICRA 2008)."""
    noise, sz, s0 = (1e-3, 0.0, 1e-3, 2e-3), 0.05, 0.1
    low = {}
    for fej in (False, True):
        ekf = EkfSlam([2.0, 0.0, np.pi / 2], np.diag([1e-6, 1e-6, s0**2]), noise,
                      first_estimates=fej)  # fmt: skip
        rng = np.random.default_rng(seed)
        low[fej] = min(np.sqrt(e.P[2, 2]) for _, e in _drive(ekf, rng, 300, noise, sz))
        p = ekf.P
        assert np.allclose(p, p.T) and np.linalg.eigvalsh(p).min() > 0.0
    assert low[True] >= s0 * (1.0 - 1e-9)
    assert low[False] < 0.6 * s0


def _pose_nees(fej: bool, runs: int, steps: int, seed: int) -> np.ndarray:
    noise, sz = (2e-3, 0.0, 5e-3, 1.5e-2), 0.1
    nees = np.zeros((runs, steps))
    rng = np.random.default_rng(seed)  # the same draws for both filters: a paired test
    for k in range(runs):
        ekf = EkfSlam([2.0, 0.0, np.pi / 2], np.diag([1e-8] * 3), noise, first_estimates=fej)
        for i, (xt, e) in enumerate(_drive(ekf, rng, steps, noise, sz, n_lamps=8)):
            err = xt - e.pose
            err[2] = wrap_angle(err[2])
            nees[k, i] = err @ np.linalg.solve(e.pose_cov, err)
    return nees.mean(axis=0)


@pytest.mark.slow
def test_monte_carlo_pose_nees_is_consistent_with_first_estimates():
    """40 Monte Carlo runs of 600 steps (30 m, two laps), the same draws for both
    filters: the pose NEES averaged over the runs, then over the last half of the steps,
    within the two-sided 95 % band of chi2(3 * 40) / 40 for the FEJ filter (3.14
    measured) and larger for the standard EKF (3.65): the consistency result of Huang et
    al. (2008) with this filter's own prediction, update and landmark initialisation.
    (With twice the noise both exceed the band, FEJ less: 4.1-4.3 against 4.5-5.4 over
    three seeds; the linearisation errors then show in both.)"""
    runs, steps = 40, 600
    hi = chi2.ppf(0.975, 3 * runs) / runs
    lo = chi2.ppf(0.025, 3 * runs) / runs
    fej = _pose_nees(True, runs, steps, 4)[steps // 2 :].mean()
    std = _pose_nees(False, runs, steps, 4)[steps // 2 :].mean()
    assert lo <= fej <= hi, (fej, lo, hi)
    assert std > fej + 0.25, (std, fej)


def _pair():
    args = ([0.0, 0.0, 0.3], np.diag([1e-4, 1e-4, 1e-3]), (1e-3, 0.0, 1e-3, 1e-3))
    return EkfSlam(*args, first_estimates=True), EkfSlam(*args)


def test_the_jacobians_are_taken_at_the_first_estimates():
    """H's heading column at the lamp's first estimate (the other columns as the
    standard EKF's); the motion Jacobian's heading column between the two predicted
    positions p_(k+1|k) - p_(k|k-1); before the first update both filters are one."""
    fej, std = _pair()
    for e in (fej, std):
        e.add_lamp([2.0, 0.5], 1e-2 * np.eye(2))
        e.predict(0.5, 0.1)
    first = fej.lamps[0].copy()
    predicted = fej.pose[:2].copy()  # p_(k|k-1)
    assert np.array_equal(fej.P, std.P) and np.array_equal(fej.x, std.x)
    for e in (fej, std):
        e.update_lamp(0, [1.6, 0.2], 1e-2 * np.eye(2))
    assert np.array_equal(fej.x, std.x)  # the lamp has not moved yet: the same update
    assert not np.allclose(fej.lamps[0], first)
    _, _, hc = fej.predict_lamps([0])
    _, hr, hl = lamp_measurement(fej.pose, fej.lamps[0])
    _, hr_first, _ = lamp_measurement(fej.pose, first)
    assert np.allclose(hc[:, :2], hr[:, :2]) and np.allclose(hc[:, 3:], hl)
    assert np.allclose(hc[:, 2], hr_first[:, 2]) and not np.allclose(hc[:, 2], hr[:, 2])
    # individual compatibility: the same S as H P H^T + R with that H
    r = 1e-2 * np.eye(2)
    z = np.array([[1.5, 0.3]])
    h, cols, hc = fej.predict_lamps([0])
    s = fej.innovation_cov(cols, hc, r)
    v = z[0] - h
    assert np.isclose(fej.individual_compatibility(z, r)[0, 0], v @ np.linalg.solve(s, v))
    # the next prediction's Jacobian
    a = np.eye(3)
    a[:2, 2] = [-0.7, 0.2]  # the standard column: replaced
    fej._x[:2] += [0.3, 0.4]  # as a prediction leaves the state before its Jacobian
    out = fej.first_estimate_motion(a)
    d = fej.pose[:2] - predicted
    assert np.allclose(out[:2, 2], [-d[1], d[0]])
    assert np.array_equal(out[:, :2], a[:, :2]) and a[0, 2] == -0.7  # a copy
    # no update since: the standard column again (p_(k|k) = p_(k|k-1))
    fej._x[:2] += [-0.05, -0.1]
    a[:2, 2] = [0.1, -0.05]  # (-dy, dx) of that motion
    assert np.allclose(fej.first_estimate_motion(a), a)


def test_an_inflated_robot_restarts_the_linearisation():
    """After ``inflate_robot`` (an unmodelled disturbance) the next prediction takes the
    standard motion Jacobian and the lamps' current estimates become their first ones."""
    ekf = EkfSlam([0.0, 0.0, 0.0], np.diag([1e-4, 1e-4, 1e-3]), (1e-3, 0.0, 1e-3, 1e-3),
                  first_estimates=True)  # fmt: skip
    ekf.add_lamp([2.0, 0.5], 1e-2 * np.eye(2))
    ekf.predict(0.5, 0.0)
    ekf.inflate_robot(np.diag([0.1, 0.1, 0.1]))
    ekf.update_lamp(0, [1.2, 0.9], 1e-2 * np.eye(2))
    moved = ekf.lamps[0].copy()
    a = np.eye(3)
    a[:2, 2] = [-0.25, 0.5]
    ekf._x[:2] += [0.5, 0.0]
    assert np.array_equal(ekf.first_estimate_motion(a), a)
    _, _, hc = ekf.predict_lamps([0])
    _, hr, _ = lamp_measurement(ekf.pose, moved)
    assert np.allclose(hc[:, 2], hr[:, 2])
