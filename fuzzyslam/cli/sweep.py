"""``fuzzyslam sweep``: a grid of config values x seeds, one table (issue 16)."""

from __future__ import annotations

from pathlib import Path

import click

from fuzzyslam.cli import cli, emit


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
@click.option("--seeds", type=click.IntRange(min=1), default=3, show_default=True,
              help="Seeds per grid point (0 .. N-1).")  # fmt: skip
@click.option("-o", "--output", "outdir", default="sweep", show_default=True,
              type=click.Path(path_type=Path),
              help="Output directory; rerun into it to go on where it stopped.")  # fmt: skip
@click.option("-j", "--jobs", type=click.IntRange(min=1), default=None,
              help="Steps at once (default: the cores, or the Dask threads).")  # fmt: skip
@click.option("--scheduler", metavar="ADDRESS", default=None,
              help="Run the steps on an existing Dask scheduler (shared filesystem).")  # fmt: skip
def sweep_command(config: str, sets: tuple[str, ...], seeds: int, outdir: Path, jobs,
                  scheduler: str | None) -> None:  # fmt: skip
    """Sweep config values: simulate, run and evaluate each grid point x seed.

    \b
    CONFIG is a YAML file or an embedded config name, e.g.
      fuzzyslam sweep quick.yaml --set fgm.freeze_run=1,2 --seeds 3 -o sweep

    Writes OUTDIR/sweep.md and sweep.json (per grid point: mean, sd, min, max over
    seeds of the position and heading errors) and each step's files under gI/seedS/.
    Resumable: a step whose command, configs and inputs are unchanged is skipped
    (counted as "skipped" in the summary), so a sweep killed halfway goes on.
    """
    from fuzzyslam.reproduce.sweep import parse_set, sweep

    parsed = [parse_set(s) for s in sets]
    emit(sweep(config, parsed, list(range(seeds)), outdir, jobs, scheduler))
