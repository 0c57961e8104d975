"""A live-map run's check of the building's right angles (fixes.live_map.
LiveRightAngleHeading._walls_seen): the angle between one scan's two wall families, which
the heading's error does not enter, tells a building whose corridors are a few degrees
off its right angles (the summary's off_right_angles_at and a line on stderr naming
fixes.live_right_angles), and never one whose walls meet square.

The real aid and the real EKF on analytic laser scans (maps_synth).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from maps_synth import corridor_lines, ring_in_lines

from fuzzyslam.config import load_config
from fuzzyslam.fixes.live_map import OFF_MIN, LiveRightAngleHeading
from fuzzyslam.fixes.scan_heading import scan_segments
from fuzzyslam.slam.ekf import EkfSlam
from fuzzyslam.streams.sonar import Ring

DEG = math.pi / 180.0
# a laser of 180 beams over 180 deg (1 deg apart), 2-deg cones, 20 m
BEAMS = np.linspace(-math.pi / 2, math.pi / 2, 180)
MOUNTS = np.stack([np.zeros(180), np.zeros(180), BEAMS], axis=1)
FOV = 2.0 * DEG
RMAX = 20.0
STEP = 0.1  # m of travel per scan
Q = np.diag([0.01**2, 0.01**2, (0.2 * DEG) ** 2])  # the odometry's noise per step


def _hall(skew_deg: float) -> np.ndarray:
    """A corridor along x (walls at y = +-1.2 m) ending in a wall at x = 30 m that
    meets it ``skew_deg`` off a right angle (maps_synth's lines: free side n.p < c)."""
    a = skew_deg * DEG
    return np.vstack([corridor_lines(0.0, 1.2), [[math.cos(a), math.sin(a), 30.0]]])


def _ring(t: float, pose, lines) -> Ring:
    ranges = ring_in_lines(np.asarray(pose, float), MOUNTS, lines, FOV, RMAX)
    return Ring(t=t, ranges=ranges, max_range=np.full(len(ranges), RMAX), fov=FOV)


@pytest.mark.parametrize("heading_error_deg", [0.0, 2.5, -4.0])
def test_one_scan_measures_the_corner_whatever_the_heading(heading_error_deg):
    """A scan seeing the side walls and the end wall: counted, and off only when the end
    wall is more than 3 deg off square, with the filter's heading right or a few degrees
    wrong (the two families' angle does not depend on it)."""
    params = load_config("real_building_scan").fixes
    pose = np.array([20.0, 0.3, 0.05])
    for skew, off in ((0.0, 0), (2.0, 0), (6.0, 1), (-5.0, 1)):
        aid = LiveRightAngleHeading(params)
        aid.reference_angle = 0.0
        segs = scan_segments(_ring(1.0, pose, _hall(skew)), MOUNTS, aid.params)
        aid._walls_seen(1.0, segs, pose[2] + heading_error_deg * DEG, (1.0 * DEG) ** 2)
        assert aid.right_angle_scans == 1, skew
        assert aid.off_right_angle_scans == off, skew


def _drive(skew_deg: float) -> tuple[LiveRightAngleHeading, EkfSlam]:
    """Learn the building over the corridor's first metres, then drive on towards the
    end wall (in view from x = 10 m) to x = 25 m, odometry perfect."""
    aid = LiveRightAngleHeading(load_config("real_building_scan").fixes)
    ekf = EkfSlam(np.zeros(3), np.diag([1e-4, 1e-4, (0.1 * DEG) ** 2]), (0.0, 0.0, 0.0, 0.0))
    lines = _hall(skew_deg)
    for k in range(1, 251):
        ekf.predict_relative(np.array([STEP, 0.0, 0.0]), Q)
        aid.on_ring(float(k), _ring(float(k), [k * STEP, 0.0, 0.0], lines), MOUNTS, ekf)
    return aid, ekf


def test_a_building_off_its_right_angles_is_told():
    """The end wall 6 deg off: once OFF_MIN scans have seen it so, the summary says when
    and the run's note names the setting; the fixes go on (the aid does not know which
    corridor is off). Square, nothing is said."""
    aid, ekf = _drive(6.0)
    assert aid.learnt_at is not None and aid.learnt_at < 100  # within the first 10 m
    assert aid.off_right_angles_at is not None
    first = aid.decisions[0].t
    assert (
        aid.off_right_angle_scans > OFF_MIN and aid.right_angle_scans == aid.off_right_angle_scans
    )
    s = aid.summary()
    assert s.off_right_angles_at == aid.off_right_angles_at
    assert s.off_right_angle_scans == aid.off_right_angle_scans
    note = aid.run_note(False)
    assert "fixes.live_right_angles: false" in note
    assert f"{aid.off_right_angle_scans} of {aid.right_angle_scans} scans" in note
    assert aid.decisions[-1].t == 250.0 and first < aid.off_right_angles_at
    square, _ = _drive(0.0)
    assert square.off_right_angles_at is None and square.run_note(False) == ""
    assert square.right_angle_scans > 50 and square.off_right_angle_scans == 0
    assert square.decisions[-1].t == 250.0 and square.summary().accepted > 190
    assert abs(ekf.x[2]) < 5.0 * DEG  # the heading fixes ran to the end
