"""The local engine of reproduce: what a pool worker pays once (imports) and per step."""

from __future__ import annotations

import subprocess
import sys

from fuzzyslam.reproduce.execute import PRELOAD, STAGES, execute
from fuzzyslam.reproduce.plan import Step


def _python(code: str) -> str:
    """Run ``code`` in a fresh interpreter (a clean sys.modules); its stdout."""
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    return p.stdout.strip()


def test_a_step_outside_dask_does_not_import_dask() -> None:
    # asking "which Dask worker am I?" must not cost a local worker the import of distributed
    out = _python(
        "import sys; from fuzzyslam.reproduce.execute import _where; "
        "print(_where(), 'distributed' in sys.modules)"
    )
    assert out == "local False"


def test_preload_loads_every_stage_and_its_on_demand_modules() -> None:
    names = (*STAGES.values(), *PRELOAD)
    out = _python(
        "import sys; from fuzzyslam.reproduce.execute import preload, STAGES, PRELOAD; "
        "preload(); print(all(m in sys.modules for m in (*STAGES.values(), *PRELOAD)), "
        "'matplotlib.pyplot' in sys.modules)"
    )
    assert out == "True True"
    assert "fuzzyslam.evaluation.figures" in names and "fuzzyslam.maps.figures" in names


def test_a_forked_pool_runs_its_steps_locally(tmp_path) -> None:
    steps = [Step(f"v{i}", ("--version",), kind="version") for i in range(3)]
    done = execute(steps, tmp_path, jobs=2)
    assert sorted(done) == ["v0", "v1", "v2"]
    assert all(r.ok and r.worker == "local" and "version" in r.summary for r in done.values())


def test_a_signal_during_the_wait_is_raised_after_it(tmp_path, monkeypatch) -> None:
    """SIGTERM arriving inside ``concurrent.futures.wait`` (which holds the futures' locks
    while it installs its waiter) is held until the loop's own point: the wait returns,
    then Terminated is raised, and the pool's workers are gone. A SIGTERM raised inside
    the wait once left a future's lock held and the sweep's shutdown hung."""
    import multiprocessing
    import os
    import signal

    import fuzzyslam.reproduce.execute as ex
    from fuzzyslam.interrupts import Terminated, install, raise_terminated

    real_wait, reached = ex.wait, []

    def wait_hit_by_sigterm(*args, **kwargs):
        if not reached:
            os.kill(os.getpid(), signal.SIGTERM)
            reached.append("after the signal")
        return real_wait(*args, **kwargs)

    monkeypatch.setattr(ex, "wait", wait_hit_by_sigterm)
    before = signal.signal(signal.SIGTERM, raise_terminated)
    install()  # a new command: its first SIGTERM raises
    try:
        steps = [Step(f"v{i}", ("--version",), kind="version") for i in range(4)]
        try:
            execute(steps, tmp_path, jobs=2)
        except Terminated:
            raised = True
        else:
            raised = False
        assert signal.getsignal(signal.SIGTERM) is raise_terminated  # restored
    finally:
        signal.signal(signal.SIGTERM, before)
    assert reached == ["after the signal"] and raised
    assert multiprocessing.active_children() == []


def test_an_idle_pool_worker_ends_quietly_on_sigterm() -> None:
    """A pool worker waiting for a step raises nothing on SIGTERM (Terminated raised in
    the pool's queue read was a traceback per idle worker, and a read cut mid-message
    left garbage for the next reader): it leaves when the pool shuts down, saying
    nothing. Inside a step, SIGTERM raises Terminated so that the step removes its
    temporary outputs, once: a second SIGTERM (the parent's, after one sent to the
    process group) does not cut that clean-up short."""
    code = (
        "import multiprocessing as mp, os, signal, time\n"
        "from concurrent.futures import ProcessPoolExecutor\n"
        "from fuzzyslam import interrupts\n"
        "def in_step():\n"
        "    with interrupts.in_step():\n"
        "        try:\n"
        "            os.kill(os.getpid(), signal.SIGTERM); time.sleep(5)\n"
        "        except interrupts.Terminated:\n"
        "            os.kill(os.getpid(), signal.SIGTERM)  # a second: the clean-up goes on\n"
        "            time.sleep(0.05)\n"
        "            return 'Terminated'\n"
        "interrupts.install()\n"
        "with interrupts.deferred():  # as execute forks its workers\n"
        "    pool = ProcessPoolExecutor(2, mp_context=mp.get_context('fork'),\n"
        "                               initializer=interrupts.worker_init)\n"
        "    print(pool.submit(in_step).result())\n"
        "    kids = mp.active_children()\n"
        "    for k in kids: k.terminate()\n"
        "    pool.shutdown()  # its manager thread reaps them (a second reaper races it)\n"
        "print(sorted(k.exitcode for k in kids))\n"
    )
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert p.returncode == 0, p.stderr
    assert p.stdout.split("\n")[:2] == ["Terminated", "[0, 0]"]
    assert p.stderr == ""


def _long_step() -> None:
    """A step of 30 s (as run_step marks one)."""
    import time

    from fuzzyslam import interrupts

    with interrupts.in_step():
        time.sleep(30)


def test_an_interrupted_pool_ends_every_step_without_an_error_in_its_thread(
    monkeypatch,
) -> None:
    """Engine.close(cancel=True), as at Ctrl-C, with one step running, one queued for the
    worker and one still pending: every future ends at once (the queued step does not
    start), the workers are gone, and the pool's manager thread raises nothing (a future
    cancelled by the caller once made it raise InvalidStateError: a traceback on
    stderr)."""
    import multiprocessing
    import threading
    import time

    from fuzzyslam.reproduce.execute import Engine

    raised = []
    monkeypatch.setattr(threading, "excepthook", lambda args: raised.append(args.exc_value))
    for _ in range(3):
        engine = Engine(jobs=1)
        futures = [engine.pool.submit(_long_step) for _ in range(3)]
        time.sleep(0.05)
        t0 = time.monotonic()
        engine.close(cancel=True)
        assert time.monotonic() - t0 < 10
        assert all(f.done() for f in futures)
        assert multiprocessing.active_children() == []
    assert raised == []
