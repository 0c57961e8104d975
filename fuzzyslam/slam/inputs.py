"""Log-to-events, the input edge of the SLAM stage: an MCAP log in, time-ordered events out.

Input streams (topic names from the config's ``topics`` section):

- odometry: ``topics.joint_states`` wheel angles (nominal ``robot.wheel_radius`` and
  ``robot.wheel_base``), or ``topics.odom`` pose increments when the log has no
  encoders or ``slam.use_encoders`` is false, or, with neither, the pose increments of
  the odom -> base transforms on ``topics.tf`` (a log recorded for slam_toolbox or
  gmapping: each read as an Odometry pose, ``log_setup.tf_odometry``, and said);
- lamps: ``topics.image`` frames + ``topics.camera_info`` (ceiling height from
  ``camera.ceiling_height``, the lens offset and image axes from the /tf_static mount of
  ``ceiling_camera`` if present, composed in 3D (a camera turned or mounted upside down),
  else ``camera.offset``; the lens distortion of the CameraInfo undone on the blobs'
  centroids, ``CeilingCamera.unproject``). The frames are ``sensor_msgs/Image`` of any
  common encoding or ``sensor_msgs/CompressedImage`` (JPEG, PNG), decoded to grey by
  the topic's type in the log (:func:`frame_stream`); a log that records only
  image_transport's ``topics.image + "/compressed"`` is read from it. Or
  ``topics.detections`` PoseArray or vision_msgs
  Detection3DArray (base_link points; the latter's own covariances are used);
  A log with neither has no lamps (``lamp_source`` "none"): the same filter on
  odometry alone, corrected only by the aids;
- range rings, only when aids are given: the sonar topics present or the laser scan
  (:func:`fuzzyslam.streams.ranges.open_ranges`, mounts from /tf_static).

The start pose: ``start_pose`` when given (``--start-pose``), else the scenario's,
else ``slam.start_pose`` when it is not all zeros, else the first odometry pose
confirmed by the glitch gate (slam/odom_gate.py) when the odometry is nav_msgs/Odometry
(a real log has no scenario), else zeros. Odometry poses that jump (stray poses) are
skipped and counted (``odometry_jumps``).

Glitches are counted in ``warnings`` (never silently used): frames of another
encoding that cannot be decoded or of another size than the CameraInfo's, frames
stamped more than
``slam.odometry_stale_s`` before the odometry's first message (``frames_before_odometry``:
where the robot was is unknown; also counted as lost frames), NaN odometry, odometry increments
faster than the robot can move (``implausible_odometry``: wheel speeds over
``SPEED_MARGIN`` (slam/odom_gate.py) times ``robot.max_speed`` plus the turn at
``robot.max_turn_rate``), header stamps out of order, joint states without the wheel
joints. A CameraInfo that no pinhole ceiling camera can have (a focal length that is
not finite and positive, fx and fy more than 1 % apart, a field of view outside
[1, 179] degrees, a principal point off the image, a lens distortion model it cannot
undo) is a bad input. Event times are
header stamps, and events come in their order, not in the order they were logged: a
detection logged up to ``REORDER_S`` after odometry stamped later is put back in its
place (``warnings.reordered``).
"""

from __future__ import annotations

import heapq
import math
import os
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from fuzzyslam.camera import IDENTITY_AXES, CeilingCamera, floor_mount
from fuzzyslam.config import Config
from fuzzyslam.errors import InputError
from fuzzyslam.slam import tf_ahead
from fuzzyslam.slam.deskew import deskewed
from fuzzyslam.slam.events import Event, Frame, Odom, RingEvent, TfFrames
from fuzzyslam.slam.latency import delay_odometry
from fuzzyslam.slam.log_setup import (
    GAP_PERIODS,
    ODOM_GAP_S,
    WRAPPED_ANGLES,
    camera_info_problem,
    detection_mount_of,
    filter_start_pose,
    first_message,
    mount_in_base,
    odometry_clock,
    odometry_source,
    streams_start,
    tf_frames,
    tf_odometry,
    twist_only,
)
from fuzzyslam.slam.odom_gate import ORIGIN, REANCHOR, SPEED_MARGIN, OdomGate, within_speed
from fuzzyslam.stamps import in_stamp_order
from fuzzyslam.streams import messages as M
from fuzzyslam.streams.ranges import RangeSensor, open_ranges
from fuzzyslam.streams.reader import LogMessage, LogReader
from fuzzyslam.streams.sonar import RingStats
from fuzzyslam.streams.static_tf import static_messages
from fuzzyslam.streams.tf import Rigid, static_tree

CAMERA_FRAME = "ceiling_camera"
# what reading the events changes that the run reports (with the reader's damage):
# LogInputs.read_state, which slam/prefetch.py sends back from the child that read them
READ_STATE = (
    "warnings",
    "first_problem",
    "gap_seconds",
    "own_covariances",
    "own_floored",
    "ring_stats",
    "lost",
    "odometry_restarts",
)
# s of stamps a late message may lag the newest one read and still be put in its place
# (LogInputs._stamp_order): camera and detector pipelines deliver within a second
REORDER_S = 5.0
CLOCK_STEP_MESSAGES = 3  # odometry messages in a row off the clock by one amount: a step


@dataclass
class LogInputs:
    """What the filter needs from one log, and the glitches met while reading it."""

    reader: LogReader
    cfg: Config
    odom_topic: str
    odom_source: str
    lamp_topic: str
    lamp_source: str
    camera: CeilingCamera | None
    mounts: np.ndarray
    start_pose: np.ndarray
    start: float
    end: float
    warnings: dict[str, int] = field(default_factory=dict)
    ring_stats: RingStats = field(default_factory=RingStats)
    first_problem: str = ""
    gap_seconds: float = 0.0
    odom_period_s: float = 0.0  # the odometry's period (odometry_clock)
    # header stamp - log time of the odometry's first message: the clock the other
    # streams are checked against (LogInputs._same_clock)
    clock_offset: float = 0.0
    odom_first: float = -np.inf  # the odometry's first stamp (odometry_clock)
    # Odometry whose pose never changes while its twist does: the twist integrated
    odom_twist: bool = False
    # odometry read from /tf (odom_source "tf"): its odom and base frames, whose
    # transforms are read as Odometry poses (log_setup.tf_odometry)
    odom_pair: tuple[str, str] | None = None
    # the detections' frame in the base frame (/tf_static), None when they are in it
    detection_mount: Rigid | None = None
    _clock_row: tuple[float, int] | None = None  # odometry messages off the clock: offset, n
    # frames and range readings not used: their stamps cannot be placed (back in time,
    # another clock): the run's filter_health counts them (slam/run_results.py)
    lost: dict[str, float] = field(default_factory=lambda: {"frames": 0, "readings": 0})
    odom_gap_s: float = ODOM_GAP_S  # a longer silence is a gap (odometry_gap_s)
    own_covariances: int = 0  # detections that brought their own covariance
    own_floored: int = 0  # ... raised to the model's (SlamParams.detection_cov_floored)
    _names: list = field(default_factory=list)
    _idx: list = field(default_factory=list)
    _rejected_in_row: int = 0
    # the stamps (s) at which the odometry driver restarted at the origin (_restarted)
    odometry_restarts: list[float] = field(default_factory=list)
    _cov_cache: tuple | None = None
    _detect: Callable | None = None  # slam/detect.py's detect_lamps, from the first frame
    ranges: RangeSensor | None = None
    _gate: OdomGate = field(default_factory=OdomGate)
    frames: TfFrames = field(default_factory=TfFrames)
    # what opening the log found worth a line on stderr, said once by the stage (a run
    # with --adapt-noise opens the log twice)
    notes: list[str] = field(default_factory=list)
    # a frame message -> its 8-bit grey image (frame_stream: by the topic's type)
    to_grey: Callable[[Any], np.ndarray] = M.image_to_array

    @property
    def placeable_from(self) -> float:
        """The earliest stamp (s) a frame or range reading can be placed at:
        ``slam.odometry_stale_s`` before the odometry's first message. One taken earlier
        was taken where the robot's pose is unknown (not the start pose: it may have been
        moving); compared with the start pose it would map its lamps wrongly."""
        return self.odom_first - self.cfg.slam.odometry_stale_s

    def warn(self, key: str, problem: str = "", count: int = 1) -> None:
        """Count a glitch of kind ``key`` (the summary's ``warnings``).

        Parameters
        ----------
        key : str
            The glitch's kind.
        problem : str
            One line on it, kept as ``first_problem`` if it is the first.
        count : int
            How many (a message's non-finite detections).
        """
        self.warnings[key] = self.warnings.get(key, 0) + count
        if problem and not self.first_problem:
            self.first_problem = problem

    def restart_line(self) -> str:
        """The one line on the odometry driver's restarts read (:meth:`_restarted`),
        '' for none: when (the new stream's first stamps, in seconds into the log: from
        :attr:`start` on the stamps' clock, as the filter_health line's
        ``diverged_after_start_s``) and what was done.

        Returns
        -------
        str
        """
        at = self.odometry_restarts
        if not at:
            return ""
        t0 = self.start + self.clock_offset  # the log's start on the stamps' clock
        when = ", ".join(f"{t - t0:.2f}" for t in at[:5]) + (", ..." if len(at) > 5 else "")
        times = "" if len(at) == 1 else f" {len(at)} times, at"
        return (
            f"{self.reader.path}: {self.odom_topic}'s driver restarted{times} {when} s into "
            "the log (its pose jumped to near (0, 0, 0) and went on from there): read on "
            "from the new origin, the motion since the restart kept (warnings.odometry_restarts)"
        )

    def read_state(self) -> dict[str, Any]:
        """What reading the events has changed that the run reports: the fields of
        ``READ_STATE`` (glitch counts, the first problem, odometry gaps, ring
        statistics) and the reader's damage (``LogReader.damage_state``).

        Returns
        -------
        dict
            Field name -> value (``damage``: the reader's); picklable.
        """
        return {k: getattr(self, k) for k in READ_STATE} | {"damage": self.reader.damage_state()}

    def restore_read_state(self, state: dict[str, Any]) -> None:
        """Take the :meth:`read_state` of another reader of the same log (the child
        process of slam/prefetch.py that made the events).

        Parameters
        ----------
        state : dict
            :meth:`read_state`'s answer.
        """
        for k in READ_STATE:
            setattr(self, k, state[k])
        self.reader.restore_damage(state["damage"])

    # -- streams --------------------------------------------------------------------------

    def events(self, rings: bool = False, ring_start: float | None = None) -> Iterator[Event]:
        """All events in time order.

        Parameters
        ----------
        rings : bool
            Merge in the range sensor's rings (for the aids).
        ring_start : float or None
            Rings from this log time (s) on: the aids' start, e.g. the map's freeze time.

        Returns
        -------
        iterator of Odom, Frame or RingEvent
        """
        main = self._stamp_order(self._main_events())
        delay = self.cfg.slam.odometry_delay_s
        if delay:
            main = delay_odometry(main, delay)  # stamps lead the motion (slam/latency.py)
        if not rings:
            return main
        merged = heapq.merge(main, self._ring_events(ring_start), key=lambda e: e.t)
        if self.ranges is not None and self.ranges.stamped_apart:
            return deskewed(merged, self.mounts)  # each reading at its stamp (slam/deskew.py)
        return merged

    def _main_events(self) -> Iterator[Event]:
        odo = self._odometry if self.odom_source == "encoders" else self._odom_pose
        if self.odom_twist:
            odo = self._odom_twist
        lamp = self._frame if self.lamp_source == "frames" else self._pose_array
        last_t = {self.odom_topic: -np.inf, self.lamp_topic: -np.inf}
        prev = None
        topics = [self.odom_topic, self.lamp_topic] if self.lamp_topic else [self.odom_topic]
        odom_topic = self.odom_topic
        unplaced = self.placeable_from
        msgs = self.reader.messages(topics)
        if self.odom_pair is not None:  # /tf's odom -> base transforms as Odometry
            msgs = tf_odometry(msgs, odom_topic, self.odom_pair)
        for m in msgs:
            topic, msg = m.topic, m.msg
            t = M.stamp_to_sec(msg.header.stamp)
            before = last_t[topic]
            if topic != odom_topic:
                if not self._same_clock(topic, t, m.t):
                    self._lose("frames", m.t)
                    continue
                if t < unplaced:
                    self.warn(
                        "frames_before_odometry",
                        f"{topic}: a frame stamped {t:.3f} s, before the odometry's first "
                        f"message ({self.odom_first:.3f} s): not used",
                    )
                    self._lose("frames", m.t)
                    continue
            elif not self._odometry_clock(topic, t, m.t):
                continue
            if t < before:
                # odometry is cumulative (wheel angles, poses): the next message carries
                # the motion of a misstamped one, at a stamp in order
                self.warn("out_of_order", f"{topic}: header stamp {t:.3f} s goes back in time")
                if topic != odom_topic:
                    self._lose("frames", m.t)
                continue
            elif t == before:
                # a repeated stamp: a duplicated message; odometry is cumulative (wheel
                # angles, poses), so the next message still carries any motion in it
                self.warn("duplicate_stamps", f"{topic}: header stamp {t:.3f} s repeated")
                continue
            elif topic == odom_topic and self.odom_gap_s < t - before < np.inf:
                gap = t - before
                self.warn("odometry_gaps", f"{topic}: silent for {gap:.2f} s before {t:.3f} s")
                self.gap_seconds += gap
            last_t[topic] = t
            if topic == odom_topic:
                ev, prev = odo(t, msg, prev)
            else:
                ev = lamp(t, msg)
            if ev is not None:
                if type(ev) is list:  # several increments at once (_restarted)
                    yield from ev
                else:
                    yield ev

    def _stamp_order(self, events: Iterator[Event]) -> Iterator[Event]:
        """``events`` (read in log-time order, each topic in stamp order) in header-stamp
        order: a bounded reorder buffer of ``REORDER_S`` seconds of stamps.

        A log records each message when it arrives: detections from a camera pipeline
        arrive a processing delay after their exposure, behind odometry stamped later.
        Merged as logged, such a frame is older than the filter's time and is lost. The
        buffer holds every event until a message stamped ``REORDER_S`` later has been
        read, then releases them in stamp order (equal stamps in read order); an event
        that arrives later than that is released as read and skipped by the runner
        (``counts.out_of_order``; slam/run_results.py flags a run that loses frames so);
        a stream logged more than ``REORDER_S`` from its stamps, against the odometry, is
        on another clock and never reaches the buffer (:meth:`_same_clock`). Events put
        back in order are counted (``warnings.reordered``).
        """
        for _t, ev, _late in in_stamp_order(self._count_reordered(events), REORDER_S):
            yield ev  # a late one too: the runner skips and counts it

    def _count_reordered(self, events: Iterator[Event]) -> Iterator[tuple[float, Event]]:
        """(stamp, event) of ``events``; those read after a later-stamped one counted
        (``warnings.reordered``)."""
        newest = -np.inf
        for ev in events:
            if ev.t < newest:
                self.warn("reordered")
            else:
                newest = ev.t
            yield ev.t, ev

    def _odometry(self, t: float, msg, prev):
        if msg.name != self._names:
            names = list(msg.name)
            try:
                self._idx = [names.index(n) for n in self.cfg.robot.wheel_joints]
            except ValueError:
                wheels = self.cfg.robot.wheel_joints
                self.warn("joint_states_without_wheels", f"joint state lacks {wheels}")
                return None, prev
            self._names = names
        idx = self._idx
        pos = np.asarray(msg.position, dtype=float)
        if len(pos) <= max(idx):
            self.warn("nan_odometry", f"missing wheel angle at t={t:.3f} s")
            return None, prev
        pos = pos.tolist()  # Python floats (two numpy scalars cost more)
        cur = (pos[idx[0]], pos[idx[1]], t)
        if not (math.isfinite(cur[0]) and math.isfinite(cur[1])):
            self.warn("nan_odometry", f"NaN wheel angle at t={t:.3f} s")
            return None, prev
        if prev is None:
            return None, cur
        d_left, d_right = cur[0] - prev[0], cur[1] - prev[1]
        dt = t - prev[2]
        if abs(d_left) > math.pi or abs(d_right) > math.pi:  # a wheel angle wrapped?
            d_left, d_right = self._unwrapped(dt, d_left, d_right, prev, cur)
        d_trans, d_rot = self._wheel_odometry(d_left, d_right)
        return self._increment(t, dt, d_trans, d_rot, prev, cur)

    def _unwrapped(
        self, dt: float, d_left: float, d_right: float, prev, cur
    ) -> tuple[float, float]:
        """The wheels' angle increments (rad) over ``dt`` from the readings ``prev`` to
        ``cur``, each taken modulo 2 pi where the driver publishes its wheel angles
        wrapped ((-pi, pi] or [0, 2 pi): a continuous joint's position, an absolute
        encoder) and the wheel crossed the wrap (``warnings.wheel_angle_wraps``): a jump of
        over pi between two angles that both lie in ``WRAPPED_ANGLES``, faster than the
        wheel can turn (``SPEED_MARGIN`` times the robot's top wheel rate, (max_speed +
        max_turn_rate b / 2) / r, slam/odom_gate.py). An unwrapped log's first turn of the
        wheels lies in that interval too: a jump the wheel can have made (a gap in the
        messages, a fast wheel at a low rate) is motion, left to the speed gate."""
        lo, hi = WRAPPED_ANGLES
        r = self.cfg.robot
        rate = SPEED_MARGIN * (r.max_speed + 0.5 * r.max_turn_rate * r.wheel_base) / r.wheel_radius
        out = []
        for d, a, b in ((d_left, prev[0], cur[0]), (d_right, prev[1], cur[1])):
            if abs(d) > max(math.pi, rate * dt) and lo <= a <= hi and lo <= b <= hi:
                self.warn("wheel_angle_wraps")
                d = math.remainder(d, math.tau)
            out.append(d)
        return out[0], out[1]

    def _increment(self, t: float, dt: float, d_trans: float, d_rot: float, prev, cur):
        """The increment ending at ``t`` (over ``dt`` s) as an Odom event and ``cur`` as the
        next reference, when the robot can move so fast (slam/odom_gate.py
        ``within_speed`` with robot.max_speed, robot.max_turn_rate); else
        :meth:`_reject`."""
        r = self.cfg.robot
        if not within_speed(dt, d_trans, d_rot, r.max_speed, r.max_turn_rate):
            return self._reject(t, prev, cur)
        self._rejected_in_row = 0
        return Odom(t, d_trans, d_rot), cur

    def _reject(self, t: float, prev, cur):
        """Count an implausible increment and drop it (the previous reading stays the
        reference); after odom_gate.REANCHOR in a row the counter was reset or replaced, so
        the latest reading becomes the reference (that motion is lost, and counted)."""
        self.warn("implausible_odometry", f"{self.odom_topic}: implausible jump at t={t:.3f} s")
        self._rejected_in_row += 1
        if self._rejected_in_row >= REANCHOR:
            self._rejected_in_row = 0
            self.warn("odometry_reanchored", f"{self.odom_topic}: restarted at t={t:.3f} s")
            return None, cur
        return None, prev

    def _wheel_odometry(self, d_left: float, d_right: float) -> tuple[float, float]:
        """``robot.wheel_increments_to_odometry`` on two floats (the hot path, 20 Hz):
        d_trans = r (dL + dR) / 2, d_rot = r (dR - dL) / b, nominal r and b."""
        r, b = self.cfg.robot.wheel_radius, self.cfg.robot.wheel_base
        return 0.5 * r * (d_left + d_right), r * (d_right - d_left) / b

    def _odom_pose(self, t: float, msg, prev):
        """An Odometry pose as the increment (d_trans, d_rot) from the previous one: the
        relative pose rel = prev^-1 (+) pose (``se2.between``) written on floats (the hot
        path, up to 100 Hz), d_trans = sign(rel_x) |rel_xy|, d_rot = rel_theta."""
        p, q = msg.pose.pose.position, msg.pose.pose.orientation
        yaw = math.atan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z))
        pose = (float(p.x), float(p.y), yaw)
        if not (math.isfinite(pose[0]) and math.isfinite(pose[1]) and math.isfinite(yaw)):
            self.warn("nan_odometry", f"NaN odometry pose at t={t:.3f} s")
            return None, prev
        status = self._gate.step(t, pose)
        if status == "jump":  # a stray pose (slam/odom_gate.py): the next is from prev
            self.warn("odometry_jumps", f"odometry pose at t={t:.3f} s jumps: skipped")
            return None, prev
        if status == "reset":  # refused poses that did not come back: real motion, kept
            self.warn("odometry_jumps_kept", f"odometry jump at t={t:.3f} s kept as motion")
        if prev is None:
            return None, (pose, t)
        if status == "restart":
            return self._restarted(prev)
        return self._pose_step(t, pose, prev)

    def _pose_step(self, t: float, pose: tuple[float, float, float], prev):
        """The increment from the pose ``prev`` ((x, y, theta), t) to ``pose`` at ``t``
        (:meth:`_odom_pose`) through :meth:`_increment`."""
        (px, py, pth), pt = prev
        dx, dy = pose[0] - px, pose[1] - py
        c, s = math.cos(pth), math.sin(pth)
        rx = c * dx + s * dy
        d_trans = math.copysign(math.hypot(dx, dy), rx)
        d_rot = math.remainder(pose[2] - pth, math.tau)
        return self._increment(t, t - pt, d_trans, d_rot, prev, (pose, t))

    def _restarted(self, prev):
        """The increments of an odometry driver that restarted at the origin (the gate's
        ``"restart"``, slam/odom_gate.py): from the origin (0, 0, 0) at the last accepted
        pose's time to the first pose after the restart (the motion since the restart),
        then from pose to pose of those the gate held back to confirm it, each at its own
        stamp (the reorder buffer puts them before the frames read meanwhile). Only the
        motion between the last pose before the restart and the restart itself is lost.
        Counted (``warnings.odometry_restarts``) and said after the run
        (``odometry_restarts``: the first pose's times)."""
        poses = self._gate.restarted
        t_new = poses[0][0]
        held = len(poses) - 1  # refused while the gate waited: not stray after all
        jumps = self.warnings.get("odometry_jumps", 0) - held
        if jumps > 0:
            self.warnings["odometry_jumps"] = jumps
        else:
            self.warnings.pop("odometry_jumps", None)
        if self.first_problem.startswith(f"odometry pose at t={t_new:.3f} s"):
            self.first_problem = ""
        self.warn("odometry_restarts", f"{self.odom_topic}: driver restarted at t={t_new:.3f} s")
        self.odometry_restarts.append(t_new)
        out = []
        ref = (ORIGIN, prev[1])
        for tk, pk in poses:
            ev, ref = self._pose_step(tk, tuple(pk), ref)
            if ev is not None:
                out.append(ev)
        return out or None, ref

    def _odom_twist(self, t: float, msg, prev):
        """An Odometry twist (forward speed v, turn rate w in the base frame, REP 105) as
        the increment since the previous message, by the trapezoid rule:
        d_trans = (v_prev + v) dt / 2, d_rot = (w_prev + w) dt / 2 (``odom_twist``: a
        driver that fills only the twist)."""
        tw = msg.twist.twist
        cur = (float(tw.linear.x), float(tw.angular.z), t)
        if not (math.isfinite(cur[0]) and math.isfinite(cur[1])):
            self.warn("nan_odometry", f"NaN odometry twist at t={t:.3f} s")
            return None, prev
        if prev is None:
            return None, cur
        dt = t - prev[2]
        if dt > self.odom_gap_s:
            # over a gap the speeds in between are unknown: one period at the end speeds,
            # not the whole silence (motion over it is lost, as the gap warning says)
            self.warn(
                "odometry_twist_gaps", f"{self.odom_topic}: motion over a {dt:.2f} s gap unknown"
            )
            dt = self.odom_period_s
        d_trans, d_rot = 0.5 * (prev[0] + cur[0]) * dt, 0.5 * (prev[1] + cur[1]) * dt
        return self._increment(t, dt, d_trans, d_rot, prev, cur)

    def _measurement_cov(self, m: int, sigma: float) -> np.ndarray:
        """(m, 2, 2) covariances sigma^2 I of m detections (the last block kept: the
        sigma of a log's frames does not change)."""
        key = (m, sigma)
        if self._cov_cache is None or self._cov_cache[0] != key:
            self._cov_cache = (key, np.repeat((np.eye(2) * sigma**2)[None], m, axis=0))
        return self._cov_cache[1].copy()

    def _frame(self, t: float, msg) -> Frame | None:
        """A frame's lamps: the message decoded to grey (``to_grey``: an undecodable one
        is one ``bad_frames``), the blobs detected, their centroids unprojected (the
        lens' distortion undone: ``CeilingCamera.unproject``) with the pixel noise
        ``slam.pixel_sigma`` on the ceiling (through the undistortion's local scale when
        the lens distorts: ``CeilingCamera.ceiling_covariances``)."""
        try:
            img = self.to_grey(msg)
        except ValueError as exc:
            self.warn("bad_frames", f"{self.lamp_topic} at t={t:.3f} s: {exc}")
            return None
        assert self.camera is not None
        if img.shape[:2] != (self.camera.height_px, self.camera.width):
            self.warn(
                "bad_frames",
                f"{self.lamp_topic} at t={t:.3f} s: {img.shape[1]}x{img.shape[0]} frame, the "
                f"CameraInfo says {self.camera.width}x{self.camera.height_px}",
            )
            return None
        p = self.cfg.slam
        detect = self._detect
        if detect is None:  # OpenCV, loaded for frames only (once: not an import per frame)
            from fuzzyslam.slam.detect import detect_lamps as detect

            self._detect = detect
        blobs = detect(img, p.threshold, p.min_area, p.max_area, p.min_fill, p.max_aspect, p.border)
        if blobs.rejected:
            self.warnings["blobs_rejected"] = (
                self.warnings.get("blobs_rejected", 0) + blobs.rejected
            )
        cam = self.camera
        if not cam.distorted:
            z = cam.unproject(blobs.uv)
            return Frame(t, z, self._measurement_cov(len(z), cam.metric_sigma(p.pixel_sigma)))
        z, cov = cam.ceiling_measurements(blobs.uv, p.pixel_sigma)
        ok = np.all(np.isfinite(z), axis=1) & np.all(np.isfinite(cov), axis=(1, 2))
        if not np.all(ok):  # beyond what the lens model can undo (a fisheye's rim)
            self.warnings["blobs_rejected"] = self.warnings.get("blobs_rejected", 0) + int(
                np.count_nonzero(~ok)
            )
            z, cov = z[ok], cov[ok]
        return Frame(t, z, cov)

    def _pose_array(self, t: float, msg) -> Frame | None:
        """Detections (PoseArray or vision_msgs/Detection3DArray): each with the message's
        own x, y covariance where it carries a valid one, else the configured range and
        bearing model (``SlamParams.detection_cov``); in a frame other than the base, put
        in the base frame by its /tf_static mount (``detection_mount``, in 3D: p' = R p +
        t, C' = R C R^T, their x, y parts)."""
        mount = self.detection_mount
        if mount is None:
            z, own = M.detections_of(msg)
        else:
            z3, own3 = M.detections_of(msg, dims=3)
            # a covariance without z terms (zeros or NaN there): its x, y block is rotated
            xy_ok = np.all(np.isfinite(own3[:, :2, :2]), axis=(1, 2))
            own3 = np.where(np.isfinite(own3) | ~xy_ok[:, None, None], own3, 0.0)
            r = mount.rotation
            z = (z3 @ r.T + mount.translation)[:, :2]
            own = (r @ own3 @ r.T)[:, :2, :2]
            with np.errstate(invalid="ignore"):  # NaN where no own covariance
                bad = ~(np.linalg.det(own) > 0) | ~(own[:, 0, 0] > 0)  # NaN, or degenerate
            own[bad] = np.nan
        ok = np.all(np.isfinite(z), axis=1)
        if not np.all(ok):
            bad = int(np.count_nonzero(~ok))  # detections, not messages
            self.warn("nan_detections", f"{bad} non-finite detection(s) at t={t:.3f} s", bad)
            z, own = z[ok], own[ok]
        cov, floored = self.cfg.slam.detection_cov_floored(z, own)
        self.own_covariances += int(np.count_nonzero(np.all(np.isfinite(own), axis=(1, 2))))
        self.own_floored += floored
        return Frame(t, z, cov)

    def _ring_events(self, start: float | None = None) -> Iterator[Event]:
        assert self.ranges is not None
        msgs = self.reader.messages(self.ranges.topics, start)  # rings before ``start`` not read
        for ring in self.ranges.rings(self._on_clock(msgs), self.ring_stats):
            yield RingEvent(ring.t, ring)

    def _on_clock(self, msgs: Iterator[LogMessage]) -> Iterator[LogMessage]:
        """The range messages on the odometry's clock (:meth:`_same_clock`) and stamped
        no earlier than a frame can be placed (``frames_before_odometry``: where the robot
        was before its odometry starts is unknown); the others counted in
        ``lost["readings"]`` (the early ones in ``warnings.readings_before_odometry``)."""
        unplaced = self.placeable_from
        for m in msgs:
            st = m.msg.header.stamp
            stamp = st.sec + st.nanosec * 1e-9
            # the hot path of _same_clock (the offset read each time: it follows steps)
            skew = stamp - m.t - self.clock_offset
            if not (-REORDER_S <= skew <= REORDER_S or self._same_clock(m.topic, stamp, m.t)):
                self._lose("readings", m.t)
            elif stamp < unplaced:
                self.warn("readings_before_odometry")
                self._lose("readings", m.t)
            else:
                yield m

    def _lose(self, kind: str, logged: float) -> None:
        """Count a frame or a range reading not used (``lost``), and the time of the first
        on the odometry's clock (``lost["first_at"]``)."""
        self.lost[kind] += 1
        self.lost.setdefault("first_at", logged + self.clock_offset)

    def _odometry_clock(self, topic: str, stamp: float, logged: float) -> bool:
        """Whether an odometry message is on the odometry's clock (``clock_offset``), and
        follow the clock when it steps.

        One message whose stamp - log time is more than ``REORDER_S`` off the odometry's
        is a glitch (a stamp of 0, a corrupted field): skipped and counted
        (``warnings.odometry_clock_glitches``; odometry is cumulative, the next message
        carries its motion). ``CLOCK_STEP_MESSAGES`` in a row off by the same amount are
        the clock stepping (an NTP correction on the robot's computer while the recorder
        kept its own): the new offset is taken for every stream from the last of them on
        (``warnings.clock_steps``, the first described); the others of the row were
        skipped as glitches.

        Parameters
        ----------
        topic : str
            The odometry topic.
        stamp, logged : float
            The message's header stamp and log time (s).

        Returns
        -------
        bool
            False for a message to skip.
        """
        off = stamp - logged
        if abs(off - self.clock_offset) <= REORDER_S:
            self._clock_row = None
            return True
        row = self._clock_row
        same = row is not None and abs(off - row[0]) <= REORDER_S
        self._clock_row = row = (row[0], row[1] + 1) if same else (off, 1)
        if row[1] < CLOCK_STEP_MESSAGES:
            self.warn(
                "odometry_clock_glitches",
                f"{topic}: a message stamped {off - self.clock_offset:+.3f} s off the "
                f"odometry's clock at log time {logged:.3f} s: skipped",
            )
            return False
        self.warn(
            "clock_steps",
            f"{topic}: the stamps stepped {off - self.clock_offset:+.3f} s against the log "
            f"times at log time {logged:.3f} s: the new clock is followed",
        )
        self.clock_offset, self._clock_row = off, None
        return True

    def _same_clock(self, topic: str, stamp: float, logged: float) -> bool:
        """Whether a message of ``topic`` (header ``stamp``, log time ``logged``, s) is on
        the odometry's clock: its stamp - log time within ``REORDER_S`` of the odometry's.

        A recorder logs every message when it arrives, on one clock, so a sensor's stamp
        minus its log time is its own latency (negative: stamped before it was logged),
        a fraction of a second. A stream whose latency differs from the odometry's by more
        than ``REORDER_S`` is stamped on another clock (a camera's own, a detector
        stamping with a frame count, a simulator's sim time for one node only): its stamps
        cannot be placed on the odometry's time line, and used as stamped they would pass
        over the odometry or fall before it. Such messages are counted
        (``warnings.clock_mismatch``, the first described) and not used. A log whose
        streams are all on one other clock (sim time for every node) is consistent and
        read as usual.

        Parameters
        ----------
        topic : str
            The message's topic.
        stamp, logged : float
            Its header stamp and its log time (s).

        Returns
        -------
        bool
        """
        skew = (stamp - logged) - self.clock_offset
        if abs(skew) <= REORDER_S:
            return True
        row = self._clock_row  # the odometry's clock may be stepping to this stream's
        if row is not None and abs(stamp - logged - row[0]) <= REORDER_S:
            return True
        self.warn(
            "clock_mismatch",
            f"{topic}: stamps {stamp - logged:+.3f} s from their log times, "
            f"{self.odom_topic}'s {self.clock_offset:+.3f} s: one of the two is on another "
            f"clock ({topic} not used beyond {REORDER_S:g} s of difference)",
        )
        return False


def frame_topic(reader: LogReader, topic: str) -> str:
    """The camera's frame topic: ``topic`` (``topics.image``) when the log has it, else
    image_transport's compressed one, ``topic + "/compressed"`` (a robot that records
    only that, as bandwidth asks), else '' (no frames).

    Parameters
    ----------
    reader : LogReader
        The log.
    topic : str
        ``topics.image``.

    Returns
    -------
    str
    """
    if reader.has(topic):
        return topic
    compressed = topic.rstrip("/") + "/compressed"
    return compressed if reader.has(compressed) else ""


def frame_stream(reader: LogReader, topic: str) -> Callable[[Any], np.ndarray]:
    """The decoder of the frames of ``topic`` by its type in the log:
    :func:`~fuzzyslam.streams.messages.image_to_array` for ``sensor_msgs/msg/Image``,
    :func:`~fuzzyslam.streams.messages.compressed_to_array` for
    ``sensor_msgs/msg/CompressedImage``.

    Parameters
    ----------
    reader : LogReader
        The log.
    topic : str
        The frame topic.

    Returns
    -------
    callable
        Message -> (H, W) uint8 grey image (ValueError on a frame it cannot decode).

    Raises
    ------
    InputError
        A topic of another type: one line naming it and its type.
    """
    typename = reader.topics[topic]
    if typename == M.IMAGE:
        return M.image_to_array
    if typename == M.COMPRESSED_IMAGE:
        return M.compressed_to_array
    raise InputError(
        reader.path,
        f"{topic} carries {typename}, not camera frames ({M.IMAGE} or "
        f"{M.COMPRESSED_IMAGE}; set topics.image)",
    )


def open_inputs(
    path: str | os.PathLike,
    cfg: Config,
    need_rings: bool = False,
    ranges: str | None = None,
    start_pose: tuple[float, float, float] | None = None,
) -> LogInputs:
    """Open a log and decide its streams; InputError naming topics and config keys if missing.

    Parameters
    ----------
    path : path
        The MCAP log.
    cfg : Config
        The run's config (topics, slam, ranges).
    need_rings : bool
        The aids need a range sensor.
    ranges : str or None
        sonar|scan (``--ranges``) overriding ``ranges.source``.
    start_pose : (float, float, float) or None
        ``--start-pose`` (m, m, rad; module docstring).

    Returns
    -------
    LogInputs
    """
    reader = LogReader(path)
    tp = cfg.topics
    source = odometry_source(reader, cfg)
    odom_topic, odom_source, passed_over, names = source[:4]
    pair = (names.odom, names.base) if names is not None else None
    period, clock, odom_first = odometry_clock(reader, odom_topic, pair)
    notes: list[str] = []
    if pair is not None:
        why = source.odom_passed_over or f"no {tp.odom}"
        if passed_over:
            why = f"{passed_over}, and {why}"
        elif cfg.slam.use_encoders and not source.odom_passed_over:
            why = f"no {tp.joint_states} or {tp.odom}"
        notes.append(
            f"{path}: {why}: the odometry is read from {odom_topic}'s {pair[0]} -> {pair[1]} "
            "transforms"
        )
    elif passed_over:
        notes.append(f"{path}: {passed_over}: the odometry is read from {odom_topic}")
    twist = odom_source == "odom" and twist_only(reader, odom_topic)
    if twist:
        notes.append(
            f"{path}: {odom_topic}'s pose does not change while its twist does: the "
            "twist is integrated (a driver that fills only the velocities)"
        )
    frames = tf_frames(
        reader,
        cfg,
        odom_topic if odom_source == "odom" else None,
        clock=(clock, REORDER_S),
        notes=notes,
        names=names,
    )
    tf_ahead.discard(path)  # the /tf read ahead, if tf_frames did not take it
    camera, detection_mount = None, None
    to_grey = M.image_to_array
    image_topic = frame_topic(reader, tp.image)
    if image_topic:
        lamp_topic, lamp_source = image_topic, "frames"
        to_grey = frame_stream(reader, image_topic)
        info = first_message(reader, tp.camera_info) if reader.has(tp.camera_info) else None
        if info is None:
            reader.require([tp.camera_info], "the config's topics.camera_info")
            raise InputError(reader.path, f"no message on {tp.camera_info}")
        offset, axes = tuple(cfg.camera.offset), IDENTITY_AXES
        tf_msgs, _ = static_messages(reader, tp, [CAMERA_FRAME], frames.base)
        if tf_msgs:  # the lens and image axes in the base frame
            tree = static_tree(tf_msgs)
            mount = mount_in_base(reader, cfg, tree, CAMERA_FRAME, frames.base, "the camera", notes)
            if mount is not None:
                offset, axes = floor_mount(mount)
        problem = camera_info_problem(info)
        if problem:
            raise InputError(reader.path, f"{tp.camera_info}: {problem}")
        camera = CeilingCamera.from_camera_info(info, cfg.camera.ceiling_height, offset, axes)
        if camera.distorted and "image_rect" in lamp_topic:  # image_pipeline's naming
            notes.append(
                f"{path}: {lamp_topic} looks rectified (image_proc's image_rect) while "
                f"{tp.camera_info} has a non-zero D, which is undone on its lamps: point "
                "topics.image at the raw image (image_raw) unless it is not rectified"
            )
    elif reader.has(tp.detections):
        lamp_topic, lamp_source = tp.detections, "detections"
        detection_mount = detection_mount_of(reader, cfg, frames.base, notes)
    else:
        lamp_topic, lamp_source = "", "none"  # odometry alone (and the aids' fixes)
    sensor = open_ranges(reader, cfg, ranges, base=frames.base) if need_rings else None
    mounts = sensor.mounts if sensor is not None else np.zeros((0, 3))
    gate = OdomGate(restarts=True)  # a driver restart read on from its origin
    pose = filter_start_pose(reader, cfg, odom_topic, odom_source, start_pose, gate, pair)
    inputs = LogInputs(
        reader,
        cfg,
        odom_topic,
        odom_source,
        lamp_topic,
        lamp_source,
        camera,
        mounts,
        pose,
        streams_start(reader, [odom_topic, lamp_topic], pair),
        reader.end,
        ranges=sensor,
        _gate=gate,
        frames=frames,
        odom_period_s=period,
        odom_gap_s=max(ODOM_GAP_S, GAP_PERIODS * period),
        clock_offset=clock,
        odom_first=odom_first,
        detection_mount=detection_mount,
        odom_twist=twist,
        odom_pair=pair,
        notes=notes,
        to_grey=to_grey,
    )
    # the run starts no earlier than the first frame that can be placed (a log time)
    inputs.start = max(inputs.start, inputs.placeable_from - clock)
    return inputs
