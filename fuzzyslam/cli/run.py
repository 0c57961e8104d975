"""``fuzzyslam run``: EKF-SLAM on ceiling lamps over a recorded log (issue 3)."""

from __future__ import annotations

import contextlib
import math
from pathlib import Path

import click

from fuzzyslam.cli import (
    LOG_TIME,
    PRESET_DEFAULT,
    cli,
    config_option,
    emit,
    ranges_option,
    stage_call,
    tell_damage,
)


def _parse_pose(_ctx, _param, value: str | None) -> tuple[float, float, float] | None:
    """``X,Y,THETA`` as three finite floats within the bounds of the config's
    ``slam.start_pose`` (a usage error otherwise)."""
    if value is None:
        return None
    try:
        x, y, th = (float(v) for v in value.split(","))
    except ValueError:
        raise click.BadParameter(f"expected X,Y,THETA (three numbers), got {value!r}") from None
    if not all(map(math.isfinite, (x, y, th))):
        raise click.BadParameter(f"expected three finite numbers, got {value!r}")
    lo, hi = _start_pose_bounds()
    if not all(lo <= v <= hi for v in (x, y, th)):
        raise click.BadParameter(
            f"each value must be in [{lo:g}, {hi:g}] (as slam.start_pose), got {value!r}"
        )
    return x, y, th


def _start_pose_bounds() -> tuple[float, float]:
    """The range of each value of the config's ``slam.start_pose``."""
    import dataclasses

    from fuzzyslam.config import DEFAULT_BOUND
    from fuzzyslam.slam.params import SlamParams

    (meta,) = (f.metadata for f in dataclasses.fields(SlamParams) if f.name == "start_pose")
    return meta.get("min", -DEFAULT_BOUND), meta.get("max", DEFAULT_BOUND)


@cli.command("run")
@click.argument("log", type=click.Path(readable=False, path_type=Path))
@click.option(
    "-o",
    "--output",
    "outdir",
    required=True,
    type=click.Path(readable=False, path_type=Path),
    help="Output directory (created; files in it are replaced only when the run succeeds).",
)
@config_option(default="the map's config with --map, else " + PRESET_DEFAULT)
@click.option(
    "--map",
    "map_dir",
    type=click.Path(readable=False, path_type=Path),
    default=None,
    help="Frozen fuzzy map directory (from 'fuzzyslam map') for heading or pose fixes.",
)
@click.option(
    "--live-map",
    is_flag=True,
    help="Build the map while localising on it (grid SLAM for a log without lamps and "
    "without a map: pose fixes against the keyframes before, loops closed after the run; "
    "not with --map). Its trajectory_closed.tum then builds the frozen map: 'fuzzyslam "
    "map LOG --trajectory OUTDIR/trajectory_closed.tum ...'.",
)
@click.option(
    "--fix",
    type=click.Choice(["heading", "pose", "none"]),
    default=None,
    help="Fixes from the map: heading (the paper), pose (full pose), none. "
    "Default: the config's fixes.mode when --map is given, else none.",
)
@click.option(
    "--fix-from",
    type=LOG_TIME,
    default=None,
    metavar="SECONDS",
    help="Log time (s: the log's own stamps, Unix time on most real logs; +S for S seconds "
    "after the log's start) from which the fixes are applied. Default: the map's freeze "
    "time (e.g. 0 to use a map frozen on another log of the same world from the start).",
)
@ranges_option
@click.option(
    "--start-pose",
    callback=_parse_pose,
    default=None,
    metavar="X,Y,THETA",
    help="Start pose (m, m, rad). Default: the log's scenario, else slam.start_pose, else "
    "the first odometry pose (nav_msgs/Odometry).",
)
@click.option(
    "--adapt-noise",
    is_flag=True,
    help="Estimate the detection noise from the log's innovations in a first pass and run "
    "again with it (logs with PoseArray detections; not with --map).",
)
@click.option(
    "--calibration",
    "calibration",
    type=click.Path(readable=False, path_type=Path),
    default=None,
    metavar="FILE",
    help="Start the odometry self-calibration from FILE (a run's calibration.yaml; implies "
    "slam.calibrate). Default with --map and slam.calibrate: the map's calibration.yaml "
    "(the calibration at its freeze time) when it has one.",
)
@click.option(
    "--prefetch/--no-prefetch",
    default=True,
    help="Read and decode the log in a second process, on a second core, and with --fix "
    "pose draw changes.png in a third (default: on where the platform forks and this "
    "process may use >= 2 CPUs; FUZZYSLAM_PREFETCH=0 turns it off too). The outputs are "
    "the same either way.",
)
@click.option(
    "--seed",
    type=click.IntRange(min=0),
    default=None,
    help="Accepted so that a pipeline can pass one seed to every stage; it changes "
    "nothing: run is deterministic without it (nothing in the filter, the fixes or the "
    "maps is random), and the same log and config give the same files.",
)
def run_command(
    log: Path,
    outdir: Path,
    config: str | None,
    map_dir,
    live_map,
    fix,
    fix_from,
    ranges,
    start_pose,
    adapt_noise,
    calibration,
    prefetch,
    seed,
) -> None:
    """EKF-SLAM on ceiling lamps over the recorded LOG (MCAP), written into OUTDIR.

    \b
    Reads odometry (wheel encoders on topics.joint_states, or topics.odom when the log
    has no readable encoders or slam.use_encoders is false, or else the odom -> base_link
    transforms on topics.tf) and lamps (camera frames on topics.image, raw or
    compressed, with topics.camera_info, or PoseArray / Detection3DArray detections on
    topics.detections; a log with neither runs on odometry and the map's fixes), and
    runs the augmented-state EKF with JCBB data association, tentative lamps and a
    guard against duplicate lamps.

    \b
    Writes trajectory.tum, odometry.tum (dead reckoning), covariance.csv,
    landmarks.yaml, updates.csv (innovation and NIS of every update attempt),
    estimates.mcap (/slam/pose; /tf map -> odom, and odom -> base_link unless the
    log's /tf carries it; /slam/landmarks: for Foxglove) and summary.json; with
    slam.calibrate (on in paper.yaml and the presets that extend it, except
    real_detections.yaml) also calibration.csv and calibration.yaml (the odometry
    factors over time, at the end);
    with --map also heading_fixes.csv (heading fixes, or --fix pose with
    fixes.pose_with_heading), pose_fixes.csv (--fix pose), changes.csv and changes.png
    (--fix pose with fixes.detect_changes), and /map and the fixes in estimates.mcap
    (a fix topic once a fix is formed); with --live-map pose_fixes.csv (and
    heading_fixes.csv with fixes.live_right_angles), trajectory_closed.tum (its loops
    closed, during the run with fixes.live_close_online and again after it,
    fixes.live_close_loops) and the map as it ended in
    estimates.mcap.
    The JSON summary is also printed on stdout; progress goes to stderr.
    """
    from fuzzyslam.forked import ChildCalls, fewer_collections, wanted
    from fuzzyslam.slam.tf_ahead import read_ahead

    # a pose run draws changes.png in a figure process (slam/stage.py): forked now, before
    # the imports below, it imports matplotlib on the second core, idle while this process
    # starts (fuzzyslam/forked.py); closed by the stage if no aid draws
    forks = wanted(prefetch)
    early = map_dir is not None and fix == "pose" and forks
    with (
        ChildCalls() if early else contextlib.nullcontext() as figures,
        fewer_collections(),  # here and in the input process (it inherits the thresholds)
        _shared_walks(),  # one record walk of a log without a summary serves every reader
        read_ahead(log, forks),  # the log's /tf read meanwhile (slam/tf_ahead.py)
    ):
        from fuzzyslam.slam.stage import run

        summary = stage_call(
            run,
            log,
            outdir,
            config,
            seed,
            map_dir,
            fix,
            fix_from,
            ranges,
            start_pose,
            adapt_noise,
            calibration,
            prefetch,
            figures=figures,
            live_map=live_map,
        )
    tell_damage(log, summary.get("log_damage"), "the estimate")
    emit(summary)


def _shared_walks() -> contextlib.AbstractContextManager[None]:
    """``streams.reader.shared_walks``, imported once the figure process is forked."""
    from fuzzyslam.streams.reader import shared_walks

    return shared_walks()
