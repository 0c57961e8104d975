"""Sonar rings among obstacles traced a block at a time equal the rings traced one by one
(the simulation's bytes must not depend on the batching)."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from fuzzyslam.se2 import interpolate_pose
from fuzzyslam.sim import sonar
from fuzzyslam.sim.obstacles import Track, box_polygon, box_segments, discs_at
from fuzzyslam.sim.params import SonarParams
from fuzzyslam.sim.record import _ideal_block

ROOM = np.array([[-6, -4, 6, -4], [6, -4, 6, 4], [6, 4, -6, 4], [-6, 4, -6, -4]], float)


def _mounts(m: int = 16) -> np.ndarray:
    a = np.linspace(0.0, 2 * np.pi, m, endpoint=False)
    return np.column_stack([0.2 * np.cos(a), 0.2 * np.sin(a), a])


def test_people_per_ring_traced_together_equal_one_by_one():
    rng = np.random.default_rng(3)
    mounts = _mounts()
    poses = np.column_stack([rng.uniform(-5, 5, (30, 2)), rng.uniform(-np.pi, np.pi, 30)])
    # three people per ring, near the robot so that many rays meet one first
    people = np.concatenate(
        [poses[:, None, :2] + rng.uniform(-1.5, 1.5, (30, 3, 2)), np.full((30, 3, 1), 0.25)],
        axis=2,
    )
    for params in (SonarParams(), SonarParams(rays_per_cone=1, max_bounces=0)):
        many = sonar.ideal_ranges_many(ROOM, poses, mounts, params, people)
        one = np.array([sonar.ideal_ranges(ROOM, sonar.sensor_poses(p, mounts), params, d)
                        for p, d in zip(poses, people, strict=True)])  # fmt: skip
        assert np.array_equal(many, one)
        walls_only = sonar.ideal_ranges_many(ROOM, poses, mounts, params)
        assert (many < walls_only).mean() > 0.1  # the people are seen


def test_ideal_block_stops_where_the_obstacles_change():
    box = box_polygon([1.0, 0.5], [0.6, 0.5], 0.0)
    tracks = [
        Track(0, "box", 2.0, 6.0, box, 0.0, np.zeros((0, 2)), 0.0),
        Track(1, "disc", 2.0, 6.0, np.zeros((0, 2)), 0.25,
              np.array([[-4.0, 0.0], [4.0, 0.0]]), 0.6),
        Track(2, "disc", 4.0, 9.0, np.zeros((0, 2)), 0.3,
              np.array([[0.0, -3.0], [0.0, 3.0]]), 0.5),
    ]  # fmt: skip
    t = np.linspace(0.0, 12.0, 121)
    pose = np.column_stack([np.linspace(-4, 4, 121), 0.3 * np.sin(t), 0.1 * t])
    dr = SimpleNamespace(t=t, pose=pose)
    mounts, params = _mounts(), SonarParams()
    times = np.arange(0.0, 11.0, 0.25)
    rows, i = [], 0
    while i < len(times):
        block = _ideal_block(dr, times[i : i + 32, None], ROOM, mounts, params, tracks)
        first = [tr.present(times[i]) for tr in tracks]
        # a block never spans a change of the obstacles present
        assert all([tr.present(s) for tr in tracks] == first for s in times[i : i + len(block)])
        rows.append(block)
        i += len(block)
    got = np.concatenate(rows)
    ref = np.array([
        sonar.ideal_ranges(np.vstack([ROOM, box_segments(tracks, s)]),
                           sonar.sensor_poses(interpolate_pose(t, pose, s), mounts), params,
                           discs_at(tracks, s))
        for s in times.tolist()
    ])  # fmt: skip
    assert np.array_equal(got, ref)
    assert len(rows) >= 4  # 0-2 s, 2-4 s, 4-6 s, 6-9 s, 9-11 s


def test_sonars_fired_in_sequence_see_the_people_where_they_are_as_each_fires():
    """A ring fired in sequence (``sonar.firing_gap_s``): sonar j of ring k is traced from
    the robot's pose and among the people (those of the ring's first firing) at its own
    firing time, equal to tracing it alone (``ideal_ranges`` of one sensor); the people
    walking at 0.6 m/s move up to 0.36 m during the ring."""
    from fuzzyslam.se2 import compose

    tracks = [
        Track(1, "disc", 0.0, 12.0, np.zeros((0, 2)), 0.25,
              np.array([[-4.0, 0.5], [4.0, 0.5]]), 0.6),
        Track(2, "disc", 0.0, 12.0, np.zeros((0, 2)), 0.3,
              np.array([[0.5, -3.0], [0.5, 3.0]]), 0.6),
    ]  # fmt: skip
    t = np.linspace(0.0, 12.0, 121)
    pose = np.column_stack([np.linspace(-3, 3, 121), 0.3 * np.sin(t), 0.2 * t])
    dr = SimpleNamespace(t=t, pose=pose)
    mounts, params = _mounts(), SonarParams(firing_gap_s=0.04)
    fire = np.arange(0.5, 10.0, 1.0)[:, None] + 0.04 * np.arange(16)
    got = _ideal_block(dr, fire, ROOM, mounts, params, tracks)
    ref = np.array([[
        sonar.ideal_ranges(ROOM, compose(interpolate_pose(t, pose, s), m)[None], params,
                           discs_at(tracks, s, row[0]))[0]
        for s, m in zip(row, mounts, strict=True)] for row in fire.tolist()
    ])  # fmt: skip
    assert got.shape == fire.shape and np.array_equal(got, ref)
    moved = np.hypot(*(discs_at(tracks, fire[0, -1]) - discs_at(tracks, fire[0, 0]))[:, :2].T)
    assert moved.max() > 0.3
