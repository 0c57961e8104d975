"""Sonar rings from a log: the 16 Range messages of one firing, grouped into an array.

A ring is the set of readings whose header stamps lie within ``tolerance`` of the
first one (the simulator stamps a whole ring alike; a real robot fires in
sequence within a fraction of the ring period). A sonar missing from a ring
reads NaN. Glitches are made explicit and counted, never silently used:

- NaN, infinite or negative ranges become NaN (``invalid``);
- ranges at or beyond max_range are "no echo" and stay as max_range (``no_echo``);
- ranges below min_range become NaN (``invalid``);
- a reading whose max_range is not a positive finite number becomes NaN (``invalid``);
- a reading whose max_range is beyond what an ultrasonic sensor can measure
  (``MAX_PLAUSIBLE_RANGE``) becomes NaN (``invalid`` and ``implausible``);
- a second reading of the same sonar at the same stamp is dropped (``duplicates``);
- a reading stamped more than ``tolerance`` before the latest one is dropped
  (``out_of_order``);
- a field of view that is not finite, not positive or wider than a half-plane
  (``MAX_PLAUSIBLE_FOV``) is replaced by the last valid one (``bad_fov``).
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field

import numpy as np

from fuzzyslam.streams.messages import planar_transforms, stamp_to_sec
from fuzzyslam.streams.reader import LogMessage

MAX_PLAUSIBLE_RANGE = 100.0  # m: no ultrasonic ranger reaches this far
MAX_PLAUSIBLE_FOV = np.pi  # rad: a cone wider than a half-plane is not a sonar beam


@dataclass
class Ring:
    """One sonar ring: time (s), ranges (count,) with NaN for missing/invalid, max ranges."""

    t: float
    ranges: np.ndarray
    max_range: np.ndarray
    fov: float


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
            **self.extra,
        }


def group_rings(
    messages: Iterable[LogMessage],
    topic_index: dict[str, int],
    count: int,
    tolerance: float = 0.05,
    stats: RingStats | None = None,
) -> Iterator[Ring]:
    """Group sonar Range messages (in log order) into rings.

    ``topic_index`` maps each sonar topic to its index in the ring.
    """
    st = stats if stats is not None else RingStats()
    cur_t: float | None = None
    ranges = np.full(count, np.nan)
    rmax = np.full(count, np.nan)
    seen = np.zeros(count, dtype=bool)
    fov = 0.0
    last_t = -np.inf

    def flush() -> Ring:
        st.rings += 1
        st.missing += int(count - np.count_nonzero(seen))
        return Ring(float(cur_t), ranges.copy(), rmax.copy(), fov)

    for m in messages:
        i = topic_index.get(m.topic)
        if i is None:
            continue
        t = stamp_to_sec(m.msg.header.stamp)
        if t < last_t - tolerance:
            st.out_of_order += 1
            continue
        if cur_t is not None and t == cur_t and seen[i]:
            st.duplicates += 1  # the same sonar twice at one stamp: a repeated message
            continue
        if cur_t is None or t - cur_t > tolerance or seen[i]:
            if cur_t is not None:
                yield flush()
            cur_t = t
            ranges[:] = np.nan
            rmax[:] = np.nan
            seen[:] = False
        seen[i] = True
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
        elif not math.isfinite(r) or r < 0 or r < lo:
            st.invalid += 1
            rmax[i] = hi
            ranges[i] = np.nan
        elif r >= hi:
            st.no_echo += 1
            rmax[i] = hi
            ranges[i] = hi
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
    tf_msgs: Iterable[object], frames: dict[str, str]
) -> tuple[np.ndarray, list[str]]:
    """(M, 3) mounts (x, y, yaw in base_link) of the sensors named by ``frames`` (topic ->
    child frame of /tf_static, in ring order) and the topics whose frame has no mount.

    Rows of the topics without a mount are NaN; the caller refuses them (a missing mount
    is never replaced by a nominal one)."""
    found: dict[str, np.ndarray] = {}
    for msg in tf_msgs:
        for child, (_parent, pose) in planar_transforms(msg).items():
            found[child] = pose
    rows, missing = [], []
    for topic, frame in frames.items():
        pose = found.get(frame)
        if pose is None:
            missing.append(topic)
            pose = np.full(3, np.nan)
        rows.append(pose)
    return np.array(rows, dtype=float).reshape(-1, 3), missing
