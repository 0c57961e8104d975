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

``estimate_odometry_delay`` measures the lag from the log itself, with no truth: the
bearing of a landmark seen in two consecutive frames changes as the odometry, read d
earlier, says the robot turned and moved; the lag that explains the changes best is the
estimate (``run`` reports it, ``odometry_delay_estimate`` in the summary).
"""

from __future__ import annotations

import heapq
import itertools
import math
from collections.abc import Iterable, Iterator
from dataclasses import dataclass

import numpy as np

from fuzzyslam.se2 import wrap_angle
from fuzzyslam.slam.events import Event, Frame, Odom


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


MIN_PAIRS = 100  # pairs of sightings below which no estimate is given
MAX_FRAME_GAP_S = 0.5  # consecutive frames further apart than this are not paired
UNIQUE_DEG = 2.0  # the second-nearest bearing must be this much (and 3x) further away
MAX_RANGE_STEP_M = 0.5
DELAY_NOTE_S = 0.05  # an estimate this far from the configured delay is told (stderr)
# the lags searched about the configured delay (s): estimate_odometry_delay's default grid
GRID_LO, GRID_HI, GRID_STEP = -0.2, 0.6, 0.025
# a lag whose residuals beat the configured delay's by fewer standard errors is not advised
DROP_Z = 3.0


def delay_note(
    estimate: float,
    configured: float,
    drop_z: float = math.inf,
    at_edge: bool = False,
    grid: tuple[float, float] = (GRID_LO, GRID_HI),
) -> str:
    """The one-line advice when the estimated latency differs from the configured one.

    A lag on the edge of the searched grid (``at_edge``: its first or last lag, ``grid``,
    about the configured delay) is a bound, not a measurement: the line says how far the
    odometry leads the motion (or, estimated below 0, lags it) as a bound on the side
    the search ended (at the upper edge, at least that lead; at the lower edge, at most
    that lead or at least that lag) and to check the clocks (a 1 s offset between the
    odometry's and the camera's stamps gave the grid's edge, 0.8 s, on MRCLAM robot 3).
    A lag inside the grid is advised only when its residuals are significantly smaller
    than the configured delay's: the paired drop of the clipped squared residuals more than
    ``DROP_Z`` standard errors (``drop_z``, :func:`paired_drop_z`); else the line says
    the fit barely changes and advises nothing (MRCLAM robot 2 with that 1 s offset:
    0.03 s, 1.7 standard errors).

    Parameters
    ----------
    estimate, configured : float
        The estimated and the configured odometry delay (s).
    drop_z : float
        The residuals' drop from the configured delay to the estimate, in standard
        errors (default: significant).
    at_edge : bool
        The estimate is on the searched grid's edge.
    grid : (float, float)
        The first and last lags searched (s, about ``configured``): the grid
        :meth:`MotionTap.estimate` was given (``DelayEstimate.grid``); default
        ``GRID_LO``, ``GRID_HI``.

    Returns
    -------
    str
        The line, when they differ by more than ``DELAY_NOTE_S``; else ''.
    """
    if abs(estimate - configured) <= DELAY_NOTE_S:
        return ""
    head = "odometry_delay_estimate: the detections' bearings say the odometry"
    if at_edge:
        # beyond the upper edge the lead is larger, beyond the lower one smaller; a
        # negative lead is a lag, and its bound the other way round
        upper = estimate > configured
        verb, size = ("leads", estimate) if estimate >= 0 else ("lags", -estimate)
        bound = "at least" if upper == (estimate >= 0) else "at most"
        return (
            f"{head} {verb} the motion by {bound} {size:.3f} s, the edge of "
            f"the lags searched ({grid[0]:+g} to {grid[1]:+g} s about slam.odometry_delay_s "
            f"= {configured:g}): not a measurement; check the clocks of the odometry and "
            "the detections (an offset between their stamps)"
        )
    if not drop_z > DROP_Z:
        return (
            f"{head} may lead the motion by {estimate:.3f} s, but the fit is barely better "
            f"than at slam.odometry_delay_s = {configured:g} ({drop_z:.1f} standard errors,"
            f" {DROP_Z:g} needed): keep it unless the clocks are known to be off"
        )
    advice = max(round(estimate, 2), 0.0)
    return (
        f"{head} leads the motion by {estimate:.3f} s (slam.odometry_delay_s is "
        f"{configured:g}): set slam.odometry_delay_s: {advice:g} in your config"
    )


@dataclass
class DelayEstimate:
    """The odometry latency the log's own bearings imply (``estimate_odometry_delay``)."""

    delay_s: float  # configured delay + the residual lag found
    pairs: int  # sightings of one landmark in consecutive frames that were used
    residual_deg: float  # robust scale of the bearing-change residuals at the estimate
    residual_at_configured_deg: float  # the same at the configured delay
    # the residuals' paired drop from the configured delay to the estimate, in standard
    # errors (paired_drop_z), and whether the estimate is on the searched grid's edge
    drop_z: float = math.nan
    at_edge: bool = False
    # the first and last lags searched (s, about the configured delay)
    grid: tuple[float, float] = (GRID_LO, GRID_HI)

    def as_dict(self) -> dict:
        """The summary's ``odometry_delay_estimate``.

        Returns
        -------
        dict
            ``delay_s``, ``pairs``, ``residual_deg``, ``residual_at_configured_deg``,
            ``residual_drop_z`` (standard errors) and ``at_search_edge``.
        """
        return {
            "delay_s": round(self.delay_s, 3),
            "pairs": self.pairs,
            "residual_deg": round(self.residual_deg, 3),
            "residual_at_configured_deg": round(self.residual_at_configured_deg, 3),
            "residual_drop_z": round(self.drop_z, 2) if math.isfinite(self.drop_z) else None,
            "at_search_edge": self.at_edge,
        }


class MotionTap:
    """Passes events through unchanged, keeping what ``estimate_odometry_delay`` needs:
    the odometry's stamps and cumulative distance and turn, and each frame's detections."""

    def __init__(self, events: Iterable[Event]) -> None:
        self._events = events
        self.odo: list[tuple[float, float, float]] = []
        self.frames: list[tuple[float, np.ndarray]] = []

    def __iter__(self) -> Iterator[Event]:
        odo, frames = self.odo, self.frames
        for ev in self._events:
            if isinstance(ev, Odom):
                odo.append((ev.t, ev.d_trans, ev.d_rot))
            elif isinstance(ev, Frame):
                frames.append((ev.t, ev.z))
            yield ev

    def estimate(
        self, configured: float, min_pairs: int = MIN_PAIRS, lags: np.ndarray | None = None
    ) -> DelayEstimate | None:
        """``estimate_odometry_delay`` on what passed (stamps as the filter saw them, so
        the lag found is added to ``configured``).

        Parameters
        ----------
        configured : float
            The delay (s) the events were restamped with.
        min_pairs : int
            Fewest pairs of consecutive sightings to give an estimate.
        lags : ndarray (g,), optional
            The lags searched (``estimate_odometry_delay``'s default grid when None); the
            estimate is ``at_edge`` within a fifth of their step of the first or last.

        Returns
        -------
        DelayEstimate or None
            None with fewer than ``min_pairs`` pairs.
        """
        if len(self.odo) < 2 or len(self.frames) < 2:
            return None
        t, d_trans, d_rot = np.asarray(self.odo, dtype=float).T
        pairs = consecutive_sightings(self.frames)
        if len(pairs) < min_pairs:
            return None
        cum_trans, cum_rot = np.cumsum(d_trans), np.cumsum(d_rot)
        grid = _grid(lags)
        lag, scale, scale0 = estimate_odometry_delay(t, cum_trans, cum_rot, pairs, grid)
        z = paired_drop_z(t, cum_trans, cum_rot, pairs, lag)
        lo, hi = float(grid.min()), float(grid.max())
        step = (hi - lo) / (len(grid) - 1) if len(grid) > 1 else GRID_STEP
        edge = min(abs(lag - lo), abs(lag - hi)) < 0.2 * step
        return DelayEstimate(configured + lag, len(pairs), scale, scale0, z, edge, (lo, hi))


def consecutive_sightings(frames: list[tuple[float, np.ndarray]]) -> np.ndarray:
    """Detections of one landmark in two consecutive frames, paired by nearest bearing.

    A detection of frame k is paired with the detection of frame k + 1 nearest in
    bearing, when that one is unique (the next nearest is more than three times as far
    and ``UNIQUE_DEG`` further) and the ranges differ by less than ``MAX_RANGE_STEP_M``;
    frames more than ``MAX_FRAME_GAP_S`` apart are not paired.

    Parameters
    ----------
    frames : list of (float, ndarray (m, 2))
        Frame stamps and detections (x, y in the robot frame), in time order.

    Returns
    -------
    ndarray (k, 5)
        Per pair: t0, t1, bearing change b1 - b0 (rad, wrapped), mean bearing (rad),
        mean range (m).
    """
    rows = []
    for (t0, z0), (t1, z1) in itertools.pairwise(frames):
        z0 = np.asarray(z0, dtype=float).reshape(-1, 2)
        z1 = np.asarray(z1, dtype=float).reshape(-1, 2)
        if not len(z0) or not len(z1) or t1 - t0 > MAX_FRAME_GAP_S:
            continue
        b0, r0 = np.arctan2(z0[:, 1], z0[:, 0]), np.hypot(z0[:, 0], z0[:, 1])
        b1, r1 = np.arctan2(z1[:, 1], z1[:, 0]), np.hypot(z1[:, 0], z1[:, 1])
        db = wrap_angle(b1[None, :] - b0[:, None])  # (m0, m1)
        cost = np.abs(db)
        j = np.argmin(cost, axis=1)
        k = np.arange(len(z0))
        best = cost[k, j]
        if cost.shape[1] > 1:
            second = np.partition(cost, 1, axis=1)[:, 1]
            unique = second >= 3.0 * best + np.radians(UNIQUE_DEG)
        else:
            unique = np.ones(len(z0), dtype=bool)
        ok = unique & (np.abs(r1[j] - r0) <= MAX_RANGE_STEP_M)
        a = np.nonzero(ok)[0]
        b = j[a]
        d = db[a, b]
        stamps = np.broadcast_to([t0, t1], (len(a), 2))
        rows.append(np.column_stack([stamps, d, b0[a] + 0.5 * d, 0.5 * (r0[a] + r1[b])]))
    return np.concatenate(rows) if rows else np.zeros((0, 5))


def _clipped_loss(t: np.ndarray, cum_trans: np.ndarray, cum_rot: np.ndarray, pairs: np.ndarray):
    """The per-pair truncated quadratic loss of :func:`estimate_odometry_delay`: a
    function of the lags (g,) giving (g, k) squared residuals db - db_pred clipped at 3
    robust sigmas of those at lag 0."""
    t0, t1, db, b, r = pairs.T
    coef = np.sin(b) / np.maximum(r, 1e-3)

    def residuals(lag: np.ndarray) -> np.ndarray:
        """(g, k) residuals db - db_pred for each lag of ``lag`` (g,)."""
        a = t0[None, :] - lag[:, None]
        c = t1[None, :] - lag[:, None]
        turn = np.interp(c, t, cum_rot) - np.interp(a, t, cum_rot)
        dist = np.interp(c, t, cum_trans) - np.interp(a, t, cum_trans)
        return db[None, :] - (-turn + dist * coef[None, :])

    # truncated quadratic loss, clipped at 3 robust sigmas of the residuals at lag 0:
    # smooth in the lag (a median is not), and a wrong pairing costs at most the clip
    clip = 3.0 * 1.4826 * float(np.median(np.abs(residuals(np.zeros(1)))))

    def loss(lag: np.ndarray) -> np.ndarray:
        return np.minimum(residuals(lag) ** 2, clip**2)

    return loss


def paired_drop_z(
    t: np.ndarray, cum_trans: np.ndarray, cum_rot: np.ndarray, pairs: np.ndarray, lag: float
) -> float:
    """How significantly the lag ``lag`` explains the bearing changes better than lag 0
    (the configured delay): the mean over the k pairs of d_i = l_i(0) - l_i(lag), the
    drop of each pair's clipped squared residual (:func:`estimate_odometry_delay`'s
    loss), over its standard error std(d) / sqrt(k) (a paired comparison: the same
    sightings at both lags). Successive pairs share frames, so the error is somewhat
    understated; ``DROP_Z`` = 3 leaves room for that.

    Parameters
    ----------
    t, cum_trans, cum_rot : ndarray (n,)
        Odometry stamps, cumulative distance and turn.
    pairs : ndarray (k, 5)
        ``consecutive_sightings``.
    lag : float
        The estimate's lag (s).

    Returns
    -------
    float
        The drop in standard errors (0 when the lag is 0 or every d_i is equal; inf
        when they all drop by the same positive amount).
    """
    loss = _clipped_loss(t, cum_trans, cum_rot, pairs)(np.array([0.0, float(lag)]))
    d = loss[0] - loss[1]
    mean, sd = float(d.mean()), float(d.std(ddof=1)) if len(d) > 1 else 0.0
    if sd > 0:
        return mean / (sd / math.sqrt(len(d)))
    return math.inf if mean > 0 else 0.0


def _grid(lags: np.ndarray | None) -> np.ndarray:
    """The lags searched: ``lags`` as floats, or the default grid (``GRID_LO`` to
    ``GRID_HI`` by ``GRID_STEP``) when None.

    Parameters
    ----------
    lags : ndarray (g,) or None

    Returns
    -------
    ndarray (g,)
    """
    if lags is None:
        return np.arange(GRID_LO, GRID_HI + 1e-9, GRID_STEP)
    return np.asarray(lags, float)


def estimate_odometry_delay(
    t: np.ndarray,
    cum_trans: np.ndarray,
    cum_rot: np.ndarray,
    pairs: np.ndarray,
    lags: np.ndarray | None = None,
) -> tuple[float, float, float]:
    """The lag d that best explains the landmarks' bearing changes by the odometry.

    A static landmark at bearing b and range r, seen by a robot moving forward at v and
    turning at w, has db/dt = -w + v sin(b) / r (the robot frame's rotation and the
    parallax of its translation). Between two frames at t0 and t1 the odometry, read
    ``d`` earlier (an increment stamped t is motion at t + d), predicts

        db_pred(d) = -(R(t1 - d) - R(t0 - d)) + (S(t1 - d) - S(t0 - d)) sin(b) / r

    with S, R the cumulative distance and turn interpolated at those times. The estimate
    is the lag on the grid ``lags`` whose residuals db - db_pred have the smallest robust
    scale (the root mean square of the residuals clipped at three robust sigmas of those
    at lag 0: a truncated quadratic loss, so that wrong pairings or moving landmarks
    cost at most the clip), refined by a parabola through the minimum and its two
    neighbours. The idea is the temporal calibration of Li and Mourikis, "Online temporal
    calibration for camera-IMU systems", IJRR 33(7), 2014, here as a batch search.

    Parameters
    ----------
    t : ndarray (n,)
        Odometry stamps, increasing (s).
    cum_trans, cum_rot : ndarray (n,)
        Cumulative distance (m) and signed turn (rad) at those stamps.
    pairs : ndarray (k, 5)
        ``consecutive_sightings``: t0, t1, bearing change, bearing, range.
    lags : ndarray (g,), optional
        Candidate lags (s), evenly spaced; default -0.2 to 0.6 s by 0.025 s.

    Returns
    -------
    lag : float
        The residual odometry latency (s) relative to the stamps given.
    scale : float
        Robust scale (clipped root mean square) of the residuals at ``lag`` (deg).
    scale_at_zero : float
        The same at lag 0 (deg): the improvement the lag brings.
    """
    grid = _grid(lags)
    loss = _clipped_loss(t, cum_trans, cum_rot, pairs)

    def scale(lag: np.ndarray) -> np.ndarray:
        """Robust residual scale (rad) for each lag of ``lag`` (g,)."""
        return np.sqrt(np.mean(loss(lag), axis=1))

    s = scale(grid)
    i = int(np.argmin(s))
    lag = float(grid[i])
    if 0 < i < len(grid) - 1:  # vertex of the parabola through the three grid points
        den = s[i - 1] - 2.0 * s[i] + s[i + 1]
        if den > 0:
            lag += 0.5 * (s[i - 1] - s[i + 1]) / den * (grid[1] - grid[0])
    at = scale(np.array([lag, 0.0]))
    return float(lag), float(np.degrees(at[0])), float(np.degrees(at[1]))
