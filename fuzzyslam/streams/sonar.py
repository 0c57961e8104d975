"""Sonar rings from a log: the 16 Range messages of one firing, grouped into an array.

A ring is one firing cycle: consecutive readings (in stamp order), each stamped within
``gap`` of the one before, in which no sonar reads twice, spanning at most
``MAX_RING_SPAN_S``. The simulator (and CARMEN) stamp a whole ring alike; a real ring
(a Pioneer's) fires its sonars in sequence, one every 40 to 60 ms or so, so one cycle
spans a third of a second or more, and the next cycle starts when the first sonar fires
again. The gap is measured from the log before grouping (:func:`firing_gap`, on the
stamps of its first ``FIRING_SAMPLE`` readings, sorted):

- simultaneous firing (readings that share a stamp average more than half the ring):
  the gap is a small tolerance, ``SIMULTANEOUS_GAP_S`` or half the smallest positive
  stamp step if that is smaller, so that the next ring's readings never join one that
  lacks a sonar;
- sequential firing: the gap is ``SEQUENTIAL_GAP_FACTOR`` (2.5) times the median
  positive step, which covers a jittery period and the double step of a dead sonar,
  at least ``SIMULTANEOUS_GAP_S`` (sonars published one by one in a loop, microseconds
  apart with millisecond hiccups, are one firing) and at most half of ``MAX_RING_SPAN_S``.

Readings are put back in stamp order first: they are held until one stamped more than
``MAX_RING_SPAN_S`` later has been read, then released in stamp order (equal stamps in
log order), so two drivers logging their banks with different delays still make whole
rings. A ring whose readings share one stamp is at that stamp. A ring whose stamps differ
is at its last reading's stamp, and says how much earlier each reading was taken
(``Ring.offsets``): the robot moves within a cycle (0.3 m and 18 deg in a 0.6 s cycle at
0.5 m/s and 30 deg/s), so each reading is placed by the robot's pose at its own stamp
(:func:`deskewed_mounts`): by the trajectory in the map stage, by the odometry in a run
(:mod:`fuzzyslam.slam.deskew`; the last stamp, so that the odometry up to every reading
is known when the ring is). Rings whose readings span more than ``gap`` are counted
(``sequential``). A sonar missing from a ring reads NaN. Glitches are made explicit and
counted, never silently used:

- NaN, negative ranges and -inf (REP 117: an object closer than min_range) become NaN
  (``invalid``);
- ranges at or beyond max_range are "no echo" and stay as max_range (``no_echo``); so is
  +inf, REP 117's "nothing detected" (a driver may publish either; ``simulate`` writes
  max_range);
- ranges below min_range become NaN (``invalid``), and so do echoes nearer than
  ``ranges.min_range_m`` (``invalid`` and ``too_near``: the robot's own body in the
  cone; 0, the default, leaves min_range the only limit), as a laser's
  (:func:`fuzzyslam.streams.scan.scan_ranges`);
- a reading whose max_range is not a positive finite number becomes NaN (``invalid``);
- a reading whose max_range is beyond what an ultrasonic sensor can measure
  (``MAX_PLAUSIBLE_RANGE``) becomes NaN (``invalid`` and ``implausible``);
- a second reading of the same sonar at the same stamp is dropped (``duplicates``);
- a reading read after one stamped more than ``MAX_RING_SPAN_S`` later (too late to be
  put back in order) is dropped (``out_of_order``);
- a field of view that is not finite, not positive or wider than a half-plane
  (``MAX_PLAUSIBLE_FOV``) is replaced by the last valid one, and until one is seen by the
  configured cone (``sonar.fov_deg``: ``group_rings``' ``cone``) (``bad_fov``): a log
  whose Range messages all say ``field_of_view: 0`` is read with the configured cone.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass, field

import numpy as np

from fuzzyslam.sim.params import SonarParams
from fuzzyslam.stamps import in_stamp_order
from fuzzyslam.streams.messages import stamp_to_sec
from fuzzyslam.streams.reader import LogMessage
from fuzzyslam.streams.tf import TfProblem, frame_mounts, planar_mount

MAX_PLAUSIBLE_RANGE = 100.0  # m: no ultrasonic ranger reaches this far
MAX_PLAUSIBLE_FOV = np.pi  # rad: a cone wider than a half-plane is not a sonar beam
MAX_RING_SPAN_S = 1.0  # s: a firing cycle longer than this is cut (24 sonars at 40 ms)
SIMULTANEOUS_GAP_S = 0.05  # s: the largest gap within a ring stamped alike
SEQUENTIAL_GAP_FACTOR = 2.5  # gap / median stamp step of sequential firing
FIRING_SAMPLE = 300  # readings whose stamps measure the firing pattern
DEFAULT_CONE = math.radians(SonarParams().fov_deg)  # rad: the config's default sonar cone


@dataclass
class Ring:
    """One sonar ring: time (s), ranges (count,) with NaN for missing/invalid, max ranges,
    the cone's full angle (rad); ``offsets`` (count,): each reading's stamp minus ``t``
    (s, <= 0; NaN where none), or None for a ring stamped alike; ``mounts`` (count, 3):
    the sensors' poses in the robot's frame at ``t`` with the motion since each reading
    taken out (:func:`deskewed_mounts`), or a laser scan's beams placed at their own
    angles (a scan of another geometry: :func:`fuzzyslam.streams.scan.scan_rings`), or
    None: the sensor's own mounts."""

    t: float
    ranges: np.ndarray
    max_range: np.ndarray
    fov: float
    offsets: np.ndarray | None = None
    mounts: np.ndarray | None = None


def ring_mounts(ring: Ring, mounts: np.ndarray) -> np.ndarray:
    """The mounts that place ``ring``'s readings in the robot's frame at its time: its
    own (deskewed, or a laser scan's of another geometry), else the sensor's.

    Parameters
    ----------
    ring : Ring
        A ring (a laser scan's has its own mounts only when its geometry differs).
    mounts : ndarray, shape (M, 3)
        The sensor's mounts.

    Returns
    -------
    ndarray, shape (M, 3)
    """
    own = getattr(ring, "mounts", None)  # an aid's duck-typed ring may have none
    return mounts if own is None else own


def deskewed_mounts(
    mounts: np.ndarray, offsets: np.ndarray, t: float, times: np.ndarray, poses: np.ndarray
) -> np.ndarray:
    """The sensors' poses in the robot's frame at ring time ``t`` when reading j was taken
    at ``t + offsets[j]`` from a moving robot: ``(-)P(t) (+) P(t + o_j) (+) m_j``, with P
    the robot's path (``poses`` at ``times``, interpolated linearly, held beyond its
    ends: :func:`fuzzyslam.se2.interpolate_poses`). The readings then sit where they were
    measured, as a scan deskewed from odometry (Thrun, Burgard and Fox, *Probabilistic
    Robotics*, 2005, sec. 6.3, the robot's motion during a scan).

    Parameters
    ----------
    mounts : ndarray, shape (M, 3)
        The sensors' poses on the robot.
    offsets : ndarray, shape (M,) or (K, M)
        Each reading's stamp minus its ring's (s; NaN: no reading, mount kept).
    t : float or ndarray, shape (K,)
        The rings' times (s).
    times : ndarray, shape (N,)
        Increasing times of the path (s).
    poses : ndarray, shape (N, 3)
        The robot's poses at ``times`` (any fixed frame: odometry or map).

    Returns
    -------
    ndarray, shape (M, 3) or (K, M, 3)
        The deskewed mounts of each ring.
    """
    from fuzzyslam.se2 import between, compose, interpolate_poses

    off = np.asarray(offsets, dtype=float)
    ts = np.asarray(t, dtype=float).reshape(-1, 1)  # (K, 1)
    off2 = off.reshape(len(ts), -1)
    at = np.where(np.isfinite(off2), ts + off2, ts)  # a missing reading: at the ring's time
    ref = interpolate_poses(times, poses, ts[:, 0], outside="hold")  # (K, 3)
    rel = between(np.repeat(ref, off2.shape[1], axis=0),
                  interpolate_poses(times, poses, at.ravel(), outside="hold"))  # fmt: skip
    m = np.broadcast_to(np.asarray(mounts, dtype=float), (*off2.shape, 3)).reshape(-1, 3)
    return compose(rel, m).reshape((*off.shape, 3))


@dataclass
class RingStats:
    rings: int = 0
    readings: int = 0
    invalid: int = 0
    no_echo: int = 0
    missing: int = 0
    out_of_order: int = 0
    extra: dict[str, int] = field(default_factory=dict)
    duplicates: int = 0
    bad_fov: int = 0
    implausible: int = 0
    sequential: int = 0  # rings whose readings' stamps span more than the gap
    zero_ranges: int = 0  # a laser's exact 0.0 below range_min (ranges.scan_zero)
    zero_invalid: int = 0  # of them, read as invalid
    too_near: int = 0  # echoes nearer than ranges.min_range_m (invalid)
    # the stamp (s) of the first scan refused (``extra["bad_scans"]``; not in as_dict)
    first_refused_at: float | None = None

    def as_dict(self) -> dict[str, int]:
        """The counts, for a stage's JSON summary."""
        return {
            "rings": self.rings,
            "readings": self.readings,
            "invalid": self.invalid,
            "no_echo": self.no_echo,
            "missing": self.missing,
            "out_of_order": self.out_of_order,
            "duplicates": self.duplicates,
            "bad_fov": self.bad_fov,
            "implausible": self.implausible,
            "sequential": self.sequential,
            "zero_ranges": self.zero_ranges,
            "zero_invalid": self.zero_invalid,
            "too_near": self.too_near,
            **self.extra,
        }


def firing_gap(stamps: Sequence[float], count: int) -> tuple[str, float]:
    """The firing pattern of a sonar ring and the gap that groups it (module docstring).

    Parameters
    ----------
    stamps : sequence of float
        Stamps (s) of the ring's first readings (about ``FIRING_SAMPLE``), any order.
    count : int
        Sonars in the ring.

    Returns
    -------
    firing : str
        ``"simultaneous"`` when readings sharing a stamp average more than half of
        ``count`` (or no two stamps differ), else ``"sequential"``.
    gap : float
        The largest stamp step (s) within one ring, for :func:`group_rings`.
    """
    t = np.sort(np.asarray(stamps, dtype=float))
    t = t[np.isfinite(t)]
    step = np.diff(t)
    pos = step[step > 0]
    if not len(pos):
        return "simultaneous", SIMULTANEOUS_GAP_S
    shared = len(t) / (len(pos) + 1)  # readings per distinct stamp
    if shared > count / 2:
        return "simultaneous", min(SIMULTANEOUS_GAP_S, 0.5 * float(pos.min()))
    gap = SEQUENTIAL_GAP_FACTOR * float(np.median(pos))
    # never below the simultaneous tolerance: sonars published one by one in a loop,
    # microseconds apart with scheduling hiccups of milliseconds, are one firing
    return "sequential", min(max(gap, SIMULTANEOUS_GAP_S), 0.5 * MAX_RING_SPAN_S)


def _in_stamp_order(
    messages: Iterable[LogMessage], topic_index: dict[str, int], st: RingStats
) -> Iterator[tuple[float, int, LogMessage]]:
    """(stamp, sonar, message) of the sonar readings, put back in stamp order
    (:func:`fuzzyslam.stamps.in_stamp_order`, a window of ``MAX_RING_SPAN_S``); a reading
    later than that is counted ``out_of_order`` and dropped."""
    readings = (
        (stamp_to_sec(m.msg.header.stamp), (i, m))
        for m in messages
        if (i := topic_index.get(m.topic)) is not None
    )
    for t, (i, m), late in in_stamp_order(readings, MAX_RING_SPAN_S):
        if late:
            st.out_of_order += 1
        else:
            yield t, i, m


def group_rings(
    messages: Iterable[LogMessage],
    topic_index: dict[str, int],
    count: int,
    gap: float = SIMULTANEOUS_GAP_S,
    stats: RingStats | None = None,
    cone: float | None = None,
    min_range: float = 0.0,
) -> Iterator[Ring]:
    """Group sonar Range messages (in log order) into rings, one per firing cycle.

    The readings are put back in stamp order (a reorder buffer of ``MAX_RING_SPAN_S``).
    A reading starts a new ring when its sonar already read in the current one, when it
    is stamped more than ``gap`` after the reading before it, or more than
    ``MAX_RING_SPAN_S`` after the ring's first (module docstring).

    Parameters
    ----------
    messages : iterable of LogMessage
        sensor_msgs/Range messages in log order (other topics are skipped).
    topic_index : dict
        Sonar topic -> its index in the ring.
    count : int
        Sonars in the ring.
    gap : float
        Largest stamp step (s) between consecutive readings of one ring (measured by
        :func:`firing_gap`).
    stats : RingStats or None
        Counts the glitches (module docstring).
    cone : float or None
        The field of view (rad) of the rings read before any reading with a valid one:
        the config's ``sonar.fov_deg`` (None: ``DEFAULT_CONE``, its default).
    min_range : float
        The least range of an echo used (``ranges.min_range_m``, m; 0: the messages'
        min_range alone): nearer echoes are invalid (``too_near``).

    Returns
    -------
    iterator of Ring
        Time (the last reading's stamp, s), ranges (count,) and max ranges (count,)
        with NaN for missing or invalid readings, the field of view and, for readings
        stamped apart, each one's offset from the ring's time.
    """
    st = stats if stats is not None else RingStats()
    cur_t: float | None = None  # the ring's first stamp
    ranges = np.full(count, np.nan)
    rmax = np.full(count, np.nan)
    seen = np.zeros(count, dtype=bool)
    offset = np.zeros(count)  # each reading's stamp - cur_t
    fov = DEFAULT_CONE if cone is None else float(cone)  # until a valid one is read
    last_t = -np.inf

    def flush() -> Ring:
        st.rings += 1
        st.missing += int(count - np.count_nonzero(seen))
        read = offset[seen]
        last = float(read.max())
        st.sequential += bool(last - read.min() > gap)
        if last == read.min():  # stamped alike: the ring is at its stamp
            return Ring(float(cur_t) + last, ranges.copy(), rmax.copy(), fov)
        # at its last reading, each reading's stamp relative to it (module docstring)
        return Ring(float(cur_t) + last, ranges.copy(), rmax.copy(), fov,
                    np.where(seen, offset - last, np.nan))  # fmt: skip

    for t, i, m in _in_stamp_order(messages, topic_index, st):
        if cur_t is not None and seen[i] and t - cur_t == offset[i]:
            st.duplicates += 1  # the same sonar twice at one stamp: a repeated message
            continue
        if cur_t is None or seen[i] or t - last_t > gap or t - cur_t > MAX_RING_SPAN_S:
            if cur_t is not None:
                yield flush()
            cur_t = t
            ranges[:] = np.nan
            rmax[:] = np.nan
            seen[:] = False
        seen[i] = True
        offset[i] = t - cur_t
        last_t = max(last_t, t)
        st.readings += 1
        r = float(m.msg.range)
        hi = float(m.msg.max_range)
        lo = float(m.msg.min_range)
        f = float(m.msg.field_of_view)
        if math.isfinite(f) and 0 < f <= MAX_PLAUSIBLE_FOV:  # floats: math, not numpy
            fov = f
        else:
            st.bad_fov += 1
        if hi > MAX_PLAUSIBLE_RANGE:
            st.invalid += 1  # finite but beyond any sonar: a corrupt reading
            st.implausible += 1
            rmax[i] = np.nan
            ranges[i] = np.nan
        elif not (math.isfinite(hi) and hi > 0):
            st.invalid += 1  # no usable max range: the reading cannot be interpreted
            rmax[i] = np.nan
            ranges[i] = np.nan
        elif math.isnan(r) or r < 0 or r < lo:  # -inf: closer than min_range (REP 117)
            st.invalid += 1
            rmax[i] = hi
            ranges[i] = np.nan
        elif r >= hi:  # +inf included: REP 117's nothing detected
            st.no_echo += 1
            rmax[i] = hi
            ranges[i] = hi
        elif r < min_range:  # the robot's own body: not a wall (ranges.min_range_m)
            st.invalid += 1
            st.too_near += 1
            rmax[i] = hi
            ranges[i] = np.nan
        else:
            rmax[i] = hi
            ranges[i] = r
    if cur_t is not None:
        yield flush()


def present_sonar_topics(topics: Iterable[str], prefix: str) -> list[str]:
    """The sonar topics of a log: ``prefix`` followed by digits (``/sonar/s00``, ...), in
    the order of their numbers (any number and subset of sonars)."""
    found = []
    for tp in topics:
        rest = tp[len(prefix) :] if tp.startswith(prefix) else ""
        if rest.isdigit():
            found.append((int(rest), tp))
    return [tp for _n, tp in sorted(found)]


def mounts_of_frames(
    tf_msgs: Iterable[object],
    frames: dict[str, str],
    base: str = "base_link",
    stand_ins: dict[str, str] | None = None,
) -> tuple[np.ndarray, list[str], dict[str, str]]:
    """Planar mounts of the sensors named by ``frames``, composed from /tf_static.

    Each mount is the sensor frame's transform in ``base`` composed down the whole
    /tf_static chain with full 3D rotations, projected onto the base plane
    (:mod:`fuzzyslam.streams.tf`): the x, y of its origin and the heading of its x axis
    (a sonar's cone axis).

    Parameters
    ----------
    tf_msgs : iterable of TFMessage
        The /tf_static messages, in log order.
    frames : dict of str to str
        Topic -> the child frame of /tf_static that places it, in ring order.
    base : str
        The robot's base frame (the odometry's child frame).
    stand_ins : dict of str to str, optional
        Filled with topic -> the /tf_static root taken as ``base`` (a tree that does not
        name ``base``; :func:`fuzzyslam.streams.tf.locate`).

    Returns
    -------
    mounts : ndarray, shape (M, 3)
        (x, y, yaw) in ``base`` of each topic; NaN rows for the topics without a mount
        or with a problem (the caller refuses them: a missing mount is never replaced
        by a nominal one).
    missing : list of str
        The topics whose frame /tf_static does not name.
    problems : dict of str to str
        Topic -> why its frame cannot be placed (two parents, a cycle, a zero
        quaternion, an axis too close to vertical), one line each.
    """
    found, missing, problems = frame_mounts(tf_msgs, frames, base, stand_ins)
    rows = np.full((len(frames), 3), np.nan)
    for k, topic in enumerate(frames):
        if topic in found:
            try:
                rows[k] = planar_mount(found[topic])
            except TfProblem as e:
                problems[topic] = str(e)
    return rows, missing, problems
