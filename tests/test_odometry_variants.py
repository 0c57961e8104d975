"""Wheel odometry as real robots record it (slam/inputs.py, slam/log_setup.py): the tiny
simulated log (tests/test_robust_logs.py's ``tiny``) rewritten as another driver would
have published its /joint_states, run with ``fuzzyslam run``. Each variant either gives
the clean log's estimate or is said in one line, never a silent wrong estimate.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from test_robust_logs import JOINTS, Tiny, cli, error_lines, keep, load_tum, rewrite, tiny

from fuzzyslam.streams.reader import LogMessage

__all__ = ["tiny"]  # the session fixture, shared with test_robust_logs.py

ODOM = "/odom"


def joints(change):
    """A rewrite fault that passes each /joint_states message through ``change(msg)``."""

    def fault(m: LogMessage):
        if m.topic == JOINTS:
            change(m.msg)
        return keep(m)

    return fault


@pytest.mark.parametrize("low", [-math.pi, 0.0], ids=["pm_pi", "zero_2pi"])
def test_wheel_angles_published_wrapped_give_the_unwrapped_run(
    tiny: Tiny, tmp_path: Path, low: float
) -> None:
    def wrap(msg) -> None:
        msg.position = np.remainder(np.asarray(msg.position) - low, math.tau) + low

    log = rewrite(tiny.log, tmp_path / "wrapped.mcap", joints(wrap))
    code, out, err = cli("run", log, "-o", tmp_path / "est", "--config", tiny.config)
    assert code == 0, err
    s = json.loads(out)
    assert s["warnings"]["wheel_angle_wraps"] > 10  # the wheels turned many times
    assert "implausible_odometry" not in s["warnings"]
    assert s["counts"]["odometry"] == tiny.run["counts"]["odometry"]
    got, want = load_tum(tmp_path / "est" / "odometry.tum"), load_tum(tiny.est / "odometry.tum")
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-9)
    got = load_tum(tmp_path / "est" / "trajectory.tum")
    np.testing.assert_allclose(got, load_tum(tiny.est / "trajectory.tum"), rtol=0, atol=1e-6)


def other_names(msg) -> None:
    msg.name = ["left_wheel_joint", "right_wheel_joint"]


def velocities_only(msg) -> None:
    msg.velocity, msg.position = np.ones(2), np.zeros(0)


def split(m: LogMessage):
    if m.topic != JOINTS:
        return keep(m)
    out = []
    for k in range(2):
        msg = type(m.msg)(
            header=m.msg.header,
            name=[m.msg.name[k]],
            position=np.asarray(m.msg.position)[k : k + 1],
            velocity=np.zeros(0),
            effort=np.zeros(0),
        )
        out.append((m.topic, m.typename, msg, m.t))
    return out


VARIANTS = {
    "other_names": (joints(other_names), "left_wheel_joint, right_wheel_joint"),
    "velocities_only": (joints(velocities_only), "velocities only"),
    "separate_messages": (split, "separate messages"),
}


@pytest.mark.parametrize("variant", list(VARIANTS))
def test_unreadable_wheel_joints_fall_back_to_odometry_and_say_so(
    tiny: Tiny, tmp_path: Path, variant: str
) -> None:
    fault, why = VARIANTS[variant]
    log = rewrite(tiny.log, tmp_path / "joints.mcap", fault)
    code, out, err = cli("run", log, "-o", tmp_path / "est", "--config", tiny.config)
    assert code == 0, err
    s = json.loads(out)
    assert s["odometry_source"] == f"odom ({ODOM})"
    (line,) = [ln for ln in error_lines(err) if JOINTS in ln]
    assert why in line and f"read from {ODOM}" in line
    # the log's /odom is the dead reckoning of the same encoders
    got = load_tum(tmp_path / "est" / "trajectory.tum")
    np.testing.assert_allclose(got, load_tum(tiny.est / "trajectory.tum"), rtol=0, atol=1e-3)


def test_unreadable_wheel_joints_without_odometry_are_one_line_naming_them(
    tiny: Tiny, tmp_path: Path
) -> None:
    def fault(m: LogMessage):
        if m.topic in (ODOM, "/tf"):  # nor odom -> base_link on /tf to read instead
            return []
        if m.topic == JOINTS:
            other_names(m.msg)
        return keep(m)

    log = rewrite(tiny.log, tmp_path / "joints.mcap", fault)
    code, out, err = cli("run", log, "-o", tmp_path / "est", "--config", tiny.config)
    assert code == 3 and out == ""
    (line,) = error_lines(err)
    assert str(log) in line and "left_wheel_joint, right_wheel_joint" in line
    assert "wheel_left_joint and wheel_right_joint" in line and "topics.odom" in line
    assert not (tmp_path / "est").exists()


def test_extra_joints_and_any_order_read_the_two_wheels(tiny: Tiny, tmp_path: Path) -> None:
    def extra(msg) -> None:
        left, right = np.asarray(msg.position)
        msg.name = ["caster_joint", "wheel_right_joint", "arm_joint", "wheel_left_joint"]
        msg.position = np.array([0.3, right, 1.0, left])

    log = rewrite(tiny.log, tmp_path / "extra.mcap", joints(extra))
    code, out, err = cli("run", log, "-o", tmp_path / "est", "--config", tiny.config)
    assert code == 0, err
    assert json.loads(out)["odometry_source"] == f"encoders ({JOINTS})"
    got = (tmp_path / "est" / "trajectory.tum").read_bytes()
    assert got == (tiny.est / "trajectory.tum").read_bytes()


def test_wheel_joints_named_in_the_config_are_the_encoders(tiny: Tiny, tmp_path: Path) -> None:
    """A robot whose /joint_states name the wheels otherwise (ros2_control's
    left_wheel_joint, right_wheel_joint), with ``robot.left_wheel_joint`` and
    ``right_wheel_joint`` saying so: its encoders are read, the clean run's estimate, no
    note (without them it falls back to /odom: the test above)."""
    log = rewrite(tiny.log, tmp_path / "named.mcap", joints(other_names))
    (tmp_path / "tiny.yaml").write_text(tiny.config.read_text(encoding="utf-8"), "utf-8")
    cfg = tmp_path / "named.yaml"
    cfg.write_text(
        "extends: tiny.yaml\nrobot:\n  left_wheel_joint: left_wheel_joint\n"
        "  right_wheel_joint: right_wheel_joint\n",
        encoding="utf-8",
    )
    code, out, err = cli("run", log, "-o", tmp_path / "est", "--config", cfg)
    assert code == 0, err
    assert "note:" not in err
    s = json.loads(out)
    assert s["odometry_source"].startswith("encoders")
    got = load_tum(tmp_path / "est" / "trajectory.tum")
    np.testing.assert_allclose(got, load_tum(tiny.est / "trajectory.tum"), rtol=0, atol=1e-9)


def test_a_gap_in_the_first_wheel_turn_is_motion_not_a_wrap(tiny: Tiny, tmp_path: Path) -> None:
    """The encoder messages of 0.05-0.6 s dropped: the wheels turn over pi in the gap
    while their angles are still within the first turn, as a wrap would look, but at a
    rate the wheels can turn: motion, not a wrap (it was unwrapped into a step backwards:
    the dead reckoning 0.31 m short at the end)."""

    def gap(m: LogMessage):
        if (
            m.topic == JOINTS
            and 0.05 < m.msg.header.stamp.sec + 1e-9 * m.msg.header.stamp.nanosec < 0.6
        ):
            return []
        return keep(m)

    log = rewrite(tiny.log, tmp_path / "gap.mcap", gap)
    code, out, err = cli("run", log, "-o", tmp_path / "est", "--config", tiny.config)
    assert code == 0, err
    assert "wheel_angle_wraps" not in json.loads(out)["warnings"]
    got, want = load_tum(tmp_path / "est" / "odometry.tum"), load_tum(tiny.est / "odometry.tum")
    assert np.hypot(*(got[-1, 1:3] - want[-1, 1:3])) < 0.02


def test_odometry_that_stops_mid_log_is_said(tiny: Tiny, tmp_path: Path) -> None:
    """/odom (the encoders dropped) whose driver stops 20 s into the log, its odom ->
    base_link on /tf with it (no other odometry to read: tests/test_odometry_sources_cut.py),
    while the camera goes on: the frames after it are skipped (an estimate held still,
    flagged events_lost) and one line on stderr says the odometry fell silent (it said
    only that the filter looked lost)."""
    start = None

    def stop(m: LogMessage):
        nonlocal start
        start = m.t if start is None else start
        if m.topic == JOINTS or (m.topic in (ODOM, "/tf") and m.t > start + 20.0):
            return []
        return keep(m)

    log = rewrite(tiny.log, tmp_path / "stop.mcap", stop)
    code, out, err = cli("run", log, "-o", tmp_path / "est", "--config", tiny.config)
    assert code == 0, err
    s = json.loads(out)
    assert s["counts"]["frames_stale_odometry"] > 10
    said = [ln for ln in err.splitlines() if "fell silent" in ln]
    assert len(said) == 1 and "odom (/odom)" in said[0]
    assert f"{s['counts']['frames_stale_odometry']} frames skipped" in said[0]


def test_encoder_ticks_instead_of_radians_are_one_line_saying_so(
    tiny: Tiny, tmp_path: Path
) -> None:
    """Wheel angles published as raw encoder ticks (4096 a turn), not radians: every
    increment is faster than the robot can move; one line says so and what to check
    (it said only "no usable odometry")."""

    def ticks(msg) -> None:
        msg.position = np.round(np.asarray(msg.position) * 4096 / math.tau)

    log = rewrite(tiny.log, tmp_path / "ticks.mcap", joints(ticks))
    code, out, err = cli("run", log, "-o", tmp_path / "est", "--config", tiny.config)
    (line,) = error_lines(err)
    assert code == 3 and out == "" and str(log) in line
    assert "faster than the robot can move" in line and "radians" in line
