"""Sonar rings fired in sequence and laser scans whose beams are taken apart, deskewed
(streams/sonar.py ``deskewed_mounts``, slam/deskew.py): the geometry against closed
forms, the odometry trail against the filter's preintegration, a simulated log whose
sonars fire 40 ms apart against the simulator's true poses, and a laser on a turning
robot against the walls of its room."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from fuzzyslam.config import load_config
from fuzzyslam.se2 import between, compose, interpolate_poses
from fuzzyslam.slam.deskew import OdometryTrail, deskewed
from fuzzyslam.slam.events import Odom, RingEvent
from fuzzyslam.slam.motion import Preintegrator
from fuzzyslam.streams.reader import LogReader
from fuzzyslam.streams.sonar import Ring, deskewed_mounts, ring_mounts

MOUNTS = np.array([[0.2, 0.0, 0.0], [0.0, 0.2, math.pi / 2], [-0.2, 0.0, math.pi]])


def test_deskew_of_a_robot_turning_in_place_rotates_each_mount_back() -> None:
    """A robot turning in place at w rad/s: reading j, taken o_j s before the ring's time
    (o_j <= 0), sits in the ring's frame at the mount turned by w o_j about the centre."""
    w, t0 = 0.5, 10.0
    times = np.linspace(9.0, 11.0, 201)
    path = np.column_stack([np.zeros_like(times), np.zeros_like(times), w * (times - t0)])
    off = np.array([-0.4, -0.2, 0.0])
    got = deskewed_mounts(MOUNTS, off, t0, times, path)
    want = np.array([compose([0.0, 0.0, w * o], m) for o, m in zip(off, MOUNTS, strict=True)])
    np.testing.assert_allclose(got, want, atol=1e-12)


def test_deskew_of_a_robot_driving_straight_shifts_each_mount_back() -> None:
    """Driving straight at v m/s along its heading (any heading): reading j sits v o_j
    behind its mount along the robot's x axis; a missing reading (NaN) keeps its mount;
    several rings at once give each ring's row."""
    v, heading = 0.5, 0.7
    times = np.linspace(0.0, 20.0, 401)
    path = np.column_stack(
        [v * times * math.cos(heading), v * times * math.sin(heading), np.full_like(times, heading)]
    )
    off = np.array([[-0.6, np.nan, 0.0], [-0.3, -0.1, 0.0]])
    got = deskewed_mounts(MOUNTS, off, np.array([5.0, 12.0]), times, path)
    zero = np.zeros(off.shape)
    want = MOUNTS + np.stack([np.nan_to_num(off) * v, zero, zero], axis=-1)
    np.testing.assert_allclose(got, want, atol=1e-12)


def test_odometry_trail_is_the_filters_preintegration() -> None:
    """The trail's dead reckoning (midpoint steps) from any of its poses to its last is
    the filter's preintegrated motion (slam/motion.py) of the same increments; it keeps
    only the last TRAIL_S seconds."""
    rng = np.random.default_rng(3)
    trail, pre = OdometryTrail(), Preintegrator((0.01, 0.0, 0.01, 0.0))
    steps = [(0.05 * k, float(d), float(r)) for k, (d, r) in enumerate(
        zip(rng.uniform(0, 0.03, 80), rng.uniform(-0.05, 0.05, 80), strict=True))]  # fmt: skip
    for k, (t, d, r) in enumerate(steps):
        trail.add(t, d, r)
        if k >= 60:
            pre.add(d, r)
    first = trail.t.index(steps[59][0])
    got = between(np.array(trail.poses[first]), np.array(trail.poses[-1]))
    np.testing.assert_allclose(got, [pre.dx, pre.dy, pre.dth], atol=1e-12)
    assert trail.t[-1] - trail.t[0] <= 2.0 and len(trail.t) < len(steps)


def test_deskewed_stage_gives_rings_their_mounts_and_leaves_the_rest() -> None:
    """``deskewed``: a ring with offsets gets mounts from the odometry before it (a turn
    in place at 1 rad/s: reading j turned back by its offset); a ring stamped alike (one
    reading) gets the sensor's own, so that a multi-ring window never lends it another
    ring's; odometry stamped back in time is left out of the trail, as the filter skips
    it."""
    events = [Odom(0.01 * k, 0.0, 0.01) for k in range(1, 101)]  # 1 rad/s for 1 s
    events[60:60] = [Odom(0.2, 1.0, 1.0)] * 5  # stamped back in time: skipped
    seq = Ring(1.0, np.ones(3), np.full(3, 5.0), 0.4, np.array([-0.5, -0.25, 0.0]))
    alike = Ring(1.0, np.ones(3), np.full(3, 5.0), 0.4)
    out = list(deskewed(iter([*events, RingEvent(1.0, seq), RingEvent(1.0, alike)]), MOUNTS))
    assert len(out) == 107 and out[:105] == events
    want = np.array([compose([0.0, 0.0, o], m) for o, m in zip(seq.offsets, MOUNTS, strict=True)])
    # the midpoint steps' chord puts the centre off by d^2 / 8 per step: micrometres
    np.testing.assert_allclose(out[105].ring.mounts, want, atol=1e-5)
    assert out[106].ring.mounts is MOUNTS and ring_mounts(alike, MOUNTS) is MOUNTS


@pytest.fixture(scope="module")
def sequential_log(tmp_path_factory) -> Path:
    """13.9 s of the quick world (one corner turned), sonar rings at 1.5 Hz whose 16
    sonars fire 40 ms apart (a 0.6 s cycle), each reading from the true pose at its own
    firing time."""
    from test_robust_logs import cli

    d = tmp_path_factory.mktemp("seq")
    cfg = d / "seq.yaml"
    cfg.write_text(
        "extends: quick.yaml\nname: seq\nscenario:\n  runs: 1\n  lap_fraction: 0.1\n"
        "sonar:\n  rate_hz: 1.5\n  firing_gap_s: 0.04\n",
        encoding="utf-8",
    )
    code, _, err = cli("simulate", cfg, "-o", d / "seq.mcap", "--truth-tum", d / "truth.tum")
    assert code == 0, err
    return d


def test_simulated_sequential_sonars_are_stamped_at_their_firing(sequential_log: Path) -> None:
    """The simulator's sequential ring: sonar j stamped (and logged) 40 ms after sonar
    j - 1; the run's inputs measure the firing as sequential and make one ring per cycle
    at its last stamp, offsets -0.6 .. 0 s."""
    from fuzzyslam.slam.inputs import open_inputs

    cfg = load_config(str(sequential_log / "seq.yaml"))
    inputs = open_inputs(sequential_log / "seq.mcap", cfg, need_rings=True)
    assert inputs.ranges.firing == "sequential"
    rings = [ev.ring for ev in inputs.events(rings=True) if type(ev) is RingEvent]
    assert len(rings) >= 15
    for ring in rings:
        np.testing.assert_allclose(ring.offsets, -0.04 * np.arange(15, -1, -1), atol=1e-6)


def test_deskewed_rings_sit_where_their_sonars_fired(sequential_log: Path) -> None:
    """Each reading of each ring, placed by its deskewed mount from the true pose at the
    last odometry stamp up to the ring's time (the filter's pose when it takes the
    ring), is where its sonar was when it fired (the true pose at its own stamp with its
    mount): within 5 mm and 1 deg (dead reckoning over 0.6 s; a reading fired after
    the last odometry stamp is compared at that stamp, as the odometry cannot know more);
    placed by the plain mounts it is off by up to the robot's motion in a cycle."""
    from fuzzyslam.slam.inputs import open_inputs

    cfg = load_config(str(sequential_log / "seq.yaml"))
    log = sequential_log / "seq.mcap"
    reader = LogReader(log)
    truth = [(m.t, m.msg.pose.pose) for m in reader.messages(["/ground_truth/odom"])]
    tt = np.array([t for t, _ in truth])
    tp = np.array([[p.position.x, p.position.y, 2 * math.atan2(p.orientation.z, p.orientation.w)]
                   for _, p in truth])  # fmt: skip
    odo = np.array([m.t for m in reader.messages(["/joint_states"])])
    inputs = open_inputs(log, cfg, need_rings=True)
    mounts = inputs.mounts
    err_d, err_p = [], []
    for ev in inputs.events(rings=True):
        if type(ev) is not RingEvent:
            continue
        ring = ev.ring
        last_odometry = odo[np.searchsorted(odo, ring.t, side="right") - 1]
        at_ring = interpolate_poses(tt, tp, [last_odometry])[0]
        fired = interpolate_poses(tt, tp, np.clip(ring.t + ring.offsets, odo[1], last_odometry))
        want = compose(fired, mounts)
        for own, errs in ((ring.mounts, err_d), (mounts, err_p)):
            got = compose(np.broadcast_to(at_ring, mounts.shape), own)
            d = got - want
            turn = np.abs(np.angle(np.exp(1j * d[:, 2])))
            errs.append([np.hypot(d[:, 0], d[:, 1]).max(), turn.max()])
    err_d, err_p = np.array(err_d), np.array(err_p)
    assert err_d[:, 0].max() < 0.005 and np.rad2deg(err_d[:, 1].max()) < 1.0
    # the robot's motion in a cycle: decimetres, and degrees in the corner
    assert err_p[:, 0].max() > 0.1 and np.rad2deg(err_p[:, 1].max()) > 2.0


def test_map_places_each_reading_by_the_trajectory_at_its_stamp(
    sequential_log: Path, tmp_path: Path, monkeypatch
) -> None:
    """The map stage with the true trajectory: every reading it fuses sits where its
    sonar was when it fired (the trajectory at the reading's own stamp with its mount),
    to a micrometre; the ring at its last stamp with the plain mounts would be off by
    up to the robot's motion in a cycle."""
    from fuzzyslam.maps import build
    from fuzzyslam.maps.fgm import FgmBuilder
    from fuzzyslam.streams.tum import read_tum

    placed = []
    real = FgmBuilder.add_rings

    def add_rings(self, poses, ranges, max_range, fov, mounts):
        placed.append((poses.copy(), np.asarray(mounts).copy()))
        return real(self, poses, ranges, max_range, fov, mounts)

    monkeypatch.setattr(FgmBuilder, "add_rings", add_rings)
    cfg = load_config(str(sequential_log / "seq.yaml"))
    log, truth = sequential_log / "seq.mcap", sequential_log / "truth.tum"
    summary = build.build_map(log, truth, tmp_path / "fgm", cfg, build.MapOptions(figures=False))
    assert summary["range_sensor"]["firing"] == "sequential"
    times, *_, offsets = build.read_rings_compact(LogReader(log), cfg, np.inf)
    poses = np.concatenate([p for p, _ in placed])
    mounts = np.concatenate([m for _, m in placed])
    assert mounts.shape == (len(times), 16, 3)
    sensor = build.open_ranges(LogReader(log), cfg, None)
    t_tr, p_tr = read_tum(truth)
    fired = interpolate_poses(t_tr, p_tr, (times[:, None] + offsets).ravel(), outside="hold")
    want = compose(fired, np.tile(sensor.mounts, (len(times), 1)))
    got = compose(np.repeat(poses, 16, axis=0), mounts.reshape(-1, 3))
    d = got - want
    assert np.abs(d[:, :2]).max() < 1e-5 and np.abs(np.angle(np.exp(1j * d[:, 2]))).max() < 1e-5
    plain = compose(np.repeat(poses, 16, axis=0), np.tile(sensor.mounts, (len(times), 1)))
    assert np.hypot(*(plain - want)[:, :2].T).max() > 0.1


@pytest.mark.slow
def test_heading_fixes_on_sequential_rings_are_the_same_with_prefetch(
    sequential_log: Path, tmp_path: Path, monkeypatch
) -> None:
    """The rings are deskewed where the events are made, so a run whose events come from
    the child process (``--prefetch``) writes the same files as the one-process run;
    the heading aid gets every ring with its own mounts."""
    from test_robust_logs import cli

    from fuzzyslam.fixes.heading import HeadingFixAid
    from fuzzyslam.slam import stage

    monkeypatch.setattr(stage, "prefetch_wanted", lambda requested: requested)
    cfg, log = sequential_log / "seq.yaml", sequential_log / "seq.mcap"
    code, _, err = cli("run", log, "--config", cfg, "-o", tmp_path / "ab")
    assert code == 0, err
    code, _, err = cli("map", log, "--config", cfg, "--trajectory", tmp_path / "ab" /
                       "trajectory.tum", "-o", tmp_path / "fgm")  # fmt: skip
    assert code == 0, err
    seen = []
    real = HeadingFixAid.on_ring
    monkeypatch.setattr(
        HeadingFixAid,
        "on_ring",
        lambda self, t, ring, mounts, ekf: (
            seen.append(ring.mounts is not None) or real(self, t, ring, mounts, ekf)
        ),
    )
    outs = {}
    for mode in ("prefetch", "no-prefetch"):
        outs[mode] = tmp_path / mode
        code, _, err = cli("run", log, "--config", cfg, "--map", tmp_path / "fgm", "--fix",
                           "heading", "--fix-from", "0", "-o", outs[mode], f"--{mode}")  # fmt: skip
        assert code == 0, err
    assert seen and all(seen)
    for name in ("trajectory.tum", "heading_fixes.csv", "updates.csv", "covariance.csv"):
        a, b = ((outs[m] / name).read_bytes() for m in outs)
        assert a == b, name


def _box_ranges(origins: np.ndarray, angles: np.ndarray, half: float) -> np.ndarray:
    """Ranges from ``origins`` (N, 2) along ``angles`` (N,) to the walls of the square
    [-half, half]^2 (the origins inside it): the nearest exit along each ray."""
    d = np.column_stack([np.cos(angles), np.sin(angles)])
    with np.errstate(divide="ignore"):
        t = np.where(d > 0, (half - origins) / d, np.where(d < 0, (-half - origins) / d, np.inf))
    return t.min(axis=1)


def test_laser_beams_taken_apart_are_deskewed_by_the_odometry(tmp_path: Path) -> None:
    """A laser taking 181 beams over 0.09 s (``time_increment``) on a robot turning in
    place at 1 rad/s in a 6 m square room: each scan is a ring at its last beam's time;
    the run's inputs place every beam, from the odometry's pose at the ring, where it was
    taken (its end point on a wall to a millimetre); placed by the stamp's pose alone
    the end points miss the walls by centimetres to decimetres (5 deg of turn at 3 m)."""
    from fuzzyslam.slam.inputs import open_inputs
    from fuzzyslam.streams import messages as M
    from fuzzyslam.streams.writer import LogWriter

    half, w, n, ti = 3.0, 1.0, 181, 0.0005
    angles = -math.pi / 2 + np.arange(n) * (math.pi / (n - 1))
    centre, laser = np.array([0.3, 0.2]), np.array([0.1, 0.0])

    def pose(t: float) -> np.ndarray:
        return np.array([*centre, w * t])

    log = tmp_path / "laser.mcap"
    odo_t = np.round(np.arange(0.0, 3.0, 0.01), 6)
    with LogWriter(log) as out:
        tfs = [M.transform_stamped(0.0, "base_link", "laser", *laser, 0.2, 0.0)]
        out.write("/tf_static", M.TF_MESSAGE, M.tf_message(tfs), 0.0)
        events = [(t, "odom") for t in odo_t] + [(0.105 + 0.1 * k, "scan") for k in range(28)]
        for t, kind in sorted(events):
            if kind == "odom":
                out.write("/odom", M.ODOMETRY, M.odometry(t, "odom", "base_link", pose(t)), t)
                continue
            tb = t + np.arange(n) * ti  # each beam's time
            th = w * tb
            org = centre + np.column_stack([np.cos(th), np.sin(th)]) * laser[0]
            r = _box_ranges(org, th + angles, half)
            scan = M.laser_scan(t, "laser", r, angles[0], angles[1] - angles[0], 0.05, 40.0, ti)
            out.write("/scan", M.LASER_SCAN, scan, t)
    cfg = load_config("real_building_scan")
    inputs = open_inputs(log, cfg, need_rings=True, ranges="scan")
    assert inputs.ranges.stamped_apart
    miss_d, miss_p = [], []
    for ev in inputs.events(rings=True):
        if type(ev) is not RingEvent:
            continue
        ring = ev.ring
        t_ref = odo_t[np.searchsorted(odo_t, ring.t, side="right") - 1]
        ref = pose(t_ref)
        # the beams taken after the last odometry (5 ms here) are held at its pose: the
        # odometry cannot know more (their miss is the robot's turn in those 5 ms)
        ok = np.isfinite(ring.ranges) & (ring.ranges < 39.0) & (ring.t + ring.offsets <= t_ref)
        for mounts, miss in ((ring.mounts, miss_d), (inputs.mounts, miss_p)):
            beams = compose(np.broadcast_to(ref, mounts.shape), mounts)[ok]
            ends = beams[:, :2] + ring.ranges[ok, None] * np.column_stack(
                [np.cos(beams[:, 2]), np.sin(beams[:, 2])]
            )
            miss.append(np.abs(np.abs(ends).max(axis=1) - half).max())
    assert len(miss_d) >= 25
    assert max(miss_d) < 1e-3 and min(miss_p) > 0.05


def test_simulate_refuses_a_ring_longer_than_a_firing_cycle_is_read(tmp_path: Path) -> None:
    """16 sonars 0.1 s apart fire over 1.5 s: longer than a ring is read as (1 s), so the
    log could not be read back as whole rings; refused in one line naming the key, and
    no file is written. 40 ms apart at 1.5 Hz is accepted (the fixture above)."""
    from test_robust_logs import cli

    cfg = tmp_path / "slow.yaml"
    cfg.write_text(
        "extends: quick.yaml\nname: slow\nsonar:\n  rate_hz: 0.5\n  firing_gap_s: 0.1\n",
        encoding="utf-8",
    )
    code, _, err = cli("simulate", cfg, "-o", tmp_path / "slow.mcap")
    assert code != 0 and "sonar.firing_gap_s 0.1 s" in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "slow.mcap").exists()
