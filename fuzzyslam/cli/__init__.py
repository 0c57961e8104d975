"""Command-line interface: parses arguments and calls the stages; nothing else.

Each command lives in its own module of this package and registers itself on
the ``cli`` group. Exit codes follow :mod:`fuzzyslam.errors`.
"""

from __future__ import annotations

import json
import sys
import traceback
from typing import Any

import click

from fuzzyslam import __version__
from fuzzyslam.errors import EXIT_INPUT, EXIT_INTERNAL, EXIT_INTERRUPTED, FuzzyslamError

CONTEXT = {"help_option_names": ["-h", "--help"], "max_content_width": 100}


@click.group(context_settings=CONTEXT)
@click.version_option(__version__, prog_name="fuzzyslam")
@click.option("--debug", is_flag=True, help="Show the full traceback when a command fails.")
def cli(debug: bool) -> None:
    """fuzzyslam: EKF-SLAM on ceiling lamps with fuzzy sonar maps, on recorded MCAP logs.

    Stages read and write files, so they chain in shell pipelines:

    \b
      fuzzyslam simulate -o sensors.mcap --seed 1
      fuzzyslam run sensors.mcap -o est
      fuzzyslam map sensors.mcap --trajectory est/trajectory.tum -o fgm
      fuzzyslam run sensors.mcap --map fgm -o est_fix
      fuzzyslam evaluate sensors.mcap est_fix -o report

    Each command prints a JSON summary on stdout and progress on stderr.
    Exit codes: 0 ok, 1 internal error, 2 usage error, 3 bad input, 130 interrupted.
    """


def seed_option(f):
    return click.option(
        "--seed",
        type=click.IntRange(min=0),
        default=None,
        help="Random seed (overrides the config's); same config and seed give the same files.",
    )(f)


def config_option(f):
    return click.option(
        "--config",
        "config",
        type=str,
        default=None,
        help="Config YAML path or embedded name (default: the paper scenario, paper.yaml).",
    )(f)


def emit(summary: dict[str, Any]) -> None:
    """Print the machine-readable summary (one JSON object) on stdout."""
    click.echo(json.dumps(summary, indent=2, sort_keys=True, default=_jsonable))


def _jsonable(obj: Any) -> Any:
    try:
        import numpy as np

        if isinstance(obj, np.generic):
            return obj.item()
        if isinstance(obj, np.ndarray):
            return obj.tolist()
    except ImportError:  # pragma: no cover
        pass
    return str(obj)


def _register() -> None:
    """Import the command modules so that they attach to ``cli``."""
    import importlib

    for name in ("simulate", "run", "map", "evaluate", "reproduce"):
        try:
            importlib.import_module(f"fuzzyslam.cli.{name}")
        except ModuleNotFoundError as exc:
            if exc.name != f"fuzzyslam.cli.{name}":
                raise


def main(argv: list[str] | None = None) -> None:
    """Entry point: run the CLI and map failures to one line and an exit code."""
    args = list(sys.argv[1:] if argv is None else argv)
    debug = "--debug" in args
    _register()
    try:
        cli.main(args=args, prog_name="fuzzyslam", standalone_mode=False)
    except click.exceptions.Exit as exc:
        sys.exit(exc.exit_code)
    except click.ClickException as exc:
        exc.show()
        sys.exit(exc.exit_code)
    except (KeyboardInterrupt, click.exceptions.Abort):
        click.echo("fuzzyslam: interrupted; no partial outputs were kept", err=True)
        sys.exit(EXIT_INTERRUPTED)
    except FuzzyslamError as exc:
        if debug:
            traceback.print_exc()
        click.echo(f"fuzzyslam: error: {exc}", err=True)
        sys.exit(getattr(exc, "exit_code", EXIT_INPUT))
    except Exception as exc:
        if debug:
            traceback.print_exc()
        msg = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        click.echo(
            f"fuzzyslam: internal error: {type(exc).__name__}: {msg} "
            "(rerun with --debug for the traceback)",
            err=True,
        )
        sys.exit(EXIT_INTERNAL)
    sys.exit(0)
