"""``fuzzyslam map``: the fuzzy global map, its nav2 picture and corridor reference angles."""

from __future__ import annotations

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


@cli.command("map")
@click.argument("log", type=click.Path(readable=False, path_type=str))
@click.option(
    "--trajectory",
    "trajectory",
    required=True,
    type=click.Path(readable=False, path_type=str),
    help="TUM trajectory placing the sonar rings (e.g. OUTDIR/trajectory.tum from 'run').",
)
@click.option(
    "-o",
    "--output",
    "outdir",
    required=True,
    type=click.Path(readable=False, path_type=str),
    help="Map directory FGMDIR (created; files appear only when all are complete).",
)
@click.option(
    "--until-run",
    type=click.IntRange(min=1),
    default=None,
    help="Freeze the map at the end of run N (default: fgm.freeze_run, 4 in the paper).",
)
@click.option(
    "--until",
    type=LOG_TIME,
    default=None,
    help="Freeze the map at this log time (s: the log's own stamps, Unix time on most real "
    "logs; +S for S seconds after the log's start) instead of at the end of a run.",
)
@click.option(
    "--skip-uncovered",
    is_flag=True,
    help="Skip (and count) sonar rings outside the trajectory instead of failing.",
)
@click.option(
    "--landmarks",
    type=click.Path(readable=False, path_type=str),
    default=None,
    help="landmarks.yaml from 'run': draw the estimated lamps in fgm.png.",
)
@click.option("--no-figures", is_flag=True, help="Do not draw the PNG figures.")
@click.option(
    "--calibration",
    type=click.Path(readable=False, path_type=str),
    default=None,
    help="calibration.csv of the trajectory's run (slam.calibrate): its factors at the "
    "freeze time go into FGMDIR/calibration.yaml, which 'run --map' starts from. "
    "Default: the calibration.csv beside the trajectory, when there.",
)
@ranges_option
@click.option(
    "--sort",
    is_flag=True,
    help="Sort the trajectory's poses by time and drop repeated stamps (counted in the "
    "summary) instead of failing on the first one out of order.",
)
@config_option(default=PRESET_DEFAULT)
def map_cmd(
    log: str,
    trajectory: str,
    outdir: str,
    until_run: int | None,
    until: float | None,
    skip_uncovered: bool,
    landmarks: str | None,
    no_figures: bool,
    calibration: str | None,
    ranges: str | None,
    sort: bool,
    config: str | None,
) -> None:
    """Build the fuzzy global map (FGM) of LOG's sonar rings or laser scans along a trajectory.

    Each reading gives evidence on the cells of its cone (occupied near the arc, empty
    inside, weighted by bearing and distance); cells hold Smets' belief masses m(E),
    m(O), m(Theta), m(conflict) combined with the unnormalised conjunctive rule; the
    conflict drives a forgetting factor. The map is frozen at the end of the window
    (default: the end of run fgm.freeze_run, read from the log's run events), split into
    corridor segments along the path, and each corridor's wall direction is found by a
    Hough transform (the reference angles of the heading fixes).

    \b
    Writes into FGMDIR:
      fgm.npz            per-cell masses, grid geometry, freeze time, log identity
      fgm.yaml, fgm.pgm  nav2 map_server occupancy picture (trinary)
      references.yaml    each corridor's reference angle (rad, mod pi), strength, region
      fgm.mcap           /map, /map_conflict, /map_references for Foxglove
      fgm.png            the FGM with the path, references and lamps (paper's Fig. 1)
      conflict.png       the conflict mass per cell
      hough.png          corridor segments and an FLM with their Hough planes (Fig. 2)
                         (the three PNGs not with --no-figures)
      calibration.yaml   the odometry calibration at the freeze time (when the
                         trajectory's run calibrated: --calibration)
      summary.json       the JSON printed on stdout

    Prints a JSON summary (cells, readings used and skipped, freeze time, reference
    angles in degrees, and, for simulated logs, the true corridor axes and wall
    precision/recall). A trajectory that does not cover the sonar rings of the window is
    an error naming the gap unless --skip-uncovered.
    """
    from fuzzyslam.maps.stage import run

    summary = stage_call(
        run,
        log,
        trajectory,
        outdir,
        config,
        until_run,
        until,
        skip_uncovered,
        landmarks,
        not no_figures,
        ranges,
        sort,
        calibration,
    )
    tell_damage(log, summary.get("log_damage"), "the map")
    emit(summary)
