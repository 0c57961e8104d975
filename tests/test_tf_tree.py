"""The run's frames agree with the log's (REP 105).

- /tf: when the log carries odom -> base_link (``fuzzyslam simulate``, a robot's driver),
  estimates.mcap's map -> odom is the estimate composed with the inverse of THE LOG'S
  odom -> base_link at the pose stamp, so that the two files compose to /slam/pose even
  when the run's own dead reckoning differs from the log's: another start pose, an
  odometry delay, another wheel radius (as AMCL does).
- The ceiling camera's mount rotation from /tf_static: a camera turned by pi about its
  optical axis (every image rotated 180 deg, the mount's yaw pi) gives the same lamps.

On a short simulated log (a third of a lap of the quick world), made once per test run.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from test_robust_logs import TINY_YAML, Tiny, tiny  # noqa: F401
from test_robust_logs import cli as run_cli

from fuzzyslam.rundir import read_landmarks
from fuzzyslam.se2 import compose, wrap_angle
from fuzzyslam.streams import messages as M
from fuzzyslam.streams.reader import LogReader
from fuzzyslam.streams.writer import LogWriter

IMAGE = "/ceiling_camera/image_raw"


def cli(*args) -> str:
    """``fuzzyslam ARGS`` in-process; its stdout (exit code 0 asserted)."""
    code, out, err = run_cli(*args)
    assert code == 0, err
    return out


@pytest.fixture(scope="module")
def log_dir(tiny: Tiny) -> Path:  # noqa: F811
    """The tiny simulated log (tiny.mcap) and its config (tiny.yaml) of
    test_robust_logs, built once per test run."""
    return tiny.dir


def _sec(stamp) -> float:
    return M.stamp_to_sec(stamp)


def log_odom(log: Path) -> tuple[np.ndarray, np.ndarray]:
    """The log's /tf odom -> base_link: stamps (N,) and poses (N, 3)."""
    t, poses = [], []
    for m in LogReader(log).messages(["/tf"]):
        for child, (parent, pose) in M.planar_transforms(m.msg).items():
            if (parent, child) == ("odom", "base_link"):
                t.append(_sec(m.msg.transforms[0].header.stamp))
                poses.append(pose)
    return np.asarray(t), np.asarray(poses).reshape(-1, 3)


def odom_at(t: np.ndarray, poses: np.ndarray, tq: float) -> tuple[np.ndarray, str]:
    """The log's odom -> base_link at ``tq`` and how it was found: its sample at that
    stamp (within 1 us: the stamps round-trip through nanoseconds), else the end sample
    held outside the series (the documented rule), else linear between the two samples
    around ``tq`` (the heading the shorter way: the simulator's /tf is at every robot
    step, so the heading turns less than pi between samples)."""
    k = int(np.argmin(np.abs(t - tq)))
    if abs(t[k] - tq) < 1e-6:
        return poses[k], "sample"
    if tq < t[0]:
        return poses[0], "held"
    if tq > t[-1]:
        return poses[-1], "held"
    i = int(np.searchsorted(t, tq)) - 1
    a = (tq - t[i]) / (t[i + 1] - t[i])
    d = poses[i + 1] - poses[i]
    d[2] = wrap_angle(d[2])
    return poses[i] + a * d, "between"


def check_tree(log: Path, est: Path) -> dict[str, int]:
    """Every /slam/pose of ``est``: its /tf is map -> odom alone at its stamp, and that
    composed with the log's odom -> base_link at the stamp is the pose (1e-6 m, 1e-6
    rad). Returns how many stamps were found each way."""
    t, poses = log_odom(log)
    assert len(t) > 100
    tf, pose = {}, []
    for m in LogReader(est).messages(["/tf", "/slam/pose"]):
        if m.topic == "/tf":
            (ts,) = m.msg.transforms
            assert (ts.header.frame_id, ts.child_frame_id) == ("map", "odom")
            tf[(ts.header.stamp.sec, ts.header.stamp.nanosec)] = M.planar_transforms(m.msg)
        else:
            pose.append(m.msg)
    assert len(pose) == len(tf) > 100
    how = {"sample": 0, "held": 0, "between": 0}
    for p in pose:
        stamp = p.header.stamp
        corr = tf[(stamp.sec, stamp.nanosec)]["odom"][1]
        base, kind = odom_at(t, poses, _sec(stamp))
        how[kind] += 1
        got, ref = compose(corr, base), M.pose_of(p.pose.pose)
        assert np.abs(got[:2] - ref[:2]).max() < 1e-6, (_sec(stamp), got, ref)
        assert abs(wrap_angle(got[2] - ref[2])) < 1e-6, (_sec(stamp), got, ref)
    return how


def test_map_odom_against_the_logs_odom_with_another_start_pose(log_dir, tmp_path) -> None:
    """--start-pose 1,2,0.5: the run's dead reckoning starts elsewhere than the log's."""
    cli("run", log_dir / "tiny.mcap", "-o", tmp_path / "est", "--config",
        log_dir / "tiny.yaml", "--start-pose", "1,2,0.5")  # fmt: skip
    how = check_tree(log_dir / "tiny.mcap", tmp_path / "est" / "estimates.mcap")
    assert how["sample"] > 100


def test_map_odom_against_the_logs_odom_with_an_odometry_delay(log_dir, tmp_path) -> None:
    """slam.odometry_delay_s 0.3: the run's odometry is 0.3 s later than the log's /tf;
    the last poses come after the log's last odom -> base_link (held)."""
    cfg = tmp_path / "delay.yaml"
    cfg.write_text(TINY_YAML + "slam:\n  odometry_delay_s: 0.3\n", encoding="utf-8")
    cli("run", log_dir / "tiny.mcap", "-o", tmp_path / "est", "--config", cfg)
    how = check_tree(log_dir / "tiny.mcap", tmp_path / "est" / "estimates.mcap")
    assert how["sample"] > 100


def test_map_odom_against_the_logs_odom_with_another_wheel_radius(log_dir, tmp_path) -> None:
    """robot.wheel_radius 2 % larger than the simulated robot's: the run's dead
    reckoning drifts from the driver's."""
    from fuzzyslam.config import load_config

    r = load_config(log_dir / "tiny.yaml").robot.wheel_radius
    cfg = tmp_path / "wheel.yaml"
    cfg.write_text(TINY_YAML + f"robot:\n  wheel_radius: {1.02 * r!r}\n", encoding="utf-8")
    cli("run", log_dir / "tiny.mcap", "-o", tmp_path / "est", "--config", cfg)
    how = check_tree(log_dir / "tiny.mcap", tmp_path / "est" / "estimates.mcap")
    assert how["sample"] > 100


def test_log_odom_interpolation_holds_the_ends() -> None:
    """slam/outputs.py ``log_odom_at``: the series' samples at their stamps, linear
    between (the heading the shorter way across pi), the end poses held outside."""
    from fuzzyslam.slam.outputs import log_odom_at

    t = np.array([1.0, 2.0, 3.0])
    p = np.array([[0.0, 0.0, 3.0], [1.0, 2.0, -3.0], [2.0, 0.0, 0.5]])
    got = log_odom_at(np.array([0.0, 1.0, 1.5, 2.0, 2.5, 9.0]), (t, p))
    assert np.allclose(got[[0, 1]], p[0]) and np.allclose(got[3], p[1])
    assert np.allclose(got[5], p[2])
    assert np.allclose(got[2, :2], [0.5, 1.0])
    assert abs(wrap_angle(got[2, 2] - math.pi)) < 1e-12  # 3 -> -3 through pi
    assert np.allclose(got[4], [1.5, 1.0, wrap_angle(-3.0 + wrap_angle(0.5 + 3.0) / 2)])
    assert log_odom_at(np.zeros(0), (t, p)).shape == (0, 3)


# -- the ceiling camera's mount rotation -----------------------------------------------


def test_camera_axes_from_the_mount_rotation() -> None:
    """camera.py ``floor_mount``: yaw pi turns the image axes (A = -I); a camera frame
    whose z points down mirrors the image's y; a tilted camera is refused; unproject
    and project invert each other through the axes."""
    from fuzzyslam.camera import CeilingCamera, floor_mount
    from fuzzyslam.streams.tf import Rigid, TfProblem, quaternion_matrix

    offset, axes = floor_mount(Rigid.planar(0.1, -0.2, math.pi))
    assert offset == pytest.approx((0.1, -0.2))
    assert np.allclose(axes, [-1, 0, 0, -1])
    roll = Rigid([0.0, 0.0, 0.3], quaternion_matrix([1.0, 0.0, 0.0, 0.0]))  # roll pi
    assert np.allclose(floor_mount(roll)[1], [1, 0, 0, -1])
    tilt = Rigid(rotation=quaternion_matrix([0.0, math.sin(0.2), 0.0, math.cos(0.2)]))
    with pytest.raises(TfProblem, match="optical axis"):
        floor_mount(tilt)
    turned = CeilingCamera(160, 120, 100.0, 79.5, 59.5, 2.5, offset, axes)
    plain = CeilingCamera(160, 120, 100.0, 79.5, 59.5, 2.5, offset)
    uv = np.array([[10.0, 20.0], [150.25, 3.5]])
    assert np.allclose(turned.unproject(uv), plain.unproject([159, 119] - uv), atol=1e-12)
    assert np.allclose(turned.project(turned.unproject(uv)), uv, atol=1e-9)


def _turn_camera(src: Path, dst: Path) -> None:
    """``src`` with every camera image rotated 180 deg and the camera's /tf_static mount
    turned by pi about its optical axis (yaw pi): the same robot, the camera turned."""
    turned = 0
    with LogWriter(dst) as w:
        reader = LogReader(src)
        for name in sorted(reader.metadata, key=lambda n: (n != "fuzzyslam.world", n)):
            w.metadata(name, reader.metadata[name])
        for m in reader.messages():
            if m.topic == "/tf_static":
                for ts in m.msg.transforms:
                    if ts.child_frame_id == "ceiling_camera":
                        q = ts.transform.rotation
                        assert (q.x, q.y, q.z, q.w) == (0.0, 0.0, 0.0, 1.0)
                        q.z, q.w = 1.0, 0.0
                        turned += 1
            elif m.topic == IMAGE:
                img = M.image_to_array(m.msg)
                m.msg.data = np.ascontiguousarray(img[::-1, ::-1]).reshape(-1)
            w.write(m.topic, m.typename, m.msg, m.t)
    assert turned == 1


@pytest.mark.slow
def test_a_camera_turned_by_pi_sees_the_same_lamps(log_dir, tmp_path) -> None:
    """The log with its images rotated 180 deg and the camera's mount yaw pi gives the
    same lamps (count, positions to 1 mm) as the log itself (needs slam/inputs.py to
    build the camera with ``camera.floor_mount`` of the /tf_static mount)."""
    turned = tmp_path / "turned.mcap"
    _turn_camera(log_dir / "tiny.mcap", turned)
    for name, log in (("plain", log_dir / "tiny.mcap"), ("turned", turned)):
        cli("run", log, "-o", tmp_path / name, "--config", log_dir / "tiny.yaml")
    plain, _ = read_landmarks(tmp_path / "plain" / "landmarks.yaml")
    got, _ = read_landmarks(tmp_path / "turned" / "landmarks.yaml")
    assert len(plain) >= 5
    assert got.shape == plain.shape
    # the same lamps, maybe numbered otherwise (a frame's blobs come in another order)
    d = np.linalg.norm(got[:, None, :] - plain[None, :, :], axis=-1)
    assert d.min(axis=1).max() < 1e-3 and d.min(axis=0).max() < 1e-3


@pytest.mark.slow
def test_map_odom_against_a_driver_that_starts_late(log_dir, tmp_path) -> None:
    """/tf also carries base_link -> wheel at every step, and the driver's odom ->
    base_link only from 8 s on (after 300 /tf messages): the pair is still found, so
    map -> odom is computed against it (wheel radius 2 % off, as above)."""
    from test_robust_logs import rewrite

    from fuzzyslam.config import load_config
    from fuzzyslam.streams.cdr_encode import encode_tf_block

    def late_driver(m):
        if m.topic != "/tf":
            return [(m.topic, m.typename, m.msg, m.t)]
        wheel = encode_tf_block(np.array([m.t]), [("base_link", "wheel")], [np.zeros((1, 3))])
        out = [(m.topic, m.typename, wheel[0], m.t)] * 2
        return out if m.t < 8.0 else [*out, (m.topic, m.typename, m.msg, m.t)]

    log = rewrite(log_dir / "tiny.mcap", tmp_path / "late.mcap", late_driver)
    r = load_config(log_dir / "tiny.yaml").robot.wheel_radius
    cfg = tmp_path / "wheel.yaml"
    cfg.write_text(TINY_YAML + f"robot:\n  wheel_radius: {1.02 * r!r}\n", encoding="utf-8")
    cli("run", log, "-o", tmp_path / "est", "--config", cfg)
    check_tree(log, tmp_path / "est" / "estimates.mcap")


def test_a_tf_on_another_clock_is_not_used(log_dir, tmp_path) -> None:
    """The log's /tf stamped 1000 s ahead of the odometry: map -> odom cannot be put
    against it, so estimates.mcap writes its own odom -> base_link (a note says why),
    and its own tree composes to /slam/pose."""
    from test_robust_logs import rewrite

    def ahead(m):
        if m.topic == "/tf":
            (ts,) = m.msg.transforms
            ts.header.stamp = M.stamp(_sec(ts.header.stamp) + 1000.0)
        return [(m.topic, m.typename, m.msg, m.t)]

    log = rewrite(log_dir / "tiny.mcap", tmp_path / "ahead.mcap", ahead)
    code, _, err = run_cli("run", log, "-o", tmp_path / "est", "--config", log_dir / "tiny.yaml")
    assert code == 0 and "another clock; estimates.mcap writes its own odom -> base" in err
    tf, pose = {}, {}
    for m in LogReader(tmp_path / "est" / "estimates.mcap").messages(["/tf", "/slam/pose"]):
        key = (m.msg.header.stamp.sec, m.msg.header.stamp.nanosec) if m.topic != "/tf" else None
        if m.topic == "/tf":
            pairs = [(x.header.frame_id, x.child_frame_id) for x in m.msg.transforms]
            assert pairs == [("map", "odom"), ("odom", "base_link")]
            h = m.msg.transforms[0].header.stamp
            tf[(h.sec, h.nanosec)] = M.planar_transforms(m.msg)
        else:
            pose[key] = M.pose_of(m.msg.pose.pose)
    assert len(pose) > 100
    for key, p in pose.items():
        est = compose(tf[key]["odom"][1], tf[key]["base_link"][1])
        assert est[:2] == pytest.approx(p[:2], abs=1e-9)


@pytest.mark.slow
def test_a_camera_under_a_root_that_is_not_the_base_is_placed_and_said(log_dir, tmp_path) -> None:
    """/tf_static hangs everything under 'chassis', a name the odometry never uses: the
    camera is placed under that root (the same lamps as the plain log) and a note says
    which frame stood in for base_link."""
    from test_robust_logs import rewrite

    def rename(m):
        if m.topic == "/tf_static":
            for ts in m.msg.transforms:
                ts.header.frame_id = "chassis"
        return [(m.topic, m.typename, m.msg, m.t)]

    log = rewrite(log_dir / "tiny.mcap", tmp_path / "chassis.mcap", rename)
    cfg = log_dir / "tiny.yaml"
    code, _, err = run_cli("run", log, "-o", tmp_path / "est", "--config", cfg)
    assert code == 0 and "the camera is placed in 'chassis' instead" in err, err
    plain = tmp_path / "plain"
    cli("run", log_dir / "tiny.mcap", "-o", plain, "--config", cfg)
    assert (tmp_path / "est" / "trajectory.tum").read_bytes() == (
        plain / "trajectory.tum"
    ).read_bytes()
    # opened twice (a first pass estimates the detection noise): the note once
    code, out, err = run_cli(
        "run", log, "-o", tmp_path / "adapted", "--config", cfg, "--adapt-noise"
    )
    assert code == 0 and err.count("the camera is placed in 'chassis' instead") == 1, err
    assert "noise_adapted" in json.loads(out)  # two passes (too short a log to estimate)
