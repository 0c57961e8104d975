"""Odometry read from /tf (a log recorded for slam_toolbox or gmapping: /scan or sonars
and /tf, the odometry only as its odom -> base_link transform; slam/log_setup.py
``odometry_source``, ``tf_odometry``).

The committed simulated sample carries the same dead-reckoned poses at the same stamps
on /odom and on /tf (checked here first), so a run of it with /tf as its only odometry
must give, to 1e-9, the trajectory of the same log read from /odom; the CARMEN excerpt's
/odom turned into /tf transforms (other transforms beside them) likewise for ``map
--trajectory`` and ``run --map --fix pose``; a log with no odometry at all is refused in
one line naming /tf among the streams looked at.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from mcap_ros2.decoder import DecoderFactory
from test_robust_logs import cli, error_lines, rewrite

from fuzzyslam.streams import messages as M
from fuzzyslam.streams.reader import LogMessage, LogReader

ROOT = Path(__file__).resolve().parents[1]
SAMPLE = ROOT / "data" / "sample.mcap"
EXCERPT = ROOT / "data" / "carmen_fr079_excerpt"
NOTE = "the odometry is read from /tf's odom -> base_link transforms"


def dropping(*topics: str):
    """A ``rewrite`` fault that leaves out the messages of ``topics``."""
    return lambda m: [] if m.topic in topics else [(m.topic, m.typename, m.msg, m.t)]


def poses(msgs) -> list[tuple]:
    """(stamp ns, x, y, qx, qy, qz, qw) of Odometry messages."""
    out = []
    for msg in msgs:
        s, p, q = msg.header.stamp, msg.pose.pose.position, msg.pose.pose.orientation
        out.append((s.sec * 10**9 + s.nanosec, p.x, p.y, q.x, q.y, q.z, q.w))
    return out


def odom_as_tf(m: LogMessage):
    """/odom as /tf: each Odometry's pose as an odom -> base_link transform with the
    same stamp, in one TFMessage with a transform of other frames before it (map ->
    odom, base_link -> laser: not odometry); other topics kept."""
    if m.topic != "/odom":
        return [(m.topic, m.typename, m.msg, m.t)]
    o = m.msg
    t = M.stamp_to_sec(o.header.stamp)
    ts = M.transform_stamped(t, "odom", "base_link", 0.0, 0.0, 0.0, 0.0)
    ts.header.stamp = o.header.stamp
    p, q = o.pose.pose.position, o.pose.pose.orientation
    tr, rot = ts.transform.translation, ts.transform.rotation
    tr.x, tr.y, tr.z = p.x, p.y, p.z
    rot.x, rot.y, rot.z, rot.w = q.x, q.y, q.z, q.w
    decoys = [
        M.transform_stamped(t, "map", "odom", 3.0, -2.0, 0.0, 1.0),
        M.transform_stamped(t, "odom", "laser", 9.0, 9.0, 0.0, 2.0),
    ]
    return [("/tf", M.TF_MESSAGE, M.tf_message([decoys[0], ts, decoys[1]]), m.t)]


@pytest.fixture(scope="module")
def sample_logs(tmp_path_factory) -> Path:
    d = tmp_path_factory.mktemp("tfodo")
    rewrite(SAMPLE, d / "tf.mcap", dropping("/joint_states", "/odom"))
    rewrite(SAMPLE, d / "odom.mcap", dropping("/joint_states"))
    rewrite(SAMPLE, d / "none.mcap", dropping("/joint_states", "/odom", "/tf"))
    return d


def test_the_sample_carries_the_same_poses_on_odom_and_tf() -> None:
    """The premise of the comparison: the simulator writes each dead-reckoned pose on
    /odom and as odom -> base_link on /tf, with the same stamp, and nothing else on /tf."""
    reader = LogReader(SAMPLE)
    odom = poses(m.msg for m in reader.messages(["/odom"]))
    tf = []
    for m in reader.messages(["/tf"]):
        for ts in m.msg.transforms:
            assert (ts.header.frame_id, ts.child_frame_id) == ("odom", "base_link")
            s, tr, q = ts.header.stamp, ts.transform.translation, ts.transform.rotation
            tf.append((s.sec * 10**9 + s.nanosec, tr.x, tr.y, q.x, q.y, q.z, q.w))
    assert len(odom) > 1000 and odom == tf


@pytest.mark.slow
def test_a_log_of_tf_alone_runs_as_its_odom(sample_logs: Path) -> None:
    """No /joint_states, no /odom: the odometry comes from /tf's odom -> base_link, said
    once, and the summary names it; every output but the summary equals the run of the
    same log read from /odom (trajectory to 1e-9)."""
    d = sample_logs
    code, out, err = cli("run", d / "tf.mcap", "-o", d / "tf_run")
    assert code == 0, err
    assert err.count(NOTE) == 1 and err.count("note:") == 1, err
    assert json.loads(out)["odometry_source"] == "tf (/tf odom -> base_link)"
    code, out, err = cli("run", d / "odom.mcap", "-o", d / "odom_run")
    assert code == 0, err
    assert json.loads(out)["odometry_source"] == "odom (/odom)"
    got = np.loadtxt(d / "tf_run" / "trajectory.tum")
    want = np.loadtxt(d / "odom_run" / "trajectory.tum")
    assert got.shape == want.shape and len(got) > 100
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-9)
    for name in ("odometry.tum", "updates.csv", "landmarks.yaml"):
        assert (d / "tf_run" / name).read_bytes() == (d / "odom_run" / name).read_bytes()


def test_no_odometry_anywhere_is_one_line_naming_tf(sample_logs: Path, tmp_path: Path) -> None:
    """No encoders, no /odom and no /tf: exit 3, the missing streams with /tf among them;
    a /tf without odom -> base (only other frames) says so."""
    d = sample_logs
    code, _, err = cli("run", d / "none.mcap", "-o", tmp_path / "est")
    lines = error_lines(err)
    assert code == 3 and len(lines) == 1, err
    assert "missing stream(s) /joint_states, /odom, /tf (set them in the config's " in lines[0]
    assert not (tmp_path / "est").exists()

    def other_frames(m: LogMessage):
        if m.topic in ("/joint_states", "/odom"):
            return []
        if m.topic == "/tf":
            for ts in m.msg.transforms:
                ts.child_frame_id = "laser"
        return [(m.topic, m.typename, m.msg, m.t)]

    log = rewrite(SAMPLE, tmp_path / "other.mcap", other_frames)
    code, _, err = cli("run", log, "-o", tmp_path / "est")
    lines = error_lines(err)
    assert code == 3 and len(lines) == 1, err
    assert "missing stream(s) /joint_states, /odom, and /tf has no odom -> base_link" in lines[0]


def test_tf_odometry_takes_the_pair_in_stamp_order() -> None:
    """Several odom -> base_link transforms in one TFMessage come in stamp order, each a
    pose as an Odometry's; other frames are left out, other topics pass."""
    from fuzzyslam.slam.log_setup import tf_odometry

    tfs = [
        M.transform_stamped(2.0, "odom", "base_link", 2.0, 0.5, 0.0, 0.2),
        M.transform_stamped(1.5, "map", "odom", 7.0, 7.0, 0.0, 0.0),
        M.transform_stamped(1.0, "/odom", "base_link", 1.0, 0.0, 0.0, 0.1),
        M.transform_stamped(1.2, "odom", "base_footprint", 5.0, 5.0, 0.0, 0.0),
    ]
    msgs = [
        LogMessage("/tf", 3.0, M.TF_MESSAGE, M.tf_message(tfs), 3 * 10**9),
        LogMessage("/scan", 3.1, "x", "scan", 31 * 10**8),
    ]
    out = list(tf_odometry(msgs, "/tf", ("odom", "base_link")))
    assert [m.topic for m in out] == ["/tf", "/tf", "/scan"]
    assert [m.t for m in out] == [3.0, 3.0, 3.1]
    assert [M.stamp_to_sec(m.msg.header.stamp) for m in out[:2]] == [1.0, 2.0]
    np.testing.assert_allclose([M.pose_of(m.msg.pose.pose) for m in out[:2]],
                               [[1.0, 0.0, 0.1], [2.0, 0.5, 0.2]])  # fmt: skip


@pytest.fixture(scope="module")
def excerpt_logs(tmp_path_factory) -> Path:
    d = tmp_path_factory.mktemp("tfcarmen")
    rewrite(EXCERPT / "log.mcap", d / "tf.mcap", odom_as_tf)
    return d


@pytest.mark.slow  # end to end: a map and a pose-fix run of each log (4 s)
def test_carmen_excerpt_with_odometry_on_tf(excerpt_logs: Path) -> None:
    """The CARMEN excerpt with /odom as /tf transforms (and other transforms beside them):
    ``map --trajectory`` builds the same map, and ``run --map --fix pose --fix-from +0``
    gives the trajectory of the log with /odom, to 1e-9."""
    d = excerpt_logs
    assert not LogReader(d / "tf.mcap").has("/odom")
    common = ["--config", "real_building_scan", "--ranges", "scan"]
    trajectories = {}
    for name, log in (("odom", EXCERPT / "log.mcap"), ("tf", d / "tf.mcap")):
        fgm = d / f"fgm_{name}"
        code, _, err = cli("map", log, "--trajectory", EXCERPT / "truth.tum", *common,
                           "--no-figures", "-o", fgm)  # fmt: skip
        assert code == 0, err
        est = d / f"est_{name}"
        code, out, err = cli("run", log, *common, "--map", fgm, "--fix", "pose",
                             "--fix-from", "+0", "-o", est)  # fmt: skip
        assert code == 0, err
        summary = json.loads(out)
        pair = " odom -> base_link" if name == "tf" else ""
        assert summary["odometry_source"] == f"{name} (/{name}{pair})"
        assert summary["aids"]["PoseFixAid"]["accepted"] > 10  # the fixes do act
        assert (NOTE in err) == (name == "tf"), err
        trajectories[name] = np.loadtxt(est / "trajectory.tum")
    odom = np.load(d / "fgm_odom" / "fgm.npz")
    tf = np.load(d / "fgm_tf" / "fgm.npz")
    for key in ("m_e", "m_o", "m_t", "m_c"):
        np.testing.assert_array_equal(tf[key], odom[key])
    got, want = trajectories["tf"], trajectories["odom"]
    assert got.shape == want.shape and len(got) > 100
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-9)


@pytest.mark.slow  # end to end, 1-3 s: the fast tier stays under a minute
def test_unreadable_encoders_without_odom_fall_back_to_tf(tmp_path: Path) -> None:
    """Wheel joints under other names and no /odom: /tf's odom -> base_link is read, one
    note saying why (the joints passed over, no /odom), the trajectory that of /odom."""

    def fault(m: LogMessage):
        if m.topic == "/odom":
            return []
        if m.topic == "/joint_states":
            m.msg.name = ["left_wheel_joint", "right_wheel_joint"]
        return [(m.topic, m.typename, m.msg, m.t)]

    log = rewrite(SAMPLE, tmp_path / "joints.mcap", fault)
    code, out, err = cli("run", log, "-o", tmp_path / "est")
    assert code == 0, err
    (line,) = error_lines(err)[:1]
    assert "/joint_states names no joints" in line and "and no /odom" in line and NOTE in line
    assert (
        err.count("note:") == 1
        and json.loads(out)["odometry_source"] == "tf (/tf odom -> base_link)"
    )
    odom = rewrite(SAMPLE, tmp_path / "odom.mcap", dropping("/joint_states"))
    code, _, err = cli("run", odom, "-o", tmp_path / "want")
    assert code == 0, err
    got = np.loadtxt(tmp_path / "est" / "trajectory.tum")
    np.testing.assert_allclose(got, np.loadtxt(tmp_path / "want" / "trajectory.tum"), atol=1e-9)


@pytest.mark.slow
def test_odometry_on_tf_that_starts_late_is_found(tmp_path: Path) -> None:
    """A bag recorded before the robot's driver came up: /tf's odom -> base_link starts
    40 s in, another frame's transform on /tf from the start (the sample without its
    encoders and /odom). The odometry is still read
    from /tf (it was refused: the transform was looked for in the first 30 s only), from
    there on, and the log's own odom -> base_link is known to the estimates (not
    written twice)."""
    start = None

    def late(m: LogMessage):
        nonlocal start
        if m.topic in ("/joint_states", "/odom"):
            return []
        start = m.t if start is None else start
        if m.topic == "/tf" and m.t < start + 40.0:  # another frame's transform only
            ts = m.msg.transforms[0]
            wheel = M.transform_stamped(0.0, "base_link", "wheel", 0.0, 0.1, 0.0, 0.0)
            wheel.header.stamp = ts.header.stamp
            m.msg.transforms = [wheel]
        return [(m.topic, m.typename, m.msg, m.t)]

    log = rewrite(SAMPLE, tmp_path / "late.mcap", late)
    code, out, err = cli("run", log, "-o", tmp_path / "est")
    assert code == 0, err
    assert NOTE in err and json.loads(out)["odometry_source"] == "tf (/tf odom -> base_link)"
    with open(tmp_path / "est" / "estimates.mcap", "rb") as f:
        from mcap.reader import make_reader

        pairs = {
            (ts.header.frame_id, ts.child_frame_id)
            for _s, _c, _m, msg in make_reader(
                f, decoder_factories=[DecoderFactory()]
            ).iter_decoded_messages(topics=["/tf"])
            for ts in msg.transforms
        }
    assert ("map", "odom") in pairs and ("odom", "base_link") not in pairs
