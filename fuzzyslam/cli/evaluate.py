"""``fuzzyslam evaluate``: errors of an estimate against ground truth, with the paper's figures."""

from __future__ import annotations

import click

from fuzzyslam.cli import cli, config_option, emit


@cli.command("evaluate")
@click.argument("truth", type=click.Path(readable=False, path_type=str))
@click.argument("estimate", type=click.Path(readable=False, path_type=str))
@click.option(
    "-o",
    "--output",
    "outdir",
    required=True,
    type=click.Path(readable=False, path_type=str),
    help="Report directory (created; metrics.json, report.md, PNG figures).",
)
@click.option(
    "--map",
    "map_dir",
    type=click.Path(readable=False, path_type=str),
    default=None,
    help="A 'fuzzyslam map' output directory: draw its FGM under Fig. 1.",
)
@click.option(
    "--label",
    default=None,
    help="Name of the estimate in the report (default: its file or directory name).",
)
@click.option(
    "--compare",
    multiple=True,
    type=click.Path(readable=False, path_type=str),
    help="Another estimate (run directory or TUM file) to put side by side, as PATH or "
    "LABEL=PATH (the name in the table and figure; default: its file or directory name); "
    "repeatable.",
)
@click.option(
    "--landmarks-truth",
    type=click.Path(path_type=str),
    default=None,
    help="YAML of the true landmarks (landmarks: [{id, x, y}, ...]) for a real log: scored "
    "after the rigid 2-D alignment of the trajectory (implies --align).",
)
@click.option(
    "--align",
    is_flag=True,
    help="Move the estimate onto the truth with one rigid 2-D motion (Umeyama, as evo's "
    "--align) before every error, NEES and landmark metric: for real logs, whose map frame "
    "is the robot's start.",
)
@config_option
def evaluate_cmd(
    truth: str,
    estimate: str,
    outdir: str,
    map_dir: str | None,
    label: str | None,
    compare: tuple[str, ...],
    landmarks_truth: str | None,
    align: bool,
    config: str | None,
) -> None:
    """Compare ESTIMATE with TRUTH and write a report into OUTDIR.

    TRUTH is an .mcap log with ground truth (nav_msgs/Odometry on /ground_truth/odom: a
    simulated log, with its world and run events too, or a real one that has the topic) or
    a TUM file.
    ESTIMATE is a 'fuzzyslam run' output directory or a TUM file. Kinds are detected by content.

    Computes, overall, per run and per phase (A = runs up to the FGM freeze, 'after' = later
    runs): x, y and heading errors, APE with and without Umeyama alignment (as evo), RPE per
    metre, NEES and NIS consistency, lamp errors after a one-to-one assignment (duplicated,
    missed lamps) and Hough heading-fix errors. Prints the headline figures as JSON.

    A real log's truth is usually a TUM file from a motion-capture system; its map frame
    differs by a rigid motion: pass --align (or --landmarks-truth FILE, which implies it).
    The truth used is written as OUTDIR/truth.tum (for evo).

    With --compare, further estimates of the same truth are evaluated alike and shown side
    by side (a table per phase and their position errors against time).
    """
    from fuzzyslam.evaluation.stage import run

    emit(run(truth, estimate, outdir, config, map_dir, label, compare, landmarks_truth, align))
