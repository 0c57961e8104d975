"""The data of the EKF-SLAM loop (:mod:`fuzzyslam.slam.runner`): its events, the
aid protocol, the rows it emits, the sink protocol and the result.

Events (built from a log by :mod:`fuzzyslam.slam.inputs`, or by a test):

- :class:`Odom`: an odometry increment (d_trans, d_rot) ending at time t;
- :class:`Frame`: lamp detections z (m, 2) in base_link with covariances (m, 2, 2);
- :class:`RingEvent`: a sonar ring, handed to the aids.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np

from fuzzyslam.slam.ekf import EkfSlam, UpdateResult
from fuzzyslam.slam.noise import DetectionNoiseEstimate
from fuzzyslam.slam.turn_check import DistanceCheck, TurnCheck
from fuzzyslam.streams.sonar import Ring

if TYPE_CHECKING:  # slam/latency.py reads the events defined here
    from fuzzyslam.slam.latency import DelayEstimate
    from fuzzyslam.slam.run_results import FilterHealth, RunCounts


# The events pickle as their constructor call, ``__reduce__``: slam/prefetch.py sends
# every event through a pipe, and a slotted dataclass's default pickle (a new object,
# then its slots' state set one by one) costs more (the paper log's pose run: the
# parent's loads 31 -> 23 ms, the child's dumps 69 -> 46 ms; its 15089 odometry
# increments alone 9.6 -> 4.5 ms and 26 -> 9.5 ms).


@dataclass(slots=True)
class Odom:
    t: float
    d_trans: float
    d_rot: float

    def __reduce__(self):
        return Odom, (self.t, self.d_trans, self.d_rot)


@dataclass(slots=True)
class Frame:
    t: float
    z: np.ndarray
    cov: np.ndarray

    def __reduce__(self):
        return Frame, (self.t, self.z, self.cov)


@dataclass(slots=True)
class RingEvent:
    """A range ring; ``ahead``: per aid, what it computed from the ring alone before the
    filter reached it (``FixAid.ahead``, made in slam/prefetch.py's child process), or
    None (nothing: the aid computes it itself)."""

    t: float
    ring: Ring
    ahead: tuple | None = None

    def __reduce__(self):
        return RingEvent, (self.t, self.ring, self.ahead)


Event = Odom | Frame | RingEvent


class FilterView(Protocol):
    """What a fix plug-in reads from the filter and does to it (``slam.ekf.EkfSlam``):
    the pose (3,) and its covariance (3, 3), the dead reckoning of the same odometry, a
    direct measurement of pose components ``idx`` (Joseph form, gated), and covariance
    inflation of the robot block."""

    odometry_pose: np.ndarray

    @property
    def pose(self) -> np.ndarray: ...

    @property
    def pose_cov(self) -> np.ndarray: ...

    def update_robot(
        self, z: np.ndarray, r: np.ndarray, idx: np.ndarray, gate_chi2: float | None = None
    ) -> UpdateResult:
        """A direct measurement z of the robot's components ``idx`` (h(x) = x[idx]),
        NIS-gated.

        Parameters
        ----------
        z : ndarray, shape (k,)
            The measurement.
        r : ndarray, shape (k, k)
            Its covariance.
        idx : ndarray of int, shape (k,)
            Robot components (0 x, 1 y, 2 heading).
        gate_chi2 : float or None
            Refused (no change) when the NIS exceeds it; None: no gate.

        Returns
        -------
        UpdateResult
            accepted, NIS, innovation (k,).
        """
        ...

    def inflate_robot(self, q: np.ndarray) -> None:
        """P_rr += q (fading memory: the filter admits an error it did not model).

        Parameters
        ----------
        q : ndarray, shape (3, 3)
            Added to the robot block.
        """
        ...


class Aid(Protocol):
    """A plug-in that corrects the filter from sonar rings (heading or pose fixes).

    Optional: ``ahead(ring, mounts)``, what it computes from a ring alone, and
    ``take_ahead(ring, value)`` (``fixes.base.FixAid``): slam/prefetch.py's child
    process computes it before the filter reaches the ring; ``figures(outdir)``, the
    calls that draw its figures after ``write`` (with ``draws_figures``: made in the
    run's figure process, fuzzyslam/forked.py)."""

    start_time: float

    def on_ring(self, t: float, ring: Ring, mounts: np.ndarray, ekf: FilterView) -> None: ...

    def summary(self) -> dict: ...

    def write(self, outdir: Path) -> None: ...


@dataclass(slots=True)
class UpdateRow:
    """One measurement update attempt (updates.csv)."""

    t: float
    kind: str
    id: int
    dof: int
    nis: float
    accepted: bool
    v: np.ndarray


@dataclass
class LampRecord:
    id: int
    x: float
    y: float
    cov: np.ndarray
    first_seen: float
    last_seen: float
    observations: int


class RowSink(Protocol):
    """Receives the rows of a run in time order, each once it is final."""

    def row(self, t: float, pose: np.ndarray, cov: np.ndarray) -> None:
        """A trajectory row: pose (3,) and covariance (6,) ``pxx pxy pxt pyy pyt ptt``."""

    def odometry_start(self, t: float) -> None:
        """Time of the start pose of the dead reckoning.

        Parameters
        ----------
        t : float
            Log time (s).
        """

    def odometry(self, t: float, d_trans: float, d_rot: float) -> None:
        """One odometry increment ending at ``t``.

        Parameters
        ----------
        t : float
            Log time (s).
        d_trans : float
            Translation (m).
        d_rot : float
            Rotation (rad).
        """

    def update(self, row: UpdateRow) -> None:
        """One measurement update attempt.

        Parameters
        ----------
        row : UpdateRow
            The attempt.
        """

    def snapshot(self, t: float, lamps: np.ndarray, covs: np.ndarray) -> None:
        """The lamps (n, 2) and their covariances (n, 2, 2) at ``t``.

        Parameters
        ----------
        t : float
            Log time (s).
        lamps : ndarray, shape (n, 2)
            Lamp positions.
        covs : ndarray, shape (n, 2, 2)
            Their covariances.
        """


class MemorySink:
    """A :class:`RowSink` that keeps every row in memory (tests, short logs)."""

    def __init__(self) -> None:
        self.t: list[float] = []
        self.x: list[np.ndarray] = []
        self.p: list[np.ndarray] = []
        self.odo_t: list[float] = []
        self.odo_u: list[tuple[float, float]] = []
        self.updates: list[UpdateRow] = []
        self.snapshots: list[tuple[float, np.ndarray, np.ndarray]] = []

    def row(self, t: float, pose: np.ndarray, cov: np.ndarray) -> None:
        self.t.append(t)
        self.x.append(pose)
        self.p.append(cov)

    def odometry_start(self, t: float) -> None:
        self.odo_t.append(t)

    def odometry(self, t: float, d_trans: float, d_rot: float) -> None:
        self.odo_t.append(t)
        self.odo_u.append((d_trans, d_rot))

    def update(self, row: UpdateRow) -> None:
        self.updates.append(row)

    def snapshot(self, t: float, lamps: np.ndarray, covs: np.ndarray) -> None:
        self.snapshots.append((t, lamps, covs))


@dataclass
class SlamResult:
    """Everything ``run`` writes: trajectory (N, 3) with covariance rows (N, 6), etc.

    With a streaming sink the rows went to the sink: ``t``, ``poses``, ``cov`` then hold
    only the last row, and ``odo_*``, ``updates``, ``snapshots`` are empty.
    """

    t: np.ndarray
    poses: np.ndarray
    cov: np.ndarray
    odo_t: np.ndarray
    odo_poses: np.ndarray
    lamps: list[LampRecord]
    updates: list[UpdateRow]
    counts: RunCounts  # (slam/run_results.py)
    snapshots: list[tuple[float, np.ndarray, np.ndarray]]
    ekf: EkfSlam
    # set by the run stage: numerical guards and the divergence test (slam/health.py),
    # and the detection noise the innovations imply (slam/noise.py)
    health: FilterHealth | None = None
    noise_estimate: DetectionNoiseEstimate | None = None
    delay_estimate: DelayEstimate | None = None  # the odometry latency (slam/latency.py)
    calibration: Any = None  # the summary's entry, calibration.CalibrationEntry (slam/stage.py)
    turn_check: TurnCheck | None = None  # the odometry's turns against the estimate's
    distance_check: DistanceCheck | None = None  # ... and its displacements

    def mean_nis(self, kind: str = "lamp") -> float:
        """Mean NIS of the accepted updates of ``kind`` (expected value: their dof).

        Parameters
        ----------
        kind : str
            The update kind (lamp, heading, pose).

        Returns
        -------
        float
            NaN without such updates.
        """
        vals = [u.nis for u in self.updates if u.kind == kind and u.accepted]
        return float(np.mean(vals)) if vals else float("nan")


@dataclass(frozen=True)
class TfFrames:
    """The /tf tree ``run`` writes into estimates.mcap: ``map`` -> ``odom`` (the filter's
    correction) and, unless the log already carries it on /tf, ``odom`` -> ``base`` (the
    dead reckoning). Names follow the log's nav_msgs/Odometry (header.frame_id,
    child_frame_id) so that the sensor log and the estimates open together as one tree
    (REP 105).

    When the log carries odom -> base, ``log_odom`` holds that series (times (N,) in s,
    increasing; poses (N, 3), the heading unwrapped: continuous): map -> odom is then
    the estimate composed with the inverse of the log's odom -> base at the estimate's
    stamp (as AMCL does), so that the two files compose to the estimate whatever the
    filter's own dead reckoning (another start pose, an odometry delay, another wheel radius)."""

    map: str = "map"
    odom: str = "odom"
    base: str = "base_link"
    odom_to_base: bool = True  # False: the log's own /tf has odom -> base
    # the log's odom -> base (t, poses), when odom_to_base is False (arrays: not compared)
    log_odom: tuple[np.ndarray, np.ndarray] | None = field(default=None, compare=False, repr=False)
