"""The evaluation as one pure computation: truth + estimate in, every metric out (no I/O)."""

from __future__ import annotations

from dataclasses import asdict, dataclass, field, replace
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from fuzzyslam.evaluation import metrics as M
from fuzzyslam.evaluation import results as R
from fuzzyslam.evaluation.align import Similarity, anchor, umeyama
from fuzzyslam.evaluation.consistency import consistency, nees
from fuzzyslam.evaluation.lamps import LampMatch, found_within, match_lamps
from fuzzyslam.evaluation.params import EvalParams
from fuzzyslam.se2 import wrap_angle
from fuzzyslam.slam.odom_gate import gate_steps
from fuzzyslam.streams.logmeta import Scenario, World
from fuzzyslam.summary import OMIT, as_json

Array = NDArray[np.float64]


@dataclass
class Truth:
    """Ground truth: poses (N, 3) at times t (N,), and, from a simulated log, world + scenario."""

    t: Array
    poses: Array
    world: World | None = None
    scenario: Scenario | None = None
    freeze_run: int | None = None
    source: str = ""
    log_damage: dict[str, Any] | None = None  # of the log the truth was read from
    # true landmark positions (K, 2) when not in a world (e.g. --landmarks-truth)
    landmarks: Array | None = None
    # stray lines dropped when read (drop_stray_truth); None: not checked (simulated log)
    lines_dropped: int | None = None
    # lines the stray-line test refused (> lines_dropped: too many to be stray, all kept)
    lines_refused: int = 0

    @property
    def landmark_array(self) -> Array | None:
        """The true landmarks: the simulated world's lamps, else ``landmarks``."""
        if self.world is not None:
            return self.world.lamp_array
        return self.landmarks


@dataclass
class Updates:
    """Rows of updates.csv: one per measurement update attempt."""

    t: Array
    kind: NDArray[np.str_]
    id: NDArray[np.int64]
    dof: NDArray[np.int64]
    nis: Array
    accepted: NDArray[np.bool_]


@dataclass
class HeadingFixes:
    """Rows of heading_fixes.csv: measured robot heading (rad) at t, accepted, reason."""

    t: Array
    measured: Array
    accepted: NDArray[np.bool_]
    reason: NDArray[np.str_]


@dataclass
class Estimate:
    """What a run produced (only t and poses are required; a TUM file gives only those)."""

    t: Array
    poses: Array
    cov: Array | None = None  # (N, 3, 3), aligned with t
    odometry: tuple[Array, Array] | None = None  # (t, poses)
    landmarks: Array | None = None  # (M, 2)
    landmark_ids: list[int] = field(default_factory=list)
    updates: Updates | None = None
    heading_fixes: HeadingFixes | None = None
    # snapshots (t, lamps (M, 2)) of the map during the run, e.g. from estimates.mcap
    landmark_history: list[tuple[float, Array]] = field(default_factory=list)
    label: str = "estimate"
    source: str = ""


@dataclass
class Evaluation:
    """Every metric (``typed``; ``metrics``: as metrics.json has it) and the series the
    figures draw."""

    typed: R.Metrics
    assoc: M.Associated
    errors: Array  # (N, 3) x, y, heading errors at assoc.t
    sigma: Array | None  # (N, 3) 1-sigma of x, y, heading from the covariance, or None
    nees: Array | None  # (N,)
    phases: list[M.Phase]
    lamp_match: LampMatch | None
    # lamp matches of the map as it stood at the end of each run (from landmark_history)
    lamp_match_by_run: dict[int, LampMatch] = field(default_factory=dict)
    fix_t: Array | None = None
    fix_err: Array | None = None
    # the rigid motion that moved the estimate onto the truth (align), None without one
    to_truth: Similarity | None = None

    @property
    def truth_in_estimate_frame(self) -> Array:
        """The compared truth (``assoc.truth``, at the estimate's stamps) in the frame of
        the estimate as the run wrote it: moved by the inverse of :attr:`to_truth`, so that
        ``||estimate - this||`` is the error every metric is taken from (the APE ``raw``
        with ``evo_ape tum truth.tum trajectory.tum``, no alignment).

        Returns
        -------
        ndarray, shape (n, 3)
            Poses (x, y, theta).
        """
        if self.to_truth is None:
            return self.assoc.truth
        return self.to_truth.inverse().apply_poses(self.assoc.truth)

    @property
    def metrics(self) -> dict[str, Any]:
        """The metrics as metrics.json holds them (:func:`fuzzyslam.summary.as_json`)."""
        return as_json(self.typed)


MAX_STRAY_SHARE = 0.01  # a truth whose refused lines are more than this share: none dropped


def drop_stray_truth(t: ArrayLike, poses: ArrayLike) -> tuple[Array, Array, int, int]:
    """A recorded truth without its stray lines: the one rule, used by ``evaluate`` and
    ``benchmarks/bench_buildings.py``.

    A truth converted from another format may hold lines a robot cannot have been at: the
    CARMEN conversions repeat the first pose now and then, a jump of metres away and back.
    Such lines are the stray poses of an odometry stream, and the same test finds them:
    the odometry glitch gate (:func:`fuzzyslam.slam.odom_gate.plausible_mask`, default
    limits: a pose the robot cannot reach from the last kept one at 2 m/s and 2 pi rad/s
    along an arc is dropped; after 10 refusals in a row the stream has really moved and
    its pose is kept). Stray lines are glitches that come back: when the gate refuses more
    than ``MAX_STRAY_SHARE`` of the lines and some of its refusals end with the stream
    taken where it went (a ``reset``: it did not come back), or run to the last line, the
    truth is of something
    faster than those limits (or an idealised path) and every line is kept. A short
    excerpt whose few strays are a larger share of its lines keeps them dropped (the first
    90 s of Freiburg 079: 13 of 428 lines, every one come back). A simulated log's truth
    is exact and is not passed through this.

    Parameters
    ----------
    t : array_like, shape (N,)
        Increasing times (s).
    poses : array_like, shape (N, 3)
        The truth's poses.

    Returns
    -------
    t : ndarray, shape (M,)
        The kept times.
    poses : ndarray, shape (M, 3)
        The kept poses.
    dropped : int
        N - M.
    refused : int
        The lines the gate refused (``dropped``, or more when none were dropped).
    """
    t = np.asarray(t, dtype=float).reshape(-1)
    p = np.asarray(poses, dtype=float).reshape(-1, 3)
    steps = gate_steps(t, p)
    keep = steps != "jump"
    refused = int((~keep).sum())
    # refusals still running at the last line never came back: the truth moved there
    moved = np.any(steps == "reset") or (t.size > 0 and not keep[-1])
    if refused > MAX_STRAY_SHARE * t.size and moved:
        return t, p, 0, refused
    return t[keep], p[keep], refused, refused


class SpanError(ValueError):
    """The estimate and the truth share no time (or too few samples to compare)."""


def _phase_block(
    ph: M.Phase,
    assoc: M.Associated,
    err: Array,
    nees_v: Array | None,
    est: Estimate,
    fix_t: Array | None,
    fix_err: Array | None,
    fix_ok: NDArray[np.bool_] | None,
    params: EvalParams,
) -> R.PhaseMetrics:
    """Every metric over the samples of one phase (see :func:`evaluate`)."""
    m = ph.mask(assoc.t)
    span = {"t0": ph.t0, "t1": ph.t1, "runs": list(ph.runs), "samples": int(m.sum())}
    if m.sum() == 0:
        return R.PhaseMetrics(**span)
    e = err[m]
    a = M.ape(assoc.est[m, :2], assoc.truth[m, :2])
    r = M.rpe_per_metre(assoc.est[m], assoc.truth[m], params.rpe_delta_m)
    nis = updates = heading_fix = OMIT
    if est.updates is not None:
        u = est.updates
        um = ph.mask(u.t) & u.accepted
        nis = {
            f"{k}_dof{d}": consistency(u.nis[um & (u.kind == k) & (u.dof == d)], int(d))
            for k, d in sorted(
                {(str(k), int(d)) for k, d in zip(u.kind[um], u.dof[um], strict=True)}
            )
        }
        att = ph.mask(u.t)
        updates = R.UpdateCounts(attempted=int(att.sum()), accepted=int((att & u.accepted).sum()))
    if fix_t is not None and fix_err is not None and fix_ok is not None:
        fm = ph.mask(fix_t)
        ok = fm & fix_ok & np.isfinite(fix_err)
        reasons = OMIT
        if est.heading_fixes is not None:
            names, counts = np.unique(est.heading_fixes.reason[fm], return_counts=True)
            reasons = {str(k): int(n) for k, n in zip(names, counts, strict=True)}
        heading_fix = R.HeadingFixMetrics(
            attempted=int(fm.sum()),
            accepted=int((fm & fix_ok).sum()),
            error_deg=M.stats(np.degrees(fix_err[ok])),
            error_all_deg=M.stats(np.degrees(fix_err[fm & np.isfinite(fix_err)])),
            reasons=reasons,
        )
    return R.PhaseMetrics(
        **span,
        x_m=M.stats(e[:, 0]),
        y_m=M.stats(e[:, 1]),
        heading_deg=M.stats(e[:, 2]).scaled(180.0 / np.pi),
        position_m=M.stats(np.hypot(e[:, 0], e[:, 1])),
        ape_m=R.ApeMetrics(
            raw=a.raw, aligned=a.aligned, aligned_scale=a.aligned_scale, alignment=a.alignment
        ),
        rpe=R.RpeMetrics(
            delta_m=r.delta_m, trans_m_per_m=r.trans_per_m, rot_deg_per_m=r.rot_deg_per_m
        ),
        distance_m=float(M.path_length(assoc.truth[m, :2])[-1]),
        nees=consistency(nees_v[m], 3) if nees_v is not None else OMIT,
        nis=nis,
        updates=updates,
        heading_fix=heading_fix,
    )


def pair(t: Array, poses: Array, truth: Truth, params: EvalParams) -> M.Associated:
    """Poses paired with the truth interpolated at their times (:func:`metrics.associate`
    with the ``max_dt_s`` and ``max_gap_s`` of ``params``).

    Parameters
    ----------
    t : ndarray, shape (N,)
        The poses' times.
    poses : ndarray, shape (N, 3)
        The poses.
    truth : Truth
        The truth.
    params : EvalParams
        ``max_dt_s`` and ``max_gap_s``.

    Returns
    -------
    Associated
        The kept samples.
    """
    return M.associate(t, poses, truth.t, truth.poses, params.max_dt_s, params.max_gap_s)


def truth_alignment(est: Estimate, truth: Truth, params: EvalParams) -> Similarity | None:
    """The rigid 2-D motion (Umeyama, no scale) that best maps the estimate's positions
    onto the truth's, paired in time (:func:`metrics.associate`).

    Parameters
    ----------
    est : Estimate
        The estimate.
    truth : Truth
        The truth.
    params : EvalParams
        ``max_dt_s`` and ``max_gap_s`` for pairing.

    Returns
    -------
    Similarity or None
        The motion; None with fewer than two pairs.
    """
    assoc = pair(est.t, est.poses, truth, params)
    if len(assoc) < 2:
        return None
    return umeyama(assoc.est[:, :2], assoc.truth[:, :2])


def align_estimate(
    est: Estimate, truth: Truth, params: EvalParams, motion: Similarity | None = None
) -> tuple[Estimate, dict]:
    """The estimate moved onto the truth by one rigid 2-D motion (Umeyama, as evo's
    ``--align``), found from the positions paired in time: poses, dead reckoning and
    landmarks are mapped by it, covariances rotated (C' = A C A^T, A = diag(R, 1)).
    For real logs, whose map frame is the robot's start and not the truth's frame.

    Parameters
    ----------
    est : Estimate
        The estimate.
    truth : Truth
        The truth.
    params : EvalParams
        ``max_dt_s`` and ``max_gap_s`` for pairing.
    motion : Similarity, optional
        The motion, when already found (:func:`truth_alignment`).

    Returns
    -------
    Estimate, dict
        The moved estimate (``est`` itself with fewer than two pairs), and the motion
        (tx_m, ty_m, theta_deg; empty without one).
    """
    s = motion if motion is not None else truth_alignment(est, truth, params)
    if s is None:
        return est, {}
    a = np.eye(3)
    a[:2, :2] = s.rotation
    out = replace(
        est,
        poses=s.apply_poses(est.poses),
        cov=a @ est.cov @ a.T if est.cov is not None else None,
        landmarks=s.apply(est.landmarks) if est.landmarks is not None else None,
        odometry=(est.odometry[0], s.apply_poses(est.odometry[1]))
        if est.odometry is not None
        else None,
        landmark_history=[(t, s.apply(lm)) for t, lm in est.landmark_history],
    )
    info = {
        "tx_m": float(s.translation[0]),
        "ty_m": float(s.translation[1]),
        "theta_deg": float(np.degrees(s.angle)),
        "nees_frame": "first pose",  # see anchored_nees
        # what the motion moved: every error but the NEES is taken after it
        "applied_to": "poses, landmarks, dead reckoning (every metric, ape_m.raw included, "
        "but the NEES)",
    }
    return out, info


def anchored_nees(
    est: Estimate, truth: Truth, params: EvalParams, assoc: M.Associated | None = None
) -> Array:
    """NEES of an unaligned estimate in its own map frame, the frame of the first pose.

    The truth is moved into the estimate's frame by the rigid motion that makes the first
    paired poses coincide (:func:`fuzzyslam.evaluation.align.anchor`); the covariances are
    the filter's own. Used for real logs, whose map frame is the robot's start.

    Parameters
    ----------
    est : Estimate
        The estimate as the run wrote it (not aligned), with covariances.
    truth : Truth
        The truth.
    params : EvalParams
        ``max_dt_s`` and ``max_gap_s`` for pairing.
    assoc : Associated, optional
        The pairing in time already made (of this estimate or of a moved copy: it depends
        on the times only).

    Returns
    -------
    ndarray, shape (n,)
        NEES per paired sample (the samples of :func:`metrics.associate`).
    """
    if assoc is None:
        assoc = pair(est.t, est.poses, truth, params)
    poses = est.poses[assoc.index]
    s = anchor(poses[0], assoc.truth[0])
    rot = np.eye(3)
    rot[:2, :2] = s.rotation
    err = M.pose_errors(s.apply_poses(poses), assoc.truth)
    return nees(err, rot @ est.cov[assoc.index] @ rot.T)


def evaluate(truth: Truth, est: Estimate, params: EvalParams, align: bool = False) -> Evaluation:
    """Compute every metric of ``est`` against ``truth``, overall, per run and per phase.

    ``align``: first move the estimate onto the truth with one rigid 2-D motion
    (:func:`align_estimate`), so that errors and landmarks are taken in the truth's
    frame up to that motion; the NEES is then taken in the estimate's own frame, anchored
    at the first pose (:func:`anchored_nees`), the frame its covariances refer to. Raises
    SpanError when fewer than two estimate samples overlap the truth in time.

    Parameters
    ----------
    truth : Truth
        Ground truth: times (N,), poses (N, 3), world and scenario when simulated.
    est : Estimate
        The run's estimate: times (M,), poses (M, 3), covariances (M, 3, 3), ...
    params : EvalParams
        The ``eval:`` section.
    align : bool
        First move the estimate onto the truth.

    Returns
    -------
    Evaluation
        The typed metrics (``typed``; ``metrics``: metrics.json) and the figures' series.
    """
    alignment = None
    to_truth = None
    raw = est
    if align:
        to_truth = truth_alignment(est, truth, params)
        est, alignment = align_estimate(est, truth, params, to_truth)
    assoc = pair(est.t, est.poses, truth, params)
    if len(assoc) < 2:
        raise SpanError(
            f"estimate time span [{est.t[0]:.3f}, {est.t[-1]:.3f}] s does not overlap the "
            f"truth's [{truth.t[0]:.3f}, {truth.t[-1]:.3f}] s (fewer than two estimate "
            f"stamps within {params.max_dt_s} s of a truth sample or between two at most "
            f"{params.max_gap_s} s apart)"
        )
    err = M.pose_errors(assoc.est, assoc.truth)
    sigma = nees_v = None
    if est.cov is not None:
        c = est.cov[assoc.index]
        sigma = np.sqrt(np.clip(np.diagonal(c, axis1=1, axis2=2), 0.0, None))
        nees_v = nees(err, c) if not alignment else anchored_nees(raw, truth, params, assoc)
    fix_t = fix_err = fix_ok = None
    if est.heading_fixes is not None and est.heading_fixes.t.size:
        hf = est.heading_fixes
        th = M.interpolate_poses(truth.t, truth.poses, hf.t)[:, 2]
        fix_t = hf.t
        fix_err = np.asarray(wrap_angle(hf.measured - th), dtype=float).reshape(-1)
        # judged where the truth may be interpolated (metrics.covered), as the poses are
        fix_err[~M.covered(truth.t, hf.t, params.max_dt_s, params.max_gap_s)] = np.nan
        fix_ok = hf.accepted
    intervals = truth.scenario.run_intervals() if truth.scenario is not None else []
    phases = M.phases_from_runs(
        intervals, truth.freeze_run, (float(assoc.t[0]), float(assoc.t[-1]))
    )
    blocks = {
        ph.name: _phase_block(ph, assoc, err, nees_v, est, fix_t, fix_err, fix_ok, params)
        for ph in phases
    }
    lamp_match = None
    lamps = OMIT
    true_lm = truth.landmark_array
    if est.landmarks is not None and true_lm is not None:
        lamp_match = match_lamps(est.landmarks, true_lm, params.lamp_max_dist_m)
        lamps = R.LampMetrics(
            **lamp_match.summary(),
            estimated=int(est.landmarks.shape[0]),
            true=int(true_lm.shape[0]),
            left_over=len(lamp_match.duplicates) + len(lamp_match.spurious),
            # true landmarks with an estimate this near (not one to one)
            true_within_0_3_m=found_within(est.landmarks, true_lm, 0.3),
            true_within_0_5_m=found_within(est.landmarks, true_lm, 0.5),
        )
    by_run: dict[int, LampMatch] = {}
    lamps_by_run = OMIT
    if est.landmark_history and truth.world is not None:
        snap_t = np.array([t for t, _ in est.landmark_history])
        lamps_by_run = {}
        for r, _t0, t1 in intervals:
            k = int(np.searchsorted(snap_t, t1, side="right")) - 1  # last snapshot by run end
            if k < 0:
                continue
            snap = est.landmark_history[k][1]
            by_run[r] = match_lamps(snap, truth.world.lamp_array, params.lamp_max_dist_m)
            lamps_by_run[f"run{r}"] = R.RunLampMetrics(
                t=float(snap_t[k]), estimated=int(snap.shape[0]), **by_run[r].summary()
            )
    odometry = OMIT
    if est.odometry is not None:
        ot, op = est.odometry
        oa = pair(ot, op, truth, params)
        if len(oa) >= 2:
            oe = M.pose_errors(oa.est, oa.truth)
            odometry = R.OdometryMetrics(
                position_m=M.stats(np.hypot(oe[:, 0], oe[:, 1])),
                heading_deg=M.stats(oe[:, 2]).scaled(180.0 / np.pi),
            )
    coverage = truth_coverage(truth, est, len(assoc))
    warnings = R.evaluation_warnings(
        coverage,
        truth.log_damage,
        blocks["overall"].nees,
        truth.lines_dropped,
        truth.lines_refused,
        truth.t.size,
        blocks["overall"].ape_m if alignment is None else None,
    )
    typed = R.Metrics(
        label=est.label,
        truth=truth.source,
        estimate=est.source,
        samples=len(assoc),
        estimate_samples=int(est.t.size),
        span_s=[float(assoc.t[0]), float(assoc.t[-1])],
        params=asdict(params),
        freeze_run=truth.freeze_run,
        phases=blocks,
        aligned_to_truth=alignment if alignment is not None else OMIT,
        lamps=lamps,
        lamps_by_run=lamps_by_run,
        odometry=odometry,
        truth_coverage=coverage,
        truth_lines_dropped=OMIT if truth.lines_dropped is None else truth.lines_dropped,
        log_damage=truth.log_damage,
        warnings=warnings,
        headline=R.headline(
            blocks, coverage, truth.log_damage, warnings, lamps, truth.lines_dropped
        ),
    )
    return Evaluation(
        typed, assoc, err, sigma, nees_v, phases, lamp_match, by_run, fix_t, fix_err, to_truth
    )


def truth_coverage(truth: Truth, est: Estimate, compared: int) -> R.TruthCoverage:
    """How much of the estimate the truth covers: the estimate's samples compared (those
    inside the truth's span with truth samples around them at most max_gap_s apart, or one
    within max_dt_s: :func:`metrics.associate`) over all of them, and both time spans.

    Parameters
    ----------
    truth : Truth
        The ground truth (its times t (N,)).
    est : Estimate
        The estimate (its times t (M,)).
    compared : int
        How many of the estimate's samples were paired with the truth.

    Returns
    -------
    TruthCoverage
    """
    n = int(est.t.size)
    return R.TruthCoverage(
        fraction=round(compared / n, 6) if n else 0.0,
        compared_samples=int(compared),
        estimate_samples=n,
        estimate_span_s=[float(est.t[0]), float(est.t[-1])] if n else None,
        truth_span_s=[float(truth.t[0]), float(truth.t[-1])],
    )
