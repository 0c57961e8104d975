"""Wheel encoders checked against the log's other odometry (slam/log_setup.py
``reversed_wheels``): a wheel whose angle runs backwards (a mirrored motor without the
driver's sign flip), or the two wheel joints swapped, is named in one line and the
other odometry (/odom, else /tf's odom -> base_link) is read instead.

The simulated log's /odom is the dead reckoning of its own encoders, so with a wheel
reversed the run must give, to 1e-9, the trajectory of the same log read from /odom
(the encoders dropped); the old choice read the reversed encoders, and only the
filter_health line said anything was wrong. A log with encoders alone is read as it is
(nothing to check them against).
"""

from __future__ import annotations

import copy
import json
import math
from pathlib import Path

import numpy as np
import pytest
from test_odometry_sources_cut import tiny_odom  # noqa: F401
from test_robust_logs import JOINTS, Tiny, cli, error_lines, keep, load_tum, rewrite, tiny  # noqa: F401

from fuzzyslam.config import load_config
from fuzzyslam.slam.log_setup import reversed_wheels
from fuzzyslam.streams.reader import LogMessage, LogReader

LEFT, RIGHT = "wheel_left_joint", "wheel_right_joint"
ODOM = "/odom"


def joints(change, drop: tuple[str, ...] = ()):
    """A ``rewrite`` fault: each JointState changed by ``change(names, positions)`` (which
    returns the new names and positions); the topics ``drop`` left out."""

    def fault(m: LogMessage):
        if m.topic in drop:
            return []
        if m.topic != JOINTS:
            return keep(m)
        msg = copy.deepcopy(m.msg)
        names, pos = change(list(msg.name), np.asarray(msg.position, dtype=np.float64))
        msg.name, msg.position = names, np.asarray(pos, dtype=np.float64)
        return [(m.topic, m.typename, msg, m.t)]

    return fault


def negate(joint: str):
    def change(names, pos):
        pos = pos.copy()
        pos[names.index(joint)] *= -1.0
        return names, pos

    return change


def swap(names, pos):
    return [{LEFT: RIGHT, RIGHT: LEFT}.get(n, n) for n in names], pos


def run(tiny: Tiny, tmp_path: Path, fault) -> tuple[dict, list[str]]:  # noqa: F811
    log = rewrite(tiny.log, tmp_path / "log.mcap", fault)
    code, out, err = cli("run", log, "-o", tmp_path / "est", "--config", tiny.config)
    assert code == 0, err
    return json.loads(out), [ln for ln in error_lines(err) if "note:" in ln]


@pytest.mark.parametrize("joint", [LEFT, RIGHT])
def test_a_reversed_wheel_is_named_and_odom_read_instead(
    tiny: Tiny,  # noqa: F811
    tiny_odom: Path,  # noqa: F811
    tmp_path: Path,
    joint: str,
) -> None:
    """One wheel's angle negated: one line names that wheel as reversed, says what to
    check and that /odom is read; the run is that of /odom (the old run read the
    encoders: a robot that spun where it drove straight)."""
    s, notes = run(tiny, tmp_path, joints(negate(joint)))
    assert s["odometry_source"] == "odom (/odom)"
    assert len(notes) == 1, notes
    other = RIGHT if joint == LEFT else LEFT
    assert f"{joint}'s angle runs against the motion /odom records" in notes[0]
    assert other + "'s" not in notes[0]
    assert "that wheel looks reversed" in notes[0] and "invert" in notes[0]
    assert notes[0].endswith("the odometry is read from /odom")
    got, want = (
        load_tum(tmp_path / "est" / "trajectory.tum"),
        load_tum(tiny_odom / "est" / "trajectory.tum"),
    )
    assert got.shape == want.shape and len(got) > 50
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-9)


@pytest.mark.slow
def test_swapped_wheel_joints_are_said(tiny: Tiny, tmp_path: Path) -> None:  # noqa: F811
    """The left and right joints' names swapped: the encoders turn against /odom; one
    line says the joints look swapped and names the config keys; /odom is read."""
    s, notes = run(tiny, tmp_path, joints(swap))
    assert s["odometry_source"] == "odom (/odom)"
    assert len(notes) == 1 and "look swapped" in notes[0], notes
    assert "robot.left_wheel_joint" in notes[0]


def test_a_reversed_wheel_is_checked_against_tf_without_odom(
    tiny: Tiny,  # noqa: F811
    tiny_odom: Path,  # noqa: F811
    tmp_path: Path,
) -> None:
    """No /odom: the encoders are checked against /tf's odom -> base_link, which is read
    instead (the same poses as /odom in the simulated log)."""
    s, notes = run(tiny, tmp_path, joints(negate(LEFT), drop=("/odom",)))
    assert s["odometry_source"] == "tf (/tf odom -> base_link)"
    assert len(notes) == 1 and f"{LEFT}'s angle runs against the motion /tf records" in notes[0]
    got, want = (
        load_tum(tmp_path / "est" / "trajectory.tum"),
        load_tum(tiny_odom / "est" / "trajectory.tum"),
    )
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-9)


def in_place(robot, change):
    """A ``rewrite`` fault: a robot that oscillates in place, theta = 0.6 sin(2 pi t / 4)
    at log time t (s), on /odom (pose (0, 0, theta)) and on its encoders (left -b theta /
    2r, right +b theta / 2r), the joints then changed by ``change(names, positions)``;
    the other topics as they are."""
    k = 0.5 * robot.wheel_base / robot.wheel_radius

    def fault(m: LogMessage):
        theta = 0.6 * math.sin(0.5 * math.pi * m.t)
        if m.topic == ODOM:
            msg = copy.deepcopy(m.msg)
            p, q = msg.pose.pose.position, msg.pose.pose.orientation
            p.x = p.y = p.z = q.x = q.y = 0.0
            q.z, q.w = math.sin(0.5 * theta), math.cos(0.5 * theta)
            return [(m.topic, m.typename, msg, m.t)]
        if m.topic != JOINTS:
            return keep(m)
        msg = copy.deepcopy(m.msg)
        names, pos = list(msg.name), np.asarray(msg.position, dtype=np.float64).copy()
        pos[names.index(LEFT)], pos[names.index(RIGHT)] = -k * theta, k * theta
        names, pos = change(names, pos)
        msg.name, msg.position = names, np.asarray(pos, dtype=np.float64)
        return [(m.topic, m.typename, msg, m.t)]

    return fault


def both(names, pos):
    return negate(RIGHT)(*negate(LEFT)(names, pos))


@pytest.mark.slow  # end to end, about 1 s: the fast tier stays under a minute
def test_swapped_joints_on_a_start_in_place_are_named_first(tiny: Tiny, tmp_path: Path) -> None:  # noqa: F811
    """Swapped joints and a start that turns in place: both wheels run against /odom
    (each follows the other's motion), which also two reversed wheels would do; the line
    names the swapped joints and the config keys first, reversed motors after (the
    unchecked line said "both wheels look reversed (a mirrored motor ...)" first). As
    recorded, the encoders pass."""
    cfg = load_config(tiny.config)
    said = {}
    for name, change in (("swapped", swap), ("both reversed", both), ("as recorded", None)):
        fault = in_place(cfg.robot, change or (lambda n, p: (n, p)))
        log = rewrite(tiny.log, tmp_path / f"{name}.mcap", fault)
        said[name] = reversed_wheels(LogReader(log), cfg)
    assert said["as recorded"] == ""
    for name in ("swapped", "both reversed"):  # the same angles: the same line
        line = said[name]
        assert f"{LEFT} and {RIGHT} look swapped (check robot.left_wheel_joint" in line, line
        assert line.index("look swapped") < line.index("reversed"), line
        assert "both wheels look reversed" not in line, line


def test_both_wheels_reversed_while_driving_are_said_so(tiny: Tiny, tmp_path: Path) -> None:  # noqa: F811
    """Both angles negated on the tiny log's start, which drives forwards: swapped joints
    would agree with /odom's forward motion, so the line says both wheels look reversed
    and not that the joints look swapped."""
    cfg = load_config(tiny.config)
    log = rewrite(tiny.log, tmp_path / "l.mcap", joints(both))
    line = reversed_wheels(LogReader(log), cfg)
    assert "both wheels look reversed" in line and "look swapped" not in line, line


@pytest.mark.slow
@pytest.mark.parametrize(
    ("name", "fault", "source"),
    [
        ("as recorded", joints(lambda n, p: (n, p)), "encoders (/joint_states)"),
        ("encoders alone", joints(negate(LEFT), drop=("/odom", "/tf")), "encoders (/joint_states)"),
    ],
)
def test_encoders_are_read_when_nothing_contradicts_them(
    tiny: Tiny,  # noqa: F811
    tmp_path: Path,
    name: str,
    fault,
    source: str,
) -> None:
    """Encoders that agree with /odom, and (reversed or not) encoders with no other
    odometry to check them against: read, with no line about the wheels."""
    s, notes = run(tiny, tmp_path, fault)
    assert s["odometry_source"] == source, name
    assert not any("wheel" in ln for ln in notes), notes
