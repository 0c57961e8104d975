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
- an exact 0.0 below range_min is read as ``ranges.scan_zero`` says (``zero_ranges``
  counts them, ``zero_invalid`` those read as invalid): ``no_echo`` (the default) as no
  return on a beam that has echoed in an earlier scan, invalid on one that has not yet
  (a beam the robot's own body blocks, or outside the laser's real view, reads 0.0 in
  every scan: it is not open space); ``invalid`` as invalid. REP 117 writes +inf for no
  return, but common drivers (a TurtleBot3's LDS-01, others) write 0.0, and a laser's
  exact 0.0 is practically never an object nearer than range_min;
- ``-inf`` (too close), NaN (erroneous) and finite ranges below range_min or above
  range_max are invalid: NaN, skipped by the evidence (``invalid``);
- an echo nearer than ``ranges.min_range_m`` (the robot's own body or struts in the
  laser's view: small positive ranges above range_min) is invalid too, not a wall
  (``too_near``; 0, the default, leaves range_min the only limit);
- a message with as many beams as the first one, its angle_min within ``ANGLE_TOL`` of
  the first one's and its angle_increment's difference summed over the scan within
  ``ANGLE_TOL`` too, has the first one's geometry (float32 fields that jitter);
- a message whose beam count or angles truly differ (an RPLidar's 180 / 179 beams) is
  read onto the first message's kept beams, so that every ring has the same M sensors:
  each kept beam takes the message's beam nearest to it in angle, when that beam is
  less than half the kept beams' spacing away (so no beam serves two), and reads NaN
  (``missing``) where the message does not cover it; each beam is placed at its own
  angle (``Ring.mounts``, from the laser's mount: :func:`fuzzyslam.streams.tf.beam_mounts`)
  unless all of them lie within ``ANGLE_TOL`` of the kept beams' (``resampled_scans``);
- a message with a non-positive or non-finite range_max, no beams, a zero or non-finite
  angle_increment, or no beam near any kept beam is refused (``bad_scans``): counted, the
  first one's stamp kept (``RingStats.first_refused_at``: a run counts them into its
  lost events), and more than ``FEW_REFUSED`` said in one line on stderr;
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
from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike

from fuzzyslam.progress import note
from fuzzyslam.streams.messages import stamp_to_sec
from fuzzyslam.streams.reader import LogMessage
from fuzzyslam.streams.sonar import Ring, RingStats
from fuzzyslam.streams.tf import Rigid, TfProblem, beam_mounts

ANGLE_TOL = 1e-4  # rad: angles this close are one geometry (float32 jitter is ~1e-7 rad)
FEW_REFUSED = 3  # more scans refused than this: a line on stderr
ZERO_READS = ("no_echo", "invalid")  # ranges.scan_zero: how an exact 0.0 is read


@dataclass(frozen=True)
class Resampled:
    """A scan read onto a geometry's kept beams (:meth:`ScanGeometry.resample`)."""

    index: np.ndarray  # (M,) int: the scan's beam for each kept beam (valid where ``ok``)
    ok: np.ndarray  # (M,) bool: the kept beam has a scan beam near it
    angles: np.ndarray  # (M,) the beams' angles in the laser frame (rad; kept ones if not ok)
    moved: bool  # some beam lies more than ANGLE_TOL off its kept beam's angle


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
        """Whether a LaserScan message has this geometry: as many beams, angle_min within
        ``ANGLE_TOL``, and its angle_increment's difference, summed over the scan, within
        ``ANGLE_TOL`` too (float32 fields that jitter).

        Parameters
        ----------
        msg : sensor_msgs/LaserScan
            The message.

        Returns
        -------
        bool
        """
        n = len(msg.ranges)
        d_min = abs(float(msg.angle_min) - self.angle_min)
        d_inc = abs(float(msg.angle_increment) - self.angle_increment)
        # NaN fields compare False: not this geometry
        return n == self.beams and d_min <= ANGLE_TOL and d_inc * max(n - 1, 1) <= ANGLE_TOL

    def resample(self, msg) -> Resampled | None:
        """A LaserScan message of another geometry read onto this one's kept beams (module
        docstring): for each kept beam the message's beam nearest in angle, when less than
        half the kept beams' spacing away.

        Parameters
        ----------
        msg : sensor_msgs/LaserScan
            The message (any beam count, angle_min and angle_increment, either sign).

        Returns
        -------
        Resampled or None
            None when the message has no beams, a zero or non-finite angle, or no beam
            near any kept beam.
        """
        n = len(msg.ranges)
        a0, inc = float(msg.angle_min), float(msg.angle_increment)
        if n == 0 or not (np.isfinite(a0) and np.isfinite(inc) and inc != 0):
            return None
        want = self.angles
        index = np.clip(np.rint((want - a0) / inc), 0, n - 1).astype(np.intp)
        got = a0 + index * inc
        off = np.abs(got - want)
        # < half the spacing: a scan beam is that near to one kept beam at most
        ok = off < 0.5 * abs(self.angle_increment) * self.step
        if not ok.any():
            return None
        moved = bool((off[ok] > ANGLE_TOL).any())
        return Resampled(index, ok, np.where(ok, got, want), moved)


def scan_geometry(msg, step: int = 1, spacing: float = 0.0) -> ScanGeometry:
    """The geometry of a LaserScan message, keeping every ``step``-th beam, or more
    apart: the kept beams at least ``spacing`` (rad) apart (:func:`kept_step`).

    Parameters
    ----------
    msg : sensor_msgs/LaserScan
        The first message.
    step : int
        Keep at least every ``step``-th beam.
    spacing : float
        The kept beams' least angle apart (rad): the evidence model's beam cone.

    Returns
    -------
    ScanGeometry
    """
    if step < 1:
        raise ValueError(f"step must be >= 1, got {step}")
    inc = float(msg.angle_increment)
    return ScanGeometry(
        str(msg.header.frame_id),
        float(msg.angle_min),
        inc,
        len(msg.ranges),
        kept_step(step, spacing, inc),
        _time_increment(msg),
    )


def kept_step(step: int, spacing: float, increment: float) -> int:
    """Every how many beams a scan is kept: ``step``, or more where its beams are so
    fine that ``step`` of them span less than ``spacing``.

    Each kept beam's cone (the evidence model's beam width) stands for the beams around
    it: kept beams closer than their cones overlap, and each wall cell is then counted by
    two or more beams as though they were independent looks, which makes a scan match
    overconfident. Measured on Freiburg 079 read as a 0.25-deg laser (1081 beams, 270 deg,
    2-deg cones): every 4th beam (1 deg apart) put 9 of 12 NIS windows of the pose run
    out of bounds and cost 3.8x the CPU; every 8th (2 deg) kept the 0.5-deg log's
    figures. Beam angles are float32: ``ANGLE_TOL`` is allowed.

    Parameters
    ----------
    step : int
        The least step (``ranges.scan_step``).
    spacing : float
        The least angle between kept beams (rad); 0 for none.
    increment : float
        The scan's angle increment (rad, either sign).

    Returns
    -------
    int
        At least ``step``.
    """
    inc = abs(float(increment))
    if not (np.isfinite(inc) and inc > 0.0) or spacing <= ANGLE_TOL:
        return int(step)
    return max(int(step), int(np.ceil((spacing - ANGLE_TOL) / inc)))


def _time_increment(msg) -> float:
    """The message's time between beams (s), 0 when not a positive finite number."""
    ti = float(msg.time_increment)
    return ti if np.isfinite(ti) and ti > 0 else 0.0


class ReadScan(NamedTuple):
    """One scan's ranges as read (:func:`scan_ranges`), with its counts."""

    ranges: np.ndarray  # (M,) echoes, range_max for no echo, NaN for invalid
    echo: np.ndarray  # (M,) bool: the beams that echoed
    invalid: int  # readings invalid (NaN)
    no_echo: int  # readings read as no echo (zeros included where read so)
    zeros: int  # exact 0.0 that are not echoes (below range_min or min_range)
    zeros_invalid: int  # of them, read as invalid
    too_near: int  # echoes within the message's limits but nearer than min_range


def scan_ranges(
    raw: np.ndarray,
    range_min: float,
    range_max: float,
    zero: str = "no_echo",
    min_range: float = 0.0,
    echoed: np.ndarray | None = None,
) -> ReadScan:
    """Raw LaserScan ranges read by the message's limits and the config's (module
    docstring): echoes kept, no return -> range_max, invalid -> NaN.

    Parameters
    ----------
    raw : ndarray, shape (M,)
        The message's ranges (float32).
    range_min, range_max : float
        The message's limits.
    zero : {"no_echo", "invalid"}
        How an exact 0.0 that is not an echo is read (``ranges.scan_zero``).
    min_range : float
        The least range of an echo used (``ranges.min_range_m``, m; 0: range_min alone).
    echoed : ndarray of bool, shape (M,), optional
        The beams that have echoed in an earlier scan: with ``zero`` ``no_echo`` a 0.0
        is no echo only on those (a beam that never echoes is blocked, or outside the
        laser's view: its 0.0 invalid); None: on every beam.

    Returns
    -------
    ReadScan
    """
    if zero not in ZERO_READS:
        raise ValueError(f"zero must be one of {', '.join(ZERO_READS)}, got {zero!r}")
    r = np.asarray(raw, dtype=float)
    with np.errstate(invalid="ignore"):
        within = np.isfinite(r) & (r >= range_min) & (r < range_max)
        echo = within & (r >= min_range)
        zeros = (r == 0.0) & ~echo
        near = within & ~echo & ~zeros
        no_echo = (r == np.inf) | (r == np.float32(range_max))
    quiet = zeros if zero == "no_echo" else np.zeros_like(zeros)
    if echoed is not None:
        quiet = quiet & echoed
    no_echo |= quiet
    out = np.where(echo, r, np.nan)
    out[no_echo] = range_max
    n_zeros = int(np.count_nonzero(zeros))
    return ReadScan(
        out,
        echo,
        int(len(r) - np.count_nonzero(echo) - np.count_nonzero(no_echo)),
        int(np.count_nonzero(no_echo)),
        n_zeros,
        n_zeros - int(np.count_nonzero(quiet)),
        int(np.count_nonzero(near)),
    )


def scan_rings(
    messages: Iterable[LogMessage],
    geometry: ScanGeometry,
    beam_width: float,
    stats: RingStats | None = None,
    laser: Rigid | ArrayLike | None = None,
    zero: str = "no_echo",
    min_range: float = 0.0,
) -> Iterator[Ring]:
    """LaserScan messages (log order) as :class:`Ring` s of the geometry's kept beams.

    A scan of another geometry is read onto the kept beams (:meth:`ScanGeometry.resample`,
    with its own mounts when its beams' angles differ); one that cannot be read is refused
    (module docstring). Glitches are counted in ``stats``; more than ``FEW_REFUSED``
    refused scans are said in one line on stderr when the messages are done with.

    Parameters
    ----------
    messages : iterable of LogMessage
        sensor_msgs/LaserScan messages in log order.
    geometry : ScanGeometry
        The first message's geometry: the rings' M kept beams.
    beam_width : float
        The cone of one beam (rad): each ring's ``fov``.
    stats : RingStats, optional
        Counts (``bad_scans``, ``resampled_scans`` among the extras).
    laser : Rigid or array_like, shape (3,), optional
        The laser's mount in the base frame (as :meth:`ScanGeometry.mounts`), which
        places the beams of a scan of another geometry; default the base frame itself.
    zero : {"no_echo", "invalid"}
        How an exact 0.0 below range_min is read (``ranges.scan_zero``,
        :func:`scan_ranges`).
    min_range : float
        The least range of an echo used (``ranges.min_range_m``, m).

    Returns
    -------
    iterator of Ring
        Ranges (M,), max ranges (M,), ``fov`` the beam width; a scan whose beams are taken
        ``time_increment`` apart at its last kept beam's time with their offsets.
    """
    st = stats if stats is not None else RingStats()
    st.extra.setdefault("bad_scans", 0)
    st.extra.setdefault("resampled_scans", 0)
    if laser is None:
        laser = Rigid()
    elif not isinstance(laser, Rigid):
        x, y, yaw = np.asarray(laser, dtype=float).reshape(3)
        laser = Rigid.planar(x, y, yaw)
    kept = geometry.kept
    echoed = np.zeros(len(kept), dtype=bool)  # the kept beams that have echoed so far
    after = kept - kept[-1]  # each kept beam's place before the last, in beams
    last_t = -np.inf
    refused, topic = 0, "the laser scans"
    try:
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
            usable = np.isfinite(hi) and hi > 0
            same = usable and geometry.matches(msg)
            other = None if same or not usable else geometry.resample(msg)
            own = None
            if other is not None and other.moved:
                try:
                    own = beam_mounts(laser, other.angles)
                except TfProblem:  # a beam of a tilted laser too near vertical
                    other = None
            if not same and other is None:
                st.extra["bad_scans"] += 1
                if st.first_refused_at is None:
                    st.first_refused_at = t
                refused += 1
                topic = getattr(m, "topic", topic)
                continue
            last_t = t
            raw = np.asarray(msg.ranges, dtype=np.float32)
            ti = _time_increment(msg)
            if same:
                got = scan_ranges(raw[kept], lo, hi, zero, min_range, echoed)
                ranges = got.ranges
                echoed |= got.echo
                read, last = len(kept), int(kept[-1])
                offsets = after * ti
            else:
                assert other is not None
                ok = other.ok
                ranges = np.full(len(kept), np.nan)
                got = scan_ranges(raw[other.index[ok]], lo, hi, zero, min_range, echoed[ok])
                ranges[ok] = got.ranges
                echoed[ok] |= got.echo
                read = int(np.count_nonzero(ok))
                last = int(other.index[ok].max())  # the last beam taken (beam k at k * ti)
                offsets = np.where(ok, (other.index - last) * ti, np.nan)
                st.missing += len(kept) - read
                st.extra["resampled_scans"] += 1
            st.rings += 1
            st.readings += read
            st.invalid += got.invalid
            st.no_echo += got.no_echo
            st.zero_ranges += got.zeros
            st.zero_invalid += got.zeros_invalid
            st.too_near += got.too_near
            rmax = np.full(len(kept), hi)
            if ti > 0 and read > 1:
                yield Ring(t + last * ti, ranges, rmax, float(beam_width), offsets, own)
            else:  # one beam read: at its own time (the stamp when ti is 0)
                yield Ring(t + last * ti, ranges, rmax, float(beam_width), mounts=own)
    finally:
        if refused > FEW_REFUSED:
            note(
                f"{topic}: {refused} laser scans refused (a range_max that is not a positive "
                "number, or no beam within the first scan's field of view); counted in "
                "bad_scans and not used"
            )
