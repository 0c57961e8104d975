"""The fix plug-ins' entries in the run summary (``aids``, one per aid by class name),
typed: each aid's ``summary()`` returns one of these dataclasses, written by
:func:`fuzzyslam.summary.as_json`, so that a figure left out is a ``TypeError`` where
the aid makes it. ``reasons`` maps each decision reason to its count (keys sorted)."""

from __future__ import annotations

from dataclasses import dataclass

from fuzzyslam.summary import OMIT


@dataclass(frozen=True, kw_only=True)
class HeadingSummary:
    """:class:`~fuzzyslam.fixes.heading.HeadingFixAid` (and the scan-line aid)."""

    rings: int  # rings decided (from the aid's start time)
    before_start: int  # rings before it
    accepted: int  # fixes the filter accepted
    recoveries: int  # bump recoveries
    flm_rings: int  # rings per FLM (1: the paper's single-ring fixes)
    multi_ring_fixes_formed: int
    reasons: dict[str, int]
    mean_nis: float | None  # of the accepted fixes (None: none)
    # the robot's largest position standard deviation at a ring (m), and the first ring at
    # which the 99 % position ellipse outgrew fixes.junction_margin (None: never), from
    # when the corridor a fix is taken from is a guess (HeadingFixAid.trouble)
    position_sigma_max_m: float = OMIT
    position_unresolved_at: float | None = OMIT
    # a live-map run's right-angle heading fixes (fixes.live_map.LiveRightAngleHeading):
    # the building's wall direction mod 90 deg learnt (None: not yet) and when
    reference_angle_deg: float | None = OMIT
    reference_learnt_at: float | None = OMIT
    # ... its scans seeing walls along and across that direction, those whose two
    # families meet more than 3 deg off a right angle, and when they were first too many
    # (None: never; a note on stderr then says so)
    right_angle_scans: int = OMIT
    off_right_angle_scans: int = OMIT
    off_right_angles_at: float | None = OMIT


@dataclass(frozen=True, kw_only=True)
class PoseSummary:
    """:class:`~fuzzyslam.fixes.pose_aid.PoseFixAid`."""

    rings: int
    before_start: int
    accepted: int
    reasons: dict[str, int]
    degenerate: int  # accepted matches with a degenerate direction (a corridor)
    mean_nis: float | None
    recoveries: int
    wide_searches: int
    near_last_match: int
    recentred_searches: int
    # a live-map run's map (fixes.live_map.LiveMapPoseAid): rings fused (keyframes), the
    # grid's shape (rows, columns) and cell size (m), times it was grown
    keyframes: int = OMIT
    map_shape: list[int] = OMIT
    map_resolution_m: float = OMIT
    map_grown: int = OMIT
    # its loop closure (fixes.live_map.KeyframeGraph; None: off): loop and sequential edges
    # matched, loop candidates tried, edges the robust weights turned down, solver
    # iterations, how far the keyframes moved (mean, max, m)
    loop_closure: dict | None = OMIT


@dataclass(frozen=True, kw_only=True)
class ChangeSummary:
    """:class:`~fuzzyslam.fixes.changes.ChangeDetector`."""

    rings: int
    skipped_uncertain: int  # rings skipped: the pose too uncertain
    detections: int
    rings_with_detections: int
