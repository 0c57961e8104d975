"""Laser scans as rings of narrow range sensors: sensor_msgs/LaserScan into arrays.

A scan of N beams is read as a ring of M = ceil(N / step) sensors, one per kept beam
(every ``step``-th beam from the one of smallest angle, whichever way the laser lists
them), each sitting at the laser's origin and headed along its beam angle
``angle_min + k * angle_increment`` (REP 103: counter-clockwise from the laser's x axis)
rotated by the laser's full 3D /tf_static mount
(:mod:`fuzzyslam.streams.tf`: an upside-down laser's beams run clockwise in the base
frame). The FGM and FLM evidence (:func:`fuzzyslam.maps.evidence.rings_evidence`)
then treats each beam as a sonar whose cone is the laser's beam width, so the maps and
fixes need no second evidence model.

Ranges are read as the message defines them (sensor_msgs/LaserScan; REP 117):

- a finite range in [range_min, range_max) is an echo;
- ``+inf`` (or exactly range_max) is "no return within range_max": kept as range_max,
  the "no echo" reading of :mod:`fuzzyslam.streams.sonar` (``no_echo``);
- ``-inf`` (too close), NaN (erroneous) and finite ranges below range_min or above
  range_max are invalid: NaN, skipped by the evidence (``invalid``);
- a message whose geometry (angle_min, angle_increment, beam count) differs from the
  first one's, or with a non-positive or non-finite range_max, is dropped (``bad_scans``);
- a scan stamped before the previous one is dropped (``out_of_order``), a repeated stamp
  too (``duplicates``).

A scan's beams are not taken at once: the header stamp is the first beam's time and beam
k is taken ``k * time_increment`` later (sensor_msgs/LaserScan). A laser that takes 25 to
100 ms per scan (a Hokuyo's 100 ms: 6 deg of a turn at 60 deg/s) is read like a sonar
ring fired in sequence: the scan's ring is at its last beam's time, with each kept beam's
offset from it (``Ring.offsets``), and each beam is placed by the robot's pose at its own
time (:func:`fuzzyslam.streams.sonar.deskewed_mounts`). A ``time_increment`` of 0 (or not
a positive number) gives the whole scan the stamp.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from fuzzyslam.streams.messages import stamp_to_sec
from fuzzyslam.streams.reader import LogMessage
from fuzzyslam.streams.sonar import Ring, RingStats
from fuzzyslam.streams.tf import Rigid, beam_mounts


@dataclass(frozen=True)
class ScanGeometry:
    """Beam layout of a laser: the kept beams' angles in the laser frame (rad)."""

    frame: str
    angle_min: float
    angle_increment: float
    beams: int
    step: int
    time_increment: float = 0.0  # s between beams (the first message's; 0: at once)

    @property
    def kept(self) -> np.ndarray:
        """Indices (M,) of the kept beams: every ``step``-th from the one of smallest angle
        (the first, or the last when ``angle_increment`` < 0), so that a laser listing its
        beams clockwise keeps the same beams as one listing them counter-clockwise."""
        first = 0 if self.angle_increment > 0 else (self.beams - 1) % self.step
        return np.arange(first, self.beams, self.step)

    @property
    def angles(self) -> np.ndarray:
        """(M,) beam angles of the kept beams in the laser frame (rad)."""
        return self.angle_min + self.kept * self.angle_increment

    def mounts(self, laser: Rigid | ArrayLike) -> np.ndarray:
        """Planar poses of the kept beams in the base frame.

        Each beam sits at the laser's origin, headed along its direction ``(cos a, sin a,
        0)`` in the laser frame rotated by the laser's full 3D mount
        (:func:`fuzzyslam.streams.tf.beam_mounts`): a laser upside down (roll = pi) at
        yaw ``psi`` heads beam ``a`` at ``psi - a``.

        Parameters
        ----------
        laser : Rigid or array_like, shape (3,)
            The laser's composed mount in the base frame (:class:`Rigid`: translation
            (3,), rotation (3, 3)), or a planar mount (x, y, yaw) (no roll or pitch).

        Returns
        -------
        ndarray, shape (M, 3)
            (x, y, yaw) of each kept beam, yaw in (-pi, pi].

        Raises
        ------
        TfProblem
            When a kept beam points too close to vertical for a planar heading.
        """
        if not isinstance(laser, Rigid):
            x, y, yaw = np.asarray(laser, dtype=float).reshape(3)
            laser = Rigid.planar(x, y, yaw)
        return beam_mounts(laser, self.angles)

    def matches(self, msg) -> bool:
        """Whether a LaserScan message has this geometry (float32 fields compared exactly)."""
        return (
            len(msg.ranges) == self.beams
            and float(msg.angle_min) == self.angle_min
            and float(msg.angle_increment) == self.angle_increment
        )


def scan_geometry(msg, step: int = 1) -> ScanGeometry:
    """The geometry of a LaserScan message, keeping every ``step``-th beam."""
    if step < 1:
        raise ValueError(f"step must be >= 1, got {step}")
    return ScanGeometry(
        str(msg.header.frame_id),
        float(msg.angle_min),
        float(msg.angle_increment),
        len(msg.ranges),
        int(step),
        _time_increment(msg),
    )


def _time_increment(msg) -> float:
    """The message's time between beams (s), 0 when not a positive finite number."""
    ti = float(msg.time_increment)
    return ti if np.isfinite(ti) and ti > 0 else 0.0


def scan_ranges(raw: np.ndarray, range_min: float, range_max: float) -> tuple[np.ndarray, int, int]:
    """(ranges (M,), invalid count, no-echo count) of raw LaserScan ranges (M,) (module
    docstring): echoes kept, no return -> range_max, invalid -> NaN."""
    r = np.asarray(raw, dtype=float)
    with np.errstate(invalid="ignore"):
        no_echo = (r == np.inf) | (r == np.float32(range_max))
        echo = np.isfinite(r) & (r >= range_min) & (r < range_max)
    out = np.where(echo, r, np.nan)
    out[no_echo] = range_max
    invalid = int(len(r) - np.count_nonzero(echo) - np.count_nonzero(no_echo))
    return out, invalid, int(np.count_nonzero(no_echo))


def scan_rings(
    messages: Iterable[LogMessage],
    geometry: ScanGeometry,
    beam_width: float,
    stats: RingStats | None = None,
) -> Iterator[Ring]:
    """LaserScan messages (log order) as :class:`Ring` s of the kept beams: ranges (M,),
    max ranges (M,), ``fov`` = the beam width (rad); a scan whose beams are taken
    ``time_increment`` apart at its last kept beam's time with their offsets (module
    docstring). Glitches counted in ``stats``."""
    st = stats if stats is not None else RingStats()
    st.extra.setdefault("bad_scans", 0)
    kept = geometry.kept
    after = kept - kept[-1]  # each kept beam's place before the last, in beams
    last_t = -np.inf
    for m in messages:
        msg = m.msg
        t = stamp_to_sec(msg.header.stamp)
        if t < last_t:
            st.out_of_order += 1
            continue
        if t == last_t:
            st.duplicates += 1
            continue
        hi, lo = float(msg.range_max), float(msg.range_min)
        if not geometry.matches(msg) or not (np.isfinite(hi) and hi > 0):
            st.extra["bad_scans"] += 1
            continue
        last_t = t
        raw = np.asarray(msg.ranges, dtype=np.float32)[kept]
        ranges, invalid, no_echo = scan_ranges(raw, lo, hi)
        st.rings += 1
        st.readings += len(kept)
        st.invalid += invalid
        st.no_echo += no_echo
        ti = _time_increment(msg)
        if ti > 0 and len(kept) > 1:
            last = float(kept[-1]) * ti
            yield Ring(t + last, ranges, np.full(len(kept), hi), float(beam_width), after * ti)
        else:
            yield Ring(t, ranges, np.full(len(kept), hi), float(beam_width))
