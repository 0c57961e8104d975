"""``fuzzyslam reproduce``: the paper's experiment, phases A to D and beyond, over seeds."""

from __future__ import annotations

from pathlib import Path

import click

from fuzzyslam.cli import MAX_SEED, SCHEDULER_ADDRESS, check_ship_files, cli, emit


@cli.command("reproduce")
@click.option(
    "-o",
    "--output",
    "outdir",
    default="reproduce",
    show_default=True,
    type=click.Path(readable=False, path_type=Path),
    help="Output directory (its files appear only when every step succeeded).",
)
@click.option(
    "--seeds",
    type=click.IntRange(min=1),
    default=5,
    show_default=True,
    help="Number of seeds (0 .. N-1); the table gives the mean and spread over them.",
)
@click.option(
    "--first-seed",
    type=click.IntRange(min=0, max=MAX_SEED),
    default=0,
    show_default=True,
    help="First seed of the range.",
)
@click.option(
    "--quick",
    is_flag=True,
    help="Two-run versions of the scenarios (quick_*.yaml): a smoke test in about a minute.",
)
@click.option(
    "--paper-only",
    is_flag=True,
    help="Only the paper's phases A-D (no all-lamps-off or people scenarios, no pose fixes).",
)
@click.option(
    "-j",
    "--jobs",
    type=click.IntRange(min=1),
    default=None,
    help="Steps at once (default: the CPUs this process may use, its affinity and cgroup "
    "quota, or the Dask cluster's worker threads).",
)
@click.option(
    "--scheduler",
    type=SCHEDULER_ADDRESS,
    default=None,
    help="Run the steps on an existing Dask distributed scheduler (tcp://host:8786) "
    "instead of a local pool; its workers must see OUTDIR's parent at the same path "
    "(a shared filesystem) and have fuzzyslam installed (pip install 'fuzzyslam[dask]').",
)
@click.option(
    "--keep-logs/--no-keep-logs",
    default=None,
    help="Keep each seed's simulated MCAP logs (4 per seed, 44 MB each on the full "
    "scenario). Default: kept for one seed, removed for more.",
)
@click.option(
    "--set",
    "sets",
    multiple=True,
    metavar="KEY=VALUE",
    help="Set a config key (dotted, e.g. slam.calibrate=true) in every config of the suite: "
    "the steps name set_*.yaml files in OUTDIR that extend the embedded configs "
    "(commands.sh and results.json record it); repeat for more keys.",
)
@click.option("--ship-files", is_flag=True,
              help="Send each step's input files with its task and take its outputs back: "
              "for Dask workers (--scheduler) that do not share OUTDIR's filesystem.")  # fmt: skip
def reproduce_command(
    outdir: Path,
    seeds: int,
    first_seed: int,
    quick: bool,
    paper_only: bool,
    jobs,
    scheduler: str | None,
    keep_logs: bool | None,
    ship_files: bool,
    sets: tuple[str, ...],
) -> None:
    """Reproduce the paper's experiment: simulate, run, map, run with fixes, evaluate.

    \b
    For each seed, from the embedded configs:
      paper.yaml         runs 1-4 with every lamp (phase A), runs 5-6 with 7 of 15
                         lamps dark: lamps only (B), heading fixes (C), pose fixes
      paper_bumps.yaml   a 10-degree unseen bump in every run, heading fixes (D)
      paper_dark.yaml    every lamp dark in runs 5-6: no, heading and pose fixes
      paper_people.yaml  boxes and walking people in runs 5-6: pose fixes and
                         change detection

    \b
    Writes into OUTDIR:
      report.md      docs/experiment.md's table (paper, target, fuzzyslam: mean and
                     spread over seeds), per-seed values and the figures
      results.json   the same table, machine-readable
      summary.png    position error against time (phases A-C; all lamps off)
      commands.sh    every step as a plain stage command
      seedN/         each step's files (logs, estimates, maps, evaluations)

    --set KEY=VALUE sets a config key in every config of the suite, e.g.
    --set slam.calibrate=true: the odometry self-calibration, whose factors the
    table compares with the simulator's true wheels (n/a without it).

    A previous reproduce output in OUTDIR is replaced whole; any other non-empty
    directory is refused. Steps run in parallel on the machine's cores, or on a Dask
    cluster with --scheduler; progress goes to stderr (a bar on a terminal, else one
    line per finished step), the path of the report and the headline figures to
    stdout (JSON).
    """
    from fuzzyslam.errors import InputError
    from fuzzyslam.reproduce.overrides import parse_one
    from fuzzyslam.reproduce.stage import run

    check_ship_files(scheduler, ship_files)
    if first_seed + seeds - 1 > MAX_SEED:  # the bound of a config's seed (and --seed)
        raise click.UsageError(
            f"the last seed, --first-seed {first_seed} + --seeds {seeds} - 1, is above "
            f"{MAX_SEED}, the largest seed"
        )
    seed_list = list(range(first_seed, first_seed + seeds))
    overrides: dict = {}
    for s in sets:
        key, value = parse_one(s)
        if key in overrides:
            raise InputError(f"--set {s}", f"'{key}' is given in more than one --set")
        overrides[key] = value
    emit(run(outdir, seed_list, quick, jobs, beyond=not paper_only,
             scheduler=scheduler, keep_logs=keep_logs, ship=ship_files,
             overrides=overrides))  # fmt: skip
