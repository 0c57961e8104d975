"""Landmark detections stamped in a frame other than the robot's base (a detector that
publishes in its camera's frame, or in the camera's optical frame): put in the base frame
by their /tf_static mount (slam/log_setup.py ``detection_mount_of``), in 3D. Checked on the
committed MRCLAM excerpt (data/real/mrclam6_excerpt), its detections moved into the other
frame: the run is the original's to rounding; a frame /tf_static does not place is one
line naming it."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from test_robust_logs import Out, cli, rewrite
from test_tf_mounts import link, quat, quaternion_matrix, tf

from fuzzyslam.streams import messages as M
from fuzzyslam.streams.reader import LogMessage, LogReader

EXCERPT = Path(__file__).resolve().parents[1] / "data" / "real" / "mrclam6_excerpt"
DETECTIONS = "/landmark_detections"


def moved(frame: str, rotation: np.ndarray, translation: np.ndarray, static):
    """A ``rewrite`` fault: each detection p (base frame, z = 0) written as R^T (p - t) in
    ``frame`` (whose mount in the base frame is (R, t)), and /tf_static ``static`` first."""
    done = []

    def fault(m: LogMessage) -> list[Out]:
        out = []
        if not done and static is not None:
            done.append(1)
            out.append(("/tf_static", M.TF_MESSAGE, static, m.t))
        if m.topic == DETECTIONS:
            for p in m.msg.poses:
                v = rotation.T @ (np.array([p.position.x, p.position.y, 0.0]) - translation)
                p.position.x, p.position.y, p.position.z = map(float, v)
            m.msg.header.frame_id = frame
        out.append((m.topic, m.typename, m.msg, m.t))
        return out

    return fault


@pytest.fixture(scope="module")
def plain(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("plain") / "est"
    code, _, err = cli("run", EXCERPT / "log.mcap", "--config", "real_detections", "-o", out)
    assert code == 0, err
    return out


@pytest.mark.parametrize(
    ("chain", "mount"),
    [
        # a camera 0.1 m ahead, 0.05 m left, turned 90 deg
        ([("base_link", "camera_link", 0.1, 0.05, 0.3, 0.0, 0.0, math.pi / 2)], "camera_link"),
        # and its optical frame (REP 103: z forward, x right, y down)
        (
            [
                ("base_link", "camera_link", 0.1, 0.05, 0.3, 0.0, 0.0, math.pi / 2),
                ("camera_link", "camera_optical", 0.0, 0.0, 0.0, -math.pi / 2, 0.0, -math.pi / 2),
            ],
            "camera_optical",
        ),
    ],
    ids=["camera_link", "optical"],
)
def test_detections_in_a_mounted_frame_give_the_same_run(
    plain: Path, tmp_path: Path, chain, mount: str
) -> None:
    """The detections written in the camera's frame with its /tf_static chain: the same
    trajectory as in base_link, to 1e-9 m (the mount composed in 3D and applied)."""
    r, t = np.eye(3), np.zeros(3)
    for _parent, _child, x, y, z, roll, pitch, yaw in chain:  # compose down the chain
        step = quaternion_matrix(quat(roll, pitch, yaw))
        t, r = t + r @ np.array([x, y, z]), r @ step
    static = tf(*(link(p, c, x, y, z, ro, pi, ya) for p, c, x, y, z, ro, pi, ya in chain))
    log = rewrite(EXCERPT / "log.mcap", tmp_path / "moved.mcap", moved(mount, r, t, static))
    code, out, err = cli("run", log, "--config", "real_detections", "-o", tmp_path / "est")
    assert code == 0, err
    got = np.loadtxt(tmp_path / "est" / "trajectory.tum")
    want = np.loadtxt(plain / "trajectory.tum")
    assert got.shape == want.shape
    assert np.abs(got[:, 1:3] - want[:, 1:3]).max() < 1e-6
    assert json.loads(out)["counts"]["detections"] > 100


@pytest.mark.slow
def test_detections_in_a_frame_tf_static_does_not_place_are_refused(tmp_path: Path) -> None:
    """Detections in 'camera_link' with a /tf_static that places only a laser: one line
    naming the frame and what to publish (before, they were used as if in base_link);
    with no /tf_static at all they are taken as in the base frame, and a note says so."""
    static = tf(link("base_link", "laser", 0.1, 0.0, 0.2))
    log = rewrite(
        EXCERPT / "log.mcap",
        tmp_path / "unplaced.mcap",
        moved("camera_link", np.eye(3), np.zeros(3), static),
    )
    code, _, err = cli("run", log, "--config", "real_detections", "-o", tmp_path / "est")
    assert code == 3 and "'camera_link'" in err and "/tf_static" in err
    assert len(err.strip().splitlines()) == 1 and not (tmp_path / "est").exists()
    bare = rewrite(
        EXCERPT / "log.mcap",
        tmp_path / "bare.mcap",
        moved("camera_link", np.eye(3), np.zeros(3), None),
    )
    code, _, err = cli("run", bare, "--config", "real_detections", "-o", tmp_path / "bare")
    assert code == 0 and "no /tf_static: the detections' frame 'camera_link'" in err


@pytest.mark.slow
def test_odometry_with_its_twist_alone_is_integrated(plain: Path, tmp_path: Path) -> None:
    """An Odometry stream whose pose stays at zero while its twist carries the motion (a
    driver that fills only the velocities; this excerpt's twist is the robot's logged
    speeds): the twist is integrated and said once on stderr (before: the robot held
    still for the whole log, and the summary was healthy). Its dead reckoning is the
    trapezoid rule on the twist with the midpoint motion model, integrated here again
    (to the file's micrometre); it stays within 0.5 m of the log's own pose over the 150 s (their
    conversion integrated the speeds another way)."""

    def twist_only(m: LogMessage) -> list[Out]:
        if m.topic == "/odom":
            p = m.msg.pose.pose
            p.position.x = p.position.y = 0.0
            p.orientation.x = p.orientation.y = p.orientation.z = 0.0
            p.orientation.w = 1.0
        return [(m.topic, m.typename, m.msg, m.t)]

    log = rewrite(EXCERPT / "log.mcap", tmp_path / "twist.mcap", twist_only)
    code, out, err = cli("run", log, "--config", "real_detections", "-o", tmp_path / "est")
    assert code == 0, err
    assert err.count("the twist is integrated") == 1
    assert json.loads(out)["odometry_source"] == "odom twist (/odom)"
    got = np.loadtxt(tmp_path / "est" / "odometry.tum")
    want = np.loadtxt(plain / "odometry.tum")
    assert got.shape == want.shape and np.abs(got[:, 0] - want[:, 0]).max() == 0
    gap = np.hypot(*(got[:, 1:3] - want[:, 1:3] - (got[0, 1:3] - want[0, 1:3])).T)
    assert 0 < gap.max() < 0.5
    # the same twist integrated here: trapezoid speeds, midpoint steps
    msgs = list(LogReader(log).messages(["/odom"]))
    t = np.array([m.msg.header.stamp.sec + 1e-9 * m.msg.header.stamp.nanosec for m in msgs])
    vw = np.array([(m.msg.twist.twist.linear.x, m.msg.twist.twist.angular.z) for m in msgs])
    dt = np.diff(t)
    period = np.median(dt[dt > 0])
    dt = np.where(dt > max(1.0, 3 * period), period, dt)  # a gap: one period (counted)
    assert json.loads(out)["warnings"].get("odometry_twist_gaps", 0) == np.sum(dt != np.diff(t))
    d = 0.5 * (vw[1:] + vw[:-1]) * dt[:, None]
    q = got[0, 4:8]
    th = 2 * math.atan2(q[2], q[3]) + np.concatenate([[0.0], np.cumsum(d[:, 1])])
    mid = th[:-1] + 0.5 * d[:, 1]
    xy = got[0, 1:3] + np.concatenate(
        [[[0.0, 0.0]], np.cumsum(d[:, :1] * np.column_stack([np.cos(mid), np.sin(mid)]), 0)]
    )
    # each row: the dead reckoning up to the last odometry stamp, the stamps moved by the
    # preset's odometry latency (slam.odometry_delay_s); TUM: 9 decimals, x y 6
    from fuzzyslam.config import load_config

    delay = load_config("real_detections").slam.odometry_delay_s
    at = np.maximum(np.searchsorted(t + delay, got[:, 0] + 1e-6, side="right") - 1, 0)
    assert np.abs(xy[at] - got[:, 1:3]).max() < 2e-6


def _twist_only(idle_until: float = -np.inf, silent: tuple[float, float] | None = None):
    """A ``rewrite`` fault: /odom with its pose held at zero (its twist kept), its twist
    zero before ``idle_until`` (log time), and no message within ``silent``."""

    def fault(m: LogMessage) -> list[Out]:
        if m.topic == "/odom":
            if silent is not None and silent[0] <= m.t - 1248444188.0 <= silent[1]:
                return []
            p = m.msg.pose.pose
            p.position.x = p.position.y = 0.0
            p.orientation.x = p.orientation.y = p.orientation.z = 0.0
            p.orientation.w = 1.0
            if m.t < idle_until:
                m.msg.twist.twist.linear.x = m.msg.twist.twist.angular.z = 0.0
        return [(m.topic, m.typename, m.msg, m.t)]

    return fault


@pytest.mark.slow  # end to end, about 1 s: the fast tier stays under a minute
def test_twist_only_odometry_after_an_idle_start_and_over_a_gap(tmp_path: Path) -> None:
    """A robot that waits 40 s (640 messages of zero twist) before it drives is still
    read from its twist; a 15 s silence of the twist-only odometry is not bridged with
    the end speeds (which invented 4.4 m): one period at most, counted."""
    start = next(m.t for m in LogReader(EXCERPT / "log.mcap").messages(["/odom"]))
    idle = rewrite(EXCERPT / "log.mcap", tmp_path / "idle.mcap", _twist_only(start + 40.0))
    code, out, err = cli("run", idle, "--config", "real_detections", "-o", tmp_path / "idle")
    assert code == 0, err
    assert json.loads(out)["odometry_source"] == "odom twist (/odom)"
    gap = rewrite(
        EXCERPT / "log.mcap", tmp_path / "gap.mcap", _twist_only(silent=(start - 1248444188.0 + 5,
                                                                       start - 1248444188.0 + 20))
    )  # fmt: skip
    code, out, err = cli("run", gap, "--config", "real_detections", "-o", tmp_path / "gap")
    assert code == 0, err
    gaps = json.loads(out)["warnings"]["odometry_twist_gaps"]
    whole = rewrite(EXCERPT / "log.mcap", tmp_path / "whole.mcap", _twist_only())
    code, out, err = cli("run", whole, "--config", "real_detections", "-o", tmp_path / "whole")
    assert code == 0, err
    assert gaps == json.loads(out)["warnings"].get("odometry_twist_gaps", 0) + 1
    odo = np.loadtxt(tmp_path / "gap" / "odometry.tum")
    steps = np.hypot(*np.diff(odo[:, 1:3], axis=0).T)
    assert steps.max() < 0.1  # no row jumps across the gap


def test_own_covariances_are_rotated_into_the_base_frame(tmp_path: Path) -> None:
    """Detection3DArray detections in a camera turned 90 deg (yaw), each with its own x, y
    covariance diag(a, b) and no z terms (zeros, ROS's unknown): in the base frame the
    point is turned and the covariance is diag(b, a) (R C R^T); the same in base_link
    keeps diag(a, b)."""
    from fuzzyslam.config import load_config
    from fuzzyslam.slam.events import Frame
    from fuzzyslam.slam.inputs import open_inputs
    from fuzzyslam.streams.writer import LogWriter

    cov = np.diag([0.04, 0.01])
    frames = {}
    for frame in ("base_link", "camera_link"):
        log = tmp_path / f"{frame}.mcap"
        with LogWriter(log) as w:
            mount = link("base_link", "camera_link", 0.1, 0.0, 0.3, yaw=math.pi / 2)
            w.write("/tf_static", M.TF_MESSAGE, tf(mount), 0.0)
            for k in range(20):
                t = 0.1 * k
                w.write("/odom", M.ODOMETRY, M.odometry(t, "odom", "base_link", np.zeros(3)), t)
                if k % 5 == 2:
                    det = M.detection3d_array(t, frame, np.array([[2.0, 1.0]]), cov[None])
                    w.write(DETECTIONS, M.DETECTION3D_ARRAY, det, t)
        inputs = open_inputs(log, load_config("real_detections"))
        frames[frame] = [ev for ev in inputs.events() if type(ev) is Frame]
    plain, turned = frames["base_link"], frames["camera_link"]
    assert len(plain) == len(turned) == 4
    np.testing.assert_allclose(plain[0].z, [[2.0, 1.0]], atol=1e-12)
    np.testing.assert_allclose(plain[0].cov[0], cov, atol=1e-12)
    np.testing.assert_allclose(turned[0].z, [[0.1 - 1.0, 2.0]], atol=1e-12)  # R(90) p + t
    np.testing.assert_allclose(turned[0].cov[0], np.diag([0.01, 0.04]), atol=1e-12)
