"""metrics.json, typed: the dataclasses :func:`fuzzyslam.evaluation.core.evaluate`
fills (one per section), written by :func:`fuzzyslam.summary.as_json`; the warnings and
the headline drawn from them.

A metric renamed or left out where it is computed is a ``TypeError`` there, not a key
missing from metrics.json (the experiment's table would then raise ``MissingMetric``).
Sections left :data:`~fuzzyslam.summary.OMIT` are absent from the file: a phase
without samples has only its span, runs and samples; ``lamps`` needs true and
estimated landmarks, ``lamps_by_run`` the map's history and a simulated world,
``odometry`` the run's dead reckoning, ``heading_fix`` heading_fixes.csv,
``aligned_to_truth`` an alignment (``--align``, ``--landmarks-truth``),
``truth_lines_dropped`` a truth that is not a simulated log's (``core.drop_stray_truth``).

Every error is taken in the truth's frame: the estimate as the run wrote it, or, with
``aligned_to_truth``, after that one rigid motion (fitted on the whole log). ``raw`` in
``ape_m`` means no alignment of its own on top of that; ``aligned`` and
``aligned_scale`` are refitted within each phase.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from fuzzyslam.evaluation.consistency import Consistency, overconfident, overconfident_threshold
from fuzzyslam.evaluation.metrics import Stats
from fuzzyslam.streams.reader import lost_something
from fuzzyslam.summary import OMIT, key


@dataclass(frozen=True, kw_only=True)
class ApeMetrics:
    """APE of positions (m) in the truth's frame: ``raw`` with no fit of its own (the
    estimate as written, or after ``aligned_to_truth`` when the whole log was aligned:
    ``evo_ape tum truth.tum trajectory.tum`` on evaluate's files), ``aligned`` after a
    rigid and ``aligned_scale`` after a similarity Umeyama fit within the phase
    (``alignment``: that rigid fit and the similarity's scale)."""

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
    """The few numbers printed on stdout and shown first in the report. ``ape_rmse_m``:
    the overall APE with no fit of its own (after ``aligned_to_truth`` when there is
    one: what evo gives on truth.tum and trajectory.tum without ``-a``);
    ``ape_aligned_rmse_m``: after a rigid fit (evo's ``-a``)."""

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
    truth_lines_dropped: int = OMIT


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
    # stray lines dropped from the truth (core.drop_stray_truth); absent for a simulated log
    truth_lines_dropped: int = OMIT
    log_damage: dict[str, Any] | None
    warnings: list[str]
    headline: Headline
    comparison: list[ComparisonRow] = OMIT  # evaluate --compare
    change_detection: dict[str, Any] = OMIT  # evaluation/changes.py (--fix pose, obstacles)


COVERAGE_WARN = 0.99  # below this fraction of the estimate compared, the summary says so
# an unaligned estimate whose position RMSE a rigid motion cuts by this factor, and by
# more than FRAMES_DIFFER_M, is in another frame than the truth (a real log's run maps in
# its start pose's frame): its raw errors and NEES measure that motion, not the filter
FRAMES_DIFFER_RATIO = 3.0
FRAMES_DIFFER_M = 0.5


def evaluation_warnings(
    cov: TruthCoverage,
    dmg: dict[str, Any] | None,
    nees: Consistency = OMIT,
    truth_lines_dropped: int | None = None,
    truth_lines_refused: int = 0,
    truth_lines: int = 0,
    unaligned_ape: ApeMetrics | None = None,
) -> list[str]:
    """What the numbers do not cover, or say loudly, in words: a truth covering only part
    of the estimate, a damaged truth log, truth lines dropped as stray, an estimate in
    another frame than the truth (``FRAMES_DIFFER_*``), an estimate grossly overconfident
    against the truth (:func:`consistency.overconfident`; said too when the frames differ:
    a start heading off by 15 deg is both).

    Parameters
    ----------
    cov : TruthCoverage
        The truth's coverage of the estimate (:func:`truth_coverage`).
    dmg : dict or None
        The truth log's damage report (``LogReader.damage()``).
    nees : Consistency or OMIT
        The overall NEES test (OMIT: no covariances).
    truth_lines_dropped : int or None
        Stray truth lines dropped (``core.drop_stray_truth``; None: not checked).
    truth_lines_refused : int
        Truth lines the stray-line test refused (more than dropped: too many, all kept).
    truth_lines : int
        The truth's lines.
    unaligned_ape : ApeMetrics or None
        The overall APE of an estimate evaluated without ``--align`` (None: aligned).

    Returns
    -------
    list of str
        One sentence per problem.
    """
    out = []
    if cov.fraction < COVERAGE_WARN:
        t0, t1 = cov.truth_span_s
        out.append(
            f"the truth covers only {100 * cov.fraction:.1f} % of the estimate's samples "
            f"({t0:.1f}-{t1:.1f} s); the rest, outside that span or in gaps of the truth "
            "longer than evaluation.max_gap_s, is not evaluated"
        )
    if lost_something(dmg):
        out.append(
            f"the truth log is damaged ({dmg.get('lost_bytes', 0)} bytes lost); ground truth "
            "is missing where it was"
        )
    if truth_lines_dropped is not None and truth_lines_refused > truth_lines_dropped:
        out.append(
            f"the odometry glitch gate refuses {truth_lines_refused} of {truth_lines} truth "
            "lines, too many to be stray: the truth moves faster than a wheeled robot's "
            "limits (2 m/s, 2 pi rad/s) or is idealised; every line kept"
        )
    if truth_lines_dropped:
        out.append(
            f"{truth_lines_dropped} stray truth line(s) dropped: poses the robot cannot "
            "have reached from the lines around them (the odometry glitch gate)"
        )
    frames_differ = (
        unaligned_ape is not None
        and unaligned_ape is not OMIT
        and unaligned_ape.raw.rmse > FRAMES_DIFFER_RATIO * unaligned_ape.aligned.rmse
        and unaligned_ape.raw.rmse - unaligned_ape.aligned.rmse > FRAMES_DIFFER_M
    )
    if frames_differ:
        out.append(
            f"the estimate looks to be in another frame than the truth: position RMSE "
            f"{unaligned_ape.raw.rmse:.3g} m as written, {unaligned_ape.aligned.rmse:.3g} m "
            "after one rigid motion (a real log's run maps in its start pose's frame); "
            "pass --align to score it in the truth's frame (the raw errors and NEES here "
            "measure that motion as well as the filter's)"
        )
    if nees is not OMIT and overconfident(nees):
        out.append(
            f"the filter is overconfident: NEES mean {nees.mean:.3g} ({nees.dof} expected, "
            f"{overconfident_threshold(nees.dof):.1f} the limit), above 100 for "
            f"{100 * nees.frac_above_100:.0f} % of the compared samples"
        )
    return out


def headline(
    phases: dict[str, PhaseMetrics],
    coverage: TruthCoverage,
    log_damage: dict[str, Any] | None,
    warnings: list[str],
    lamps: LampMetrics,
    truth_lines_dropped: int | None = None,
) -> Headline:
    """The few numbers printed on stdout and shown first in the report.

    Parameters
    ----------
    phases : dict of str to PhaseMetrics
        The phases' metrics (``overall`` always; ``A`` and ``after`` when present).
    coverage : TruthCoverage
        The truth's coverage of the estimate.
    log_damage : dict or None
        The truth log's damage report.
    warnings : list of str
        :func:`evaluation_warnings`.
    lamps : LampMetrics or OMIT
        The final map's lamps against the truth (OMIT: no landmarks to compare).
    truth_lines_dropped : int or None
        Stray truth lines dropped (None: not checked, a simulated log).

    Returns
    -------
    Headline
    """
    ov = phases["overall"]

    def position(name: str) -> float:
        ph = phases.get(name)
        return ph.position_m.mean if ph is not None and ph.position_m is not OMIT else OMIT

    has_lamps = lamps is not OMIT
    has_nees = ov.nees is not OMIT
    fix = ov.heading_fix.error_deg if ov.heading_fix is not OMIT else None
    return Headline(
        position_mean_m=ov.position_m.mean,
        heading_mean_deg=ov.heading_deg.mean,
        ape_rmse_m=ov.ape_m.raw.rmse,
        ape_aligned_rmse_m=ov.ape_m.aligned.rmse,
        rpe_m_per_m=ov.rpe.trans_m_per_m.mean,
        truth_coverage=coverage.fraction,
        log_damage=log_damage,
        warnings=warnings,
        phase_A_position_mean_m=position("A"),
        after_position_mean_m=position("after"),
        nees_mean=ov.nees.mean if has_nees else OMIT,
        nees_in_band=ov.nees.in_band if has_nees else OMIT,
        lamps_true_within_0_5_m=lamps.true_within_0_5_m if has_lamps else OMIT,
        lamps_left_over=lamps.left_over if has_lamps else OMIT,
        lamp_error_mean_m=lamps.error_m["mean"] if has_lamps else OMIT,
        lamps_duplicated=lamps.duplicates if has_lamps else OMIT,
        lamps_missed=lamps.missed if has_lamps else OMIT,
        lamps_spurious=lamps.spurious if has_lamps else OMIT,
        lamps_estimated=lamps.estimated if has_lamps else OMIT,
        heading_fix_error_mean_deg=fix.mean if fix is not None else OMIT,
        heading_fix_error_std_deg=fix.std if fix is not None else OMIT,
        truth_lines_dropped=OMIT if truth_lines_dropped is None else truth_lines_dropped,
    )
