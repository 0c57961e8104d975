"""Time stamps in text outputs: one format for every CSV file (and TUM's time column).

Log times are seconds, often Unix time (about 1.7e9 s): a format with significant digits
("%.9g") would round them to ten seconds. Fixed point with nine decimals keeps every
digit a float64 holds (its resolution at 1.7e9 s is 0.24 us: the last two or three of
the nine decimals of a Unix time are that rounding, not the sensor's nanoseconds;
simulated times, which start at 0, keep nanoseconds).

Times the user gives (:class:`LogTime`) are the log's own stamps, or ``+S``: S seconds
after the log's first message.
"""

from __future__ import annotations

import bisect
import math
from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from typing import TypeVar

T = TypeVar("T")

TIME_FORMAT = "%.9f"

# Two stamps this close (s) are one instant, whatever their size: a Unix time's float64
# resolution is 0.24 us, and other tools' text files keep microseconds. An absolute
# tolerance: a relative one (numpy's isclose default, 1e-5) is hours at 1.7e9 s.
SAME_INSTANT_S = 1e-6


def to_ns(t: float) -> int:
    """Integer nanoseconds of a time in seconds: the float's own value rounded to the
    nearest nanosecond (ties to even), the same digits as its nine-decimal text
    (:func:`format_time`).

    In integers: t = n / d exactly (d a power of two), so t in ns is n 10^9 / d, rounded.
    ``round(t * 1e9)`` is not that: at Unix times the product (about 1.7e18) is rounded
    to 256 ns before ``round`` sees it.

    Parameters
    ----------
    t : float
        Seconds.

    Returns
    -------
    int
    """
    n, d = float(t).as_integer_ratio()
    q, r = divmod(n * 1_000_000_000, d)
    if 2 * r > d or (2 * r == d and q & 1):
        q += 1
    return q


def split_ns(t: float) -> tuple[int, int]:
    """(sec, nanosec) of a builtin_interfaces/Time for ``t`` seconds (:func:`to_ns`).

    Parameters
    ----------
    t : float
        Seconds.

    Returns
    -------
    (int, int)
    """
    return divmod(to_ns(t), 1_000_000_000)


def format_time(t: float) -> str:
    """Fixed-point text of a time in seconds; empty for NaN or infinity."""
    return TIME_FORMAT % t if math.isfinite(t) else ""


@dataclass(frozen=True)
class LogTime:
    """A time the user gives on the command line (``--until``, ``--fix-from``): the log's
    own stamp in seconds (``600``; Unix time on a real robot's log, about 1.7e9 s), or
    ``+600``, seconds after the log's first message (the same on every log).

    Parameters
    ----------
    seconds : float
        The stamp, or the offset from the log's start when ``relative``.
    relative : bool
        Counted from the log's first message.
    """

    seconds: float
    relative: bool = False

    def at(self, start: float) -> float:
        """The log time (s) this stands for in a log whose first message is at ``start``.

        Parameters
        ----------
        start : float
            The log's first message's time (s).

        Returns
        -------
        float
        """
        return start + self.seconds if self.relative else self.seconds

    def __str__(self) -> str:
        return ("+" if self.relative else "") + format_seconds(self.seconds)


def format_seconds(t: float) -> str:
    """The shortest text that reads back as ``t`` (``600``, ``1600000229.5``): for times in
    messages to the user, where ``%g`` would print a Unix time as 1.6e+09.

    Parameters
    ----------
    t : float
        Seconds.

    Returns
    -------
    str
    """
    text = repr(float(t))
    return text[:-2] if text.endswith(".0") else text


def log_time(value: float | LogTime | None, start: float) -> float | None:
    """``value`` as a log time (s) in a log starting at ``start``: a :class:`LogTime`
    resolved, a plain number taken as the log's own stamp, None kept.

    Parameters
    ----------
    value : float, LogTime or None
        What the user gave.
    start : float
        The log's first message's time (s).

    Returns
    -------
    float or None
    """
    if value is None:
        return None
    return value.at(start) if isinstance(value, LogTime) else float(value)


def in_stamp_order(
    stamped: Iterable[tuple[float, T]], window: float
) -> Iterator[tuple[float, T, bool]]:
    """Items read in log order, put back in the order of their stamps by a bounded
    reorder buffer: each is held until one stamped more than ``window`` later has been
    read, then released in stamp order (equal stamps in read order).

    A recorder logs each message when it arrives, so messages of several sources (or of
    one that lags) come a little out of stamp order; a buffer of ``window`` seconds of
    stamps puts back every message that lags less than that. The held items are a list
    sorted by (stamp, read order) read from its head: an item in order (nearly all) is
    appended, one out of order inserted by bisection.

    Parameters
    ----------
    stamped : iterable of (float, item)
        (stamp s, item) in the order read.
    window : float
        The longest lag put back (s).

    Returns
    -------
    iterator of (float, item, bool)
        (stamp, item, late): the items in stamp order; an item stamped more than
        ``window`` before the newest read so far is yielded at once with ``late`` True
        (out of order: the caller drops or counts it).
    """
    held: list[tuple[float, int, T]] = []
    head = 0
    newest = -math.inf
    for seq, (t, item) in enumerate(stamped):
        if t < newest - window:
            yield t, item, True
            continue
        entry = (t, seq, item)
        if t >= newest:
            newest = t
            held.append(entry)
        else:
            bisect.insort(held, entry, lo=head)
        due = newest - window
        while held[head][0] < due:
            yield held[head][0], held[head][2], False
            head += 1
        if head > 1024:  # drop what was released
            del held[:head]
            head = 0
    for t, _seq, item in held[head:]:
        yield t, item, False
