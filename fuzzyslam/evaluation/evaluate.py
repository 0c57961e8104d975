"""Edge of the evaluation: read TRUTH and ESTIMATE files, run the core, write REPORTDIR.

TRUTH is an MCAP log with ground truth (a simulated one, its world and scenario inside, or
a real one with the ground truth topic) or a TUM file;
ESTIMATE is a ``fuzzyslam run`` output directory or a TUM file. Kinds are detected by content.
"""

from __future__ import annotations

import csv
import os
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from fuzzyslam import rundir as R
from fuzzyslam.errors import InputError
from fuzzyslam.evaluation.core import (
    Estimate,
    Evaluation,
    HeadingFixes,
    SpanError,
    Truth,
    Updates,
    drop_stray_truth,
    evaluate,
)
from fuzzyslam.evaluation.params import EvalParams
from fuzzyslam.evaluation.results import ComparisonPhase, ComparisonRow
from fuzzyslam.fileio import OutputDir, check_input_file, check_outputs
from fuzzyslam.maps.grid import BeliefMap
from fuzzyslam.progress import Progress, note
from fuzzyslam.rundir import split_label  # LABEL=PATH of --compare
from fuzzyslam.se2 import quaternion_to_yaw
from fuzzyslam.streams.logmeta import read_scenario, read_world
from fuzzyslam.streams.reader import MCAP_MAGIC, LogReader
from fuzzyslam.streams.topics import Topics
from fuzzyslam.streams.tum import format_tum, read_tum, read_tum_planar
from fuzzyslam.summary import OMIT, path_text

KIND_MCAP = "mcap"
RUN_MARKS = ("trajectory.tum", "summary.json", "estimates.mcap")  # a run's, not a bag's
KIND_TUM = "tum"
KIND_RUNDIR = "rundir"


def detect_kind(path: str | os.PathLike) -> str:
    """``mcap`` (magic bytes), ``rundir`` (a directory) or ``tum`` (text whose first data line
    has 8 numeric columns); anything else is an InputError."""
    p = Path(path)
    if not p.exists():
        raise InputError(p, "does not exist")
    if p.is_dir():
        return KIND_RUNDIR
    check_input_file(p)
    with open(p, "rb") as f:
        head = f.read(4096)
    if head.startswith(MCAP_MAGIC):
        return KIND_MCAP
    try:
        text = head.decode("utf-8")
    except UnicodeDecodeError:
        text = ""
    for line in text.splitlines():
        s = line.strip()
        if not s or s.startswith("#"):
            continue
        parts = s.replace(",", " ").split()
        try:
            [float(v) for v in parts]
        except ValueError:
            break
        if len(parts) == 8:
            return KIND_TUM
        break
    raise InputError(
        p, "unknown file kind (expected an MCAP log, a TUM trajectory or a run output directory)"
    )


# --- truth --------------------------------------------------------------------------------


def read_truth(path: str | os.PathLike, progress: bool = True) -> Truth:
    """Ground truth from a simulated log (with world, scenario, freeze run), another log's
    ground truth topic or a TUM file.

    A recorded truth (a TUM file, a log without a scenario) loses its stray lines
    (:func:`fuzzyslam.evaluation.core.drop_stray_truth`), counted in ``lines_dropped``;
    a simulated log's truth is exact and kept whole (``lines_dropped`` None).

    Parameters
    ----------
    path : str or os.PathLike
        The TUM file or MCAP log.
    progress : bool
        The reading's progress bar (when progress is enabled).

    Returns
    -------
    Truth
    """
    kind = detect_kind(path)
    p = Path(path)
    if kind == KIND_RUNDIR and not any((p / f).exists() for f in RUN_MARKS):
        kind = KIND_MCAP if any(p.glob("*.mcap")) else kind  # a ros2 bag folder (bag_file)
    if kind == KIND_TUM:
        t, poses, planar = read_tum_planar(path)
        if not planar:
            note(f"{path}: a 3-D trajectory: evaluated in the plane (z, roll and pitch ignored)")
        t, poses, dropped, refused = drop_stray_truth(t, poses)
        return Truth(t, poses, source=path_text(path), lines_dropped=dropped, lines_refused=refused)
    if kind != KIND_MCAP:
        raise InputError(
            path, "TRUTH must be an MCAP log with ground truth or a TUM file, not a directory"
        )
    reader = LogReader(path)
    world = read_world(reader)
    scenario = read_scenario(reader)
    topic = Topics().ground_truth
    if scenario is not None:
        topic = scenario.config.get("topics", {}).get("ground_truth", topic)
    if topic not in reader.topics:
        raise InputError(
            path, f"log has no ground truth (no topic {topic}); give a log with it or a TUM file"
        )
    ts, rows = [], []  # (x, y, qx, qy, qz, qw) per message; the yaws at once below
    with Progress(reader.end - reader.start, "evaluate: reading ground truth", progress) as bar:
        for lm in reader.messages([topic]):
            p = lm.msg.pose.pose
            o = p.orientation
            ts.append(lm.t)
            rows.append((p.position.x, p.position.y, o.x, o.y, o.z, o.w))
            bar.update_to(lm.t - reader.start)
    if len(ts) < 2:
        raise InputError(path, f"ground truth topic {topic} holds fewer than two poses")
    t = np.asarray(ts)
    raw = np.asarray(rows, dtype=float)
    ps = np.column_stack([raw[:, 0], raw[:, 1], quaternion_to_yaw(raw[:, 2:])])  # as pose_of
    order = np.argsort(t, kind="stable")
    t, ps = t[order], ps[order]
    freeze = dropped = None
    refused = 0
    if scenario is not None:
        fr = scenario.config.get("fgm", {}).get("freeze_run")
        freeze = int(fr) if fr is not None else None
    else:  # a recorded log's truth
        t, ps, dropped, refused = drop_stray_truth(t, ps)
    return Truth(
        t,
        ps,
        world,
        scenario,
        freeze,
        path_text(path),
        reader.damage(),
        lines_dropped=dropped,
        lines_refused=refused,
    )


# --- estimate -----------------------------------------------------------------------------


def _read_csv(path: Path, required: list[str]) -> dict[str, list[str]]:
    try:
        with open(path, newline="", encoding="utf-8") as f:
            rows = list(csv.reader(f))
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(path, f"cannot read CSV: {exc}") from None
    if not rows:
        raise InputError(path, "empty CSV (no header)")
    header = [h.strip() for h in rows[0]]
    missing = [c for c in required if c not in header]
    if missing:
        raise InputError(path, f"CSV lacks column(s) {', '.join(missing)}")
    cols: dict[str, list[str]] = {h: [] for h in header}
    for lineno, r in enumerate(rows[1:], 2):
        if not r:
            continue
        if len(r) != len(header):
            raise InputError(path, f"line {lineno}: {len(r)} fields, header has {len(header)}")
        for h, v in zip(header, r, strict=True):
            cols[h].append(v.strip())
    return cols


def _floats(path: Path, name: str, vals: list[str]) -> np.ndarray:
    try:
        return np.array([float(v) if v != "" else np.nan for v in vals], dtype=float)
    except ValueError:
        raise InputError(path, f"column {name} holds a non-numeric value") from None


def read_covariance(path: Path, n: int) -> np.ndarray:
    """covariance.csv -> (n, 3, 3); rows must match trajectory.tum one to one."""
    names = ["t", "pxx", "pxy", "pxt", "pyy", "pyt", "ptt"]
    c = _read_csv(path, names)
    v = {k: _floats(path, k, c[k]) for k in names}
    if v["t"].size != n:
        raise InputError(path, f"{v['t'].size} rows, but trajectory.tum has {n} poses")
    cov = np.empty((n, 3, 3))
    cov[:, 0, 0], cov[:, 1, 1], cov[:, 2, 2] = v["pxx"], v["pyy"], v["ptt"]
    cov[:, 0, 1] = cov[:, 1, 0] = v["pxy"]
    cov[:, 0, 2] = cov[:, 2, 0] = v["pxt"]
    cov[:, 1, 2] = cov[:, 2, 1] = v["pyt"]
    return cov


def read_updates(path: Path) -> Updates:
    names = ["t", "kind", "id", "dof", "nis", "accepted"]
    c = _read_csv(path, names)
    return Updates(
        t=_floats(path, "t", c["t"]),
        kind=np.array(c["kind"], dtype=str),
        id=np.nan_to_num(_floats(path, "id", c["id"]), nan=-1).astype(np.int64),
        dof=np.nan_to_num(_floats(path, "dof", c["dof"]), nan=0).astype(np.int64),
        nis=_floats(path, "nis", c["nis"]),
        accepted=np.nan_to_num(_floats(path, "accepted", c["accepted"])) > 0.5,
    )


def read_heading_fixes(path: Path) -> HeadingFixes:
    c = _read_csv(path, ["t", "measured", "accepted", "reason"])
    return HeadingFixes(
        t=_floats(path, "t", c["t"]),
        measured=_floats(path, "measured", c["measured"]),
        accepted=np.nan_to_num(_floats(path, "accepted", c["accepted"])) > 0.5,
        reason=np.array(c["reason"], dtype=str),
    )


def read_landmark_history(path: Path, topic: str) -> list[tuple[float, np.ndarray]]:
    """Snapshots (t, lamps (M, 2)) of the /slam/landmarks MarkerArrays in estimates.mcap.

    Each message holds the whole map; lamps are the ADD markers of namespace ``lamps`` (or,
    if there is none, every non-text marker).
    """
    reader = LogReader(path)
    if topic not in reader.topics:
        return []
    out = []
    for lm in reader.messages([topic]):
        mk = [m for m in lm.msg.markers if m.action == 0]
        lamps = [m for m in mk if m.ns == "lamps"] or [m for m in mk if m.type != 9]
        xy = np.array([[m.pose.position.x, m.pose.position.y] for m in lamps], dtype=float)
        out.append((lm.t, xy.reshape(-1, 2)))
    return out


def read_estimate(path: str | os.PathLike, label: str | None = None, full: bool = True) -> Estimate:
    """An estimate from a run OUTDIR (every file it holds) or a TUM file (poses only);
    ``full=False``: only what a compared estimate's row and curve need (trajectory.tum and
    landmarks.yaml: not the covariances, updates, dead reckoning, fixes or map history).
    Its label and source (the report's and the figures' text) as
    :func:`fuzzyslam.summary.path_text` has them."""
    kind = detect_kind(path)
    p = Path(path)
    if kind == KIND_TUM:
        t, poses = read_tum(p)
        return Estimate(t, poses, label=path_text(label or p.stem), source=path_text(p))
    if kind != KIND_RUNDIR:
        raise InputError(p, "ESTIMATE must be a run output directory or a TUM file, not a log")
    traj = p / R.TRAJECTORY
    if not traj.is_file():
        raise InputError(p, "not a run output directory (no trajectory.tum)")
    t, poses = read_tum(traj)
    est = Estimate(t, poses, label=path_text(label or p.name), source=path_text(p))
    if (p / R.LANDMARKS).is_file():
        est.landmarks, est.landmark_ids = R.read_landmarks(p / R.LANDMARKS)
    if not full:
        return est
    if (p / R.COVARIANCE).is_file():
        est.cov = read_covariance(p / R.COVARIANCE, t.size)
    if (p / R.ODOMETRY).is_file():
        est.odometry = read_tum(p / R.ODOMETRY)
    if (p / R.UPDATES).is_file():
        est.updates = read_updates(p / R.UPDATES)
    if (p / R.HEADING_FIXES).is_file():
        est.heading_fixes = read_heading_fixes(p / R.HEADING_FIXES)
    if (p / R.ESTIMATES).is_file():
        est.landmark_history = read_landmark_history(p / R.ESTIMATES, Topics().slam_landmarks)
    return est


def read_fgm(mapdir: str | os.PathLike) -> BeliefMap:
    """The FGM of a ``fuzzyslam map`` output directory (fgm.npz), for drawing under Fig. 1
    (read and validated by ``maps.mapio.load_fgm``, the one reader of map files)."""
    from fuzzyslam.maps.mapio import load_fgm

    p = Path(mapdir)
    return load_fgm(p / "fgm.npz" if p.is_dir() else p).map


# --- the whole stage ----------------------------------------------------------------------


@dataclass
class EvaluateResult:
    evaluation: Evaluation
    outdir: Path
    files: list[str]


def run_evaluate(
    truth_path: str | os.PathLike,
    estimate_path: str | os.PathLike,
    outdir: str | os.PathLike,
    params: EvalParams | None = None,
    map_dir: str | os.PathLike | None = None,
    label: str | None = None,
    compare: Sequence[str | os.PathLike] = (),
    landmarks_truth: str | os.PathLike | None = None,
    align: bool = False,
) -> EvaluateResult:
    """Read, evaluate, and write metrics.json, the figures and report.md into ``outdir``.

    ``compare``: more estimates (run directories or TUM files, each optionally written
    ``LABEL=PATH`` to name it in the table and figure) evaluated against the same
    truth with the same parameters; ``metrics["comparison"]`` holds one row per estimate
    (the main one first), report.md a side-by-side table and ``compare.png`` their position
    errors against time.

    ``landmarks_truth``: a YAML of true landmarks (``landmarks: [{id, x, y}, ...]``, the
    layout of landmarks.yaml) for a truth without a world (a real log); the estimate is
    then aligned onto the truth (``align``: one rigid 2-D motion, core.align_estimate)
    before every metric, as the map frame of a real run is its start, not the truth's.

    Every input is read and checked before anything is written; the outputs appear together
    (fileio.OutputDir), so a failure leaves ``outdir`` as it was. ``truth.tum`` in
    ``outdir`` is the truth that was used (stray lines dropped), interpolated at the
    estimate's compared stamps and written in the estimate's frame (moved by the inverse
    of the alignment, if any), so that ``evo_ape tum truth.tum trajectory.tum`` gives
    the overall ``ape_m.raw`` and, with ``-a``, ``ape_m.aligned``.

    On stderr, as every command: the work's progress once the inputs are read
    (:class:`fuzzyslam.progress.Progress`, off with FUZZYSLAM_NO_PROGRESS) and, at the
    end, each warning of metrics.json as a one-line note (:func:`warning_notes`).
    """
    from fuzzyslam.evaluation import figures, report

    params = params or EvalParams()
    extra_inputs = [landmarks_truth] if landmarks_truth is not None else []
    labelled = [split_label(c) for c in compare]
    compare = [c for _, c in labelled]
    check_outputs([truth_path, estimate_path, *compare, *extra_inputs], [outdir])
    staged = OutputDir(outdir, owns=("fig4_lamps.png", "consistency.png", "compare.png"))
    staged.check()  # an unusable output said now, not after the work (as run's)
    fgm = read_fgm(map_dir) if map_dir is not None else None
    est = read_estimate(estimate_path, label)
    # a compared estimate gives a row of the side-by-side table and a curve: its
    # trajectory and lamps only
    others = [read_estimate(c, lab, full=False) for lab, c in labelled]
    true_lamps = None
    if landmarks_truth is not None:  # before the truth: a log's truth takes longer to read
        true_lamps, _ = R.read_landmarks(Path(landmarks_truth), truth=True)
        align = True
    truth = read_truth(truth_path)
    if true_lamps is not None:
        truth.landmarks = true_lamps
    # every input read: the work, with its start and end on stderr as the other commands'
    # (progress.Progress: one step per evaluation, the change metrics, figures and files)
    with Progress(len(others) + 4, "evaluate: metrics, figures and report") as bar:
        try:
            ev = evaluate(truth, est, params, align=align)
        except SpanError as exc:
            raise InputError(estimate_path, str(exc)) from None
        bar.update_to(1)
        evs = [(est, ev)]
        for path, other in zip(compare, others, strict=True):
            try:
                evs.append((other, evaluate(truth, other, params, align=align)))
            except SpanError as exc:
                raise InputError(path, str(exc)) from None
            bar.update_to(len(evs))
        if others:
            rows = [comparison_row(e, v) for e, v in evs]
            ev = replace(ev, typed=replace(ev.typed, comparison=rows))
        from fuzzyslam.evaluation.changes import change_metrics

        changes = change_metrics(truth_path, estimate_path, truth.t, truth.poses[:, :2])
        if changes is not None:  # --fix pose on a log with obstacles (issue 8)
            ev = replace(ev, typed=replace(ev.typed, change_detection=changes))
        bar.update_to(len(evs) + 1)
        with staged as tmp:
            figs = figures.draw_all(tmp, truth, est, ev, fgm)
            if others:
                figures.fig_compare(tmp / "compare.png", truth, [(e.label, v) for e, v in evs])
                figs["compare"] = "compare.png"
            bar.update_to(len(evs) + 2)
            # the truth as compared, at the estimate's stamps (evo pairs the two files
            # exactly) and in the frame of trajectory.tum (the alignment undone): `evo_ape
            # tum truth.tum trajectory.tum` = the overall ape_m.raw, with -a = ape_m.aligned
            (tmp / "truth.tum").write_text(
                format_tum(ev.assoc.t, ev.truth_in_estimate_frame), encoding="utf-8"
            )
            report.write_metrics(tmp / "metrics.json", ev.metrics)
            report.write_report(tmp / "report.md", ev.metrics, figs)
            files = sorted(x.name for x in tmp.iterdir())
    for line in warning_notes(evs):
        note(line)
    return EvaluateResult(ev, Path(outdir), files)


def warning_notes(evs: Sequence[tuple[Estimate, Evaluation]]) -> list[str]:
    """The evaluations' warnings (metrics.json ``warnings``) as one-line notes for stderr:
    the main estimate's as they are, a compared estimate's that the main one has not
    (those of the truth are everyone's) after its label.

    Parameters
    ----------
    evs : sequence of (Estimate, Evaluation)
        The main estimate first, then the compared ones.

    Returns
    -------
    list of str
        One line each (no prefix: :func:`fuzzyslam.progress.note` adds it).
    """
    if not evs:
        return []
    main = list(evs[0][1].typed.warnings)
    out = [f"warning: {w}" for w in main]
    for est, ev in evs[1:]:
        out += [f"warning: {est.label}: {w}" for w in ev.typed.warnings if w not in main]
    return [" ".join(line.split()) for line in out]


def comparison_row(est: Estimate, ev: Evaluation) -> ComparisonRow:
    """One estimate's row of the side-by-side comparison: per phase, position error mean
    and max (m), heading error mean and max (deg); lamps duplicated.

    Parameters
    ----------
    est : Estimate
        The estimate (its label and source).
    ev : Evaluation
        Its evaluation.

    Returns
    -------
    ComparisonRow
    """
    phases = {
        name: ComparisonPhase(
            position_mean_m=b.position_m.mean,
            position_max_m=b.position_m.max,
            heading_mean_deg=b.heading_deg.mean,
            heading_max_deg=b.heading_deg.max,
        )
        for name, b in ev.typed.phases.items()
        if b.position_m is not OMIT
    }
    lamps = ev.typed.lamps
    return ComparisonRow(
        label=est.label,
        estimate=est.source,
        phases=phases,
        lamps_duplicated=lamps.duplicates if lamps is not OMIT else None,
    )


def summary(res: EvaluateResult) -> dict[str, Any]:
    """The JSON printed on stdout: where the report is and the headline metrics."""
    return {
        "report": str(res.outdir / "report.md"),
        "metrics": str(res.outdir / "metrics.json"),
        "files": res.files,
        **res.evaluation.metrics["headline"],
    }
