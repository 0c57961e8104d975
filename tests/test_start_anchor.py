"""The map's first lamps born at their first sighting (slam/start_anchor.py), on the real
SlamRunner and EkfSlam: the rewound filter against a second, straight-line construction;
the lamps anchored to the start pose where the confirming frame's pose has drifted; an
update before the first birth moves the snapshot to the next frame."""

from __future__ import annotations

import numpy as np
import pytest

from fuzzyslam import se2
from fuzzyslam.robot import motion_step
from fuzzyslam.slam import calibration as cal
from fuzzyslam.slam.ekf import EkfSlam, Preintegrator, lamp_init
from fuzzyslam.slam.params import SlamParams
from fuzzyslam.slam.runner import Frame, Odom, RingEvent, SlamRunner

LAMPS = np.array([[0.3, 0.4], [2.0, -0.5], [2.4, 0.6]])  # world (m)
R = np.eye(2) * 0.002**2
DRIFT = 0.0006  # rad of unseen heading error per odometry step: 4.8 mrad in 0.4 s


def drive(runner, t_end=0.4, aid_at=None):
    """Straight at 0.3 m/s from the origin; odometry (20 Hz) reports a turn the robot did
    not make (DRIFT per step); frames (5 Hz, from t = 0) see LAMPS exactly from the true
    pose. Returns the frames' detections and the odometry increments."""
    truth, frames, incs = np.zeros(3), [], []
    for k in range(round(t_end / 0.05) + 1):
        t = 0.05 * k
        if k:
            truth = motion_step(truth, 0.015, 0.0)
            incs.append((0.015, DRIFT))
            runner.odometry(Odom(t, 0.015, DRIFT))
        if aid_at is not None and abs(t - aid_at) < 1e-9:
            runner.ring(RingEvent(t, None))
        if k % 4 == 0:
            z = se2.inverse_transform_points(truth, LAMPS)
            runner.frame(Frame(t, z, np.repeat(R[None], len(z), axis=0)))
            frames.append(z)
    return frames, incs


def reference(params, frames, incs, calibration=None):
    """The filter that made the lamps landmarks at t = 0, written out: the start pose,
    add_lamp from the first frame's detections, one prediction of all the odometry."""
    cm = calibration
    ekf = EkfSlam(
        np.zeros(3),
        np.diag(np.square(params.start_sigma)),
        params.odometry_noise,
        calib=None if cm is None else cm.factors,
        calib_cov=None if cm is None else cm.cov,
    )
    for z in frames[0]:
        ekf.add_lamp(z, R)
    if cm is None:
        pre = Preintegrator(params.odometry_noise)
        for inc in incs:
            pre.add(*inc)
        ekf.predict_relative(pre.delta, pre.q)
    else:
        pre = cal.CalibratedPreintegrator(params.odometry_noise, cm)
        pre.reset(ekf.calib)
        for inc in incs:
            pre.add(*inc)
        ekf.predict_relative(pre.delta, pre.q_calib(ekf.calib_cov), pre.d_calib)
        cal.diffuse(ekf, cm.var_per_m * pre.dist + cm.var_per_rad * pre.turn)
    return ekf


@pytest.mark.parametrize("calibrate", [False, True])
def test_first_lamps_born_at_first_sighting_equal_rewound_filter(calibrate):
    p = SlamParams(tentative_hits=3, calibrate=calibrate)
    cm = cal.prior("wheels", p, 0.4) if calibrate else None
    runner = SlamRunner(p, np.zeros(3), calibration=cm)
    frames, incs = drive(runner)  # confirmed by the frame at 0.4 s
    assert runner.ekf.n_lamps == len(LAMPS) and runner.counts["lamps_created"] == len(LAMPS)
    ref = reference(p, frames, incs, cm)
    np.testing.assert_allclose(runner.ekf.x, ref.x, rtol=0, atol=1e-12)
    np.testing.assert_allclose(runner.ekf.P, ref.P, rtol=0, atol=1e-15)
    np.testing.assert_allclose(runner.ekf.odometry_pose, ref.odometry_pose, atol=1e-12)


def test_first_lamps_anchored_to_start_pose_not_to_drifted_pose():
    p = SlamParams(tentative_hits=3)
    runner = SlamRunner(p, np.zeros(3))
    frames, _ = drive(runner)
    # born at t = 0 from the exact start pose: at their true places
    assert np.abs(runner.ekf.lamps - LAMPS).max() < 1e-9
    # the confirming frame's pose carries 4.8 mrad of heading drift: lamps born from it
    # would sit up to 1.1 cm off (range 2.3 m)
    late = np.array([lamp_init(runner.ekf.pose, z)[0] for z in frames[-1]])
    assert np.abs(late - LAMPS).max() > 0.008
    # and the filter's heading still has the drift (nothing has observed it yet)
    assert runner.ekf.pose[2] == pytest.approx(8 * DRIFT, abs=1e-9)


class _HeadingAid:
    """A fix aid that applies one heading measurement (the true heading, 0)."""

    start_time = 0.0

    def on_ring(self, t, ring, mounts, ekf):
        ekf.update_robot([0.0], [[1e-4]], [2], gate_chi2=1e6)


def test_update_before_first_birth_moves_the_snapshot():
    """A heading update at 0.1 s drops the snapshot of the frame at 0 s (it would no
    longer rewind exactly): the lamps confirmed at 0.4 s are born from the next frame's
    sightings (0.2 s), at the filter's pose there, not from the confirming frame's."""
    p = SlamParams(tentative_hits=3)
    runner = SlamRunner(p, np.zeros(3), aids=[_HeadingAid()])
    poses, frame = {}, runner.frame

    def spy(ev):
        runner.flush()
        poses[round(ev.t, 2)] = runner.ekf.pose
        frame(ev)

    runner.frame = spy
    frames, _ = drive(runner, aid_at=0.1)
    assert runner.ekf.n_lamps == len(LAMPS)
    at = {t: np.array([lamp_init(poses[t], z)[0] for z in frames[k]]) for k, t in
          enumerate((0.0, 0.2, 0.4))}  # fmt: skip
    np.testing.assert_allclose(runner.ekf.lamps, at[0.2], rtol=0, atol=1e-12)
    assert np.abs(at[0.4] - at[0.2]).max() > 1e-3 and np.abs(at[0.0] - at[0.2]).max() > 1e-4
