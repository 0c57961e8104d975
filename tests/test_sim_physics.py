"""Simulator physics against analytic answers: world, sonar, camera, encoders, driver."""

from __future__ import annotations

import dataclasses
import itertools

import cv2
import numpy as np
import pytest

from fuzzyslam.config import load_config
from fuzzyslam.se2 import wrap_angle
from fuzzyslam.sim import camera as simcam
from fuzzyslam.sim import sonar
from fuzzyslam.sim.encoders import (
    noisy_increments,
    quantise,
    simulate_encoders,
    true_wheel_increments,
)
from fuzzyslam.sim.params import Bump, CameraParams, RobotParams, ScenarioParams, SonarParams
from fuzzyslam.sim.path import drive
from fuzzyslam.sim.world import build_world, centreline_array, loop_length, point_at


@pytest.fixture(scope="module")
def paper():
    return load_config("paper")


# --- world -------------------------------------------------------------------------


def _dist_point_line(p, a, b):
    d = b - a
    return abs(d[0] * (p[1] - a[1]) - d[1] * (p[0] - a[0])) / np.linalg.norm(d)


def test_walls_are_offsets_of_the_centre_line(paper):
    world = build_world(paper.world, paper.camera)
    centre = centreline_array(paper.world)
    walls = world.wall_array
    n = len(centre)
    assert len(walls) == 2 * n
    half = paper.world.corridor_width / 2
    for i in range(n):
        a, b = centre[i], centre[(i + 1) % n]
        for w in (walls[i], walls[n + i]):  # left and right wall of edge i
            # both end points of the wall lie width/2 from the centre-line edge's line
            assert _dist_point_line(w[:2], a, b) == pytest.approx(half, abs=1e-9)
            assert _dist_point_line(w[2:], a, b) == pytest.approx(half, abs=1e-9)
            # and the wall is parallel to it
            e, f = w[2:] - w[:2], b - a
            cross = e[0] * f[1] - e[1] * f[0]
            assert abs(cross) < 1e-9 * np.linalg.norm(b - a) * np.linalg.norm(w[2:] - w[:2])


def test_corridor_axes_and_lamps(paper):
    world = build_world(paper.world, paper.camera)
    axes = np.array([c.axis for c in world.corridors])
    for c in world.corridors:
        a, b = np.array(c.a), np.array(c.b)
        expect = np.mod(np.arctan2(*(b - a)[::-1]), np.pi)
        assert c.axis == pytest.approx(expect)
    # at least one corridor neither parallel nor perpendicular to the first one
    rel = np.mod(axes - axes[0], np.pi / 2)
    assert np.any((rel > 0.1) & (rel < np.pi / 2 - 0.1))
    # lamps on the centre line, evenly spaced along it
    lamps = world.lamp_array
    assert len(lamps) == paper.world.lamp_count
    centre = centreline_array(paper.world)
    s = np.linspace(0, loop_length(centre), 20001)
    line, _ = point_at(centre, s)
    d = np.min(np.linalg.norm(lamps[:, None, :] - line[None], axis=2), axis=1)
    assert d.max() < 2e-3
    spacing = loop_length(centre) / len(lamps)
    idx = np.argmin(np.linalg.norm(lamps[:, None, :] - line[None], axis=2), axis=1)
    assert np.allclose(np.diff(s[idx]), spacing, atol=5e-3)


# --- sonar -------------------------------------------------------------------------

QUIET = SonarParams(noise_frac=0.0, quantization=0.0, crosstalk_prob=0.0)


@pytest.mark.slow
def test_sonar_head_on_reads_the_distance():
    walls = np.array([[3.0, -10.0, 3.0, 10.0]])
    mounts = np.array([[0.225, 0.0, 0.0]])
    pose = np.array([0.0, 0.4, 0.0])
    ideal = sonar.ideal_ranges(walls, sonar.sensor_poses(pose, mounts), QUIET)
    assert ideal[0] == pytest.approx(3.0 - 0.225, abs=1e-12)
    # with noise and quantisation: multiples of an inch, mean within 1 %, spread ~1 %
    p = SonarParams(crosstalk_prob=0.0)
    rng = np.random.default_rng(3)
    r = np.array([sonar.ring(walls, pose, mounts, p, rng)[0] for _ in range(3000)])
    assert np.allclose(r / p.quantization, np.round(r / p.quantization), atol=1e-9)
    assert r.mean() == pytest.approx(2.775, rel=0.002)
    expect_std = np.hypot(0.01 * 2.775, p.quantization / np.sqrt(12))
    assert r.std() == pytest.approx(expect_std, rel=0.1)


def test_sonar_beyond_critical_angle_reads_max_range():
    walls = np.array([[-10.0, 1.0, 10.0, 1.0]])  # one wall, y = 1
    half = QUIET.fov_deg / 2
    for extra in (1.0, 10.0, 30.0):
        incidence = QUIET.critical_angle_deg + half + extra  # every ray beyond the cut-off
        yaw = np.radians(90.0 - incidence)
        s = np.array([[0.0, 0.0, yaw]])
        assert np.isinf(sonar.ideal_ranges(walls, s, QUIET)[0])
        assert sonar.measure(sonar.ideal_ranges(walls, s, QUIET), QUIET, np.random.default_rng(0))[
            0
        ] == pytest.approx(QUIET.max_range)
    # just inside the cut-off the edge ray echoes at its own path length
    yaw = np.radians(90.0 - (QUIET.critical_angle_deg + half - 1.0))
    r = sonar.ideal_ranges(walls, np.array([[0.0, 0.0, yaw]]), QUIET)[0]
    assert r == pytest.approx(1.0 / np.cos(np.radians(QUIET.critical_angle_deg - 1.0)), rel=1e-9)


def test_sonar_specular_bounce_returns_long():
    # wall A (y = 1) hit at 45 deg, mirror to wall B normal to the reflected ray
    a = np.array([[-10.0, 1.0, 10.0, 1.0]])
    hit = np.array([1.0, 1.0])
    out = np.array([1.0, -1.0]) / np.sqrt(2)
    c = hit + 2.0 * out
    tang = np.array([1.0, 1.0]) / np.sqrt(2)
    b = np.array([[*(c - 3 * tang), *(c + 3 * tang)]])
    walls = np.vstack([a, b])
    s = np.array([[0.0, 0.0, np.pi / 4]])
    one_ray = dataclasses.replace(QUIET, rays_per_cone=1)
    assert sonar.ideal_ranges(walls, s, one_ray)[0] == pytest.approx(np.sqrt(2) + 2.0)
    cone = sonar.ideal_ranges(walls, s, QUIET)[0]
    assert cone > 3.0  # long: three times the true distance to wall A
    no_bounce = dataclasses.replace(QUIET, max_bounces=0)
    assert np.isinf(sonar.ideal_ranges(walls, s, no_bounce)[0])


def test_sonar_concave_corner_echoes_from_wide_angle():
    walls = np.array([[2.0, -5.0, 2.0, 2.0], [-5.0, 2.0, 2.0, 2.0]])  # corner at (2, 2)
    s = np.array([[0.0, 0.0, np.pi / 4]])  # 45 deg incidence on both walls
    r = sonar.ideal_ranges(walls, s, QUIET)[0]
    assert r == pytest.approx(2.0 * np.sqrt(2), rel=0.03)


def test_sonar_crosstalk_fraction():
    p = SonarParams(crosstalk_prob=0.1, noise_frac=0.0, quantization=0.0)
    rng = np.random.default_rng(1)
    r = np.concatenate([sonar.measure(np.full(16, 3.0), p, rng) for _ in range(2000)])
    short = np.mean(r < 2.9)
    expect = 0.1 * (2.9 - p.min_range) / (3.0 - p.min_range)
    assert short == pytest.approx(expect, abs=0.01)
    assert r.min() >= p.min_range and r.max() <= 3.0


# --- camera ------------------------------------------------------------------------


def _centroid(img: np.ndarray, bg: np.ndarray, thr: int = 128) -> np.ndarray:
    n, lab, _stats, _c = cv2.connectedComponentsWithStats((img >= thr).astype(np.uint8))
    assert n == 2, "expected exactly one blob"
    # intensity-weighted centroid of the blob grown by one pixel (covers the AA rim)
    mask = cv2.dilate((lab == 1).astype(np.uint8), np.ones((3, 3), np.uint8)) > 0
    w = np.where(mask, np.clip(img.astype(float) - bg, 0, None), 0.0)
    v, u = np.mgrid[0 : img.shape[0], 0 : img.shape[1]]
    return np.array([(w * u).sum() / w.sum(), (w * v).sum() / w.sum()])


def test_lamp_lands_on_the_analytic_pixel():
    params = CameraParams(noise_sigma=2.0)
    cam = simcam.make_camera(params)
    bg = simcam.background(cam, params)
    f = (params.width / 2) / np.tan(np.radians(params.hfov_deg) / 2)  # analytic focal length
    rng = np.random.default_rng(7)
    errs = []
    for _ in range(40):
        x, y = rng.uniform([-1.5, -1.0], [1.5, 1.0])
        img = simcam.render(cam, np.array([[x, y]]), 0.12, params, bg, rng)
        u = (params.width - 1) / 2 + f * x / params.ceiling_height
        v = (params.height - 1) / 2 + f * y / params.ceiling_height
        errs.append(_centroid(img, bg) - [u, v])
    errs = np.abs(np.array(errs))
    assert errs.max() < 0.15  # sub-pixel
    assert errs.mean() < 0.05


def test_disc_coverage_conserves_area_and_failed_lamp_is_dark():
    params = CameraParams()
    cam = simcam.make_camera(params)
    rpx = cam.radius_px(0.12)
    cov = simcam.coverage(cam, np.array([[40.3, 70.7]]), rpx, params.supersample)
    assert cov.min() >= 0.0 and cov.max() <= 1.0
    for r in (1.5, rpx, 6.0, 10.0):
        cov = simcam.coverage(cam, np.array([[40.3, 70.7]]), r, params.supersample)
        assert cov.sum() == pytest.approx(np.pi * r**2, rel=0.02)
    bg = simcam.background(cam, params)
    dark = simcam.render(cam, np.zeros((0, 2)), 0.12, params, bg, np.random.default_rng(0))
    assert dark.max() < params.background + 6 * params.noise_sigma



def test_disc_coverage_is_the_whole_canvas_box_filtered():
    """coverage() box-filters only the blocks under each disc: the same float32 bytes as
    drawing every disc on the whole supersampled canvas and resizing all of it, for discs
    inside, across and beyond the image edges and overlapping ones."""
    params = CameraParams()
    cam = simcam.make_camera(params)
    w, h = cam.width, cam.height_px
    rng = np.random.default_rng(5)
    for _ in range(60):
        k = int(rng.choice([1, 2, 3, 4]))
        rpx = float(rng.uniform(0.5, 15.0))
        uv = rng.uniform(-20.0, max(w, h) + 20.0, size=(int(rng.integers(1, 5)), 2))
        uv[0] = rng.uniform(0, 4, 2) if rng.random() < 0.3 else uv[0]  # near a corner
        canvas = np.zeros((h * k, w * k), np.uint8)
        s = float(1 << simcam.SHIFT)
        r = max(round((k * rpx - simcam.AA_RADIUS_EXCESS) * s), 1)
        for u, v in uv:
            if -rpx - 1 < u < w + rpx and -rpx - 1 < v < h + rpx:
                c = (round((k * (u + 0.5) - 0.5) * s), round((k * (v + 0.5) - 0.5) * s))
                cv2.circle(canvas, c, r, 255, -1, cv2.LINE_AA, simcam.SHIFT)
        whole = canvas.astype(np.float32)
        if k > 1:
            whole = cv2.resize(whole, (w, h), interpolation=cv2.INTER_AREA)
        got = simcam.coverage(cam, uv, rpx, k)
        assert got.dtype == np.float32 and got.tobytes() == (whole / 255.0).tobytes()


# --- encoders ----------------------------------------------------------------------


def test_encoder_noise_statistics_match_config():
    robot = RobotParams(wheel_noise=0.02)
    rng = np.random.default_rng(11)
    phi = np.full((200000, 2), 0.3)
    err = (noisy_increments(phi, robot.wheel_noise, rng) - phi) / np.sqrt(0.3)
    assert abs(err.mean()) < 4 * robot.wheel_noise / np.sqrt(err.size)
    assert err.std() == pytest.approx(robot.wheel_noise, rel=0.01)
    q = quantise(np.cumsum(phi[:, 0]), robot.ticks_per_rev)
    assert np.abs(q - np.cumsum(phi[:, 0])).max() <= np.pi / robot.ticks_per_rev + 1e-12


def test_encoder_systematic_errors_analytic():
    robot = RobotParams(wheel_noise=0.0, ticks_per_rev=10**9)
    n, step = 1000, 0.01  # 10 m straight
    enc = simulate_encoders(
        np.full(n, step), np.zeros(n), robot, np.zeros(3), np.random.default_rng(0)
    )
    dist = n * step
    left, right = dist / robot.left_scale, dist / robot.right_scale
    assert enc.d_trans.sum() == pytest.approx(0.5 * (left + right), rel=1e-6)
    assert enc.d_rot.sum() == pytest.approx((right - left) / robot.wheel_base, rel=1e-5)
    # turning in place by 2 pi: the nominal base is base_scale too short
    phi_l, phi_r = true_wheel_increments(np.zeros(1), np.array([2 * np.pi]), robot)
    d_rot = robot.wheel_radius * (phi_r * robot.right_scale - phi_l * robot.left_scale)
    assert d_rot[0] / robot.wheel_base == pytest.approx(2 * np.pi * robot.base_scale)


# --- driver ------------------------------------------------------------------------


@pytest.mark.slow
def test_drive_runs_alternate_and_bump_is_corrected(paper):
    centre = centreline_array(paper.world)
    scen = ScenarioParams(
        runs=2, lap_fraction=0.2, bumps=[Bump(run=1, fraction=0.3, angle_deg=10.0)]
    )
    dr = drive(centre, paper.robot, scen)
    kinds = [(e.kind, e.run, e.direction) for e in dr.events]
    assert kinds[0] == ("run_start", 1, 1)
    assert ("run_start", 2, -1) in kinds and kinds[-1][:2] == ("run_end", 2)
    bump = [e for e in dr.events if e.kind == "bump"]
    assert len(bump) == 1 and bump[0].angle == pytest.approx(np.radians(10.0))
    k = int(np.argmax(np.abs(dr.bump)))
    jump = wrap_angle(dr.pose[k + 1, 2] - dr.pose[k, 2] - dr.d_rot[k])
    assert jump == pytest.approx(np.radians(10.0), abs=1e-9)
    # back at the start after going out and back; the follower never leaves the corridor
    assert np.hypot(*(dr.pose[-1, :2] - dr.pose[0, :2])) < 0.05
    s = np.linspace(0, loop_length(centre), 5000)
    line, _ = point_at(centre, s)
    lateral = np.min(np.linalg.norm(dr.pose[:, None, :2] - line[None], axis=2), axis=1)
    assert lateral.max() < paper.world.corridor_width / 2 - paper.robot.radius
    # with the driver's sideways wander the path still stays well inside the corridor
    wander = drive(centre, paper.robot, ScenarioParams(runs=1), np.random.default_rng(2))
    lat = np.min(np.linalg.norm(wander.pose[::10, None, :2] - line[None], axis=2), axis=1)
    assert 0.1 < lat.max() < paper.world.corridor_width / 2 - paper.robot.radius
    assert np.hypot(*(wander.pose[-1, :2] - wander.pose[0, :2])) < 0.05
    # the speed limit holds
    assert np.all(np.abs(dr.d_trans) <= paper.robot.max_speed / paper.robot.rate_hz + 1e-12)


def test_too_wide_corridor_is_a_config_error(paper):
    from fuzzyslam.errors import ConfigError

    narrow = dataclasses.replace(
        paper.world, centerline=[[0.0, 0.0], [2.0, 0.0], [2.0, 1.5], [0.0, 1.5]]
    )
    build_world(dataclasses.replace(narrow, corridor_width=1.0), paper.camera)
    with pytest.raises(ConfigError, match="corridor_width"):
        build_world(dataclasses.replace(narrow, corridor_width=3.0), paper.camera)


def test_two_bumps_in_one_run(paper):
    centre = centreline_array(paper.world)
    scen = ScenarioParams(
        runs=1,
        lap_fraction=0.2,
        bumps=[Bump(run=1, fraction=0.6, angle_deg=-5.0), Bump(run=1, fraction=0.2)],
    )
    dr = drive(centre, paper.robot, scen)
    got = [np.degrees(e.angle) for e in dr.events if e.kind == "bump"]
    assert got == pytest.approx([10.0, -5.0])
    assert np.degrees(dr.bump.sum()) == pytest.approx(5.0)


def test_odometry_spread_matches_encoder_noise():
    """Through the whole encoder pipeline: var(sum d_trans) = (r/2)^2 2 s^2 Phi and
    var(sum d_rot) = (r/b)^2 2 s^2 Phi for a straight drive turning each wheel by Phi."""
    robot = RobotParams(left_scale=1.0, right_scale=1.0, base_scale=1.0, wheel_noise=0.02)
    n, step = 400, 0.015
    rng = np.random.default_rng(5)
    trans, rot = [], []
    for _ in range(400):
        enc = simulate_encoders(np.full(n, step), np.zeros(n), robot, np.zeros(3), rng)
        trans.append(enc.d_trans.sum())
        rot.append(enc.d_rot.sum())
    phi = n * step / robot.wheel_radius
    var_wheel = robot.wheel_noise**2 * phi
    r, b = robot.wheel_radius, robot.wheel_base
    assert np.mean(trans) == pytest.approx(n * step, abs=3 * np.sqrt(var_wheel) * r / 20)
    assert np.var(trans) == pytest.approx((r / 2) ** 2 * 2 * var_wheel, rel=0.2)
    assert np.var(rot) == pytest.approx((r / b) ** 2 * 2 * var_wheel, rel=0.2)


def test_interpolate_pose_wraps_heading():
    from fuzzyslam.sim.record import interpolate_pose, sensor_times

    t = np.array([0.0, 1.0])
    poses = np.array([[0.0, 0.0, np.pi - 0.1], [1.0, 2.0, -np.pi + 0.1]])
    mid = interpolate_pose(t, poses, 0.5)
    assert mid[:2] == pytest.approx([0.5, 1.0])
    assert abs(wrap_angle(mid[2] - np.pi)) < 1e-12  # through pi, not through 0
    ts = sensor_times(4.0, 1.0)
    assert ts == pytest.approx([0.0, 0.25, 0.5, 0.75, 1.0])


def test_laps_turn_once_around_and_headings_are_wrapped(paper):
    """Loop topology: a forward lap turns +360 deg, a backward lap -360 deg, a turnaround
    +-180 deg; stored headings stay in (-pi, pi]."""
    centre = centreline_array(paper.world)
    dr = drive(centre, paper.robot, ScenarioParams(runs=2), np.random.default_rng(0))
    assert np.all(dr.pose[:, 2] > -np.pi) and np.all(dr.pose[:, 2] <= np.pi)
    ks = [int(np.searchsorted(dr.t, e.t)) for e in dr.events]
    turns = np.degrees([dr.d_rot[a:b].sum() for a, b in itertools.pairwise(ks)])
    # events: start1, end1, start2, end2 -> lap 1, turnaround, lap 2
    assert turns[0] == pytest.approx(360.0, abs=15.0)
    assert abs(turns[1]) == pytest.approx(180.0, abs=15.0)
    assert turns[2] == pytest.approx(-360.0, abs=15.0)


def test_scalar_wrap_matches_se2():
    from fuzzyslam.se2 import wrap_angle_scalar

    a = np.linspace(-25.0, 25.0, 20001)
    assert np.array_equal([wrap_angle_scalar(float(x)) for x in a], wrap_angle(a))
    assert wrap_angle_scalar(-np.pi) == pytest.approx(np.pi)
