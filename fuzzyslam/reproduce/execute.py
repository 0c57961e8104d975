"""Run a plan of stage commands on the machine's cores (the edge of ``reproduce``).

Each step is the ``fuzzyslam`` command line it shows, run through the CLI in a worker
process whose working directory is the (temporary) output directory, so the results are
those of the same commands typed in a shell (``commands.sh``). Steps start as soon as
their dependencies are done, longest remaining chain first. The first failing step stops
the plan: running steps finish, nothing new starts, and its one-line error is raised.
"""

from __future__ import annotations

import contextlib
import io
import json
import multiprocessing
import os
import time
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from fuzzyslam.errors import EXIT_INTERNAL, FuzzyslamError
from fuzzyslam.progress import Progress
from fuzzyslam.reproduce.plan import Step, critical_path


class StepFailed(FuzzyslamError):
    """A step of the plan failed; carries that step's exit code."""

    def __init__(self, step: Step, message: str, exit_code: int) -> None:
        self.exit_code = exit_code
        super().__init__(f"step {step.key} failed ({step.command}): {message}")


@dataclass
class StepResult:
    key: str
    ok: bool
    seconds: float
    summary: dict[str, Any] | None = None
    error: str = ""
    exit_code: int = 0
    stderr: str = ""


def run_step(argv: tuple[str, ...], root: str) -> tuple[bool, float, Any, str, int, str]:
    """Run ``fuzzyslam ARGV`` in ``root`` in this process; return (ok, seconds, summary,
    error line, exit code, stderr text). Errors are returned as text (they cross a process
    boundary); the step's stderr (warnings) is kept for results.json, off the progress bar."""
    import click

    from fuzzyslam.cli import _register, cli

    os.chdir(root)
    os.environ["FUZZYSLAM_NO_PROGRESS"] = "1"
    _register()
    out, err = io.StringIO(), io.StringIO()
    t0 = time.perf_counter()
    try:
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            cli.main(args=list(argv), prog_name="fuzzyslam", standalone_mode=False)
    except FuzzyslamError as exc:
        fail = " ".join(str(exc).split()), exc.exit_code
    except click.ClickException as exc:
        fail = exc.format_message(), exc.exit_code
    except Exception as exc:  # a bug in a stage: report it as an internal failure
        msg = " ".join(str(exc).split()) or type(exc).__name__
        fail = f"{type(exc).__name__}: {msg}", EXIT_INTERNAL
    else:
        fail = None
    seconds = time.perf_counter() - t0
    if fail is not None:
        return False, seconds, None, fail[0], fail[1], err.getvalue()
    text = out.getvalue()
    try:
        summary = json.loads(text) if text.strip() else {}
    except json.JSONDecodeError:
        summary = {"stdout": text}
    return True, seconds, summary, "", 0, err.getvalue()


def execute(
    steps: list[Step], root: Path, jobs: int, label: str = "reproduce"
) -> dict[str, StepResult]:
    """Run every step (dependencies first) with ``jobs`` worker processes in ``root``."""
    prio = critical_path(steps)
    pending = {s.key: s for s in steps}
    done: dict[str, StepResult] = {}
    running: dict[Future, Step] = {}
    failure: StepResult | None = None
    total = sum(s.cost for s in steps)
    ctx = multiprocessing.get_context("fork" if os.name == "posix" else "spawn")
    with Progress(total, label) as bar, ProcessPoolExecutor(jobs, mp_context=ctx) as pool:
        try:
            while pending or running:
                if failure is None:
                    ready = [s for s in pending.values() if all(d in done for d in s.deps)]
                    ready.sort(key=lambda s: (-prio[s.key], s.key))
                    for s in ready[: max(jobs - len(running), 0)]:
                        del pending[s.key]
                        running[pool.submit(run_step, s.argv, str(root))] = s
                elif not running:
                    break
                if not running:
                    raise RuntimeError("plan is stuck: steps wait on steps that never ran")
                finished, _ = wait(running, return_when=FIRST_COMPLETED)
                for fut in finished:
                    s = running.pop(fut)
                    res = StepResult(s.key, *fut.result())
                    if res.ok:
                        done[s.key] = res
                        bar.update_to(sum(st.cost for st in steps if st.key in done))
                    elif failure is None:
                        failure = res
        except BaseException:
            for fut in running:
                fut.cancel()
            pool.shutdown(wait=True, cancel_futures=True)
            raise
    if failure is not None:
        step = next(s for s in steps if s.key == failure.key)
        raise StepFailed(step, failure.error, failure.exit_code)
    return done
