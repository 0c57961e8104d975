"""``fuzzyslam sweep``: a grid of config values x seeds, one table (issue 16)."""

from __future__ import annotations

from pathlib import Path

import click

from fuzzyslam.cli import MAX_SEED, SCHEDULER_ADDRESS, check_ship_files, cli, emit


@cli.command("sweep")
@click.argument("config")
@click.option(
    "--set",
    "sets",
    multiple=True,
    required=True,
    metavar="KEY=V1,V2,...",
    help="A config key (dotted, e.g. fgm.freeze_run) and its values; repeat for a grid.",
)
@click.option("--seeds", type=click.IntRange(min=1), default=None,
              help="Seeds per grid point (0 .. N-1; default 3).")  # fmt: skip
@click.option("--logs", "logs_glob", metavar="GLOB", default=None,
              help="Recorded logs (a glob, e.g. 'runs/*/log.mcap') to run at every grid "
              "point instead of simulated seeds; evaluated against truth.tum beside a log "
              "(aligned) or the log's own ground truth.")  # fmt: skip
@click.option("-o", "--output", "outdir", default="sweep", show_default=True,
              type=click.Path(path_type=Path),
              help="Output directory: absent, empty or a previous sweep's; rerun into it "
              "to go on where it stopped.")  # fmt: skip
@click.option("-j", "--jobs", type=click.IntRange(min=1), default=None,
              help="Steps at once (default: the usable CPUs, or the Dask threads).")  # fmt: skip
@click.option("--scheduler", type=SCHEDULER_ADDRESS, default=None,
              help="Run the steps on an existing Dask scheduler (shared filesystem).")  # fmt: skip
@click.option("--ship-files", is_flag=True,
              help="Send each step's input files with its task and take its outputs back: "
              "for Dask workers (--scheduler) that do not share OUTDIR's filesystem.")  # fmt: skip
def sweep_command(config: str, sets: tuple[str, ...], seeds: int | None,
                  logs_glob: str | None, outdir: Path, jobs,
                  scheduler: str | None, ship_files: bool) -> None:  # fmt: skip
    """Sweep config values: simulate, run and evaluate each grid point x seed (or run and
    evaluate each grid point x recorded log with --logs).

    \b
    CONFIG is a YAML file or an embedded config name, e.g.
      fuzzyslam sweep quick.yaml --set fgm.freeze_run=1,2 --seeds 3 -o sweep
      fuzzyslam sweep real_detections.yaml --set slam.gate_chi2=9,16 --logs 'runs/*/log.mcap' -o sw

    Writes OUTDIR/sweep.md and sweep.json (per grid point: mean, sd, min, max over
    seeds or logs of the position and heading errors), one figure per swept key
    (sweep_KEY.png) and each step's files under gI/seedS/ (gI/logJ_NAME/; the steps
    read each log through a link, logs/logJ_NAME/, so OUTDIR may move).
    Resumable: a step whose command, configs, inputs and code (the package's sources,
    numpy, scipy, opencv and mcap versions) are unchanged is skipped
    (counted as "skipped" in the summary), so a sweep killed halfway goes on.
    Every grid point's config is checked before anything is written; an OUTDIR that
    is neither empty nor a previous sweep's output is refused; a rerun with another grid
    replaces the old one (its other grid points, seeds and figures are removed).
    """
    import glob

    from fuzzyslam.errors import InputError
    from fuzzyslam.reproduce.overrides import parse_set
    from fuzzyslam.reproduce.sweep import sweep

    check_ship_files(scheduler, ship_files)
    if logs_glob is not None and seeds is not None:
        raise click.UsageError("give --seeds or --logs, not both")
    if seeds is not None and seeds - 1 > MAX_SEED:  # the bound of a config's seed (--seed)
        raise click.UsageError(
            f"the last seed, --seeds {seeds} - 1, is above {MAX_SEED}, the largest seed"
        )
    parsed = [parse_set(s) for s in sets]
    logs = None
    if logs_glob is not None:
        from fuzzyslam.streams.reader import bag_file

        # files, and ros2 bag folders as their MCAP file (a split bag: one line)
        found = [Path(p) for p in glob.glob(logs_glob, recursive=True)]
        logs = sorted(
            str(bag_file(p)) for p in found if p.is_file() or (p / "metadata.yaml").is_file()
        )
        if not logs:
            raise InputError(logs_glob, "--logs matches no file")
    emit(sweep(config, parsed, list(range(seeds or 3)), outdir, jobs, scheduler, logs,
               ship_files))  # fmt: skip
