"""metrics.json, typed: the dataclasses :func:`fuzzyslam.evaluation.core.evaluate`
fills (one per section), written by :func:`fuzzyslam.summary.as_json`.

A metric renamed or left out where it is computed is a ``TypeError`` there, not a key
missing from metrics.json (the experiment's table would then raise ``MissingMetric``).
Sections left :data:`~fuzzyslam.summary.OMIT` are absent from the file: a phase
without samples has only its span, runs and samples; ``lamps`` needs true and
estimated landmarks, ``lamps_by_run`` the map's history and a simulated world,
``odometry`` the run's dead reckoning, ``heading_fix`` heading_fixes.csv.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from fuzzyslam.evaluation.metrics import Consistency, Stats
from fuzzyslam.summary import OMIT, key


@dataclass(frozen=True, kw_only=True)
class ApeMetrics:
    """APE of positions (m): raw, after a rigid and after a similarity alignment."""

    raw: Stats
    aligned: Stats
    aligned_scale: Stats
    alignment: dict[str, float]


@dataclass(frozen=True, kw_only=True)
class RpeMetrics:
    """RPE per metre of travel over ``delta_m`` metres."""

    delta_m: float
    trans_m_per_m: Stats
    rot_deg_per_m: Stats


@dataclass(frozen=True, kw_only=True)
class UpdateCounts:
    """Measurement updates of the phase (updates.csv): attempted, accepted."""

    attempted: int
    accepted: int


@dataclass(frozen=True, kw_only=True)
class HeadingFixMetrics:
    """Heading fixes of the phase against the true heading (deg); ``reasons`` counts
    heading_fixes.csv's reasons."""

    attempted: int
    accepted: int
    error_deg: Stats
    error_all_deg: Stats
    reasons: dict[str, int] = OMIT


@dataclass(frozen=True, kw_only=True)
class PhaseMetrics:
    """Every metric over the samples of one phase (overall, A, after, run<r>)."""

    t0: float
    t1: float
    runs: list[int]
    samples: int
    x_m: Stats = OMIT
    y_m: Stats = OMIT
    heading_deg: Stats = OMIT
    position_m: Stats = OMIT
    ape_m: ApeMetrics = OMIT
    rpe: RpeMetrics = OMIT
    distance_m: float = OMIT
    nees: Consistency = OMIT
    nis: dict[str, Consistency] = OMIT
    updates: UpdateCounts = OMIT
    heading_fix: HeadingFixMetrics = OMIT


@dataclass(frozen=True, kw_only=True)
class LampSummary:
    """A one-to-one matching of estimated to true lamps (``LampMatch.summary()``)."""

    matched: int
    duplicates: int
    spurious: int
    missed: int
    max_dist_m: float
    error_m: dict[str, Any]
    per_lamp_error_m: list[float | None]
    duplicate_ids: list[int]
    missed_ids: list[int]


@dataclass(frozen=True, kw_only=True)
class LampMetrics(LampSummary):
    """The final map's lamps against the true ones."""

    estimated: int
    true: int
    left_over: int
    true_within_0_3_m: int = field(metadata=key("true_within_0.3_m"))
    true_within_0_5_m: int = field(metadata=key("true_within_0.5_m"))


@dataclass(frozen=True, kw_only=True)
class RunLampMetrics(LampSummary):
    """The map as it stood at the end of a run (its last snapshot, at ``t``)."""

    t: float
    estimated: int


@dataclass(frozen=True, kw_only=True)
class OdometryMetrics:
    """The run's dead reckoning against the truth."""

    position_m: Stats
    heading_deg: Stats


@dataclass(frozen=True, kw_only=True)
class TruthCoverage:
    """How much of the estimate the truth covers (``core.truth_coverage``)."""

    fraction: float
    compared_samples: int
    estimate_samples: int
    estimate_span_s: list[float] | None
    truth_span_s: list[float]


@dataclass(frozen=True, kw_only=True)
class Headline:
    """The few numbers printed on stdout and shown first in the report."""

    position_mean_m: float
    heading_mean_deg: float
    ape_rmse_m: float
    ape_aligned_rmse_m: float
    rpe_m_per_m: float
    truth_coverage: float
    log_damage: dict[str, Any] | None
    warnings: list[str]
    phase_A_position_mean_m: float = OMIT
    after_position_mean_m: float = OMIT
    nees_mean: float = OMIT
    nees_in_band: bool = OMIT
    lamps_true_within_0_5_m: int = field(default=OMIT, metadata=key("lamps_true_within_0.5_m"))
    lamps_left_over: int = OMIT
    lamp_error_mean_m: float = OMIT
    lamps_duplicated: int = OMIT
    lamps_missed: int = OMIT
    lamps_spurious: int = OMIT
    lamps_estimated: int = OMIT
    heading_fix_error_mean_deg: float = OMIT
    heading_fix_error_std_deg: float = OMIT


@dataclass(frozen=True, kw_only=True)
class ComparisonPhase:
    """One phase of a compared estimate: position and heading errors, mean and max."""

    position_mean_m: float
    position_max_m: float
    heading_mean_deg: float
    heading_max_deg: float


@dataclass(frozen=True, kw_only=True)
class ComparisonRow:
    """One estimate of ``evaluate --compare`` (evaluation/evaluate.py ``comparison_row``)."""

    label: str
    estimate: str
    phases: dict[str, ComparisonPhase]
    lamps_duplicated: int | None


@dataclass(frozen=True, kw_only=True)
class Metrics:
    """metrics.json: every metric of one estimate against the truth."""

    label: str
    truth: str
    estimate: str
    samples: int
    estimate_samples: int
    span_s: list[float]
    params: dict[str, Any]
    freeze_run: int | None
    phases: dict[str, PhaseMetrics]
    aligned_to_truth: dict[str, float] = OMIT
    lamps: LampMetrics = OMIT
    lamps_by_run: dict[str, RunLampMetrics] = OMIT
    odometry: OdometryMetrics = OMIT
    truth_coverage: TruthCoverage
    log_damage: dict[str, Any] | None
    warnings: list[str]
    headline: Headline
    comparison: list[ComparisonRow] = OMIT  # evaluate --compare
    change_detection: dict[str, Any] = OMIT  # evaluation/changes.py (--fix pose, obstacles)
