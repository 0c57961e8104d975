"""Edge of the SLAM stage: events from an MCAP log in, result files out.

Input streams (topic names from the config's ``topics`` section):

- odometry: ``topics.joint_states`` wheel angles (nominal ``robot.wheel_radius`` and
  ``robot.wheel_base``), or ``topics.odom`` pose increments when the log has no
  encoders or ``slam.use_encoders`` is false;
- lamps: ``topics.image`` mono8 frames + ``topics.camera_info`` (ceiling height from
  ``camera.ceiling_height``, lens offset from /tf_static ``ceiling_camera`` if present,
  else ``camera.offset``), or ``topics.detections`` PoseArray or vision_msgs
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
encoding or of another size than the CameraInfo's, NaN odometry, odometry increments
faster than the robot can move (``implausible_odometry``: wheel speeds over
``ODOM_SPEED_MARGIN`` times ``robot.max_speed`` plus the turn at
``robot.max_turn_rate``), header stamps out of order, joint states without the wheel
joints. A CameraInfo that no pinhole ceiling camera can have (a focal length that is
not finite and positive, fx and fy more than 1 % apart, a field of view outside
[1, 179] degrees, a principal point off the image) is a bad input. Event times are
header stamps.
"""

from __future__ import annotations

import csv
import heapq
import io
import json
import math
import os
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import yaml

from fuzzyslam.camera import CeilingCamera
from fuzzyslam.config import Config
from fuzzyslam.errors import InputError
from fuzzyslam.robot import WHEEL_NAMES
from fuzzyslam.se2 import compose, inverse, wrap_angle
from fuzzyslam.slam.odom_gate import OdomGate, first_plausible_pose
from fuzzyslam.slam.runner import Event, Frame, Odom, RingEvent, SlamResult, UpdateRow
from fuzzyslam.stamps import TIME_FORMAT, format_time
from fuzzyslam.streams import messages as M
from fuzzyslam.streams.cdr import encode_pose_with_covariance_block, encode_tf_block
from fuzzyslam.streams.logmeta import read_scenario
from fuzzyslam.streams.ranges import RangeSensor, open_ranges
from fuzzyslam.streams.reader import LogReader
from fuzzyslam.streams.sonar import RingStats
from fuzzyslam.streams.tum import format_tum
from fuzzyslam.streams.writer import LogWriter

CAMERA_FRAME = "ceiling_camera"
MAP_FRAME, ODOM_FRAME, BASE_FRAME = "map", "odom", "base_link"  # the /tf tree written
ODOM_GAP_S = 1.0  # odometry silent for longer than this: a gap (counted, motion kept)
ODOM_SPEED_MARGIN = 3.0  # increments over this many times the robot's top speed: rejected
ODOM_SLACK_S = 0.2  # s of top speed always allowed (stamp jitter, a first message)
ODOM_REANCHOR = 5  # after this many rejections in a row, restart from the latest reading


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
    own_covariances: int = 0  # detections that brought their own covariance
    _names: list = field(default_factory=list)
    _idx: list = field(default_factory=list)
    _rejected_in_row: int = 0
    _cov_cache: tuple | None = None
    ranges: RangeSensor | None = None
    _gate: OdomGate = field(default_factory=OdomGate)

    def warn(self, key: str, problem: str = "") -> None:
        self.warnings[key] = self.warnings.get(key, 0) + 1
        if problem and not self.first_problem:
            self.first_problem = problem

    # -- streams --------------------------------------------------------------------------

    def events(self, rings: bool = False, ring_start: float | None = None) -> Iterator[Event]:
        """All events in time order (rings merged in only when ``rings``, from
        ``ring_start`` on when given: the aids' start, e.g. the map's freeze time)."""
        main = self._main_events()
        if not rings:
            return main
        return heapq.merge(main, self._ring_events(ring_start), key=lambda e: e.t)

    def _main_events(self) -> Iterator[Event]:
        odo = self._odometry if self.odom_source == "encoders" else self._odom_pose
        lamp = self._frame if self.lamp_source == "frames" else self._pose_array
        last_t = {self.odom_topic: -np.inf, self.lamp_topic: -np.inf}
        prev = None
        topics = [self.odom_topic, self.lamp_topic] if self.lamp_topic else [self.odom_topic]
        for m in self.reader.messages(topics):
            t = M.stamp_to_sec(m.msg.header.stamp)
            if t < last_t[m.topic]:
                self.warn("out_of_order", f"{m.topic}: header stamp {t:.3f} s goes back in time")
                if m.topic == self.lamp_topic:
                    continue
                t = last_t[m.topic]  # an odometry increment is still motion: keep it
            elif t == last_t[m.topic]:
                # a repeated stamp: a duplicated message; odometry is cumulative (wheel
                # angles, poses), so the next message still carries any motion in it
                self.warn("duplicate_stamps", f"{m.topic}: header stamp {t:.3f} s repeated")
                continue
            elif m.topic == self.odom_topic and ODOM_GAP_S < t - last_t[m.topic] < np.inf:
                gap = t - last_t[m.topic]
                self.warn("odometry_gaps", f"{m.topic}: silent for {gap:.2f} s before {t:.3f} s")
                self.gap_seconds += gap
            last_t[m.topic] = t
            if m.topic == self.odom_topic:
                ev, prev = odo(t, m.msg, prev)
            else:
                ev = lamp(t, m.msg)
            if ev is not None:
                yield ev

    def _odometry(self, t: float, msg, prev):
        names = list(msg.name)
        if names != self._names:
            try:
                self._idx = [names.index(n) for n in WHEEL_NAMES]
            except ValueError:
                self.warn("joint_states_without_wheels", f"joint state lacks {WHEEL_NAMES}")
                return None, prev
            self._names = names
        idx = self._idx
        pos = msg.position
        if len(pos) <= max(idx):
            self.warn("nan_odometry", f"missing wheel angle at t={t:.3f} s")
            return None, prev
        cur = (float(pos[idx[0]]), float(pos[idx[1]]), t)
        if not (math.isfinite(cur[0]) and math.isfinite(cur[1])):
            self.warn("nan_odometry", f"NaN wheel angle at t={t:.3f} s")
            return None, prev
        if prev is None:
            return None, cur
        d_trans, d_rot = self._wheel_odometry(cur[0] - prev[0], cur[1] - prev[1])
        if not self._plausible(t - prev[2], d_trans, d_rot):
            return self._reject(t, prev, cur)
        self._rejected_in_row = 0
        return Odom(t, d_trans, d_rot), cur

    def _plausible(self, dt: float, d_trans: float, d_rot: float) -> bool:
        """An increment the robot can drive in ``dt``: |d_trans| and |d_rot| within
        ODOM_SPEED_MARGIN times robot.max_speed and robot.max_turn_rate (the physical
        bound; a wheel angle of +1e6 rad is a glitch, not motion)."""
        r = self.cfg.robot
        span = ODOM_SPEED_MARGIN * (max(dt, 0.0) + ODOM_SLACK_S)
        return abs(d_trans) <= r.max_speed * span and abs(d_rot) <= r.max_turn_rate * span

    def _reject(self, t: float, prev, cur):
        """Count an implausible increment and drop it (the previous reading stays the
        reference); after ODOM_REANCHOR in a row the counter was reset or replaced, so
        the latest reading becomes the reference (that motion is lost, and counted)."""
        self.warn("implausible_odometry", f"{self.odom_topic}: implausible jump at t={t:.3f} s")
        self._rejected_in_row += 1
        if self._rejected_in_row >= ODOM_REANCHOR:
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
        if not all(math.isfinite(v) for v in pose):
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
        (px, py, pth), pt = prev
        dx, dy = pose[0] - px, pose[1] - py
        c, s = math.cos(pth), math.sin(pth)
        rx = c * dx + s * dy
        d_trans = math.copysign(math.hypot(dx, dy), rx)
        d_rot = math.remainder(yaw - pth, math.tau)
        if not self._plausible(t - pt, d_trans, d_rot):
            return self._reject(t, prev, (pose, t))
        self._rejected_in_row = 0
        return Odom(t, d_trans, d_rot), (pose, t)

    def _measurement_cov(self, m: int, sigma: float) -> np.ndarray:
        """(m, 2, 2) covariances sigma^2 I of m detections (the last block kept: the
        sigma of a log's frames does not change)."""
        key = (m, sigma)
        if self._cov_cache is None or self._cov_cache[0] != key:
            self._cov_cache = (key, np.repeat((np.eye(2) * sigma**2)[None], m, axis=0))
        return self._cov_cache[1].copy()

    def _frame(self, t: float, msg) -> Frame | None:
        try:
            img = M.image_to_array(msg)
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
        from fuzzyslam.slam.detect import detect_lamps  # OpenCV, loaded for frames only

        blobs = detect_lamps(
            img, p.threshold, p.min_area, p.max_area, p.min_fill, p.max_aspect, p.border
        )
        if blobs.rejected:
            self.warnings["blobs_rejected"] = (
                self.warnings.get("blobs_rejected", 0) + blobs.rejected
            )
        z = self.camera.unproject(blobs.uv)
        return Frame(t, z, self._measurement_cov(len(z), self.camera.metric_sigma(p.pixel_sigma)))

    def _pose_array(self, t: float, msg) -> Frame | None:
        """Detections (PoseArray or vision_msgs/Detection3DArray): each with the message's
        own x, y covariance where it carries a valid one, else the configured range and
        bearing model (``SlamParams.detection_cov``)."""
        z, own = M.detections_of(msg)
        ok = np.all(np.isfinite(z), axis=1)
        if not np.all(ok):
            self.warn("nan_detections", f"NaN detection at t={t:.3f} s")
            z, own = z[ok], own[ok]
        cov = self.cfg.slam.detection_cov(z)
        has = np.all(np.isfinite(own), axis=(1, 2))
        if np.any(has):
            cov[has] = own[has]
            self.own_covariances += int(np.count_nonzero(has))
        return Frame(t, z, cov)

    def _ring_events(self, start: float | None = None) -> Iterator[Event]:
        assert self.ranges is not None
        msgs = self.reader.messages(self.ranges.topics, start)  # rings before ``start`` not read
        for ring in self.ranges.rings(msgs, self.ring_stats):
            yield RingEvent(ring.t, ring)


def camera_info_problem(info) -> str | None:
    """Why a CameraInfo cannot be a pinhole ceiling camera (None if it can): a size
    that is not positive, focal lengths fx, fy that are not finite and positive or
    differ by more than 1 % (square pixels are assumed), a horizontal field of view
    outside [1, 179] degrees, a principal point that is not finite or is off the image."""
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
    return None


def _first(reader: LogReader, topic: str):
    for m in reader.messages([topic]):
        return m.msg
    return None


def open_inputs(
    path: str | os.PathLike,
    cfg: Config,
    need_rings: bool = False,
    ranges: str | None = None,
    start_pose: tuple[float, float, float] | None = None,
) -> LogInputs:
    """Open a log and decide its streams; InputError naming topics and config keys if missing.

    ``ranges``: sonar|scan (``--ranges``) overriding ``ranges.source``; ``start_pose``:
    ``--start-pose`` (module docstring)."""
    reader = LogReader(path)
    tp = cfg.topics
    if cfg.slam.use_encoders and reader.has(tp.joint_states):
        odom_topic, odom_source = tp.joint_states, "encoders"
    elif reader.has(tp.odom):
        odom_topic, odom_source = tp.odom, "odom"
    else:
        looked = [tp.odom] if not cfg.slam.use_encoders else [tp.joint_states, tp.odom]
        keys = "topics.odom" if not cfg.slam.use_encoders else "topics.joint_states / topics.odom"
        reader.require(looked, f"the config's {keys}")
        raise AssertionError("unreachable")
    camera = None
    if reader.has(tp.image):
        lamp_topic, lamp_source = tp.image, "frames"
        info = _first(reader, tp.camera_info) if reader.has(tp.camera_info) else None
        if info is None:
            reader.require([tp.camera_info], "the config's topics.camera_info")
            raise InputError(reader.path, f"no message on {tp.camera_info}")
        offset = tuple(cfg.camera.offset)
        if reader.has(tp.tf_static):
            for m in reader.messages([tp.tf_static]):
                tf = M.planar_transforms(m.msg)
                if CAMERA_FRAME in tf:
                    offset = tuple(tf[CAMERA_FRAME][1][:2])
        problem = camera_info_problem(info)
        if problem:
            raise InputError(reader.path, f"{tp.camera_info}: {problem}")
        camera = CeilingCamera.from_camera_info(info, cfg.camera.ceiling_height, offset)
    elif reader.has(tp.detections):
        lamp_topic, lamp_source = tp.detections, "detections"
    else:
        lamp_topic, lamp_source = "", "none"  # odometry alone (and the aids' fixes)
    sensor = open_ranges(reader, cfg, ranges) if need_rings else None
    mounts = sensor.mounts if sensor is not None else np.zeros((0, 3))
    gate = OdomGate()
    pose = _start_pose(reader, cfg, odom_topic, odom_source, start_pose, gate)
    return LogInputs(
        reader,
        cfg,
        odom_topic,
        odom_source,
        lamp_topic,
        lamp_source,
        camera,
        mounts,
        pose,
        reader.start,
        reader.end,
        ranges=sensor,
        _gate=gate,
    )


def _first_odometry_pose(
    reader: LogReader, topic: str, default: np.ndarray, gate: OdomGate
) -> np.ndarray:
    """The first confirmed odometry pose (slam/odom_gate.py ``first_plausible_pose``, from
    the first 100 messages), ``gate`` primed with it; ``default`` when there is none."""
    t, poses = [], []
    for m in reader.messages([topic]):
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


def _start_pose(
    reader: LogReader, cfg: Config, odom_topic: str, odom_source: str, given, gate: OdomGate
):
    """The filter's start pose (module docstring), checked finite."""
    scen = read_scenario(reader) if given is None else None
    if given is not None:
        pose = np.asarray(given, dtype=float)
    elif scen is not None:
        pose = np.asarray(scen.start_pose, dtype=float)
    else:
        pose = np.asarray(cfg.slam.start_pose, dtype=float)
        if odom_source == "odom" and pose.shape == (3,) and not np.any(pose):
            pose = _first_odometry_pose(reader, odom_topic, pose, gate)
    if pose.shape != (3,) or not np.all(np.isfinite(pose)):
        raise InputError(reader.path, "start pose must be three finite numbers (x, y, theta)")
    return pose


# -- outputs -------------------------------------------------------------------------------


def _csv_text(header: list[str], rows) -> str:
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(header)
    w.writerows(rows)
    return buf.getvalue()


def _num(v: float) -> str:
    return f"{v:.9g}" if math.isfinite(v) else ""


def _fmt_rows(a: np.ndarray) -> str:
    """CSV rows of a finite float array (N, k): the time column (first) in
    ``stamps.TIME_FORMAT``, the others to 9 significant digits."""
    if len(a) == 0:
        return ""
    fmt = ",".join([TIME_FORMAT] + ["%.9g"] * (a.shape[1] - 1))
    return "\n".join(fmt % tuple(r) for r in a.tolist()) + "\n"


def landmarks_dict(res: SlamResult) -> dict:
    return {
        "frame": "map",
        "landmarks": [
            {
                "id": int(lm.id),
                "x": float(lm.x),
                "y": float(lm.y),
                "cov": [[float(v) for v in row] for row in lm.cov],
                "first_seen": float(lm.first_seen),
                "last_seen": float(lm.last_seen),
                "observations": int(lm.observations),
            }
            for lm in res.lamps
        ],
    }


def _lamp_markers(t: float, lamps: np.ndarray, covs: np.ndarray) -> object:
    """One flat ellipse per lamp (3 sigma, at least 5 cm across); marker id = lamp id."""
    markers = []
    for i, (xy, c) in enumerate(zip(lamps, covs, strict=True)):
        w, v = np.linalg.eigh(c)
        ang = float(np.arctan2(v[1, 1], v[0, 1]))
        sx, sy = (max(6.0 * float(np.sqrt(max(e, 0.0))), 0.05) for e in (w[1], w[0]))
        markers.append(
            M.marker(
                t,
                "map",
                "lamps",
                i,
                2,
                (xy[0], xy[1], ang),
                2.5,
                (sx, sy, 0.02),
                (1.0, 0.8, 0.1, 0.8),
            )
        )
    return M.marker_array(markers)


def _pose_message(t: float, pose: np.ndarray, c: np.ndarray):
    """/slam/pose of a trajectory row (covariance row ``pxx pxy pxt pyy pyt ptt``)."""
    cov3 = np.array([[c[0], c[1], c[2]], [c[1], c[3], c[4]], [c[2], c[4], c[5]]])
    return M.pose_with_covariance(t, "map", pose, cov3)


def dead_reckoning_at(t: np.ndarray, odo_t: np.ndarray, odo_poses: np.ndarray) -> np.ndarray:
    """The dead-reckoning poses (N, 3) at times ``t``: the pose after the last odometry
    increment at or before each time (the one the filter's estimate has integrated; the
    first pose, the start pose, before the first increment)."""
    idx = np.searchsorted(np.asarray(odo_t, dtype=float), np.asarray(t, dtype=float), "right")
    return np.asarray(odo_poses, dtype=float).reshape(-1, 3)[np.maximum(idx - 1, 0)]


def tf_payloads(t: np.ndarray, poses: np.ndarray, odo: np.ndarray) -> list[bytes]:
    """CDR of the /tf messages of trajectory rows: map -> odom (the filter's correction,
    estimate (+) (-)dead reckoning) and odom -> base_link (the dead reckoning ``odo`` at
    the same times), so that map -> odom -> base_link composes to the estimate."""
    poses = np.asarray(poses, dtype=float).reshape(-1, 3)
    odo = np.asarray(odo, dtype=float).reshape(-1, 3)
    frames = [(MAP_FRAME, ODOM_FRAME), (ODOM_FRAME, BASE_FRAME)]
    return encode_tf_block(t, frames, [compose(poses, inverse(odo)), odo])


def _update_fields(u: UpdateRow) -> list:
    """The updates.csv fields of one update attempt (unused innovation components empty)."""
    return [
        format_time(u.t),
        u.kind,
        u.id,
        u.dof,
        _num(u.nis),
        int(u.accepted),
        *(_num(x) for x in (*u.v, np.nan, np.nan, np.nan)[:3]),
    ]


UPDATES_HEADER = ["t", "kind", "id", "dof", "nis", "accepted", "v0", "v1", "v2"]
COVARIANCE_HEADER = "t,pxx,pxy,pxt,pyy,pyt,ptt\n"


def _tum_lines(t, poses) -> str:
    """TUM lines of ``format_tum`` without its header line (a block of a longer file)."""
    return format_tum(t, poses).split("\n", 1)[1]


class ExactSum:
    """Exactly rounded running sum of floats in O(1) memory (Shewchuk's partials, the
    algorithm of ``math.fsum``: J. R. Shewchuk, "Adaptive precision floating-point
    arithmetic", Discrete Comput. Geom. 18, 1997)."""

    def __init__(self) -> None:
        self.partials: list[float] = []
        self.n = 0

    def add(self, x: float) -> None:
        i = 0
        for y in self.partials:
            if abs(x) < abs(y):
                x, y = y, x
            hi = x + y
            lo = y - (hi - x)
            if lo:
                self.partials[i] = lo
                i += 1
            x = hi
        self.partials[i:] = [x]
        self.n += 1

    def mean(self) -> float | None:
        return math.fsum(self.partials) / self.n if self.n else None


class StreamingOutputs:
    """A ``RowSink`` (slam/runner.py) writing the files of docs/contracts.md sec. 2 into the
    staging directory ``tmp`` as the rows come, in blocks, so memory stays flat over long
    logs. The files are the same bytes as :func:`write_result` on the whole result, but
    estimates.mcap, whose /slam/pose (each followed by its /tf) and /slam/landmarks
    messages are interleaved in log-time order (same messages, same payloads). /tf needs
    the dead reckoning at each row's time: the odometry block is integrated before each
    block of rows, and the poses from the last one at or before the last row are kept.
    Rows and messages are buffered and written ``rows_block`` rows at a time.

    The dead reckoning is ``robot.integrate`` evaluated block by block with the running
    sums carried over (cumulative sums are sequential, so the floats are the same).
    Use as a context manager inside ``OutputDir``; :meth:`finish` writes landmarks.yaml
    and the extra messages; on an exception every file is closed (and the staging
    directory is removed by ``OutputDir``)."""

    rows_block = 1024  # trajectory rows formatted per block
    odometry_block = 4096  # odometry increments integrated per block

    def __init__(self, tmp: Path, cfg: Config, start_pose: np.ndarray) -> None:
        self.tmp = Path(tmp)
        self.topics = cfg.topics
        self.start_pose = np.asarray(start_pose, dtype=float)
        self.rows = 0
        self.lamp_nis = ExactSum()  # accepted lamp updates (summary's mean_nis_lamp)
        self._rows: list[tuple[float, np.ndarray, np.ndarray]] = []
        # estimates.mcap messages of the buffered block: (is /slam/landmarks, t, a, b)
        self._messages: list[tuple[bool, float, np.ndarray, np.ndarray]] = []
        self._odo_t: list[float] = []
        self._odo_u: list[tuple[float, float]] = []
        self._carry = (0.0, 0.0, 0.0)  # running sums of d_rot, dx, dy
        self._odo_first = True
        # dead-reckoning poses integrated but maybe still needed by /tf (from the last one
        # at or before the last row written)
        self._dr_t = np.zeros(0)
        self._dr_p = np.zeros((0, 3))

    def __enter__(self) -> StreamingOutputs:
        def text(name: str):
            return open(self.tmp / name, "w", encoding="utf-8", newline="")

        self._files = []
        try:
            self._traj = text("trajectory.tum")
            self._files.append(self._traj)
            self._odo = text("odometry.tum")
            self._files.append(self._odo)
            self._cov = text("covariance.csv")
            self._files.append(self._cov)
            self._upd = text("updates.csv")
            self._files.append(self._upd)
            self._mcap = LogWriter(self.tmp / "estimates.mcap").__enter__()
        except BaseException:
            self._close()
            raise
        self._mcap_open = True
        header = format_tum(np.zeros(0), np.zeros((0, 3)))  # the header line alone
        self._traj.write(header)
        self._odo.write(header)
        self._cov.write(COVARIANCE_HEADER)
        self._csv = csv.writer(self._upd, lineterminator="\n")
        self._csv.writerow(UPDATES_HEADER)
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        if self._mcap_open:  # not finished: an error or Ctrl-C; no estimates.mcap
            self._mcap_open = False
            self._mcap.__exit__(exc_type or RuntimeError, exc, tb)
        self._close()

    def _close(self) -> None:
        for f in self._files:
            f.close()

    # -- RowSink ---------------------------------------------------------------------

    def row(self, t: float, pose: np.ndarray, cov: np.ndarray) -> None:
        self.rows += 1
        self._rows.append((t, pose, cov))
        self._messages.append((False, t, pose, cov))
        if len(self._rows) >= self.rows_block:
            self._flush_rows()

    def odometry_start(self, t: float) -> None:
        self._odo_t.append(t)

    def odometry(self, t: float, d_trans: float, d_rot: float) -> None:
        self._odo_t.append(t)
        self._odo_u.append((d_trans, d_rot))
        if len(self._odo_u) >= self.odometry_block:
            self._flush_odometry()

    def update(self, row: UpdateRow) -> None:
        if row.kind == "lamp" and row.accepted:
            self.lamp_nis.add(row.nis)
        self._csv.writerow(_update_fields(row))

    def snapshot(self, t: float, lamps: np.ndarray, covs: np.ndarray) -> None:
        self._messages.append((True, t, lamps, covs))

    # -- blocks ----------------------------------------------------------------------

    def _flush_rows(self) -> None:
        """Write the buffered rows and messages (in blocks: building the messages in a
        batch costs half as much as one at a time between filter steps)."""
        tp = self.topics
        t = np.array([r[0] for r in self._rows], dtype=float)
        poses = np.array([r[1] for r in self._rows], dtype=float).reshape(-1, 3)
        cov = np.array([r[2] for r in self._rows], dtype=float).reshape(-1, 6)
        cdr = iter(encode_pose_with_covariance_block(t, poses, cov, "map"))
        self._flush_odometry()  # every increment up to the rows' times (runner: rows lag)
        odo = dead_reckoning_at(t, self._dr_t, self._dr_p)
        tf = iter(tf_payloads(t, poses, odo))
        if len(t):
            keep = max(int(np.searchsorted(self._dr_t, t[-1], "right")) - 1, 0)
            self._dr_t, self._dr_p = self._dr_t[keep:], self._dr_p[keep:]
        for lamps, tm, a, b in self._messages:  # in the order they came
            if lamps:
                self._mcap.write(tp.slam_landmarks, M.MARKER_ARRAY, _lamp_markers(tm, a, b), tm)
            else:
                self._mcap.write_cdr(tp.slam_pose, M.POSE_COV_STAMPED, next(cdr), tm)
                self._mcap.write_cdr(tp.tf, M.TF_MESSAGE, next(tf), tm)
        self._messages.clear()
        if not self._rows:
            return
        self._traj.write(_tum_lines(t, poses))
        self._cov.write(_fmt_rows(np.column_stack([t, cov])))
        self._rows.clear()

    def _flush_odometry(self) -> None:
        """``robot.integrate`` over the buffered increments, continuing the running sums."""
        if not self._odo_t:
            return
        u = np.asarray(self._odo_u, dtype=float).reshape(-1, 2)
        d_trans, d_rot = u[:, 0], u[:, 1]
        s = self.start_pose
        c_rot, c_x, c_y = self._carry
        rot = np.cumsum(np.concatenate([[c_rot], d_rot]))
        theta = s[2] + rot
        th_mid = theta[:-1] + 0.5 * d_rot
        cx = np.cumsum(np.concatenate([[c_x], d_trans * np.cos(th_mid)]))
        cy = np.cumsum(np.concatenate([[c_y], d_trans * np.sin(th_mid)]))
        poses = np.column_stack([s[0] + cx, s[1] + cy, wrap_angle(theta)])
        if not self._odo_first:
            poses = poses[1:]  # the previous block's last pose, already written
        odo_t = np.asarray(self._odo_t, dtype=float)
        self._odo.write(_tum_lines(odo_t, poses))
        self._dr_t = np.concatenate([self._dr_t, odo_t])
        self._dr_p = np.concatenate([self._dr_p, poses])
        self._carry = (float(rot[-1]), float(cx[-1]), float(cy[-1]))
        self._odo_first = False
        self._odo_t.clear()
        self._odo_u.clear()

    def finish(self, res: SlamResult, extra=()) -> None:
        """Write what is left: the last blocks, landmarks.yaml and ``extra`` (topic, type
        name, message, t) messages of estimates.mcap (e.g. the aids' /slam/changes), and
        close estimates.mcap (renamed into place inside ``tmp``)."""
        self._flush_rows()
        self._flush_odometry()
        (self.tmp / "landmarks.yaml").write_text(
            yaml.safe_dump(landmarks_dict(res), sort_keys=False), encoding="utf-8"
        )
        for topic, typename, msg, t in extra:
            self._mcap.write(topic, typename, msg, t)
        self._mcap_open = False
        self._mcap.__exit__(None, None, None)
        self._close()


def write_outputs(tmp: Path, out: StreamingOutputs, res: SlamResult, extra=()) -> None:
    """Complete the streamed files of docs/contracts.md sec. 2 (but summary.json and the fix
    files) in the staging directory ``tmp`` (:meth:`StreamingOutputs.finish`)."""
    assert out.tmp == Path(tmp)
    out.finish(res, extra)


def write_summary(tmp: Path, summary: dict) -> None:
    (tmp / "summary.json").write_text(
        json.dumps(summary, indent=2, sort_keys=True, default=float) + "\n", encoding="utf-8"
    )


def write_result(tmp: Path, res: SlamResult, cfg: Config, extra=()) -> None:
    """The files of docs/contracts.md sec. 2 but summary.json and the fix files, into ``tmp``,
    from a whole in-memory result (``SlamRunner.run`` with its default ``MemorySink``).
    ``run`` streams the same files instead (:class:`StreamingOutputs`).

    ``extra``: further (topic, type name, message, t) for estimates.mcap (e.g. the aids'
    ``/slam/changes``)."""
    (tmp / "trajectory.tum").write_text(format_tum(res.t, res.poses), encoding="utf-8")
    (tmp / "odometry.tum").write_text(format_tum(res.odo_t, res.odo_poses), encoding="utf-8")
    (tmp / "covariance.csv").write_text(
        COVARIANCE_HEADER + _fmt_rows(np.column_stack([res.t, res.cov])),
        encoding="utf-8",
    )
    (tmp / "updates.csv").write_text(
        _csv_text(UPDATES_HEADER, (_update_fields(u) for u in res.updates)), encoding="utf-8"
    )
    (tmp / "landmarks.yaml").write_text(
        yaml.safe_dump(landmarks_dict(res), sort_keys=False), encoding="utf-8"
    )
    tp = cfg.topics
    tf = tf_payloads(res.t, res.poses, dead_reckoning_at(res.t, res.odo_t, res.odo_poses))
    with LogWriter(tmp / "estimates.mcap") as w:
        for t, pose, c, m in zip(res.t, res.poses, res.cov, tf, strict=True):
            w.write(tp.slam_pose, M.POSE_COV_STAMPED, _pose_message(t, pose, c), t)
            w.write_cdr(tp.tf, M.TF_MESSAGE, m, t)
        for t, lamps, covs in res.snapshots:
            w.write(tp.slam_landmarks, M.MARKER_ARRAY, _lamp_markers(t, lamps, covs), t)
        for topic, typename, msg, t in extra:
            w.write(topic, typename, msg, t)
