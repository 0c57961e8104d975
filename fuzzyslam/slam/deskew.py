"""Sonar rings fired in sequence (and laser scans whose beams are taken
``time_increment`` apart), deskewed by the odometry as a run reads them.

A ring whose sonars fire one after another (a Pioneer's: 40 ms apart, a 0.6 s cycle) is
taken from a moving robot: in a turn at 30 deg/s its first reading is 18 deg behind its
last. Placed by one pose, the ring smears the walls the heading and pose aids measure
(the simulated paper scenario, 1.5 Hz rings with sonars 40 ms apart, 5 seeds: the
heading fixes' error std 0.54 deg fired at once, 1.38 deg in sequence by one pose, 0.56
deg deskewed; phase C's largest position error 4.3, 14.0 and 4.2 cm).

A sequential ring (a scan likewise: :mod:`fuzzyslam.streams.scan`) comes at its last
reading's stamp with each reading's offset (:class:`fuzzyslam.streams.sonar.Ring`); the
events are in stamp order, so every odometry increment up to that stamp has come before
it. :class:`OdometryTrail` keeps the dead reckoning of the last ``TRAIL_S`` seconds of
increments (the filter's own midpoint motion model, :mod:`fuzzyslam.slam.motion`), and
:func:`deskewed` gives each such ring the mounts that place its readings in the robot's
frame at the ring's time (:func:`fuzzyslam.streams.sonar.deskewed_mounts`; the robot's
pose at the ring's time is the trail's last, the pose the filter has when it handles
the ring; a reading taken after that odometry stamp is held there). Over a cycle the
dead reckoning's error is millimetres and a fraction of a degree.
"""

from __future__ import annotations

import math
from collections.abc import Iterator

import numpy as np

from fuzzyslam.slam.events import Event, Odom, RingEvent
from fuzzyslam.streams.sonar import MAX_RING_SPAN_S, deskewed_mounts

TRAIL_S = 2.0 * MAX_RING_SPAN_S  # s of odometry kept: a whole cycle and its lateness


class OdometryTrail:
    """The dead reckoning (t, x, y, theta) of the last ``TRAIL_S`` seconds of odometry
    increments, in an arbitrary fixed frame (it starts at the origin).

    x' = x + d cos(theta + r / 2), y' = y + d sin(theta + r / 2), theta' = theta + r for
    an increment (d, r): the midpoint model of the filter's prediction
    (:mod:`fuzzyslam.slam.motion`; Thrun, Burgard and Fox 2005, sec. 5.4).
    """

    def __init__(self) -> None:
        self.t: list[float] = []
        self.poses: list[tuple[float, float, float]] = []
        self._pose = (0.0, 0.0, 0.0)

    def add(self, t: float, d_trans: float, d_rot: float) -> None:
        """Compose one increment ending at ``t`` (s); drop what is older than ``TRAIL_S``.

        Parameters
        ----------
        t : float
            The increment's end (s).
        d_trans : float
            Translation (m).
        d_rot : float
            Rotation (rad).
        """
        if self.t and t < self.t[-1]:
            return  # back in time: the filter skips it too (slam/runner.py)
        x, y, th = self._pose
        h = th + 0.5 * d_rot
        self._pose = (x + d_trans * math.cos(h), y + d_trans * math.sin(h), th + d_rot)
        if self.t and t == self.t[-1]:  # a repeated stamp: the later pose
            self.poses[-1] = self._pose
            return
        self.t.append(t)
        self.poses.append(self._pose)
        cut = 0
        while cut < len(self.t) - 1 and self.t[cut] < t - TRAIL_S:
            cut += 1
        if cut:
            del self.t[:cut], self.poses[:cut]

    def mounts(self, ring_t: float, offsets: np.ndarray, mounts: np.ndarray) -> np.ndarray:
        """The mounts (M, 3) of a ring at ``ring_t`` whose readings were taken at
        ``ring_t + offsets``: :func:`~fuzzyslam.streams.sonar.deskewed_mounts` on the
        trail, the ring's own pose the trail's last (what the filter has at ``ring_t``).

        Parameters
        ----------
        ring_t : float
            The ring's time (s).
        offsets : ndarray, shape (M,)
            Each reading's stamp minus ``ring_t`` (s; NaN: none).
        mounts : ndarray, shape (M, 3)
            The sensors' poses on the robot.

        Returns
        -------
        ndarray, shape (M, 3)
            ``mounts`` themselves when the trail has no motion to take out.
        """
        if len(self.t) < 2:
            return mounts
        # the reference at the trail's last stamp (<= ring_t: the filter's pose then);
        # readings after it are held there, before the trail at its first pose
        last = self.t[-1]
        off = np.asarray(offsets, dtype=float) + (ring_t - last)
        return deskewed_mounts(mounts, off, last, np.array(self.t), np.array(self.poses))


def deskewed(events: Iterator[Event], mounts: np.ndarray) -> Iterator[Event]:
    """``events`` (in stamp order) with each ring that has reading offsets given the
    mounts that deskew it (``Ring.mounts``, module docstring; from the ring's own mounts
    when it has them, a laser scan of another geometry), and each ring without offsets
    (one reading, or one stamp) the sensor's own (or its own), so that a multi-ring
    window never takes another ring's for it; other events as they are.

    Parameters
    ----------
    events : iterator of Odom, Frame or RingEvent
        The run's events.
    mounts : ndarray, shape (M, 3)
        The range sensor's mounts.

    Returns
    -------
    iterator of Odom, Frame or RingEvent
    """
    trail = OdometryTrail()
    for ev in events:
        kind = type(ev)
        if kind is Odom:
            trail.add(ev.t, ev.d_trans, ev.d_rot)
        elif kind is RingEvent:
            off, own = ev.ring.offsets, ev.ring.mounts  # own: a scan of another geometry
            base = mounts if own is None else own
            ev.ring.mounts = base if off is None else trail.mounts(ev.t, off, base)
        yield ev
