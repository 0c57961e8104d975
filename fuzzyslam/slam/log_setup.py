"""What a log says before its events: the camera's calibration checked, the /tf frame
names of the estimates, the filter's start pose (the rules in
:mod:`fuzzyslam.slam.inputs`' docstring), the streams' start, the detections' mount
(:func:`detection_mount_of`), whether an Odometry carries its motion in its twist alone
(:func:`twist_only`), and the odometry's period and clock (:func:`odometry_clock`; the
other streams are checked against its clock as they are read,
``LogInputs._same_clock``). Used by :func:`fuzzyslam.slam.inputs.open_inputs`.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Iterable, Iterator
from types import SimpleNamespace
from typing import NamedTuple

import numpy as np

from fuzzyslam.camera import distortion_coefficients
from fuzzyslam.config import Config
from fuzzyslam.errors import InputError
from fuzzyslam.robot import WHEEL_NAMES, odometry_to_wheel_increments
from fuzzyslam.se2 import between, interpolate_poses, quaternion_to_yaw
from fuzzyslam.slam import tf_ahead
from fuzzyslam.slam.events import TfFrames
from fuzzyslam.slam.odom_gate import SPEED_MARGIN, OdomGate, first_plausible_pose
from fuzzyslam.streams import messages as M
from fuzzyslam.streams.logmeta import read_scenario
from fuzzyslam.streams.reader import LogMessage, LogReader
from fuzzyslam.streams.static_tf import static_messages
from fuzzyslam.streams.tf import Rigid, TfProblem, locate, static_tree

ODOM_GAP_S = 1.0  # odometry silent for longer than this: a gap (counted, motion kept)
GAP_PERIODS = 3.0  # ... or for this many of its periods (the median step), whichever is longer
# /odom silent for at least this share of the log's span (and a gap) while /tf's
# odom -> base goes on: read /tf instead (odom_cut_short; a shorter end is a shutdown)
CUT_SHORT_FRAC = 0.1
SLOW_ODOMETRY_S = 0.5  # odometry slower than this (its median step): a note (slam/stage.py)
# (CARMEN logs at 4.6 and 5.4 Hz localise as well as faster ones; ACES cut to 1.1 Hz not)
PERIOD_SAMPLES = 500  # odometry messages its period and clock are measured on
# rad: wheel angles published wrapped lie in (-pi, pi] or [0, 2 pi) (LogInputs._unwrapped)
WRAPPED_ANGLES = (-math.pi - 1e-9, math.tau + 1e-9)


def camera_info_problem(info) -> str | None:
    """Why a CameraInfo cannot be a pinhole ceiling camera (None if it can): a size
    that is not positive, focal lengths fx, fy that are not finite and positive or
    differ by more than 1 % (square pixels are assumed), a horizontal field of view
    outside [1, 179] degrees, a principal point that is not finite or is off the image,
    a lens distortion the camera cannot undo (``distortion_model`` and ``d``:
    :func:`fuzzyslam.camera.distortion_coefficients`; plumb_bob, rational_polynomial and
    equidistant can; any model with D all zeros is none).

    Parameters
    ----------
    info : sensor_msgs/CameraInfo
        The message (width, height, k: the 3x3 camera matrix row by row,
        distortion_model, d).

    Returns
    -------
    str or None
    """
    w, h = int(info.width), int(info.height)
    if not (0 < w <= 100_000 and 0 < h <= 100_000):
        return f"image size {w}x{h} is not a camera's"
    k = np.asarray(info.k, dtype=float).ravel()
    if k.shape != (9,) or not np.all(np.isfinite(k)):
        return "the camera matrix K must be nine finite numbers"
    fx, fy, cx, cy = k[0], k[4], k[2], k[5]
    if not (fx > 0 and fy > 0):
        return f"focal lengths must be > 0 (fx = {fx:.6g}, fy = {fy:.6g})"
    if abs(fx - fy) > 0.01 * max(fx, fy):
        return f"fx = {fx:.6g} and fy = {fy:.6g} differ (square pixels are assumed)"
    hfov = 2.0 * math.degrees(math.atan(w / (2.0 * fx)))
    if not 1.0 <= hfov <= 179.0:
        return f"focal length {fx:.6g} px gives a {hfov:.3g}-degree field of view"
    if not (-0.5 <= cx <= w - 0.5 and -0.5 <= cy <= h - 0.5):
        return f"principal point ({cx:.6g}, {cy:.6g}) is off the {w}x{h} image"
    try:
        distortion_coefficients(getattr(info, "distortion_model", ""), getattr(info, "d", ()))
    except ValueError as exc:
        return str(exc)
    return None


def first_message(reader: LogReader, topic: str):
    """The first message of ``topic`` (None when it has none).

    Parameters
    ----------
    reader : LogReader
        The log.
    topic : str
        The topic.

    Returns
    -------
    message or None
        The decoded message.
    """
    for m in reader.messages([topic]):
        return m.msg
    return None


def base_frame(reader: LogReader, cfg: Config) -> str:
    """The robot's base frame, in which the sensors' /tf_static mounts are expressed: that
    of the odometry a run of the log reads (:func:`odometry_source`, the one decision:
    the child frame of its nav_msgs/Odometry, the base frame of /tf's odom -> base, or
    ``base_link`` (REP 105) for the encoders), ``base_link`` for a log without odometry
    (a map built from a trajectory needs none).

    Parameters
    ----------
    reader : LogReader
        The log.
    cfg : Config
        The config (``topics``, ``slam.use_encoders``).

    Returns
    -------
    str
    """
    try:
        source = odometry_source(reader, cfg)
    except InputError:
        return TfFrames().base
    odom = source.topic if source.kind == "odom" else None
    return tf_frames(reader, cfg, odom, series=False, names=source.tf).base


JOINT_LOOK = 50  # JointState messages looked at for the wheels (joint_state_problem)


def joint_state_problem(
    reader: LogReader, topic: str, wheels: tuple[str, str] = WHEEL_NAMES
) -> str:
    """Why the wheel encoders of ``topic`` (sensor_msgs/JointState) cannot be read ('' when
    they can), from its first ``JOINT_LOOK`` messages: no message names both wheel joints
    (``wheels``; another robot's names, a skid-steer's four wheels, or the two
    wheels published in separate messages), or their positions are empty (a driver that
    fills only the velocities). Read as they are, each such message would be skipped,
    and the run would end with no odometry.

    Parameters
    ----------
    reader : LogReader
        The log.
    topic : str
        The JointState topic.
    wheels : (str, str)
        The left and right wheels' joint names (``robot.left_wheel_joint``,
        ``robot.right_wheel_joint``).

    Returns
    -------
    str
        One line ('' for none).
    """
    seen: list[str] = []
    for m in itertools.islice(reader.messages([topic]), JOINT_LOOK):
        names = [str(n) for n in m.msg.name]
        if all(w in names for w in wheels):
            if len(m.msg.position) < len(names) and len(m.msg.velocity):
                return "carries the wheels' velocities only (position empty)"
            return ""
        seen += [n for n in names if n not in seen]
    both = " and ".join(wheels)
    if all(w in seen for w in wheels):
        return f"carries {both} in separate messages, not both in one"
    return (
        f"names no joints {both} (it names: {', '.join(seen) or 'none'}; "
        "robot.left_wheel_joint / right_wheel_joint name them)"
    )


class OdometrySource(NamedTuple):
    """The odometry the filter reads (:func:`odometry_source`)."""

    topic: str
    kind: str  # encoders, odom or tf
    passed_over: str  # why the encoders were passed over ('' when they were not)
    tf: TfFrames | None  # kind tf: the odom and base frames of its transforms
    # kind tf in a log that has topics.odom: why /odom was passed over (odom_cut_short)
    odom_passed_over: str = ""


def odometry_source(reader: LogReader, cfg: Config) -> OdometrySource:
    """The odometry the filter reads: ``topics.joint_states`` (\"encoders\") when
    ``slam.use_encoders`` and the log has it and its wheels can be read
    (:func:`joint_state_problem`) and agree with the log's other odometry
    (:func:`reversed_wheels`), else ``topics.odom`` (\"odom\", nav_msgs/Odometry),
    unless it falls silent for a substantial part of the log (a gap and a tenth of it)
    while /tf's odom -> base goes on (:func:`odom_cut_short`),
    else the odom -> base transforms of ``topics.tf`` (\"tf\", as slam_toolbox and
    gmapping read it: a log of /scan and /tf alone; :func:`tf_odometry_frames`, read as
    Odometry poses by :func:`tf_odometry`). Decided once, for the whole run.

    Parameters
    ----------
    reader : LogReader
        The log.
    cfg : Config
        The config (``topics``, ``slam.use_encoders``).

    Returns
    -------
    OdometrySource
        The topic, the source (encoders, odom or tf), why the encoders were passed over
        ('' when they were not) and the /tf frames; InputError (one line, what to
        change) when none can be read.
    """
    tp = cfg.topics
    problem = ""
    if cfg.slam.use_encoders and reader.has(tp.joint_states):
        problem = joint_state_problem(reader, tp.joint_states, cfg.robot.wheel_joints)
        if not problem:
            problem = reversed_wheels(reader, cfg)
            if not problem:
                return OdometrySource(tp.joint_states, "encoders", "", None)
        else:
            problem = f"{tp.joint_states} {problem}"
    if reader.has(tp.odom):
        cut = odom_cut_short(reader, cfg)
        if cut is not None:
            return OdometrySource(tp.tf, "tf", problem, cut[0], cut[1])
        return OdometrySource(tp.odom, "odom", problem, None)
    frames = tf_odometry_frames(reader, cfg)
    if frames is not None:
        return OdometrySource(tp.tf, "tf", problem, frames)
    if problem:
        raise InputError(
            reader.path,
            f"{problem}: the wheel encoders are read from the angles of joints "
            f"{' and '.join(cfg.robot.wheel_joints)}, both in each message; record them so, or "
            f"record nav_msgs/Odometry (topics.odom) or odom -> base_link on {tp.tf}",
        )
    keys = "topics.joint_states / topics.odom" if cfg.slam.use_encoders else "topics.odom"
    looked = [tp.joint_states, tp.odom] if cfg.slam.use_encoders else [tp.odom]
    option = f"the config's {keys} / topics.tf"
    if not reader.has(tp.tf):
        reader.require([*looked, tp.tf], option)
    have = ", ".join(sorted(reader.topics)) or "none"
    raise InputError(
        reader.path,
        f"missing stream(s) {', '.join(looked)}, and {tp.tf} has no "
        f"{TfFrames().odom} -> {' or '.join(BASE_ALIASES)} transform "
        f"(set them in {option}; the log has: {have})",
    )


def odom_cut_short(reader: LogReader, cfg: Config) -> tuple[TfFrames, str] | None:
    """The /tf odometry to read instead of ``topics.odom`` when /odom covers markedly less
    of the log than /tf's odom -> base transforms (a driver whose /odom publisher stopped
    while its /tf broadcaster, or another node's, went on), with the reason in one line;
    None to read /odom.

    The rule is a substantial loss: /odom is silent for at least
    loss = max(gap, ``CUT_SHORT_FRAC`` of the log's span) after its last message, gap
    being the odometry's own (:func:`odometry_clock`: max(``ODOM_GAP_S``,
    ``GAP_PERIODS`` periods)), while /tf carries an odom -> base transform logged at
    least that long after /odom's last (it need not reach the log's end), and /tf's
    odometry starts no later than /odom's first message + gap (it loses nothing at the
    start). Read as /odom, such a run holds still from /odom's end on ("fell silent").
    A shorter shortfall is the end of a recording, not a lost driver: at shutdown the
    wheel driver often stops seconds before the node that broadcasts odom -> base (an
    EKF, robot_localization), and swapping the whole run's odometry for those seconds
    gains nothing (the run says the silence as "fell silent" instead). Cheap: /odom's
    last message comes from its last chunks (``LogReader.last_time``), and /tf is read
    from then on only until its first odom -> base; a log whose /odom reaches within
    max(``ODOM_GAP_S``, ``CUT_SHORT_FRAC`` of the span) of the log's end is not looked
    at further.

    Parameters
    ----------
    reader : LogReader
        The log.
    cfg : Config
        The config (``topics.odom``, ``topics.tf``).

    Returns
    -------
    (TfFrames, str) or None
        /tf's odometry frames (:func:`tf_odometry_frames`) and why /odom was passed over.
    """
    tp = cfg.topics
    if not reader.has(tp.tf):
        return None
    last = reader.last_time(tp.odom)
    share = CUT_SHORT_FRAC * (reader.end - reader.start)
    if last is None or last > reader.end - max(ODOM_GAP_S, share):
        return None  # /odom reaches (near) the log's end (or has no message: not this rule)
    frames = tf_odometry_frames(reader, cfg)
    if frames is None:
        return None
    pair = (frames.odom, frames.base)
    period = odometry_clock(reader, tp.odom)[0]
    gap = max(ODOM_GAP_S, GAP_PERIODS * period)
    loss = max(gap, share)
    if last > reader.end - loss:
        return None
    first_odom = next(iter(reader.messages([tp.odom])), None)
    first_tf = next(odometry_messages(reader, tp.tf, pair), None)
    if first_odom is None or first_tf is None or first_tf.t > first_odom.t + gap:
        return None
    later = tf_odometry(reader.messages([tp.tf], last + loss), tp.tf, pair)
    if next(later, None) is None:
        return None
    t0 = reader.start
    return frames, (
        f"{tp.odom} falls silent at {last - t0:.2f} s of the log's {reader.end - t0:.2f} s "
        f"(its driver stopped?) while {tp.tf}'s {pair[0]} -> {pair[1]} goes on"
    )


CHECK_PATH_M = 2.0  # m of the other odometry's first motion the encoders are checked on
CHECK_TURN_RAD = math.pi / 2  # ... and rad of turn (|d_rot| summed): a turn to compare
CHECK_MESSAGES = 5000  # of its messages read at most (a robot idle that long: no check)
CHECK_STEP_S = 0.25  # s: the grid both are compared on (latencies, rates differ)
CHECK_WHEEL_RAD = math.pi  # rad each wheel must turn (by both sources) for a verdict
CHECK_AGREE = 0.5  # |correlation| of a wheel's increments with the other's: a verdict


def reversed_wheels(reader: LogReader, cfg: Config) -> str:
    """Why the wheel encoders must not be read ('' when they may): a wheel whose angle
    runs against the motion the log's other odometry (``topics.odom``, else /tf's
    odom -> base) records over its first stretch of motion (``CHECK_PATH_M`` of path and
    ``CHECK_TURN_RAD`` of turn, at most ``CHECK_MESSAGES`` messages), in one line naming
    the wheel and what to check.

    A mirrored motor whose sign the driver does not flip publishes a wheel angle that
    runs backwards: read as it is, driving straight looks like spinning on the spot
    (d_rot = r (dR - dL) / b with dL of the wrong sign) and the run is wrong from the
    start. The other odometry's increments (d_trans, d_rot) on a ``CHECK_STEP_S`` grid
    give the wheel increments it implies, dL = (d_trans - b d_rot / 2) / r and
    dR = (d_trans + b d_rot / 2) / r (``robot.odometry_to_wheel_increments``, nominal r
    and b); each measured wheel's increments are compared with them by their
    correlation about zero, c = sum(d_meas d_implied) / sqrt(sum d_meas^2 sum
    d_implied^2) (+1: the same motion, -1: reversed; an error of r only scales the
    implied increments, one of b shifts them little). A wheel with c < -``CHECK_AGREE``
    is reversed; both wheels agreeing (c > ``CHECK_AGREE``) while the turns
    anti-correlate are the two joints swapped; both wheels reversed while each agrees
    with the other wheel's implied increments are named as swapped joints first (a
    start that turns in place, dL = -dR, where the two cannot be told apart and a wrong
    joint name is the likelier slip), then as two mirrored motors. No verdict (''), when
    either source or
    either wheel moves less than ``CHECK_WHEEL_RAD`` or the log has no other odometry.
    With a verdict :func:`odometry_source` reads the other odometry: the driver's own,
    which the robot drove by (a driver that applies its sign flip to its odometry but
    publishes the raw joint angles).

    Parameters
    ----------
    reader : LogReader
        The log.
    cfg : Config
        The config (``topics``, ``robot`` wheel joints, radius and base).

    Returns
    -------
    str
        One line ('' for none).
    """
    tp, robot = cfg.topics, cfg.robot
    pair = None
    other = tp.odom
    if not reader.has(tp.odom):
        frames = tf_odometry_frames(reader, cfg)
        if frames is None:
            return ""
        other, pair = tp.tf, (frames.odom, frames.base)
    t, poses = [], []
    path = turn = 0.0
    for m in itertools.islice(odometry_messages(reader, other, pair), CHECK_MESSAGES):
        p = M.pose_of(m.msg.pose.pose)
        if not np.all(np.isfinite(p)):
            continue
        if poses:
            path += math.hypot(p[0] - poses[-1][0], p[1] - poses[-1][1])
            turn += abs(math.remainder(p[2] - poses[-1][2], math.tau))
        t.append(m.t)
        poses.append(p)
        if path >= CHECK_PATH_M and turn >= CHECK_TURN_RAD:
            break
    if len(t) < 2 or t[-1] - t[0] < 2 * CHECK_STEP_S:
        return ""
    js_t, js = [], []
    left, right = robot.wheel_joints
    for m in reader.messages([tp.joint_states]):
        if m.t > t[-1]:
            break
        names = list(m.msg.name)
        pos = m.msg.position
        if left in names and right in names and len(pos) == len(names):
            js_t.append(m.t)
            js.append((pos[names.index(left)], pos[names.index(right)]))
    if len(js_t) < 2:
        return ""
    return _wheel_verdict(
        np.asarray(t), np.asarray(poses), np.asarray(js_t), np.asarray(js, dtype=float), cfg, other
    )


def _wheel_verdict(
    t: np.ndarray, poses: np.ndarray, js_t: np.ndarray, wheels: np.ndarray, cfg: Config, other: str
) -> str:
    """:func:`reversed_wheels`' comparison of the wheel angles ``wheels`` (M, 2: left,
    right, rad) logged at ``js_t`` (M,) with the poses ``poses`` (N, 3) of the odometry
    ``other`` logged at ``t`` (N,), on their common stretch; its line ('' for none)."""
    robot = cfg.robot
    # wheel angles published wrapped unwrapped, as LogInputs._unwrapped does: a jump over
    # pi, faster than the wheel can turn, between two angles both in WRAPPED_ANGLES
    d = np.diff(wheels, axis=0)
    rate = SPEED_MARGIN * (robot.max_speed + 0.5 * robot.max_turn_rate * robot.wheel_base)
    rate /= robot.wheel_radius
    lo, hi = WRAPPED_ANGLES
    inside = (wheels >= lo) & (wheels <= hi)
    wrapped = (np.abs(d) > np.maximum(math.pi, rate * np.diff(js_t))[:, None]) & (
        inside[1:] & inside[:-1]
    )
    d = np.where(wrapped, np.remainder(d + math.pi, math.tau) - math.pi, d)
    ang = np.vstack([wheels[:1], wheels[:1] + np.cumsum(d, axis=0)])
    lo, hi = max(t[0], js_t[0]), min(t[-1], js_t[-1])
    if hi - lo < 2 * CHECK_STEP_S:
        return ""
    grid = np.arange(lo, hi + 1e-9, CHECK_STEP_S)
    p = interpolate_poses(t, poses, grid)
    rel = between(p[:-1], p[1:])  # each step in the frame of its start: (d_trans, ., d_rot)
    want_l, want_r = odometry_to_wheel_increments(
        rel[:, 0], rel[:, 2], robot.wheel_radius, robot.wheel_base
    )
    got_l = np.diff(np.interp(grid, js_t, ang[:, 0]))
    got_r = np.diff(np.interp(grid, js_t, ang[:, 1]))
    moved = [np.sum(np.abs(v)) for v in (want_l, want_r, got_l, got_r)]
    if min(moved) < CHECK_WHEEL_RAD:
        return ""

    def corr(a: np.ndarray, b: np.ndarray) -> float:
        return float(np.dot(a, b) / math.sqrt(np.dot(a, a) * np.dot(b, b)))

    c_l, c_r = corr(got_l, want_l), corr(got_r, want_r)
    b = robot.wheel_base
    turn_got = float(np.sum(got_r - got_l)) * robot.wheel_radius / b
    turn_want = float(np.sum(rel[:, 2]))
    said = (
        f"over the first {grid[-1] - grid[0]:.1f} s of motion {other} turns "
        f"{math.degrees(turn_want):+.0f} deg, the encoders {math.degrees(turn_got):+.0f} deg"
    )
    tp = cfg.topics
    left, right = robot.wheel_joints
    bad = [w for w, c in ((left, c_l), (right, c_r)) if c < -CHECK_AGREE]
    if len(bad) == 2 and min(corr(got_l, want_r), corr(got_r, want_l)) > CHECK_AGREE:
        # each wheel follows the other's motion: on a start that turns in place (dL = -dR)
        # swapped joints read exactly as both wheels reversed; a wrong joint name is the
        # likelier slip than two mirrored motors
        return (
            f"{tp.joint_states}: both wheels' angles run against the motion {other} records "
            f"({said}) and each follows the other wheel's: {left} and {right} look swapped "
            "(check robot.left_wheel_joint and right_wheel_joint first; if they are right, "
            "both wheels are reversed: mirrored motors whose sign the driver does not flip, "
            "check their direction / invert setting)"
        )
    if bad:
        which = " and ".join(bad)
        return (
            f"{tp.joint_states}: {which}'s angle runs against the motion {other} records "
            f"({said}): {'that wheel looks' if len(bad) == 1 else 'both wheels look'} "
            "reversed (a mirrored motor whose sign the driver does not flip: check its "
            "direction / invert setting, and that robot.left_wheel_joint and "
            "right_wheel_joint name the right joints)"
        )
    if min(c_l, c_r) > CHECK_AGREE and np.sum(np.abs(rel[:, 2])) >= 0.5 * CHECK_TURN_RAD:
        d_rot_got = (got_r - got_l) * robot.wheel_radius / b
        if corr(d_rot_got, rel[:, 2]) < -CHECK_AGREE:
            return (
                f"{tp.joint_states}: the encoders turn against {other} ({said}): "
                f"{left} and {right} look swapped (check robot.left_wheel_joint and "
                "right_wheel_joint)"
            )
    return ""


TF_SEARCH_S = 30.0  # s of /tf searched for odom -> base (a driver starts within this)


def tf_odometry_frames(reader: LogReader, cfg: Config) -> TfFrames | None:
    """The frames of the odom -> base transforms of ``topics.tf`` that the odometry can
    be read from when the log has neither encoders nor nav_msgs/Odometry
    (:func:`odometry_source`): parent ``odom``, child ``base_link`` or ``base_footprint``
    (``BASE_ALIASES``, REP 120; ``base_link`` when a message has both), looked for in the whole
    of /tf, however late they start (a bag recorded before the robot's driver came up;
    leading slashes dropped).

    Parameters
    ----------
    reader : LogReader
        The log.
    cfg : Config
        The config (``topics.tf``).

    Returns
    -------
    TfFrames or None
        Their odom and base names (None when /tf has no such transform).
    """
    if not reader.has(cfg.topics.tf):
        return None
    odom = TfFrames().odom
    for m in reader.messages([cfg.topics.tf]):
        found = {
            str(ts.child_frame_id).lstrip("/")
            for ts in m.msg.transforms
            if str(ts.header.frame_id).lstrip("/") == odom
        }
        for base in BASE_ALIASES:
            if base in found:
                return TfFrames(odom=odom, base=base)
    return None


def tf_odometry(
    msgs: Iterable[LogMessage], topic: str, pair: tuple[str, str]
) -> Iterator[LogMessage]:
    """``msgs`` with each TFMessage of ``topic`` replaced by its ``pair`` (odom, base)
    transforms read as nav_msgs/Odometry (``header``, ``child_frame_id``,
    ``pose.pose.position`` and ``.orientation``: the transform's own header, translation
    and rotation, not copied), one message each at the TFMessage's log time, several in
    one TFMessage in stamp order; its other transforms are left out, and a TFMessage
    without the pair with them. The Odometry path then reads them unchanged (the gate,
    the clock checks, the increments). Messages of other topics pass as they are.

    Parameters
    ----------
    msgs : iterable of LogMessage
        Messages in log-time order.
    topic : str
        The /tf topic (``topics.tf``).
    pair : (str, str)
        The odometry's odom and base frames (:func:`tf_odometry_frames`).

    Returns
    -------
    iterator of LogMessage
    """
    for m in msgs:
        if m.topic != topic:
            yield m
            continue
        found = [
            ts
            for ts in m.msg.transforms
            if (str(ts.header.frame_id).lstrip("/"), str(ts.child_frame_id).lstrip("/")) == pair
        ]
        if len(found) > 1:
            found.sort(key=lambda ts: (ts.header.stamp.sec, ts.header.stamp.nanosec))
        for ts in found:
            tr = ts.transform
            pose = SimpleNamespace(
                pose=SimpleNamespace(position=tr.translation, orientation=tr.rotation)
            )
            odo = SimpleNamespace(header=ts.header, child_frame_id=ts.child_frame_id, pose=pose)
            yield m._replace(msg=odo)


def odometry_messages(
    reader: LogReader, topic: str, pair: tuple[str, str] | None = None
) -> Iterator[LogMessage]:
    """The messages of the odometry ``topic``: with ``pair`` (the odometry read from /tf:
    :func:`odometry_source`) and ``topic`` a TFMessage topic, its ``pair`` transforms as
    Odometry (:func:`tf_odometry`); else as logged.

    Parameters
    ----------
    reader : LogReader
        The log.
    topic : str
        The topic.
    pair : (str, str) or None
        The odom and base frames of odometry read from /tf.

    Returns
    -------
    iterator of LogMessage
    """
    msgs = reader.messages([topic])
    if pair is None or reader.topics.get(topic) != M.TF_MESSAGE:
        return msgs
    return tf_odometry(msgs, topic, pair)


def tf_frames(
    reader: LogReader,
    cfg: Config,
    odom_topic: str | None,
    *,
    series: bool = True,
    clock: tuple[float, float] | None = None,
    notes: list[str] | None = None,
    names: TfFrames | None = None,
) -> TfFrames:
    """The /tf frames of the estimates (:class:`TfFrames`): the odometry's own frame names
    when it is nav_msgs/Odometry (``odom_topic``; else odom and base_link), and whether
    the log's /tf already carries odom -> base (looked for in its first ``TF_SEARCH_S``: a
    robot's driver, or ``fuzzyslam simulate``), so that it is not written twice; if it
    does, its odom -> base series over the whole /tf (``TfFrames.log_odom``: the stamps
    of the transforms, sorted, one pose per stamp (the last one), non-finite ones
    dropped, the heading unwrapped; None when none is left), which map -> odom is
    computed against.

    Parameters
    ----------
    reader : LogReader
        The log.
    cfg : Config
        The config (``topics.tf``).
    odom_topic : str or None
        The nav_msgs/Odometry topic (None: encoders, the default names).
    series : bool
        Read the log's odom -> base series (False: the frame names only).
    clock : (float, float), optional
        The odometry's stamp - log time (s) and the largest difference (s) another
        stream may have from it (:func:`odometry_clock`, ``slam.inputs.REORDER_S``): a
        series on another clock cannot be put against, and is left out (a note says so;
        the run then writes its own odom -> base).
    notes : list of str, optional
        Gets that note (for the caller to say once: a run with --adapt-noise opens the
        log twice).
    names : TfFrames, optional
        The odom and base names to use instead (the odometry read from /tf:
        :func:`tf_odometry_frames`).

    Returns
    -------
    TfFrames
    """
    frames = names if names is not None else TfFrames()
    if odom_topic is not None:
        first = first_message(reader, odom_topic)
        odom = str(first.header.frame_id).lstrip("/") if first is not None else ""
        base = str(first.child_frame_id).lstrip("/") if first is not None else ""
        frames = TfFrames(odom=odom or "odom", base=base or "base_link")
    if not reader.has(cfg.topics.tf):
        return frames
    pair = (frames.odom, frames.base)
    # read ahead by a forked process while the run started (slam/tf_ahead.py)
    ahead = tf_ahead.take(reader.path, cfg.topics.tf) if series else None
    if ahead is not None:
        found, t, logged, xyq = _pair_transforms(ahead, pair, names is None)
    else:
        found, t, logged, xyq = _read_pair(reader, cfg.topics.tf, pair, series, names is None)
    if not found:
        return frames
    offset = float(np.median(np.subtract(t, logged))) if len(t) else 0.0
    if clock is not None and abs(offset - clock[0]) > clock[1]:
        line = (
            f"{reader.path}: {cfg.topics.tf} odom -> base is stamped {offset:+.3f} s from its "
            f"log times, the odometry {clock[0]:+.3f} s: another clock; estimates.mcap "
            "writes its own odom -> base"
        )
        if notes is not None:
            notes.append(line)
        return frames
    return TfFrames(
        frames.map, frames.odom, frames.base, odom_to_base=False, log_odom=_odom_series(t, xyq)
    )


def _read_pair(reader: LogReader, topic: str, pair: tuple[str, str], series: bool, search: bool):
    """``tf_frames``' read of ``topic``: (found, stamps (s), their messages' log times (s),
    (x, y, qx, qy, qz, qw) of each) of the transforms of ``pair``; ``search``: the pair
    looked for in the topic's first ``TF_SEARCH_S`` only; without ``series``, found only."""
    found = False
    t: list[float] = []
    xyq: list[tuple[float, ...]] = []  # x, y, qx, qy, qz, qw
    logged: list[float] = []  # their messages' log times
    t_first = None
    for m in reader.messages([topic]):
        t_first = m.t if t_first is None else t_first
        for ts in m.msg.transforms:
            if (str(ts.header.frame_id).lstrip("/"), str(ts.child_frame_id).lstrip("/")) != pair:
                continue
            found = True
            if not series:
                break
            tr, q = ts.transform.translation, ts.transform.rotation
            t.append(M.stamp_to_sec(ts.header.stamp))
            logged.append(m.t)
            xyq.append((tr.x, tr.y, q.x, q.y, q.z, q.w))
        if found and not series:
            break
        if not found and search and m.t - t_first > TF_SEARCH_S:
            break  # (the odometry's own transforms are on /tf: found, however late)
    return found, t, logged, xyq


def _pair_transforms(ahead, pair: tuple[str, str], search: bool):
    """:func:`_read_pair`'s answer (with its series) from the topic read ahead
    (``tf_ahead.TopicTransforms``): the pair's transforms if it is found, that is if its
    first message comes before any message logged over ``TF_SEARCH_S`` after the first
    (``search``; the read stops there otherwise), with the same floats."""
    got = ahead.pairs.get(pair)
    if got is None:
        return False, [], [], []
    first, t, logged, xyq = got
    if search:
        late = np.flatnonzero(ahead.msg_t - ahead.msg_t[0] > TF_SEARCH_S)
        if len(late) and late[0] < first:
            return False, [], [], []
    return True, t, logged, xyq


def _odom_series(t, xyq):
    """(t (N,), poses (N, 3)) of transforms (x, y, quaternion): finite ones, sorted by
    stamp, the last one of each stamp, the heading unwrapped (continuous over the whole
    series: ``outputs.log_odom_at`` interpolates slices of it); None when none is left."""
    if not len(t):
        return None
    tt = np.asarray(t, dtype=float)
    a = np.asarray(xyq, dtype=float).reshape(-1, 6)
    ok = np.isfinite(tt) & np.all(np.isfinite(a), axis=1)
    ok &= np.linalg.norm(a[:, 2:], axis=1) > 1e-9
    tt, a = tt[ok], a[ok]
    if not len(tt):
        return None
    order = np.argsort(tt, kind="stable")
    tt, a = tt[order], a[order]
    last = np.append(tt[1:] != tt[:-1], True)  # the last transform of each stamp
    tt, a = tt[last], a[last]
    yaw = np.unwrap(np.reshape(quaternion_to_yaw(a[:, 2:]), -1))  # continuous (outputs.py)
    poses = np.column_stack([a[:, 0], a[:, 1], yaw])
    return tt, poses


def first_odometry_pose(
    reader: LogReader,
    topic: str,
    default: np.ndarray,
    gate: OdomGate,
    pair: tuple[str, str] | None = None,
) -> np.ndarray:
    """The first confirmed odometry pose (slam/odom_gate.py ``first_plausible_pose``, from
    the first 100 messages), ``gate`` primed with it; ``default`` when there is none.

    Parameters
    ----------
    reader : LogReader
        The log.
    topic : str
        Its nav_msgs/Odometry topic.
    default : ndarray, shape (3,)
        The pose without a confirmed one.
    gate : OdomGate
        The glitch gate, primed with the pose found.
    pair : (str, str) or None
        The odom and base frames when ``topic`` is /tf (:func:`odometry_messages`).

    Returns
    -------
    ndarray, shape (3,)
        x, y (m), theta (rad).
    """
    t, poses = [], []
    for m in odometry_messages(reader, topic, pair):
        p = M.pose_of(m.msg.pose.pose)
        if np.all(np.isfinite(p)):
            t.append(M.stamp_to_sec(m.msg.header.stamp))
            poses.append(p)
        if len(t) >= 100:
            break
    first = first_plausible_pose(np.asarray(t), np.asarray(poses).reshape(-1, 3), gate)
    if first is None:
        return default
    gate.prime(*first)
    return np.asarray(first[1], dtype=float)


def filter_start_pose(
    reader: LogReader,
    cfg: Config,
    odom_topic: str,
    odom_source: str,
    given,
    gate: OdomGate,
    pair: tuple[str, str] | None = None,
):
    """The filter's start pose (:mod:`fuzzyslam.slam.inputs`' docstring), checked finite.

    Parameters
    ----------
    reader : LogReader
        The log.
    cfg : Config
        The run's config (``slam.start_pose``).
    odom_topic : str
        The odometry topic.
    odom_source : str
        "odom" (nav_msgs/Odometry), "tf" (its odom -> base transforms) or "encoders".
    given : (float, float, float) or None
        ``--start-pose``.
    gate : OdomGate
        The glitch gate (primed when the first odometry pose is used).
    pair : (str, str) or None
        The odom and base frames of odometry read from /tf (:func:`odometry_messages`).

    Returns
    -------
    ndarray, shape (3,)
        x, y (m), theta (rad); InputError when not finite.
    """
    scen = read_scenario(reader) if given is None else None
    if given is not None:
        pose = np.asarray(given, dtype=float)
    elif scen is not None:
        pose = np.asarray(scen.start_pose, dtype=float)
    else:
        pose = np.asarray(cfg.slam.start_pose, dtype=float)
        if odom_source in ("odom", "tf") and pose.shape == (3,) and not np.any(pose):
            pose = first_odometry_pose(reader, odom_topic, pose, gate, pair)
    if pose.shape != (3,) or not np.all(np.isfinite(pose)):
        raise InputError(reader.path, "start pose must be three finite numbers (x, y, theta)")
    return pose


def streams_start(
    reader: LogReader, topics: list[str], pair: tuple[str, str] | None = None
) -> float:
    """The log time of the first message of the streams the filter reads (odometry,
    lamps): the run's start, not the log's (a converter may log /tf_static or a
    CameraInfo at time 0, decades before a Unix-time robot's first message).

    Parameters
    ----------
    reader : LogReader
        The log.
    topics : list of str
        The streams ('' for none).
    pair : (str, str) or None
        The odom and base frames of odometry read from /tf: its first such transform's
        (:func:`odometry_messages`).

    Returns
    -------
    float
        Seconds; the log's start when none of them has a message.
    """
    firsts = [
        m.t for tp in topics if tp for m in itertools.islice(odometry_messages(reader, tp, pair), 1)
    ]
    return min(firsts, default=reader.start)


def odometry_clock(
    reader: LogReader, topic: str, pair: tuple[str, str] | None = None
) -> tuple[float, float, float]:
    """The odometry's period, clock offset and first stamp, from its first
    ``PERIOD_SAMPLES`` messages.

    - the period: the median step between their header stamps (steps that go back or
      repeat left out), so that neither a gap nor other streams logged before or after
      it change it. The odometry has a gap when silent for longer than ``ODOM_GAP_S`` or
      ``GAP_PERIODS`` of this period, whichever is longer (odometry at 1 Hz is slow, not
      silent); odometry slower than ``SLOW_ODOMETRY_S`` gets a note
      (:func:`slow_odometry_note`);
    - the clock offset: the median of their header stamp - log time, the clock the
      other streams are checked against (``LogInputs._same_clock``); the median, so that
      a glitched stamp does not set it;
    - the first stamp: the earliest of them (a detection stamped well before it cannot
      be placed: ``LogInputs._main_events``).

    Parameters
    ----------
    reader : LogReader
        The log.
    topic : str
        The odometry topic.
    pair : (str, str) or None
        The odom and base frames when ``topic`` is /tf: its odom -> base transforms'
        stamps (:func:`odometry_messages`).

    Returns
    -------
    (float, float, float)
        Period, clock offset and first stamp (s); 0 for the period and offset that fewer
        than two (one) messages cannot give, -inf for the stamp of no message.
    """
    stamps, logged = [], []
    for m in odometry_messages(reader, topic, pair):
        stamps.append(M.stamp_to_sec(m.msg.header.stamp))
        logged.append(m.t)
        if len(stamps) >= PERIOD_SAMPLES:
            break
    t = np.asarray(stamps, dtype=float)
    steps = np.diff(t)
    steps = steps[steps > 0]
    period = float(np.median(steps)) if len(steps) else 0.0
    offset = float(np.median(t - np.asarray(logged, dtype=float))) if len(t) else 0.0
    return period, offset, float(t.min()) if len(t) else -np.inf


def slow_odometry_note(topic: str, period: float) -> str:
    """The one-line note for odometry slower than ``SLOW_ODOMETRY_S``, else ''.

    The filter predicts with the odometry it has read, so a measurement between two
    messages is compared with the pose of the message before it, and the motion between
    two messages is taken as one arc (slam/motion.py), which turn-then-drive is not.
    Both errors grow with the period: with the ACES log's odometry cut from 5.4 to 1.1 Hz
    (measured 2026-12-03) its pose fixes err 1.0 m mean instead of 0.12 m.

    Parameters
    ----------
    topic : str
        The odometry topic.
    period : float
        Its period, the median step (s), :func:`odometry_clock`.

    Returns
    -------
    str
    """
    if period <= SLOW_ODOMETRY_S:
        return ""
    return (
        f"odometry on {topic} comes at {1.0 / period:.1f} Hz: measurements between its "
        f"messages are compared with the pose of the message before, and each increment "
        f"is taken as one arc; below about {1.0 / SLOW_ODOMETRY_S:.0f} Hz expect fixes and "
        f"landmarks to degrade (record odometry faster if you can)"
    )


TWIST_AFTER = 20  # messages with a twist and an unchanged pose: a twist-only driver
TWIST_LIMIT = 20_000  # messages read at most (a robot idle that long: the pose is read)


def twist_only(reader: LogReader, topic: str) -> bool:
    """Whether a nav_msgs/Odometry stream carries its motion in the twist alone: its
    pose stays the first one's through ``TWIST_AFTER`` messages after its twist first
    says the robot moves (a driver that fills only the velocities; its pose read as
    motion would hold the robot still). A robot that waits before it drives is read
    until it does (at most ``TWIST_LIMIT`` messages).

    Parameters
    ----------
    reader : LogReader
        The log.
    topic : str
        The Odometry topic.

    Returns
    -------
    bool
    """
    first, moved_at = None, None
    for k, m in enumerate(reader.messages([topic])):
        if k >= TWIST_LIMIT:
            break
        p, q = m.msg.pose.pose.position, m.msg.pose.pose.orientation
        pose = (p.x, p.y, p.z, q.x, q.y, q.z, q.w)
        if first is None:
            first = pose
        elif pose != first:
            return False
        tw = m.msg.twist.twist
        if moved_at is None and (abs(tw.linear.x) > 1e-6 or abs(tw.angular.z) > 1e-6):
            moved_at = k
        if moved_at is not None and k - moved_at >= TWIST_AFTER:
            return True
    return False


def mount_in_base(
    reader: LogReader, cfg: Config, tree, frame: str, base: str, what: str, notes: list[str]
) -> Rigid | None:
    """The mount of ``frame`` in ``base`` from the static tree (:func:`locate`), None when
    the tree does not name the frame; a root standing in for a base frame the tree never
    names gets a line in ``notes``.

    Parameters
    ----------
    reader : LogReader
        The log (named in the error).
    cfg : Config
        Its topics (``tf_static``, named in the lines).
    tree : TfTree
        Its /tf_static tree (:func:`static_tree`).
    frame : str
        The sensor's frame.
    base : str
        The robot's base frame.
    what : str
        The sensor, for the lines ("the camera").
    notes : list of str
        Gets the stand-in line.

    Returns
    -------
    Rigid or None

    Raises
    ------
    InputError
        A frame the tree cannot place (another root, a cycle, two parents): one line.
    """
    tf_static = cfg.topics.tf_static
    try:
        found = locate(tree, frame, base)
    except TfProblem as e:
        raise InputError(reader.path, f"{tf_static} cannot place {what}: {e}") from None
    if found is None:
        return None
    mount, stand_in = found
    if stand_in is not None:  # as the range sensors' mounts_source says
        notes.append(
            f"{reader.path}: {tf_static} does not name the base frame {base!r}: {what} is "
            f"placed in {stand_in!r} instead"
        )
    return mount


# REP 120: base_footprint is base_link projected on the floor, the same planar frame
BASE_ALIASES = ("base_link", "base_footprint")


def detection_mount_of(reader: LogReader, cfg: Config, base: str, notes: list[str]) -> Rigid | None:
    """The mount in ``base`` of the frame the detections are stamped in (the first
    message's ``header.frame_id``), composed from /tf_static (:func:`locate`); None when
    they are in ``base`` (or name no frame, or name ``base_link``/``base_footprint`` when
    the other is the base and /tf_static does not tell them apart: REP 120, one planar
    frame, or the log has no /tf_static at all: taken as the base, with a note).

    Parameters
    ----------
    reader : LogReader
        The log.
    cfg : Config
        Its topics (``detections``, ``tf_static``).
    base : str
        The robot's base frame (the odometry's child frame).
    notes : list of str
        Gets a line when a /tf_static root stands in for an unnamed base frame.

    Returns
    -------
    Rigid or None

    Raises
    ------
    InputError
        When the detections' frame cannot be placed on the base frame: one line naming it.
    """
    tp = cfg.topics
    first = first_message(reader, tp.detections)
    frame = str(first.header.frame_id).lstrip("/") if first is not None else ""
    if not frame or frame == base:
        return None
    msgs, _ = static_messages(reader, tp, [frame], base)  # /tf_static (or /tf's constant)
    tree = static_tree(msgs) if msgs or reader.has(tp.tf_static) else None
    what = f"the detections' frame {frame!r}"
    mount = mount_in_base(reader, cfg, tree, frame, base, what, notes) if tree is not None else None
    if mount is not None or (frame in BASE_ALIASES and base in BASE_ALIASES):
        return mount
    if tree is None:  # as the sonars without /tf_static: the robot's own frame, said
        notes.append(
            f"{reader.path}: no {tp.tf_static}: {what} is taken as the base frame {base!r}"
        )
        return None
    raise InputError(
        reader.path,
        f"{tp.detections}: detections in frame {frame!r}, which {tp.tf_static} does not "
        f"place on the base frame {base!r} (publish {base} -> {frame} on "
        f"{tp.tf_static}, or stamp the detections in {base!r})",
    )
