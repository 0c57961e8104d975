"""The evaluation as one pure computation: truth + estimate in, every metric out (no I/O)."""

from __future__ import annotations

from dataclasses import asdict, dataclass, field, replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from fuzzyslam.evaluation import metrics as M
from fuzzyslam.evaluation.align import umeyama
from fuzzyslam.evaluation.params import EvalParams
from fuzzyslam.se2 import wrap_angle
from fuzzyslam.streams.logmeta import Scenario, World

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
    # true landmark positions (K, 2) when not in a world (e.g. --landmarks-truth)
    landmarks: Array | None = None

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
    """Every metric (``metrics``, JSON-ready) and the series the figures draw."""

    metrics: dict[str, Any]
    assoc: M.Associated
    errors: Array  # (N, 3) x, y, heading errors at assoc.t
    sigma: Array | None  # (N, 3) 1-sigma of x, y, heading from the covariance, or None
    nees: Array | None  # (N,)
    phases: list[M.Phase]
    lamp_match: M.LampMatch | None
    # lamp matches of the map as it stood at the end of each run (from landmark_history)
    lamp_match_by_run: dict[int, M.LampMatch] = field(default_factory=dict)
    fix_t: Array | None = None
    fix_err: Array | None = None


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
) -> dict[str, Any]:
    """Every metric over the samples of one phase (see :func:`evaluate`)."""
    m = ph.mask(assoc.t)
    out: dict[str, Any] = {
        "t0": ph.t0,
        "t1": ph.t1,
        "runs": list(ph.runs),
        "samples": int(m.sum()),
    }
    if m.sum() == 0:
        return out
    e = err[m]
    out["x_m"] = M.stats(e[:, 0]).to_dict()
    out["y_m"] = M.stats(e[:, 1]).to_dict()
    out["heading_deg"] = M.stats(e[:, 2]).scaled(180.0 / np.pi).to_dict()
    out["position_m"] = M.stats(np.hypot(e[:, 0], e[:, 1])).to_dict()
    a = M.ape(assoc.est[m, :2], assoc.truth[m, :2])
    out["ape_m"] = {
        "raw": a.raw.to_dict(),
        "aligned": a.aligned.to_dict(),
        "aligned_scale": a.aligned_scale.to_dict(),
        "alignment": a.alignment,
    }
    r = M.rpe_per_metre(assoc.est[m], assoc.truth[m], params.rpe_delta_m)
    out["rpe"] = {
        "delta_m": r.delta_m,
        "trans_m_per_m": r.trans_per_m.to_dict(),
        "rot_deg_per_m": r.rot_deg_per_m.to_dict(),
    }
    out["distance_m"] = float(M.path_length(assoc.truth[m, :2])[-1])
    if nees_v is not None:
        out["nees"] = M.consistency(nees_v[m], 3).to_dict()
    if est.updates is not None:
        u = est.updates
        um = ph.mask(u.t) & u.accepted
        out["nis"] = {
            f"{k}_dof{d}": M.consistency(u.nis[um & (u.kind == k) & (u.dof == d)], int(d)).to_dict()
            for k, d in sorted(
                {(str(k), int(d)) for k, d in zip(u.kind[um], u.dof[um], strict=True)}
            )
        }
        att = ph.mask(u.t)
        out["updates"] = {
            "attempted": int(att.sum()),
            "accepted": int((att & u.accepted).sum()),
        }
    if fix_t is not None and fix_err is not None and fix_ok is not None:
        fm = ph.mask(fix_t)
        ok = fm & fix_ok & np.isfinite(fix_err)
        out["heading_fix"] = {
            "attempted": int(fm.sum()),
            "accepted": int((fm & fix_ok).sum()),
            "error_deg": M.stats(np.degrees(fix_err[ok])).to_dict(),
            "error_all_deg": M.stats(np.degrees(fix_err[fm & np.isfinite(fix_err)])).to_dict(),
        }
        if est.heading_fixes is not None:
            reasons, counts = np.unique(est.heading_fixes.reason[fm], return_counts=True)
            out["heading_fix"]["reasons"] = {
                str(k): int(n) for k, n in zip(reasons, counts, strict=True)
            }
    return out


def align_estimate(est: Estimate, truth: Truth, params: EvalParams) -> tuple[Estimate, dict]:
    """The estimate moved onto the truth by one rigid 2-D motion (Umeyama, as evo's
    ``--align``), found from the positions paired in time: poses, dead reckoning and
    landmarks are mapped by it, covariances rotated (C' = A C A^T, A = diag(R, 1)).
    For real logs, whose map frame is the robot's start and not the truth's frame."""
    assoc = M.associate(est.t, est.poses, truth.t, truth.poses, params.max_dt_s)
    if len(assoc) < 2:
        return est, {}
    s = umeyama(assoc.est[:, :2], assoc.truth[:, :2])
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
    }
    return out, info


def evaluate(truth: Truth, est: Estimate, params: EvalParams, align: bool = False) -> Evaluation:
    """Compute every metric of ``est`` against ``truth``, overall, per run and per phase.

    ``align``: first move the estimate onto the truth with one rigid 2-D motion
    (:func:`align_estimate`), so that errors, NEES and landmarks are taken in the truth's
    frame up to that motion. Raises SpanError when fewer than two estimate samples overlap
    the truth in time.
    """
    alignment = None
    if align:
        est, alignment = align_estimate(est, truth, params)
    assoc = M.associate(est.t, est.poses, truth.t, truth.poses, params.max_dt_s)
    if len(assoc) < 2:
        raise SpanError(
            f"estimate time span [{est.t[0]:.3f}, {est.t[-1]:.3f}] s does not overlap the "
            f"truth's [{truth.t[0]:.3f}, {truth.t[-1]:.3f}] s (within {params.max_dt_s} s)"
        )
    err = M.pose_errors(assoc.est, assoc.truth)
    sigma = nees_v = None
    if est.cov is not None:
        c = est.cov[assoc.index]
        sigma = np.sqrt(np.clip(np.diagonal(c, axis1=1, axis2=2), 0.0, None))
        nees_v = M.nees(err, c)
    fix_t = fix_err = fix_ok = None
    if est.heading_fixes is not None and est.heading_fixes.t.size:
        hf = est.heading_fixes
        th = M.interpolate_poses(truth.t, truth.poses, hf.t)[:, 2]
        fix_t = hf.t
        fix_err = np.asarray(wrap_angle(hf.measured - th)).reshape(-1)
        fix_ok = hf.accepted
    intervals = truth.scenario.run_intervals() if truth.scenario is not None else []
    phases = M.phases_from_runs(
        intervals, truth.freeze_run, (float(assoc.t[0]), float(assoc.t[-1]))
    )
    metrics: dict[str, Any] = {
        "label": est.label,
        "truth": truth.source,
        "estimate": est.source,
        "samples": len(assoc),
        "estimate_samples": int(est.t.size),
        "span_s": [float(assoc.t[0]), float(assoc.t[-1])],
        "params": asdict(params),
        "freeze_run": truth.freeze_run,
        "phases": {
            ph.name: _phase_block(ph, assoc, err, nees_v, est, fix_t, fix_err, fix_ok, params)
            for ph in phases
        },
    }
    if alignment is not None:
        metrics["aligned_to_truth"] = alignment
    lamp_match = None
    true_lm = truth.landmark_array
    if est.landmarks is not None and true_lm is not None:
        lamp_match = M.match_lamps(est.landmarks, true_lm, params.lamp_max_dist_m)
        metrics["lamps"] = lamp_match.summary()
        metrics["lamps"]["estimated"] = int(est.landmarks.shape[0])
        metrics["lamps"]["true"] = int(true_lm.shape[0])
        metrics["lamps"]["left_over"] = len(lamp_match.duplicates) + len(lamp_match.spurious)
        for d in (0.3, 0.5):  # true landmarks with an estimate this near (not one to one)
            metrics["lamps"][f"true_within_{d:g}_m"] = M.found_within(est.landmarks, true_lm, d)
    by_run: dict[int, M.LampMatch] = {}
    if est.landmark_history and truth.world is not None:
        snap_t = np.array([t for t, _ in est.landmark_history])
        metrics["lamps_by_run"] = {}
        for r, _t0, t1 in intervals:
            k = int(np.searchsorted(snap_t, t1, side="right")) - 1  # last snapshot by run end
            if k < 0:
                continue
            lamps = est.landmark_history[k][1]
            by_run[r] = M.match_lamps(lamps, truth.world.lamp_array, params.lamp_max_dist_m)
            metrics["lamps_by_run"][f"run{r}"] = {
                "t": float(snap_t[k]),
                "estimated": int(lamps.shape[0]),
                **by_run[r].summary(),
            }
    if est.odometry is not None:
        ot, op = est.odometry
        oa = M.associate(ot, op, truth.t, truth.poses, params.max_dt_s)
        if len(oa) >= 2:
            oe = M.pose_errors(oa.est, oa.truth)
            metrics["odometry"] = {
                "position_m": M.stats(np.hypot(oe[:, 0], oe[:, 1])).to_dict(),
                "heading_deg": M.stats(oe[:, 2]).scaled(180.0 / np.pi).to_dict(),
            }
    metrics["headline"] = headline(metrics)
    return Evaluation(
        metrics, assoc, err, sigma, nees_v, phases, lamp_match, by_run, fix_t, fix_err
    )


def headline(metrics: dict[str, Any]) -> dict[str, Any]:
    """The few numbers printed on stdout and shown first in the report."""
    ov = metrics["phases"]["overall"]
    h: dict[str, Any] = {
        "position_mean_m": ov["position_m"]["mean"],
        "heading_mean_deg": ov["heading_deg"]["mean"],
        "ape_rmse_m": ov["ape_m"]["raw"]["rmse"],
        "ape_aligned_rmse_m": ov["ape_m"]["aligned"]["rmse"],
        "rpe_m_per_m": ov["rpe"]["trans_m_per_m"]["mean"],
    }
    if "A" in metrics["phases"] and "position_m" in metrics["phases"]["A"]:
        h["phase_A_position_mean_m"] = metrics["phases"]["A"]["position_m"]["mean"]
    if "after" in metrics["phases"] and "position_m" in metrics["phases"]["after"]:
        h["after_position_mean_m"] = metrics["phases"]["after"]["position_m"]["mean"]
    if "nees" in ov:
        h["nees_mean"] = ov["nees"]["mean"]
        h["nees_in_band"] = ov["nees"]["in_band"]
    if "lamps" in metrics:
        lm = metrics["lamps"]
        h["lamps_true_within_0.5_m"] = lm["true_within_0.5_m"]
        h["lamps_left_over"] = lm["left_over"]
        h["lamp_error_mean_m"] = lm["error_m"]["mean"]
        h["lamps_duplicated"] = lm["duplicates"]
        h["lamps_missed"] = lm["missed"]
        h["lamps_spurious"] = lm["spurious"]
        h["lamps_estimated"] = lm["estimated"]
    if "heading_fix" in ov:
        h["heading_fix_error_mean_deg"] = ov["heading_fix"]["error_deg"]["mean"]
        h["heading_fix_error_std_deg"] = ov["heading_fix"]["error_deg"]["std"]
    return h
