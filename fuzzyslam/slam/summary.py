"""The ``run`` stage's summary, typed (summary.json and stdout): :class:`RunSummary`,
filled by :func:`fuzzyslam.slam.stage.make_summary` and written by
:func:`fuzzyslam.summary.as_json`."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from fuzzyslam.slam.calibration import CalibrationEntry
from fuzzyslam.slam.run_results import FilterHealth, RunCounts
from fuzzyslam.summary import OMIT


@dataclass(frozen=True, kw_only=True)
class RunSummary:
    """The ``run`` stage's JSON summary (stdout and summary.json, docs/contracts.md
    sec. 2). Fields left :data:`~fuzzyslam.summary.OMIT` are absent from the JSON:
    ``first_warning`` (no input problem), ``noise_estimate`` and
    ``odometry_delay_estimate`` (lamps from frames), ``calibration`` (off), ``aids``,
    ``rings``, ``range_sensor`` (no fixes), ``invalid_ranges`` (no fixes, or at most a
    third of the range readings invalid: :func:`fuzzyslam.streams.ranges.invalid_ranges`),
    ``noise_adapted`` (without ``--adapt-noise``). ``odometry_turn_check`` and
    ``odometry_distance_check`` are always there, null for a log too short or turning
    (moving) too little (slam/turn_check.py)."""

    command: str = "run"
    log: str
    config: dict[str, str] = OMIT  # name, source, chosen_by (fuzzyslam/presets.py)
    odometry_source: str
    lamp_source: str
    start_pose: list[float]
    log_duration_s: float
    counts: RunCounts
    filter_health: FilterHealth
    lamps: int
    duplicates_guarded: int
    mean_nis_lamp: float | None
    mean_nis_lamp_dof: int = 2
    final_pose: list[float] | None
    final_pose_sigma: list[float] | None
    trajectory_rows: int
    warnings: dict[str, int]
    truncated_log: bool
    log_damage: dict[str, Any]
    wall_time_s: float
    real_time_factor: float | None
    first_warning: str = OMIT
    noise_estimate: dict[str, Any] | None = OMIT
    odometry_delay_estimate: dict[str, Any] | None = OMIT
    odometry_turn_check: dict[str, Any] | None = None
    odometry_distance_check: dict[str, Any] | None = None
    calibration: CalibrationEntry = OMIT
    aids: dict[str, Any] = OMIT  # class name -> summary() (a fixes/summaries.py dataclass)
    rings: dict[str, Any] = OMIT
    range_sensor: dict[str, Any] = OMIT
    invalid_ranges: dict[str, Any] = OMIT
    noise_adapted: dict[str, Any] | None = OMIT
