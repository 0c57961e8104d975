"""``fuzzyslam run``: EKF-SLAM on ceiling lamps over a recorded log (issue 3)."""

from __future__ import annotations

import math
from pathlib import Path

import click

from fuzzyslam.cli import LOG_TIME, cli, config_option, emit, ranges_option, seed_option
from fuzzyslam.config import load_config


def _build_aids(
    map_dir: Path | None, fix: str | None, cfg, log: Path, fix_from: float | None = None
) -> list:
    """Heading/pose-fix aids from a frozen map (``fuzzyslam.fixes.aids.make_aids``)."""
    mode = fix if fix is not None else ("none" if map_dir is None else cfg.fixes.mode)
    if mode == "none":
        return []
    if map_dir is None:
        raise click.UsageError(f"--fix {mode} needs --map FGMDIR (a frozen map from 'map')")
    from fuzzyslam.fixes.aids import make_aids
    from fuzzyslam.maps.mapio import log_identity
    from fuzzyslam.streams.logmeta import read_world
    from fuzzyslam.streams.reader import LogReader

    world = read_world(LogReader(log))  # the identity the map stage recorded (maps/build.py)
    world_dict = world.to_dict() if world is not None else None
    return make_aids(
        map_dir, mode, cfg, fix_from, expect_log_id=log_identity(world_dict, Path(log).name)
    )


def _parse_pose(_ctx, _param, value: str | None) -> tuple[float, float, float] | None:
    """``X,Y,THETA`` as three finite floats."""
    if value is None:
        return None
    try:
        x, y, th = (float(v) for v in value.split(","))
    except ValueError:
        raise click.BadParameter(f"expected X,Y,THETA (three numbers), got {value!r}") from None
    if not all(map(math.isfinite, (x, y, th))):
        raise click.BadParameter(f"expected three finite numbers, got {value!r}")
    return x, y, th


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
@config_option
@click.option(
    "--map",
    "map_dir",
    type=click.Path(readable=False, path_type=Path),
    default=None,
    help="Frozen fuzzy map directory (from 'fuzzyslam map') for heading or pose fixes.",
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
    help="Log time (s) from which the fixes are applied. Default: the map's freeze time "
    "(e.g. 0 to use a map frozen on another log of the same world from the start).",
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
@seed_option
def run_command(
    log: Path,
    outdir: Path,
    config: str | None,
    map_dir,
    fix,
    fix_from,
    ranges,
    start_pose,
    adapt_noise,
    calibration,
    seed,
) -> None:
    """EKF-SLAM on ceiling lamps over the recorded LOG (MCAP), written into OUTDIR.

    \b
    Reads odometry (wheel encoders on topics.joint_states, or topics.odom when the log
    has no encoders or slam.use_encoders is false) and lamps (mono8 frames on
    topics.image with topics.camera_info, or PoseArray detections on
    topics.detections; a log with neither runs on odometry and the map's fixes), and
    runs the augmented-state EKF with JCBB data association, tentative lamps and a
    guard against duplicate lamps.

    \b
    Writes trajectory.tum, odometry.tum (dead reckoning), covariance.csv,
    landmarks.yaml, updates.csv (innovation and NIS of every update attempt),
    estimates.mcap (/slam/pose, /tf, /slam/landmarks for Foxglove) and summary.json;
    with --map also heading_fixes.csv (and changes.csv with --fix pose), and /map and
    the fixes in estimates.mcap.
    The JSON summary is also printed on stdout; progress goes to stderr.
    """
    from fuzzyslam.slam.stage import run_stage

    cfg = load_config(config, seed)
    aids = _build_aids(map_dir, fix, cfg, log, fix_from)
    if calibration is None and map_dir is not None and cfg.slam.calibrate:
        found = Path(map_dir) / "calibration.yaml"  # maps/build.py: at the freeze time
        calibration = found if found.is_file() else None
    if adapt_noise and aids:
        raise click.UsageError("--adapt-noise cannot be combined with heading or pose fixes")
    emit(
        run_stage(
            log,
            outdir,
            cfg,
            aids,
            adapt_noise=adapt_noise,
            ranges=ranges,
            start_pose=start_pose,
            calibration=calibration,
        )
    )
