"""Sensor mounts from /tf_static (streams/tf.py): chains composed up to the robot's base
frame, full 3D rotations projected onto the base plane (an upside-down laser is not
mirrored), and trees that cannot place a sensor refused with one clear line.

Every expected value is computed by hand from the offsets and angles written here.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from test_robust_logs import rewrite

from fuzzyslam.config import load_config
from fuzzyslam.errors import InputError
from fuzzyslam.streams import messages as M
from fuzzyslam.streams.ranges import open_ranges
from fuzzyslam.streams.reader import LogReader
from fuzzyslam.streams.scan import scan_geometry
from fuzzyslam.streams.sonar import RingStats, mounts_of_frames
from fuzzyslam.streams.tf import (
    Rigid,
    TfProblem,
    compose_to_base,
    constant_transforms,
    frame_mounts,
    locate,
    quaternion_matrix,
    static_tree,
)
from fuzzyslam.streams.writer import LogWriter

PI = math.pi


def quat(roll: float = 0.0, pitch: float = 0.0, yaw: float = 0.0) -> tuple[float, ...]:
    """(x, y, z, w) of R = Rz(yaw) Ry(pitch) Rx(roll) (the ROS / URDF rpy order)."""
    cr, sr = math.cos(roll / 2), math.sin(roll / 2)
    cp, sp = math.cos(pitch / 2), math.sin(pitch / 2)
    cy, sy = math.cos(yaw / 2), math.sin(yaw / 2)
    return (
        sr * cp * cy - cr * sp * sy,
        cr * sp * cy + sr * cp * sy,
        cr * cp * sy - sr * sp * cy,
        cr * cp * cy + sr * sp * sy,
    )


def link(parent, child, x=0.0, y=0.0, z=0.0, roll=0.0, pitch=0.0, yaw=0.0, q=None):
    """A TransformStamped parent -> child with a full 3D rotation (rpy or quaternion q)."""
    ts = M.transform_stamped(0.0, parent, child, x, y, z, 0.0)
    r = ts.transform.rotation
    r.x, r.y, r.z, r.w = q if q is not None else quat(roll, pitch, yaw)
    return ts


def tf(*links):
    return M.tf_message(list(links))


def wrap(a):
    return np.arctan2(np.sin(a), np.cos(a))


# --- (a) chains are composed --------------------------------------------------------------

CHAIN = tf(
    link("base_footprint", "base_link", 0.05, 0.0, 0.1, yaw=0.1),
    link("base_link", "laser_mount", 0.2, 0.1, 0.05, yaw=PI / 2),
    link("laser_mount", "laser", 0.1, 0.0, 0.02, yaw=PI / 4),
)


def test_a_three_link_chain_composes_to_the_hand_computed_mount():
    """laser in laser_mount (0.1, 0) at pi/4; laser_mount in base_link (0.2, 0.1) at
    pi/2: the laser sits at (0.2, 0.1) + Rz(pi/2) (0.1, 0) = (0.2, 0.2), heading 3 pi/4,
    not at its immediate parent's (0.1, 0, pi/4). Up to base_footprint, once more."""
    mounts, missing, problems = mounts_of_frames([CHAIN], {"/scan": "laser"}, base="base_link")
    assert not missing and not problems
    assert np.allclose(mounts[0], [0.2, 0.2, 3 * PI / 4])
    mounts, _, _ = mounts_of_frames([CHAIN], {"/scan": "laser"}, base="base_footprint")
    c, s = math.cos(0.1), math.sin(0.1)
    want = [0.05 + 0.2 * c - 0.2 * s, 0.2 * s + 0.2 * c, 3 * PI / 4 + 0.1]
    assert np.allclose(mounts[0], want)
    z = compose_to_base(static_tree([CHAIN]), "laser", "base_footprint").translation[2]
    assert z == pytest.approx(0.1 + 0.05 + 0.02)


def test_a_repeated_child_keeps_the_later_transform_and_the_base_is_its_own_mount():
    first = tf(link("base_link", "sonar_0", 0.3, 0.0, yaw=0.0))
    later = tf(link("base_link", "sonar_0", 0.1, -0.2, yaw=-1.0))
    mounts, missing, problems = mounts_of_frames([first, later], {"/sonar/s00": "sonar_0"})
    assert np.allclose(mounts[0], [0.1, -0.2, -1.0]) and not missing and not problems
    tree = static_tree([first])
    assert np.allclose(compose_to_base(tree, "base_link", "base_link").rotation, np.eye(3))
    assert compose_to_base(tree, "nowhere", "base_link") is None


# --- (b) the full rotation: an upside-down laser is not mirrored ----------------------------


def test_b_quaternion_matrix_is_normalised_and_refuses_a_zero_quaternion():
    q = 3.0 * np.array(quat(roll=PI))
    assert np.allclose(quaternion_matrix(q), np.diag([1.0, -1.0, -1.0]))
    assert np.allclose(quaternion_matrix(quat(yaw=PI / 2)), [[0, -1, 0], [1, 0, 0], [0, 0, 1]])
    with pytest.raises(TfProblem, match="zero"):
        quaternion_matrix([0.0, 0.0, 0.0, 0.0])


def test_b_beams_of_an_upside_down_laser_run_clockwise():
    """Roll pi: beam a in the laser frame points at -a in the base frame (plus the mount
    yaw); an identity mount keeps the angles."""
    msg = M.laser_scan(0.0, "laser", np.ones(13), -PI / 2, PI / 12)
    geom = scan_geometry(msg)
    a = geom.angles
    ident = geom.mounts(Rigid())
    assert np.allclose(ident[:, 2], a) and np.allclose(ident[:, :2], 0.0)
    for yaw in (0.0, 0.4, PI / 2):
        tree = static_tree([tf(link("base_link", "laser", 0.1, -0.05, 0.3, roll=PI, yaw=yaw))])
        beams = geom.mounts(compose_to_base(tree, "laser"))
        assert np.allclose(beams[:, 2], wrap(yaw - a), atol=1e-12)
        assert np.allclose(beams[:, :2], [0.1, -0.05])
    # the same through a quaternion written as (1, 0, 0, 0): roll pi about x
    tree = static_tree([tf(link("base_link", "laser", q=(1.0, 0.0, 0.0, 0.0)))])
    assert np.allclose(geom.mounts(compose_to_base(tree, "laser"))[:, 2], -a)


def test_b_a_sonar_tilted_near_vertical_or_a_zero_quaternion_is_refused():
    """A sonar looking 85 deg up has no planar heading; one tilted 30 deg down keeps its
    yaw; a zero quaternion is a problem of its frame."""
    msgs = [
        tf(
            link("base_link", "up", 0.1, 0.0, pitch=-math.radians(85.0), yaw=0.3),
            link("base_link", "down", 0.1, 0.0, pitch=math.radians(30.0), yaw=0.3),
            link("base_link", "zero", 0.1, 0.0, q=(0.0, 0.0, 0.0, 0.0)),
        )
    ]
    frames = {"/sonar/s00": "up", "/sonar/s01": "down", "/sonar/s02": "zero"}
    mounts, missing, problems = mounts_of_frames(msgs, frames)
    assert not missing and set(problems) == {"/sonar/s00", "/sonar/s02"}
    assert "85 deg out of the base plane" in problems["/sonar/s00"]
    assert "zero" in problems["/sonar/s02"] and "'zero'" in problems["/sonar/s02"]
    assert np.allclose(mounts[1], [0.1, 0.0, 0.3])
    assert np.isnan(mounts[[0, 2]]).all()


# --- (c) a chain that does not reach the base -------------------------------------------------


def test_c_a_tree_without_the_base_composes_to_its_root_and_names_it():
    """robot -> mount -> sonar_0 with base "base_link" nowhere in the tree: the mount in
    "robot", which is reported as standing in for the base."""
    msg = tf(
        link("robot", "mount", 0.2, 0.0, yaw=PI / 2),
        link("mount", "sonar_0", 0.1, 0.0, yaw=0.25),
    )
    stand_ins: dict[str, str] = {}
    mounts, missing, problems = mounts_of_frames(
        [msg], {"/sonar/s00": "sonar_0"}, "base_link", stand_ins
    )
    assert not missing and not problems
    assert np.allclose(mounts[0], [0.2, 0.1, PI / 2 + 0.25])
    assert stand_ins == {"/sonar/s00": "robot"}
    assert locate(static_tree([msg]), "mount", "base_link")[1] == "robot"
    assert locate(static_tree([msg]), "robot", "robot")[1] is None


@pytest.mark.parametrize(
    ("links", "base", "root"),
    [
        # pan_tilt has no static parent; base_link carries the other sensors
        ([link("pan_tilt", "laser", 0.1, yaw=PI), link("base_link", "sonar_0", 0.2)],
         "base_link", "pan_tilt"),
        # a static odom -> laser by mistake, base_link elsewhere
        ([link("odom", "laser", 1.0, 2.0, yaw=1.0), link("base_link", "sonar_0", 0.2)],
         "base_link", "odom"),
        # base_link under another root
        ([link("chassis", "laser", 0.1), link("base_footprint", "base_link", 0.1)],
         "base_link", "chassis"),
        # the base nowhere in the tree, but the root is a world frame (REP 105)
        ([link("odom", "laser", 1.0, 2.0, yaw=1.0)], "base_footprint", "odom"),
        ([link("/map", "laser", 1.0)], "base_link", "map"),
    ],
    ids=["pan_tilt", "odom", "other_root", "odom_no_base", "map_no_base"],
)  # fmt: skip
def test_c_a_sensor_not_connected_to_the_base_is_refused(links, base, root):
    """A sensor whose chain ends at a root that is not the base, while the base is in the
    tree (or the root is a world-fixed frame), cannot be placed: one clear line, never
    the mount in the root as if it were the base (the old code placed the laser so)."""
    with pytest.raises(TfProblem) as exc:
        compose_to_base(static_tree([tf(*links)]), "laser", base)
    assert str(exc.value) == (
        f"frame 'laser' is not connected to the base frame {base!r} in /tf_static "
        f"(its chain ends at {root!r})"
    )


def test_c_a_sibling_branch_is_expressed_in_the_base():
    """base_footprint -> base_link (0.1, 0, yaw 0.2) and base_footprint -> sonar_0
    (0.3, 0.1, yaw 0.5): in base_link, Rz(-0.2) (0.2, 0.1) at yaw 0.3."""
    msg = tf(
        link("base_footprint", "base_link", 0.1, 0.0, 0.05, yaw=0.2),
        link("base_footprint", "sonar_0", 0.3, 0.1, 0.2, yaw=0.5),
    )
    mounts, _, problems = mounts_of_frames([msg], {"/sonar/s00": "sonar_0"}, "base_link")
    c, s = math.cos(0.2), math.sin(0.2)
    assert not problems
    assert np.allclose(mounts[0], [c * 0.2 + s * 0.1, -s * 0.2 + c * 0.1, 0.3])


def test_c_open_ranges_refuses_a_disconnected_laser_and_names_a_stand_in_root(tmp_path):
    """End to end: a laser under pan_tilt while the sonars hang under base_link is one
    InputError line; a tree base_link -> laser read with the odometry's base_footprint
    places the laser in base_link and says so in mounts_source."""
    cfg = load_config("quick.yaml")
    log = tmp_path / "disc.mcap"
    _scan_log(log, [link("pan_tilt", "laser", 0.1), link("base_link", "sonar_0")], [1.0] * 5,
              "base_link")  # fmt: skip
    with pytest.raises(InputError) as exc:
        open_ranges(LogReader(log), cfg, "scan", base="base_link")
    msg = str(exc.value)
    assert "\n" not in msg and msg.endswith(
        "/tf_static cannot place /scan (frame 'laser'): frame 'laser' is not connected to "
        "the base frame 'base_link' in /tf_static (its chain ends at 'pan_tilt')"
    )
    other = tmp_path / "bfp.mcap"
    _scan_log(other, [link("base_link", "laser", 0.1, 0.2, 0.3)], [1.0] * 5, "base_footprint")
    sensor = open_ranges(LogReader(other), cfg, "scan", base="base_footprint")
    assert np.allclose(sensor.mounts[:, :2], [0.1, 0.2])
    assert sensor.describe()["mounts_source"] == (
        "/tf_static (root 'base_link' taken as the base frame 'base_footprint')"
    )


# --- (d) trees that cannot place a sensor -------------------------------------------------


def test_d_a_cycle_or_a_child_with_two_parents_is_a_clear_problem():
    cycle = tf(link("a", "b", 1.0), link("b", "c", 1.0), link("c", "a", 1.0))
    _, missing, problems = frame_mounts([cycle], {"/sonar/s00": "a"}, "base_link")
    assert not missing and "cycle" in problems["/sonar/s00"]
    assert "a -> b -> c -> a" in problems["/sonar/s00"]
    two = [tf(link("base_link", "laser", 0.1)), tf(link("laser_mount", "laser", 0.2))]
    _, _, problems = frame_mounts(two, {"/scan": "laser"}, "base_link")
    p = problems["/scan"]
    assert "two parents" in p and "'base_link'" in p and "'laser_mount'" in p


def test_d_open_ranges_refuses_a_cycle_in_one_line(tmp_path: Path):
    log = tmp_path / "cycle.mcap"
    with LogWriter(log) as w:
        w.write("/tf_static", M.TF_MESSAGE, tf(link("laser", "x"), link("x", "laser")), 0.0)
        w.write("/scan", M.LASER_SCAN, M.laser_scan(0.5, "laser", np.ones(5), -0.5, 0.25), 0.5)
    with pytest.raises(InputError) as exc:
        open_ranges(LogReader(log), load_config("quick.yaml"), "scan")
    msg = str(exc.value)
    assert "/tf_static cannot place /scan (frame 'laser')" in msg and "cycle" in msg
    assert "\n" not in msg


# --- (e) end to end: an upside-down laser under a chain sees the world unmirrored ---------


def _scan_log(path: Path, links, ranges, base: str) -> None:
    with LogWriter(path) as w:
        w.write("/tf_static", M.TF_MESSAGE, tf(*links), 0.0)
        for k in range(3):
            t = 0.5 + 0.25 * k
            w.write("/odom", M.ODOMETRY, M.odometry(t, "odom", base, np.zeros(3)), t)
            msg = M.laser_scan(t, "laser", ranges, -PI / 2, PI / 18)
            w.write("/scan", M.LASER_SCAN, msg, t)


def test_e_upside_down_laser_under_a_chain_matches_a_flat_one(tmp_path: Path):
    """chassis -> laser_mount (0.1, 0.05, yaw 0.3) -> laser (0.05, 0, roll pi): beam a
    at (0.1 + 0.05 cos 0.3, 0.05 + 0.05 sin 0.3) heading 0.3 - a. A flat laser at the
    same place with its beams in reverse order sees the same (heading, range) pairs."""
    n = 19
    ranges = 1.0 + 0.1 * np.arange(n)
    cfg = load_config("quick.yaml")
    flipped, flat = tmp_path / "flipped.mcap", tmp_path / "flat.mcap"
    _scan_log(
        flipped,
        [
            link("base_footprint", "chassis", 0.0, 0.0, 0.1),
            link("chassis", "laser_mount", 0.1, 0.05, 0.2, yaw=0.3),
            link("laser_mount", "laser", 0.05, 0.0, 0.1, roll=PI),
        ],
        ranges,
        "chassis",
    )
    x, y = 0.1 + 0.05 * math.cos(0.3), 0.05 + 0.05 * math.sin(0.3)
    _scan_log(flat, [link("chassis", "laser", x, y, 0.3, yaw=0.3)], ranges[::-1], "chassis")
    a = np.float32(-PI / 2) + np.arange(n) * np.float64(np.float32(PI / 18))

    pairs = []
    for log in (flipped, flat):
        sensor = open_ranges(LogReader(log), cfg, "scan", base="chassis")
        assert sensor.kind == "scan" and np.allclose(sensor.mounts[:, :2], [x, y])
        ring = next(iter(sensor.rings(LogReader(log).messages(sensor.topics), RingStats())))
        order = np.argsort(sensor.mounts[:, 2])
        pairs.append(np.column_stack([sensor.mounts[order, 2], ring.ranges[order]]))
        if log == flipped:
            assert np.allclose(sensor.mounts[:, 2], 0.3 - a)
    assert np.allclose(pairs[0], pairs[1], atol=1e-5)


def test_decimation_keeps_the_same_beams_whichever_way_they_are_listed():
    """A laser listing 20 beams counter-clockwise and one listing them clockwise (negative
    angle increment), every 4th kept: the same beam angles (19 is not a multiple of 4,
    so counting from the first beam of each would keep different beams)."""
    from types import SimpleNamespace

    from fuzzyslam.streams.scan import scan_geometry

    n, inc = 20, math.radians(5.0)
    ccw = SimpleNamespace(header=SimpleNamespace(frame_id="laser"), angle_min=-0.8,
                          angle_increment=inc, ranges=[1.0] * n, time_increment=0.0)  # fmt: skip
    cw = SimpleNamespace(header=SimpleNamespace(frame_id="laser"), angle_min=-0.8 + (n - 1) * inc,
                         angle_increment=-inc, ranges=[1.0] * n, time_increment=0.0)  # fmt: skip
    a = np.sort(scan_geometry(ccw, step=4).angles)
    b = np.sort(scan_geometry(cw, step=4).angles)
    assert len(a) == len(b) == 5 and np.allclose(a, b) and a[0] == pytest.approx(-0.8)


# --- (e) mounts broadcast on /tf (ROS 1's static_transform_publisher) ----------------------

EXCERPT = Path(__file__).resolve().parents[1] / "data" / "carmen_fr079_excerpt"


def test_e_constant_transforms_keep_what_never_moves():
    """Of a /tf stream: a mount republished with float jitter (1e-6) is kept once, as first
    seen; the odometry's moving odom -> base_link, a mount that moves 5 mm once, one that
    turns by 0.2 deg once and a child under two parents are left out."""
    msgs = []
    for k in range(50):
        t = 0.1 * k
        jitter = 1e-6 * (-1) ** k
        msgs.append(
            tf(
                link("odom", "base_link", 0.01 * k, 0.0, yaw=0.002 * k),
                link("base_link", "laser", 0.2 + jitter, -0.1, 0.3, roll=PI),
                link("base_link", "pan", 0.1 + (0.005 if k == 30 else 0.0)),
                link("base_link", "tilt", yaw=math.radians(0.2) if k == 40 else 0.0),
                link("base_link" if k % 2 else "base_footprint", "camera", 0.1),
            )
        )
        for ts in msgs[-1].transforms:
            ts.header.stamp = M.header(t, "x").stamp
    kept = constant_transforms(msgs)
    assert [(ts.header.frame_id, ts.child_frame_id) for ts in kept] == [("base_link", "laser")]
    assert kept[0].transform.translation.x == pytest.approx(0.2 + 1e-6, abs=1e-12)


def _mounts_on_tf(path: Path, pan: bool = False) -> Path:
    """The excerpt with its /tf_static mounts moved to /tf, republished with every /odom
    message beside the odometry's odom -> base_link (a ROS 1 log's static_transform_publisher);
    ``pan``: the laser's mount turning (a pan unit), no longer a mount."""
    mounts = [m.msg for m in LogReader(EXCERPT / "log.mcap").messages(["/tf_static"])]
    links = [ts for msg in mounts for ts in msg.transforms]

    def fault(m):
        if m.topic == "/tf_static":
            return []
        if m.topic != "/odom":
            return [(m.topic, m.typename, m.msg, m.t)]
        p = m.msg.pose.pose.position
        odo = link("odom", "base_link", p.x, p.y)
        now = [odo, *links]
        if pan:
            turn = link("base_link", "laser", yaw=0.3 * math.sin(m.t))
            now = [odo, turn, *(ts for ts in links if ts.child_frame_id != "laser")]
        return [(m.topic, m.typename, m.msg, m.t), ("/tf", M.TF_MESSAGE, tf(*now), m.t)]

    return rewrite(EXCERPT / "log.mcap", path, fault)


def test_e_sensors_placed_by_tf_mounts_as_by_tf_static(tmp_path: Path):
    """The excerpt's laser and 9 sonars, their mounts on /tf instead of /tf_static: the
    same mounts, said to come from /tf; a laser whose /tf mount turns is refused in one
    line that says /tf was looked at."""
    cfg = load_config("real_building_scan.yaml")
    log = _mounts_on_tf(tmp_path / "tf.mcap")
    for kind in ("scan", "sonar"):
        a = open_ranges(LogReader(EXCERPT / "log.mcap"), cfg, kind)
        b = open_ranges(LogReader(log), cfg, kind)
        np.testing.assert_allclose(b.mounts, a.mounts, atol=1e-12)
        assert a.mounts_source == "/tf_static" and b.mounts_source == "/tf (constant transforms)"
        assert b.topics == a.topics and len(b.mounts) == (90 if kind == "scan" else 9)
    pan = _mounts_on_tf(tmp_path / "pan.mcap", pan=True)
    with pytest.raises(InputError) as e:
        open_ranges(LogReader(pan), cfg, "scan")
    assert "no /tf_static mount for /scan (frame 'laser'), nor a constant transform on /tf" in str(
        e.value
    )
    assert open_ranges(LogReader(pan), cfg, "sonar").mounts_source == "/tf (constant transforms)"


def test_e_a_scan_in_the_base_frame_needs_no_mount_and_says_so(tmp_path: Path):
    """No /tf_static and the scans stamped in base_link: the laser is the base (identity
    mounts), and ``mounts_source`` says no transform was needed instead of naming a
    /tf_static the log does not have."""

    def fault(m):
        if m.topic == "/tf_static":
            return []
        if m.topic == "/scan":
            m.msg.header.frame_id = "base_link"
        return [(m.topic, m.typename, m.msg, m.t)]

    log = rewrite(EXCERPT / "log.mcap", tmp_path / "base.mcap", fault)
    cfg = load_config("real_building_scan.yaml")
    s = open_ranges(LogReader(log), cfg, "scan")
    assert s.mounts_source == "none needed: /scan is in the base frame 'base_link'"
    a = open_ranges(LogReader(EXCERPT / "log.mcap"), cfg, "scan")  # its laser at the base
    np.testing.assert_allclose(s.mounts, a.mounts, atol=1e-12)
