"""Command-line interface: parses arguments and calls the stages; nothing else.

Each command lives in its own module of this package and registers itself on
the ``cli`` group. Exit codes follow :mod:`fuzzyslam.errors`.
"""

from __future__ import annotations

import contextlib
import math
import os
import re
import sys
import traceback
from typing import Any

import click

from fuzzyslam import __version__
from fuzzyslam.errors import (
    EXIT_INPUT,
    EXIT_INTERNAL,
    EXIT_INTERRUPTED,
    EXIT_OK,
    EXIT_TERMINATED,
    FuzzyslamError,
    UsageError,
)
from fuzzyslam.fileio import WRITE_ERRNOS, guard_inputs, write_error
from fuzzyslam.interrupts import Terminated
from fuzzyslam.interrupts import install as install_interrupts
from fuzzyslam.summary import summary_text

# One BLAS/OpenMP thread per process, set before numpy loads (none of the imports above
# loads it; the commands do, later) and inherited by reproduce's workers: the filter's
# small matrix products gain nothing from threads, and on a busy machine the threads wait
# for cores (issue 16; benchmarks/bench_blas.py). FUZZYSLAM_BLAS_THREADS=N sets another
# count, "default" leaves the libraries' own; a variable the user set already wins.
BLAS_VARIABLES = (
    "OPENBLAS_NUM_THREADS",
    "OMP_NUM_THREADS",
    "MKL_NUM_THREADS",
    "BLIS_NUM_THREADS",
    "VECLIB_MAXIMUM_THREADS",
    "NUMEXPR_NUM_THREADS",
)
_blas_threads = os.environ.get("FUZZYSLAM_BLAS_THREADS", "1")
_BLAS_USER_SET = any(v in os.environ for v in BLAS_VARIABLES)
# numpy loaded before this module (a script or a test calling main): the variables come
# too late for its BLAS, which main then limits at run time (_blas_limits)
_NUMPY_FIRST = "numpy" in sys.modules
if _blas_threads != "default":
    for _var in BLAS_VARIABLES:
        os.environ.setdefault(_var, _blas_threads)

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

    Each command prints a JSON summary on stdout and progress on stderr. Errors
    are one line naming the file and the problem; outputs are written under
    temporary names and appear only when complete; an input is never overwritten.

    \b
    Exit codes:
      0    success
      1    internal error (a bug; --debug shows the traceback)
      2    usage error (bad option or argument)
      3    bad input: a missing, unreadable, malformed or inconsistent file or
           config, or an output that would overwrite an input
      130  interrupted (Ctrl-C); 143 terminated (SIGTERM): no partial outputs
    """
    guard_inputs(True)


MAX_LOG_TIME_S = 1e10  # s: a log time beyond this (epoch time of year 2286) is not one


class LogTimeType(click.ParamType):
    """A log time in seconds (:class:`fuzzyslam.stamps.LogTime`): the log's own stamp, or
    ``+S`` for S seconds after its first message; a finite number in [0, MAX_LOG_TIME_S]
    (nan, inf and 1e300 are usage errors, exit 2, not crashes further on)."""

    name = "SECONDS"

    def convert(self, value: Any, param: Any, ctx: Any) -> Any:
        from fuzzyslam.stamps import LogTime

        if isinstance(value, LogTime):
            return value
        text = str(value).strip()
        relative = text.startswith("+")
        try:
            t = float(text[1:] if relative else text)
        except (TypeError, ValueError):
            self.fail(f"{value!r} is not a number of seconds (or +SECONDS)", param, ctx)
        if not (math.isfinite(t) and 0.0 <= t <= MAX_LOG_TIME_S):
            self.fail(
                f"must be a finite log time in [0, {MAX_LOG_TIME_S:g}] s, got {value}", param, ctx
            )
        return LogTime(t, relative)


LOG_TIME = LogTimeType()


# The address schemes of a Dask distributed scheduler (distributed's comm backends);
# an address without one is tcp, as Dask reads it
SCHEDULER_SCHEMES = ("tcp", "tls", "inproc", "ucx", "ws", "wss")
_HOST_PORT = re.compile(r"(\[[0-9A-Fa-f:.]+\]|[A-Za-z0-9._-]+):([0-9]{1,5})")


class SchedulerAddressType(click.ParamType):
    """A Dask scheduler's address, ``[SCHEME://]HOST:PORT`` (``--scheduler``), checked
    for its form before anything connects: a scheme among :data:`SCHEDULER_SCHEMES`
    (none: tcp), a host and a port in 1..65535 (``inproc://`` names a process's own
    scheduler: anything after the scheme). A malformed address is a usage error naming
    the option (exit 2), not a scheduler that did not answer."""

    name = "ADDRESS"

    def convert(self, value: Any, param: Any, ctx: Any) -> Any:
        text = str(value).strip()
        scheme, sep, location = text.partition("://")
        if not sep:
            scheme, location = "tcp", text
        if scheme not in SCHEDULER_SCHEMES:
            self.fail(
                f"{value!r}: unknown address scheme '{scheme}' (a Dask scheduler's address "
                f"is [SCHEME://]HOST:PORT, SCHEME one of {', '.join(SCHEDULER_SCHEMES)})",
                param,
                ctx,
            )
        if scheme == "inproc" and location:
            return text
        m = _HOST_PORT.fullmatch(location)
        if m is None or not 1 <= int(m.group(2)) <= 65535:
            self.fail(
                f"{value!r} is not a Dask scheduler's address [SCHEME://]HOST:PORT "
                "(e.g. tcp://10.0.0.1:8786): "
                + ("no port" if m is None and ":" not in location else "a bad host or port"),
                param,
                ctx,
            )
        return text


SCHEDULER_ADDRESS = SchedulerAddressType()


def check_ship_files(scheduler: str | None, ship_files: bool) -> None:
    """Refuse ``--ship-files`` without ``--scheduler`` (a usage error, exit 2): the files
    travel to Dask workers; a local pool's processes share them already.

    Parameters
    ----------
    scheduler : str or None
        The ``--scheduler`` address.
    ship_files : bool
        Whether ``--ship-files`` was given.
    """
    if ship_files and scheduler is None:
        raise click.UsageError(
            "--ship-files needs --scheduler: it sends the steps' files to Dask workers "
            "(the local pool reads them where they are)"
        )


# The largest seed: a config's ``seed`` is refused above it (config.py's DEFAULT_BOUND,
# the bound of a field without its own; not imported: config.py loads numpy, which must
# come after the BLAS variables above), so ``--seed`` (simulate), reproduce's seeds and
# sweep's are too: a seed given on the command line is one a config may hold
MAX_SEED = 1_000_000_000


def seed_option(f):
    return click.option(
        "--seed",
        type=click.IntRange(min=0, max=MAX_SEED),
        default=None,
        help="Random seed (overrides the config's); same config and seed give the same files.",
    )(f)


PRESET_DEFAULT = (
    "the preset for the log's streams: paper (lamps, or a simulated log), real_detections "
    "(landmark detections), real_building_sonar (a sonar ring, no lamps) or "
    "real_building_scan (a laser scan, no lamps); said on stderr and in the summary's config"
)


def config_option(f=None, *, default: str = "the paper scenario, paper.yaml"):
    """``--config``, its default as ``default`` says (``@config_option`` or
    ``@config_option(default=...)``)."""

    def deco(g):
        return click.option(
            "--config",
            "config",
            type=str,
            default=None,
            help=f"Config YAML path or embedded name (default: {default}).",
        )(g)

    return deco(f) if f is not None else deco


def ranges_option(f):
    """``--ranges sonar|scan``: the range sensor of the maps and fixes (issue 13)."""
    return click.option(
        "--ranges",
        type=click.Choice(["sonar", "scan"]),
        default=None,
        help="Range sensor: the sonar ring (topics.sonar_prefix) or the laser scan "
        "(topics.scan). Default: the config's ranges.source (auto: the sonar ring when "
        "the log has one, else the scan).",
    )(f)


def stage_call(entry: Any, *args: Any, **kwargs: Any) -> Any:
    """Call a stage's entry, its reads of a log sharing one record walk (a log without a
    summary: ``streams.reader.shared_walks``); its UsageError is shown as click's usage
    errors are."""
    from fuzzyslam.streams.reader import shared_walks  # the stages import it anyway

    try:
        with shared_walks():
            return entry(*args, **kwargs)
    except UsageError as exc:
        raise click.UsageError(str(exc)) from None


def emit(summary: dict[str, Any]) -> None:
    """Print the machine-readable summary (one JSON object) on stdout; a full disk under
    a redirected stdout is the bad-input error of that output (exit 3)."""
    text = summary_text(summary)
    try:
        click.echo(text)
        sys.stdout.flush()
    except BrokenPipeError:
        raise
    except OSError as exc:
        raise write_error("<stdout>", exc, replaced=True) from exc


def tell_damage(log: Any, damage: dict | None, what: str) -> None:
    """One note on stderr when the log was damaged or cut off (a summary's
    ``log_damage``): how much was lost, and that ``what`` covers the intact part only.

    Parameters
    ----------
    log : path
        The log, as the user named it.
    damage : dict or None
        The summary's ``log_damage`` (``LogReader.damage()``).
    what : str
        The output made from the log ("the estimate", "the map").
    """
    from fuzzyslam.progress import note
    from fuzzyslam.streams.reader import lost_something

    if not lost_something(damage):
        return
    note(
        f"{log}: the log is damaged or cut off: {damage.get('lost_bytes', 0)} bytes lost "
        f"({100 * damage.get('lost_fraction', 0.0):.2f} % of the file), "
        f"{damage.get('damaged_records', 0)} damaged records skipped, "
        f"{damage.get('salvaged_messages', 0)} messages salvaged; {what} covers the "
        "intact part only (the summary's log_damage)"
    )


COMMANDS = ("simulate", "run", "map", "evaluate", "reproduce", "sweep")


def _register(args: list[str] | None = None) -> None:
    """Import the command modules so that they attach to ``cli``: with the command line
    ``args``, only its command's when it names one (the group's options are flags, so the
    first argument not starting with '-' is the command), else all (help, a typo)."""
    import importlib

    first = next((a for a in args or () if not a.startswith("-")), None)
    for name in (first,) if first in COMMANDS else COMMANDS:
        try:
            importlib.import_module(f"fuzzyslam.cli.{name}")
        except ModuleNotFoundError as exc:
            if exc.name != f"fuzzyslam.cli.{name}":
                raise


# click >= 8.2 raises it for a command line without a command (older ones print the help)
_NO_ARGS_IS_HELP: Any = getattr(click.exceptions, "NoArgsIsHelpError", ())


def _one_line(text: str) -> str:
    return " ".join(text.split()) if text else ""


def main(argv: list[str] | None = None) -> None:
    """Entry point: run the CLI and map failures to one line and an exit code.

    ``--debug`` may be given anywhere on the command line (it is moved before the
    command for click). SIGTERM is handled like Ctrl-C (temporary outputs removed,
    exit 130 for SIGINT, 143 for SIGTERM). An OSError naming a file (permission
    denied, disk full, ...) is a one-line error on that file with exit code 3.
    """
    args = list(sys.argv[1:] if argv is None else argv)
    debug = "--debug" in args
    if debug:
        args = ["--debug", *(a for a in args if a != "--debug")]
    install_interrupts()
    code = EXIT_OK
    try:
        _register(args)
        _invoke(args)
    except click.exceptions.Exit as exc:
        code = exc.exit_code
    except _NO_ARGS_IS_HELP as exc:  # bare ``fuzzyslam``: the help, as click shows it
        click.echo(exc.format_message(), err=True)
        code = exc.exit_code
    except click.UsageError as exc:  # one line, as every failure (click's is four)
        cmd = exc.ctx.command_path if exc.ctx is not None else "fuzzyslam"
        click.echo(
            f"{cmd}: usage error: {_one_line(exc.format_message())} (see '{cmd} --help')",
            err=True,
        )
        code = exc.exit_code
    except click.ClickException as exc:
        exc.show()
        code = exc.exit_code
    except (KeyboardInterrupt, click.exceptions.Abort) as exc:
        # click turns KeyboardInterrupt into Abort (raised from it)
        if isinstance(exc, Terminated) or isinstance(exc.__cause__, Terminated):
            click.echo("fuzzyslam: terminated; no partial outputs were kept", err=True)
            code = EXIT_TERMINATED
        else:
            click.echo("fuzzyslam: interrupted; no partial outputs were kept", err=True)
            code = EXIT_INTERRUPTED
    except BrokenPipeError:
        # stdout closed early (e.g. piped into head): not an error of ours
        with contextlib.suppress(OSError, ValueError):
            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())  # quiet exit flush
        code = EXIT_OK
    except FuzzyslamError as exc:
        if debug:
            traceback.print_exc()
        click.echo(f"fuzzyslam: error: {_one_line(str(exc))}", err=True)
        code = getattr(exc, "exit_code", EXIT_INPUT)
    except OSError as exc:
        if debug:
            traceback.print_exc()
        if exc.filename is None and exc.errno in WRITE_ERRNOS:
            line = _one_line(str(write_error("output", exc, replaced=True)))
            click.echo(f"fuzzyslam: error: {line}", err=True)
            code = EXIT_INPUT
        elif exc.filename is None:
            _internal(exc)
            code = EXIT_INTERNAL
        else:
            problem = exc.strerror or type(exc).__name__
            click.echo(f"fuzzyslam: error: {exc.filename}: {_one_line(problem)}", err=True)
            code = EXIT_INPUT
    except Exception as exc:
        if debug:
            traceback.print_exc()
        _internal(exc)
        code = EXIT_INTERNAL
    sys.exit(code)


def _blas_limits() -> contextlib.AbstractContextManager:
    """The CLI's BLAS thread count where numpy was loaded before the variables were set
    (module comment): threadpoolctl's run-time limit, so that a command called in-process
    computes the same floats as in its own process (a matrix product's sums are split
    differently by more threads: the live map's matches, and so its trajectory, differ
    in the last bits, which a long run can amplify). Nothing to do otherwise, or where
    the user chose the count."""
    if not _NUMPY_FIRST or _BLAS_USER_SET or not _blas_threads.isdigit():
        return contextlib.nullcontext()
    from threadpoolctl import threadpool_limits

    return threadpool_limits(limits=int(_blas_threads))


def _invoke(args: list[str]) -> None:
    """Parse ``args`` and run the command, as ``cli.main(standalone_mode=False)`` does
    but without its blank line on stderr at Ctrl-C (click's, before raising Abort): an
    interruption is one line, :func:`main`'s. Shell completion is kept."""
    completion = getattr(cli, "_main_shell_completion", None)
    if completion is not None:
        completion({}, "fuzzyslam")
    with _blas_limits(), cli.make_context("fuzzyslam", args) as ctx:
        cli.invoke(ctx)


# commands whose process leaves at once when done (:func:`entry`), without the
# interpreter's finalisation, which frees every object module by module (55 ms after a pose
# run of the paper log, 2 % of it): their outputs are written, closed and renamed before
# main returns, their children reaped, and nothing of theirs waits for an exit handler
LEAVE_AT_ONCE = frozenset({"run"})


def entry() -> None:
    """The process entry (``fuzzyslam`` and ``python -m fuzzyslam``): :func:`main`, and an
    interrupted run (exit 130 or 143) leaves the process at once, after flushing, without
    the interpreter's finalisation: a second KeyboardInterrupt raised there (a signal
    arriving late, or one left pending by a C extension) would otherwise turn the exit
    status into death by SIGINT (-2) after the one-line message was already written.
    So does every exit of a command of :data:`LEAVE_AT_ONCE` (the finalisation's time),
    but under a profiler or a tracer (``python -m cProfile``, coverage), whose data are
    written after the command returns.
    Every temporary output is removed before :func:`main` returns (context managers).
    Closed standard descriptors get the null device and a reader that goes away is not
    an error (:func:`fuzzyslam.cli.std.guard_streams`)."""
    from fuzzyslam.cli.std import guard_streams

    guard_streams()
    command = next((a for a in sys.argv[1:] if not a.startswith("-")), None)
    try:
        main()
    except SystemExit as exc:
        watched = sys.getprofile() is not None or sys.gettrace() is not None
        if exc.code in (EXIT_INTERRUPTED, EXIT_TERMINATED) or (
            command in LEAVE_AT_ONCE and not watched  # a profiler's or coverage's data
        ):  # are written after main returns (or by an exit handler): let them be
            for f in (sys.stdout, sys.stderr):
                with contextlib.suppress(Exception):
                    f.flush()
            os._exit(int(exc.code or 0))
        raise


def _internal(exc: BaseException) -> None:
    msg = _one_line(str(exc).splitlines()[0]) if str(exc).strip() else type(exc).__name__
    click.echo(
        f"fuzzyslam: internal error: {type(exc).__name__}: {msg} "
        "(rerun with --debug for the traceback)",
        err=True,
    )
