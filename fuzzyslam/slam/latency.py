"""Odometry latency: odometry stamps that lead the motion they describe.

A robot whose odometry integrates commanded (or filtered) wheel velocities stamps each
increment when the command is sent, and the wheels follow one actuation lag later
(0.1-0.3 s on small robots): the odometry pose at stamp t is the true pose at t + d. A
camera stamps its frames when they are exposed. Fed as stamped, the filter predicts the
turn d seconds before it happens, and every detection made while turning at rate w is
compared with a heading w d ahead of the true one (0.2 s at 0.5 rad/s is 6 deg, against
a bearing noise of 1 deg): wrong pairings and a wobbling map (docs/models.md sec. 2b).

``delay_odometry`` moves every odometry increment to t + d and restores the time order
of the event stream with a heap; the other events keep their stamps. The time offset
between sensors is the temporal calibration of Li and Mourikis, "Online temporal
calibration for camera-IMU systems", IJRR 33(7), 2014, here a constant from the config.
"""

from __future__ import annotations

import heapq
import itertools
from collections.abc import Iterable, Iterator

from fuzzyslam.slam.events import Event, Odom


def delay_odometry(events: Iterable[Event], delay: float) -> Iterator[Event]:
    """The events with every ``Odom`` restamped t + ``delay``, in time order.

    Parameters
    ----------
    events : iterable of Event
        Events in the order of their stamps (as read from the log).
    delay : float
        Odometry latency d >= 0 (s): the motion of an increment stamped t happens at t + d.

    Returns
    -------
    iterator of Event
        The same events, odometry restamped, ordered by time; events with equal times keep
        their input order. An event is released once an event read later has a stamp at
        least as late, so at most ``delay`` seconds of odometry is held back.
    """
    if not delay >= 0.0:
        raise ValueError(f"odometry delay must be >= 0 s, got {delay}")
    heap: list[tuple[float, int, Event]] = []
    order = itertools.count()
    for ev in events:
        stamp = ev.t
        if isinstance(ev, Odom):
            ev = Odom(stamp + delay, ev.d_trans, ev.d_rot)
        heapq.heappush(heap, (ev.t, next(order), ev))
        while heap and heap[0][0] <= stamp:
            yield heapq.heappop(heap)[2]
    while heap:
        yield heapq.heappop(heap)[2]
