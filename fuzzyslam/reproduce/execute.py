"""Run a plan of stage commands on the machine's cores or a Dask cluster (the edge of
``reproduce``).

Each step is the ``fuzzyslam`` command line it shows, run through the CLI in a worker
process whose working directory is the (temporary) output directory, so the results are
those of the same commands typed in a shell (``commands.sh``). Steps start as soon as
their dependencies are done, longest remaining chain first. The first failing step stops
the plan: running steps finish, nothing new starts, and its one-line error is raised.

The engine only places the steps: a local process pool, or the workers of an existing
Dask distributed scheduler (``scheduler="tcp://host:8786"``). Inputs and outputs move by
path, so the workers must see the output directory's parent at the same absolute path
(a shared filesystem); only the steps' JSON summaries travel through Dask. With
``ship=True`` the files travel with the tasks instead (``reproduce/ship.py``): workers
need no shared filesystem.
"""

from __future__ import annotations

import contextlib
import gc
import importlib
import io
import json
import multiprocessing
import os
import socket
import sys
import threading
import time
from collections.abc import Callable
from concurrent.futures import FIRST_COMPLETED, Executor, Future, ProcessPoolExecutor, wait
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from fuzzyslam import interrupts
from fuzzyslam.cpus import usable_cpus
from fuzzyslam.errors import EXIT_INTERNAL, FuzzyslamError, InputError
from fuzzyslam.fileio import guard_inputs
from fuzzyslam.forked import GC_THRESHOLD
from fuzzyslam.progress import PlanProgress
from fuzzyslam.reproduce.plan import Step, critical_path, ready_order
from fuzzyslam.summary import summary_text


class StepFailed(FuzzyslamError):
    """A step of the plan failed; carries that step's exit code."""

    def __init__(self, step: Step, message: str, exit_code: int) -> None:
        self.exit_code = exit_code
        super().__init__(f"step {step.key} failed ({step.command}): {message}")


@dataclass
class StepResult:
    """What one step gave back: its outcome, time, JSON summary and where it ran."""

    key: str
    ok: bool
    seconds: float
    summary: dict[str, Any] | None = None
    error: str = ""
    exit_code: int = 0
    stderr: str = ""
    worker: str = ""  # the Dask worker's address, or "local"
    host: str = ""
    pid: int = 0


# One step at a time per process: a step changes the process's working directory and
# its stdout/stderr, so a Dask worker with several threads must not run two at once.
_STEP_LOCK = threading.Lock()


def _where() -> str:
    """The address of the Dask worker running this task, or "local" outside Dask (a
    process without ``distributed`` loaded is no Dask worker: importing it only to ask
    would cost a local pool worker a second of CPU)."""
    dist = sys.modules.get("distributed")
    if dist is None:
        return "local"
    try:
        return dist.get_worker().address
    except ValueError:
        return "local"


# The entry of each kind of step: the stage package's ``stage.run`` (its public API)
STAGES = {
    "simulate": "fuzzyslam.sim.stage",
    "run": "fuzzyslam.slam.stage",
    "map": "fuzzyslam.maps.stage",
    "evaluate": "fuzzyslam.evaluation.stage",
}


# What the steps import on demand (inside functions), loaded with the stage entries by
# :func:`preload` in the parent of a forked pool, which its workers then share
PRELOAD = (
    "fuzzyslam.sim.record",
    # the aids import their modules when a run asks for them (fixes/aids.py)
    "fuzzyslam.fixes.heading",
    "fuzzyslam.fixes.pose_aid",
    "fuzzyslam.fixes.changes",
    "fuzzyslam.maps.mapio",
    "fuzzyslam.maps.figures",
    "fuzzyslam.maps.viewer",
    "fuzzyslam.streams.writer",
    "fuzzyslam.evaluation.changes",
    "fuzzyslam.evaluation.figures",
    "fuzzyslam.evaluation.report",
)


def preload() -> None:
    """Import every stage's entry and what its steps import on demand, and build the
    rosbags typestore, in this process. Called before a local pool forks its workers, so
    that they inherit the modules instead of each importing them again (matplotlib,
    the stages: about 2 s of CPU per worker).

    The imported objects are then frozen out of the garbage collector's generations
    (``gc.freeze``, meant for a parent before it forks: a full collection of a worker
    would otherwise rescan the ~90 000 objects of the modules, 0.1 s each), and the
    young generation collected every ``GC_THRESHOLD[0]`` allocations (``run``'s too:
    ``fuzzyslam.forked.fewer_collections``). Measured on a map and two evaluate steps
    run twice in a warm process: 1.09 s of collections without, 0.76 s frozen, 0.55 s
    frozen with the threshold (of ~13 s of steps). The collector's timing changes
    nothing the steps compute."""
    for module in (*STAGES.values(), *PRELOAD):
        importlib.import_module(module)
    from fuzzyslam.streams.typestore import typestore

    typestore()
    gc.freeze()
    gc.set_threshold(*GC_THRESHOLD)


def _entry(kind: str) -> Callable[..., dict[str, Any]]:
    """The entry of a step of ``kind``: a stage's ``run``; "version", the package's version
    (``fuzzyslam --version``: a step that does nothing, to try the engine)."""
    if kind == "version":
        from fuzzyslam import __version__

        return lambda: {"version": __version__}
    return importlib.import_module(STAGES[kind]).run


def not_visible(outdir: str, where: str, host: str) -> str:
    """The line of a step whose worker cannot see the plan's directory: it names the
    user's output directory ``outdir`` (never the temporary ``.part`` directory the steps
    run in, which the user never named) and the worker, and says what to do.

    Parameters
    ----------
    outdir : str
        The output directory as the user gave it (``-o``).
    where, host : str
        The worker's address and host name.

    Returns
    -------
    str
    """
    return (
        f"{outdir}: the output directory is not visible on the worker {where} on "
        f"{host}; workers must see its filesystem at the same path (a shared one), or add "
        "--ship-files to send the files with the steps"
    )


def run_step(
    kind: str, call: tuple[tuple[str, Any], ...], root: str, shown: str | None = None
) -> tuple:
    """Run a step, the stage ``kind``'s entry ``run(**dict(call))`` (``Step.call``: the
    same as the step's ``fuzzyslam`` command line), in ``root`` in this process.

    Parameters
    ----------
    kind : str
        simulate | run | map | evaluate (:data:`STAGES`).
    call : tuple of (str, object)
        The keyword arguments of the stage's entry.
    root : str
        The absolute working directory of the step (the plan's output directory).
    shown : str or None
        The output directory as the user named it (where ``root``, a temporary
        directory beside it, goes), for the error of a worker that cannot see ``root``;
        None: ``root``.

    Returns
    -------
    tuple
        (ok, seconds, summary, error line, exit code, stderr text, worker, host, pid).
        Errors are returned as text (they cross a process boundary); the step's stderr
        (warnings) is kept for results.json, off the progress display. BLAS is held to
        one thread during the step (one process per core is the engine's parallelism).
    """
    from threadpoolctl import threadpool_limits

    from fuzzyslam.streams.reader import shared_walks

    where, host, pid = _where(), socket.gethostname(), os.getpid()
    if not os.path.isdir(root):
        msg = not_visible(shown or root, where, host)
        return False, 0.0, None, msg, InputError.exit_code, "", where, host, pid
    with _STEP_LOCK:
        cwd = os.getcwd()
        os.chdir(root)
        os.environ["FUZZYSLAM_NO_PROGRESS"] = "1"
        guard_inputs(True)  # as each command does: no output may replace one of its inputs
        out, err = io.StringIO(), io.StringIO()
        t0 = time.perf_counter()
        try:
            with (
                interrupts.in_step(),
                shared_walks(),
                threadpool_limits(limits=1),
                contextlib.redirect_stdout(out),
                contextlib.redirect_stderr(err),
            ):
                summary = _entry(kind)(**dict(call))
        except FuzzyslamError as exc:
            fail = " ".join(str(exc).split()), exc.exit_code
        except Exception as exc:  # a bug in a stage: report it as an internal failure
            msg = " ".join(str(exc).split()) or type(exc).__name__
            fail = f"{type(exc).__name__}: {msg}", EXIT_INTERNAL
        else:
            fail = None
        finally:
            with contextlib.suppress(OSError):
                os.chdir(cwd)
        seconds = time.perf_counter() - t0
    if fail is not None:
        return False, seconds, None, fail[0], fail[1], err.getvalue(), where, host, pid
    summary = json.loads(summary_text(summary))  # as the command prints it (JSON types)
    return True, seconds, summary, "", 0, err.getvalue(), where, host, pid


class Engine:
    """Where the steps run: a local process pool or a Dask distributed cluster.

    Parameters
    ----------
    jobs : int
        Steps run at once (local pool: its processes; Dask: the default is the
        cluster's worker threads).
    scheduler : str or None
        Address of an existing Dask scheduler (``tcp://host:8786``); None: local pool.
    ship : bool
        Send each step's input files with it and take its outputs back (no shared
        filesystem needed).
    """

    def __init__(self, jobs: int | None, scheduler: str | None = None,
                 ship: bool = False) -> None:  # fmt: skip
        self.scheduler = scheduler
        self.ship = ship
        self._shipped: dict[Future, tuple[str, ...]] = {}
        self._client = None
        if scheduler is None:
            self.jobs = max(1, jobs or usable_cpus())
            ctx = multiprocessing.get_context("fork" if os.name == "posix" else "spawn")
            if ctx.get_start_method() == "fork":
                preload()  # the workers, forked at the first step, inherit the imports
            self.pool: Executor = ProcessPoolExecutor(
                self.jobs, mp_context=ctx, initializer=interrupts.worker_init
            )
            self.where = f"a local pool of {self.jobs} processes"
            return
        try:
            from distributed import Client
        except ImportError:
            raise InputError(
                scheduler, "--scheduler needs Dask: pip install 'fuzzyslam[dask]'"
            ) from None
        # Dask's own connect timeout when the user set it in the environment, else 10 s
        timeout = os.environ.get("DASK_DISTRIBUTED__COMM__TIMEOUTS__CONNECT", "10s")
        self._client = _connect(Client, scheduler, timeout)
        quiet_dask()  # its errors become our one line (ClusterFailed), not log tracebacks
        threads = sum(
            w.get("nthreads", 1) for w in self._client.scheduler_info()["workers"].values()
        )
        if threads == 0:
            self._client.close()
            raise InputError(scheduler, "the Dask scheduler has no workers")
        self.jobs = jobs or threads
        self.pool = self._client.get_executor(pure=False)
        self.where = f"the Dask scheduler {scheduler} ({threads} worker threads)"

    def submit(self, step: Step, root: Path, shown: Path | None = None) -> Future:
        """Start ``step`` in ``root`` (``shown``: the output directory as the user named
        it, for errors); a concurrent.futures Future of run_step's tuple."""
        fn, args = run_step, (step.kind, step.call, str(root), str(shown or root))
        if self.ship:
            from fuzzyslam.reproduce.ship import pack_inputs, rewrite_call, run_shipped_step

            argv, files = pack_inputs(step.argv, root)
            fn, args = run_shipped_step, (step.kind, rewrite_call(step.call, step.argv, argv),
                                          argv, files)  # fmt: skip
        kw = {"key": _task_key(step)} if self._client is not None else {}
        fut = self.pool.submit(fn, *args, **kw)
        if self.ship:
            self._shipped[fut] = args[2]
        return fut

    def result(self, fut: Future, root: Path) -> tuple:
        """run_step's tuple of a finished step; a shipped step's outputs are written
        into ``root`` first."""
        out = fut.result()
        argv = self._shipped.pop(fut, None)
        if argv is None:
            return out
        from fuzzyslam.reproduce.ship import write_outputs

        if out[0]:
            write_outputs(argv, out[-1], root)
        return out[:-1]

    def close(self, cancel: bool = False) -> None:
        """Stop the pool (or leave the cluster); with ``cancel`` (an interrupt), queued steps
        are cancelled and the local pool's running steps terminated (their temporary
        outputs removed by their own SIGTERM handling), so that Ctrl-C or SIGTERM does not
        wait for them.

        The queued steps are cancelled by the pool itself (``cancel_futures``), never by
        the caller: a future cancelled from outside stays in the local pool's queue, and a
        pool that then finds its terminated workers gone sets an exception on it, which
        raises in its manager thread (a traceback on stderr, one killed sweep in ~450)."""
        if self._client is None:
            if cancel:  # interrupted: stop the running steps now instead of waiting for them
                for child in multiprocessing.active_children():  # the pool's workers
                    child.terminate()  # SIGTERM: each step removes its temporary outputs
            self.pool.shutdown(wait=True, cancel_futures=cancel)
            return
        self.pool.shutdown(wait=not cancel)  # Dask's executor: wait=False cancels
        self._client.close()


CONNECT_MARGIN_S = 5.0  # beyond the connect timeout: the handshake of what answered


def _connect(client_type: Any, scheduler: str, timeout: str) -> Any:
    """A Dask Client of ``scheduler``, or one line (InputError) on why there is none.

    Dask's connect timeout covers the TCP connection; a server that accepts it and then
    says nothing (the scheduler's dashboard, port 8787, or another HTTP server) would hold
    the handshake for ever, and one that answers with something else makes the client
    read garbage (a frame of exabytes). So the client is made in a thread given the
    timeout plus ``CONNECT_MARGIN_S``, and any failure is the scheduler's: nothing that
    answered there was a Dask scheduler.
    """
    from dask.utils import parse_timedelta

    box: dict[str, Any] = {}

    def make() -> None:
        try:
            box["client"] = client_type(scheduler, timeout=timeout, set_as_default=False)
        except BaseException as exc:  # reported below, in one line
            box["error"] = exc

    worker = threading.Thread(target=make, name="dask-connect", daemon=True)
    worker.start()
    worker.join(float(parse_timedelta(timeout)) + CONNECT_MARGIN_S)
    if worker.is_alive():
        raise InputError(
            scheduler,
            f"no Dask scheduler answered within {timeout} (is this the scheduler's "
            "address, port 8786 by default, and not its dashboard's?)",
        )
    exc = box.pop("error", None)
    if exc is not None:
        if isinstance(exc, (OSError, TimeoutError)):  # Dask's own words: refused, timed out
            msg = " ".join(str(exc).split())[:200] or type(exc).__name__
            why = f"cannot reach the Dask scheduler: {msg}"
        else:  # whatever the client made of a foreign reply (a numpy error, say): not shown
            why = (
                "what answered is not a Dask scheduler (its reply is not Dask's protocol; "
                "is this the scheduler's address, port 8786 by default?)"
            )
        _drop_half_made_client(exc)
        raise InputError(scheduler, why) from None
    return box["client"]


def _drop_half_made_client(exc: BaseException) -> None:
    """Collect the client whose construction raised ``exc`` now, with the errors of its
    ``__del__`` (closing a connection to something that is no scheduler) kept off
    stderr: otherwise they would print a traceback at exit, after the one line."""
    import gc

    exc.__traceback__ = None  # its frames hold the half-made client
    hook = sys.unraisablehook
    sys.unraisablehook = lambda unraisable: None
    try:
        gc.collect()
    finally:
        sys.unraisablehook = hook


def quiet_dask() -> None:
    """Keep Dask's logged errors and warnings off stderr: a scheduler or worker that goes
    away is reported once, in one line (:class:`ClusterFailed`), and the large-graph
    warning of steps that carry their files (``--ship-files``) is expected."""
    import logging
    import warnings

    for name in ("distributed", "distributed.client", "distributed.worker"):
        logging.getLogger(name).setLevel(logging.CRITICAL)
    warnings.filterwarnings("ignore", message="Sending large graph", category=UserWarning)


class ClusterFailed(FuzzyslamError):
    """The Dask cluster failed under a step (its scheduler gone, its connection lost):
    one line naming the scheduler, exit 3 (not a bug of ours, nor of the step)."""

    exit_code = 3

    def __init__(self, scheduler: str, step: str, exc: BaseException) -> None:
        msg = " ".join(str(exc).split())[:200]
        super().__init__(
            f"{scheduler}: the Dask cluster failed while running {step} "
            f"({type(exc).__name__}{': ' + msg if msg and msg != type(exc).__name__ else ''})"
            "; nothing was written"
        )


def remove_stale_parts(root: Path) -> list[Path]:
    """Remove the temporary outputs (``.NAME.XXXX.part``, fuzzyslam/fileio.py) left in
    ``root`` by a step whose process was killed (a worker lost, the OOM killer) and that
    the engine ran again elsewhere: once every step has succeeded none is in use.

    Parameters
    ----------
    root : Path
        The plan's working directory.

    Returns
    -------
    list of Path
        What was removed.
    """
    import shutil

    gone = []
    for part in sorted(root.rglob(".*.part"), key=lambda q: len(q.parts)):
        if not part.exists():
            continue  # inside a .part directory removed already
        if part.is_dir() and not part.is_symlink():
            shutil.rmtree(part, ignore_errors=True)
        else:
            part.unlink(missing_ok=True)
        gone.append(part)
    return gone


def _task_key(step: Step) -> str:
    """A Dask task key naming the step (readable on the dashboard), unique per submit."""
    return f"fuzzyslam {step.key} {time.time_ns()}"


# Longest wait for a step before a held Ctrl-C or SIGTERM is raised (interrupts.deferred)
POLL_S = 0.1


def _poll(timeout: float | None) -> float:
    return POLL_S if timeout is None else min(timeout, POLL_S)


def execute(
    steps: list[Step],
    root: Path,
    jobs: int | None = None,
    label: str = "reproduce",
    scheduler: str | None = None,
    heartbeat_s: float = 30.0,
    final: Path | None = None,
    on_done: Callable[[Step, StepResult], None] | None = None,
    ship: bool = False,
    engine_info: dict[str, Any] | None = None,
) -> dict[str, StepResult]:
    """Run every step (dependencies first) in ``root``.

    Parameters
    ----------
    steps : list of Step
        The plan (every dependency a step of it).
    root : Path
        The working directory of every step (on a filesystem the workers share).
    jobs : int or None
        Steps at once (default: the machine's cores, or the cluster's worker threads).
    label : str
        Name on the progress display.
    scheduler : str or None
        Address of an existing Dask scheduler; None runs on a local process pool.
    heartbeat_s : float
        Longest silence of the line-per-step progress (stderr not a terminal).
    final : Path or None
        Where ``root`` goes when the plan succeeded (named in the first progress line).
    on_done : callable or None
        Called with (step, result) as each step succeeds (sweep's resume records).
    ship : bool
        Send the files with the tasks (workers without a shared filesystem).
    engine_info : dict or None
        Filled with ``jobs``, the most steps that ran at once: ``jobs`` when given, else
        the local pool's processes or the Dask cluster's worker threads when the plan
        started (a worker that replaces a lost one adds none: the engine never has more
        than this many steps out).

    Returns
    -------
    dict
        Step key -> StepResult of every step.
    """
    root = Path(root).resolve()
    prio = critical_path(steps)
    pending = {s.key: s for s in steps}
    done: dict[str, StepResult] = {}
    running: dict[Future, Step] = {}
    started: dict[str, float] = {}
    failure: StepResult | None = None
    engine = Engine(jobs, scheduler, ship)
    if engine_info is not None:
        engine_info["jobs"] = engine.jobs
    costs = {s.key: s.cost for s in steps}
    with PlanProgress(sum(costs.values()), len(steps), label, heartbeat_s) as bar:
        moved = f" (moved to {final} when every step succeeded)" if final else ""
        bar.line(f"{len(steps)} steps on {engine.where}; writing into {root}{moved}")
        try:
            with interrupts.deferred() as held:
                while pending or running:
                    if failure is None:
                        ready = [s for s in pending.values() if all(d in done for d in s.deps)]
                        ready = ready_order(ready, prio)
                        for s in ready[: max(engine.jobs - len(running), 0)]:
                            del pending[s.key]
                            running[engine.submit(s, root, final)] = s
                            started[s.key] = time.monotonic()
                    elif not running:
                        break
                    if not running:
                        raise RuntimeError("plan is stuck: steps wait on steps that never ran")
                    finished, _ = wait(
                        running, timeout=_poll(bar.timeout()), return_when=FIRST_COMPLETED
                    )
                    if not finished:
                        now = time.monotonic()
                        bar.heartbeat(
                            len(done), [(s.key, now - started[s.key]) for s in running.values()]
                        )
                    for fut in finished:
                        s = running.pop(fut)
                        try:
                            res = StepResult(s.key, *engine.result(fut, root))
                        except Exception as exc:  # the step's own failures are in its result
                            if scheduler is None:
                                raise
                            raise ClusterFailed(scheduler, s.key, exc) from exc
                        if res.ok:
                            done[s.key] = res
                            if on_done is not None:
                                on_done(s, res)
                            bar.step_done(
                                s.key,
                                res.seconds,
                                len(done),
                                res.worker,
                                sum(costs[k] for k in done),
                            )
                        elif failure is None:
                            failure = res
                    held.deliver()  # Ctrl-C or SIGTERM, raised here: no lock is held
        except BaseException:
            with interrupts.deferred():  # a second Ctrl-C waits for the steps' clean-up
                engine.close(cancel=True)
            raise
    engine.close()
    if failure is not None:
        step = next(s for s in steps if s.key == failure.key)
        raise StepFailed(step, failure.error, failure.exit_code)
    remove_stale_parts(root)  # a killed step's temporary outputs (the step ran again)
    return done
