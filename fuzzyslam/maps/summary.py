"""The ``map`` stage's summary, typed (summary.json and stdout): :class:`MapSummary`
and its sections, filled by :func:`fuzzyslam.maps.build.build_map` and written by
:func:`fuzzyslam.summary.as_json`."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from fuzzyslam.summary import OMIT


@dataclass(frozen=True, kw_only=True)
class ReferenceEntry:
    """A corridor reference in the map summary (the map stage's ``Reference``)."""

    id: int
    name: str
    angle_deg: float
    strength: float
    ambiguous: bool


@dataclass(frozen=True, kw_only=True)
class ReferenceTruth:
    """A reference against the nearest true corridor axis (simulated logs)."""

    id: int
    true_corridor: str
    true_axis_deg: float
    error_deg: float


@dataclass(frozen=True, kw_only=True)
class WallQuality:
    """The frozen map's walls against the true walls (maps/quality.py)."""

    precision: float
    recall: float
    map_cells: int
    true_cells: int


@dataclass(frozen=True, kw_only=True)
class MapSummary:
    """The ``map`` stage's JSON summary (stdout and summary.json, docs/contracts.md
    sec. 3); ``calibration`` is absent (:data:`~fuzzyslam.summary.OMIT`) when the
    trajectory's run had no odometry calibration; ``invalid_ranges`` unless more than a
    third of the range readings were invalid
    (:func:`fuzzyslam.streams.ranges.invalid_ranges`)."""

    log: str
    config: dict[str, str] = OMIT  # name, source, chosen_by (fuzzyslam/presets.py)
    trajectory: str
    output: str
    log_id: str
    cells: int
    shape: list[int]
    origin: list[float]
    resolution: float
    rings_used: int
    readings_used: int
    readings_skipped: int
    rings_skipped: int
    sonar_stats: dict[str, Any]
    range_sensor: dict[str, Any]
    invalid_ranges: dict[str, Any] = OMIT
    trajectory_repeats_dropped: int
    cell_updates: int
    cells_touched: int
    freeze_time: float
    freeze_rule: str
    references: list[ReferenceEntry]
    reference_truth: list[ReferenceTruth]
    wall_quality: WallQuality | None
    build_seconds: float
    log_damage: dict[str, Any]
    calibration: dict[str, Any] = OMIT
    wall_seconds: float = OMIT
