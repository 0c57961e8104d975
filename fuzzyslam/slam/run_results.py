"""What the EKF-SLAM loop hands back, typed: its event counts (:class:`RunCounts`), the
filter's health (:class:`FilterHealth`, assembled by :func:`filter_health`) and the
:class:`~fuzzyslam.slam.events.SlamResult` of a memory or streaming sink
(:func:`slam_result`). The run summary's ``counts`` and ``filter_health`` are these
dataclasses, written by :func:`fuzzyslam.summary.as_json` (docs/contracts.md sec. 2):
a counter or health figure left out is a ``TypeError`` where it is made."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from fuzzyslam.robot import integrate
from fuzzyslam.slam.ekf import EkfSlam
from fuzzyslam.slam.events import LampRecord, MemorySink, RowSink, SlamResult
from fuzzyslam.slam.health import DivergenceMonitor, orphan_landmarks
from fuzzyslam.slam.map_motion import MapMotionMonitor
from fuzzyslam.streams.sonar import RingStats
from fuzzyslam.summary import OMIT


@dataclass(frozen=True, kw_only=True)
class RunCounts:
    """The run summary's ``counts``: events handled and what became of them.

    ``detections_own_covariance`` (detections that carried their own covariance) and
    ``detections_own_floored`` (of those, raised to the configured model:
    ``slam.detection_own_covariance``) are present for logs whose lamps come as
    detections only (set by the run stage).
    """

    odometry: int  # odometry increments
    frames: int  # camera frames (or detection messages)
    detections: int  # lamp detections in them
    associated: int  # paired with a mapped lamp (JCBB) and used in an update
    lamps_created: int
    lamps_deferred: int  # unpaired while an aid found the pose suspect
    duplicates_guarded: int  # refused: near a mapped lamp no other detection explains
    ambiguous: int  # another hypothesis fitted nearly as well
    frames_stale_odometry: int  # skipped: the odometry had been silent
    rings: int  # sonar rings (or scans)
    aid_calls: int  # rings handed to aids
    out_of_order: int  # events older than the last one, skipped
    tentative_expired: int
    tentative_pending: int
    detections_own_covariance: int = OMIT
    detections_own_floored: int = OMIT
    # the relocalisation test's (slam/relocalise.py), present when it is on
    relocalisation_tests: int = OMIT
    relocalisations: int = OMIT  # accepted: the pose had left its covariance


LOST_SHARE = 0.05  # more than this share of a stream not used: trouble (events_lost)


@dataclass
class LateEvents:
    """Events the runner skipped because they came older than the filter's time: a
    message logged more than ``slam.inputs.REORDER_S`` after others stamped later (a
    detector pipeline that lags). Each lost frame is a missed correction and each lost
    odometry increment is lost motion (:func:`lost_events`)."""

    frames: int = 0
    odometry: int = 0
    first_at: float | None = None  # the filter's time when the first was skipped (s)
    stale_at: float | None = None  # the first frame skipped on silent odometry (s)

    def add(self, ev: object, now: float) -> None:
        """Count one skipped event.

        Parameters
        ----------
        ev : Odom, Frame or RingEvent
            The event (rings are the aids' and are not counted here).
        now : float
            The filter's time (s).
        """
        kind = type(ev).__name__
        if kind not in ("Frame", "Odom"):
            return
        if kind == "Frame":
            self.frames += 1
        else:
            self.odometry += 1
        if self.first_at is None:
            self.first_at = now


def lost_events(
    late: LateEvents,
    counts: RunCounts,
    lost: dict[str, float],
    readings: int,
    stats: RingStats | None = None,
) -> tuple[str, float] | None:
    """``("events_lost", time of the first loss)`` when more than ``LOST_SHARE`` of the
    frames, of the odometry increments, of the range readings or of the laser scans were
    not used, else None.

    Lost: frames and odometry the runner skipped as too late (``late``), frames it
    skipped because the odometry had gone silent (``counts.frames_stale_odometry``: a
    driver that stopped), frames and range readings the input edge did not use
    (``lost``, slam/inputs.py: stamped back in time, or on another clock than the
    odometry's), and laser scans the range sensor refused (``stats``: the extra count
    ``bad_scans`` against the scans read, :func:`fuzzyslam.streams.scan.scan_rings`).
    A run that loses a stream so is estimated from what is left, and says so.

    Parameters
    ----------
    late : LateEvents
        The runner's skipped events.
    counts : RunCounts
        The run's counts (frames and odometry increments used).
    lost : dict
        ``LogInputs.lost``: ``frames``, ``readings`` and ``first_at`` (s, when any).
    readings : int
        Range readings read (``RingStats.readings``).
    stats : RingStats, optional
        The range sensor's counts: its refused scans (``extra["bad_scans"]``, the first
        at ``first_refused_at``) against its rings.

    Returns
    -------
    tuple of (str, float) or None
    """
    stale = counts.frames_stale_odometry  # read, but skipped: the odometry had gone silent
    frames = late.frames + int(lost["frames"]) + stale
    refused = int(stats.extra.get("bad_scans", 0)) if stats is not None else 0
    shares = (
        (frames, counts.frames - stale),
        (late.odometry, counts.odometry),
        (int(lost["readings"]), readings),
        (refused, stats.rings if stats is not None else 0),
    )
    if all(n <= LOST_SHARE * (n + used) for n, used in shares):
        return None
    first = stats.first_refused_at if refused and stats is not None else None
    times = [
        t for t in (late.first_at, late.stale_at, lost.get("first_at"), first) if t is not None
    ]
    return "events_lost", min(times)


@dataclass(frozen=True, kw_only=True)
class FilterHealth:
    """The run summary's ``filter_health``: the EKF's numerical guards, the windowed NIS
    and association-rate tests (:class:`~fuzzyslam.slam.health.DivergenceMonitor`), the
    longest odometry gap and the orphan landmarks (:func:`filter_health`)."""

    s_regularised: int  # near-singular innovation covariances regularised
    p_repaired: int  # covariances repaired to symmetric positive definite
    nis_windows: int
    nis_windows_out_of_bounds: int
    nis_worst_window_ratio: float
    association_windows: int
    association_windows_out_of_bounds: int
    landmark_births: int
    landmark_births_untrusted: int
    diverged: bool
    reasons: list[str]
    diverged_at: float | None  # on the log's stamp clock (s; Unix time on real logs)
    out_of_bounds_spans: list[list[float]]
    odometry_gap_s: float
    orphan_landmarks: int
    # landmark motion windows (slam/map_motion.py), present when lamps were mapped
    map_motion_windows: int = OMIT
    map_motion_windows_out_of_bounds: int = OMIT
    # diverged_at as seconds from the log's start (LogInputs.start on the stamps' clock),
    # present when the run is flagged and its start is known
    diverged_after_start_s: float | None = OMIT


# the likely causes of each reason, named in the flagged line on stderr (slam/stage.py)
REASON_CAUSES = {
    "nis": "noise set too small, a sensor mount or clock offset",
    "nis_rate": "noise set too small, a sensor mount or clock offset",
    "association": "an odometry scale or turn error, a detector mount's yaw",
    "orphan_landmarks": "detection noise too small, a mount or time error",
    "map_motion": "an odometry delay or clock offset, bearing noise too small",
    "position_unresolved": (
        "fixes too sparse for the odometry noise, an odometry turn or scale error, "
        "fixes.junction_margin"
    ),
    "pose_off_map": (
        "heading fixes on the wrong walls: a start pose off, an odometry scale or turn "
        "error, a range sensor's mount yaw, odometry noise set too small"
    ),
    "pose_matches_ambiguous": (
        "too few range sensors or a featureless place for the map, a start pose off the "
        "map's (--start-pose)"
    ),
    "pose_matches_refused": (
        "a start pose off the map's (--start-pose: a log's odometry starts at its own "
        "origin), odometry scale, the range sensor's mount, a clock offset"
    ),
    "live_map_inconsistent": (
        "the live map drifted: a laser too short for the corridors (range_max), the "
        "robot's own body in the scan (ranges.min_range_m), walls a few degrees off the "
        "building's right angles (fixes.live_right_angles)"
    ),
    "events_lost": "stamps on another clock or back in time, a driver that stopped",
    "odometry_turn_scale": "the odometry's turn scale (wheel base, driver), not the noise",
    "odometry_distance_scale": (
        "the odometry's distance scale (wheel radius, tyre wear, driver), not the noise"
    ),
}


def reason_causes(reasons: Sequence[str]) -> str:
    """The reasons, each with its likely causes (``REASON_CAUSES``), for one line:
    ``association: odometry scale ...; orphan_landmarks: ...``.

    Parameters
    ----------
    reasons : sequence of str
        ``filter_health.reasons``.

    Returns
    -------
    str
    """
    parts = []
    for r in reasons:
        cause = REASON_CAUSES.get(r)
        parts.append(f"{r}: {cause}" if cause else r)
    return "; ".join(parts)


def filter_health(
    guards: dict[str, int],
    monitor: DivergenceMonitor,
    gap_s: float,
    lamps: list[LampRecord],
    map_motion: MapMotionMonitor | None = None,
    aids: Sequence[Any] = (),
    lost: tuple[str, float] | None = None,
    start: float | None = None,
) -> FilterHealth:
    """The filter's health at the end of a run: the guards' and windows' counts; the map
    turned untrustworthy (orphan landmarks, :func:`~fuzzyslam.slam.health.orphan_landmarks`)
    also counts as divergence (reason ``orphan_landmarks``, from the earlier time).

    Parameters
    ----------
    guards : dict
        ``EkfSlam.guards``: ``s_regularised`` and ``p_repaired`` counts.
    monitor : DivergenceMonitor
        The runner's NIS and association-rate windows.
    gap_s : float
        The longest gap in the odometry (s).
    lamps : list of LampRecord
        The mapped lamps (birth times, observation counts).
    map_motion : MapMotionMonitor, optional
        The runner's landmark motion windows (reason ``map_motion``).
    aids : sequence, optional
        The fix plug-ins; one with a ``trouble()`` that answers (reason, time) adds that
        reason (the heading aid's ``position_unresolved``: the position's 99 % ellipse
        wider than the margin of its corridor choice, fixes/heading.py); one with
        ``troubles()`` adds each (reason, time) of its list instead (the pose aid's
        ``pose_matches_ambiguous`` and ``pose_matches_refused``).
    lost : (str, float), optional
        :func:`lost_events`' answer (reason ``events_lost``).
    start : float, optional
        The log's start on the stamps' clock (s): ``diverged_after_start_s`` is
        ``diverged_at`` - ``start`` (the time into the log the notes print).

    Returns
    -------
    FilterHealth
    """
    windows = monitor.summary()
    reasons = list(windows.pop("reasons"))
    diverged_at = windows.pop("diverged_at")
    diverged = windows.pop("diverged")
    orphans, orphans_at = orphan_landmarks(
        np.array([lm.first_seen for lm in lamps]),
        np.array([lm.observations for lm in lamps]),
    )
    findings = []  # (reason, from when) beyond the windows'
    if orphans_at is not None:
        findings.append(("orphan_landmarks", orphans_at))
    motion = {}
    if map_motion is not None and map_motion.windows:
        motion = {
            "map_motion_windows": map_motion.windows,
            "map_motion_windows_out_of_bounds": map_motion.out_of_bounds,
        }
        if map_motion.diverged_at is not None:
            findings.append(("map_motion", map_motion.diverged_at))
    for aid in aids:
        many = getattr(aid, "troubles", None)  # an aid with several findings
        if many is not None:
            findings.extend(many())
            continue
        trouble = getattr(aid, "trouble", None)
        found = trouble() if trouble is not None else None
        if found is not None:
            findings.append(found)
    if lost is not None:
        findings.append(lost)
    after = OMIT
    if diverged_at is not None and start is not None:
        after = round(float(diverged_at) - float(start), 3)
    health = FilterHealth(
        **guards,
        **windows,
        diverged=diverged,
        reasons=reasons,
        diverged_at=diverged_at,
        odometry_gap_s=round(gap_s, 3),
        orphan_landmarks=orphans,
        **motion,
        diverged_after_start_s=after,
    )
    for reason, t in findings:
        health = with_finding(health, reason, t, start)
    return health


def with_finding(
    health: FilterHealth, reason: str, at: float, start: float | None = None
) -> FilterHealth:
    """``health`` with one more reason (the aids' findings, orphan landmarks, lost events
    in :func:`filter_health`; the odometry's turns against the estimate's, found once
    the rows are written, slam/turn_check.py): flagged, from the earlier of ``at`` and
    the time it was flagged from.

    Parameters
    ----------
    health : FilterHealth
        :func:`filter_health`'s answer.
    reason : str
        The reason (a key of ``REASON_CAUSES``).
    at : float
        From when (s, on the stamps' clock).
    start : float, optional
        The log's start on the stamps' clock (``diverged_after_start_s``).

    Returns
    -------
    FilterHealth
    """
    t = at if health.diverged_at is None else min(health.diverged_at, at)
    after = round(float(t) - float(start), 3) if start is not None else OMIT
    return replace(
        health,
        diverged=True,
        reasons=[*health.reasons, reason],
        diverged_at=t,
        diverged_after_start_s=after,
    )


def slam_result(
    sink: RowSink,
    start_pose: np.ndarray,
    last: tuple[float, np.ndarray, np.ndarray] | None,
    lamps: list[LampRecord],
    counts: RunCounts,
    ekf: EkfSlam,
) -> SlamResult:
    """The loop's result from its sink: a :class:`MemorySink`'s rows (the dead reckoning
    integrated from ``start_pose``), or, streamed, only the last trajectory row.

    Parameters
    ----------
    sink : RowSink
        The rows' sink (all rows given to it).
    start_pose : ndarray, shape (3,)
        The start pose (x, y, theta) of the dead reckoning.
    last : (float, ndarray (3,), ndarray (6,)) or None
        The last trajectory row: time, pose, covariance's upper triangle.
    lamps : list of LampRecord
        The mapped lamps.
    counts : RunCounts
        The loop's counts.
    ekf : EkfSlam
        The filter at the end.

    Returns
    -------
    SlamResult
        Trajectory ``t`` (N,), ``poses`` (N, 3), ``cov`` (N, 6), dead reckoning ``odo_t``
        (K,), ``odo_poses`` (K, 3), update rows and snapshots (N = 1 or 0 and the rest
        empty when streamed).
    """
    if not isinstance(sink, MemorySink):  # streamed: only the last row is kept
        rows = [last] if last is not None else []
        return SlamResult(
            np.array([r[0] for r in rows]),
            np.array([r[1] for r in rows]).reshape(-1, 3),
            np.array([r[2] for r in rows]).reshape(-1, 6),
            np.zeros(0),
            np.zeros((0, 3)),
            lamps,
            [],
            counts,
            [],
            ekf,
        )
    u = np.asarray(sink.odo_u, dtype=float).reshape(-1, 2)
    odo = integrate(start_pose, u[:, 0], u[:, 1]) if sink.odo_t else np.zeros((0, 3))
    return SlamResult(
        np.asarray(sink.t),
        np.asarray(sink.x).reshape(-1, 3),
        np.asarray(sink.p).reshape(-1, 6),
        np.asarray(sink.odo_t),
        odo,
        lamps,
        sink.updates,
        counts,
        sink.snapshots,
        ekf,
    )
