"""The figure process (fuzzyslam/forked.py ``ChildCalls``): calls made in a forked child
that imported its modules first; their results and exceptions as in this process; a
child that is gone, or a call that does not pickle, made here instead; the child reaped
on every way out.

(That a pose run's changes.png is drawn there, byte for byte the one-process PNG, is
tests/test_prefetch.py's ``test_fixes_outputs_are_the_same``.)
"""

from __future__ import annotations

import os
import signal
import sys
import time

import numpy as np
import pytest
from test_prefetch import reaped, refused_fork  # noqa: F401
from test_robust_logs import tiny  # noqa: F401

from fuzzyslam.forked import ChildCalls, ChildTraceback

pytestmark = pytest.mark.skipif(
    not sys.platform.startswith("linux"), reason="the child process needs fork (Linux)"
)


def where_and_sum(a: np.ndarray, b: np.ndarray) -> tuple[int, np.ndarray]:
    """The calling process and a + b."""
    return os.getpid(), a + b


def slow_where(seconds: float) -> int:
    """The calling process, after ``seconds``."""
    time.sleep(seconds)
    return os.getpid()


def imported(name: str) -> bool:
    """Whether the calling process has imported ``name``."""
    return name in sys.modules


class TwoArgs(Exception):
    """An exception that does not survive pickling (its ``__init__`` takes two)."""

    def __init__(self, a: str, b: str) -> None:
        super().__init__(f"{a} and {b}")


def fail(kind: str) -> None:
    """Raise a picklable or an unpicklable exception."""
    if kind == "value":
        raise ValueError("a bug in the figure")
    raise TwoArgs("one", "two")


def test_calls_are_made_in_the_child_with_their_results() -> None:
    a, b = np.arange(5.0), np.full(5, 0.5)
    with ChildCalls(warm=()) as calls:
        pid = calls.pid
        for _ in range(2):  # one child serves several calls
            where, total = calls.submit(where_and_sum, a, b).result()
            assert where == pid != os.getpid()
            np.testing.assert_array_equal(total, a + b)
    assert calls.pid is None and reaped(pid)


def test_the_child_imports_its_modules_first() -> None:
    name = "wave"  # not imported by this test process (checked)
    if name in sys.modules:
        pytest.skip(f"{name} is already imported here")
    with ChildCalls(warm=(name, "no_such_module_at_all")) as calls:
        assert calls.submit(imported, name).result()  # the failed import is left for a call to meet
    assert name not in sys.modules


@pytest.mark.parametrize("kind", ["value", "unpicklable"])
def test_the_childs_exception_is_raised_here(kind: str) -> None:
    with ChildCalls(warm=()) as calls, pytest.raises(Exception) as info:
        calls.submit(fail, kind).result()
    assert type(info.value).__name__ == ("ValueError" if kind == "value" else "TwoArgs")
    assert str(info.value) == ("a bug in the figure" if kind == "value" else "one and two")
    assert isinstance(info.value.__cause__, ChildTraceback)
    assert "in fail" in info.value.__cause__.text  # the child's traceback


def test_a_child_that_is_gone_or_a_call_that_does_not_pickle_is_made_here() -> None:
    a, b = np.ones(3), np.ones(3)
    with ChildCalls(warm=()) as calls:
        pid = calls.pid
        assert calls.submit(lambda: os.getpid()).result() == os.getpid()  # a lambda: not sent
        os.kill(pid, signal.SIGKILL)
        where, total = calls.submit(where_and_sum, a, b).result()
        assert where == os.getpid() and np.all(total == 2.0)
        assert calls.pid is None and reaped(pid)  # reaped when found gone


def test_an_exception_in_the_parent_reaps_the_child() -> None:
    with pytest.raises(KeyboardInterrupt), ChildCalls(warm=()) as calls:
        pid = calls.pid
        raise KeyboardInterrupt
    assert reaped(pid)


def test_submitted_calls_run_while_this_process_goes_on() -> None:
    """``submit`` returns at once; results come back in any order asked, each its own;
    a child killed with calls in flight leaves them to be made here."""
    a = np.arange(3.0)
    with ChildCalls(warm=()) as calls:
        pid = calls.pid
        first, second = calls.submit(where_and_sum, a, a), calls.submit(where_and_sum, a, 2 * a)
        where2, total2 = second.result()  # the first's reply is read on the way
        where1, total1 = first.result()
        assert where1 == where2 == pid and np.all(total1 == 2 * a) and np.all(total2 == 3 * a)
        late = [calls.submit(slow_where, 0.3) for _ in range(2)]
        time.sleep(0.1)  # the child is in the first call
        os.kill(pid, signal.SIGKILL)
        assert [job.result() for job in late] == [os.getpid()] * 2
    assert reaped(pid)


def test_a_refused_fork_makes_the_calls_here(refused_fork: list[int]) -> None:  # noqa: F811
    """No process to spare (``fork`` failing with EAGAIN): no child, the calls made here,
    no descriptor left open."""
    refused = refused_fork
    before = len(os.listdir("/proc/self/fd"))
    with ChildCalls(warm=()) as calls:
        assert calls.pid is None
        job = calls.submit(where_and_sum, np.ones(2), np.ones(2))
        where, total = job.result()
        assert where == os.getpid() and np.all(total == 2.0)
        assert job.result()[1] is total  # made once
    assert len(os.listdir("/proc/self/fd")) == before and refused == [1]


def test_a_child_started_early_imports_what_it_is_told_later() -> None:
    """``start`` before ``with`` forks once (``with`` keeps that child); ``preload`` has
    the child import more modules while this process goes on, not this process."""
    name = "wave"  # not imported by this test process (checked)
    if name in sys.modules:
        pytest.skip(f"{name} is already imported here")
    calls = ChildCalls(warm=())
    calls.start()
    pid = calls.pid
    assert pid is not None
    with calls:
        assert calls.pid == pid  # not forked again
        calls.preload(name, "no_such_module_at_all")
        assert calls.submit(imported, name).result()
    assert name not in sys.modules and calls.pid is None and reaped(pid)


# a pose run, noting whether the stage's modules were loaded when the first figure
# process was started, and the figure process's pid against the pids that drew
EARLY_SCRIPT = """
import os, sys
from fuzzyslam import forked
from fuzzyslam.fixes import changes

starts = []
real_start, real_draw = forked.ChildCalls.start, changes.draw_changes

def start(self):
    if self.pid is None and not starts:
        starts.append("fuzzyslam.slam.stage" in sys.modules)
    real_start(self)
    if len(starts) == 1:
        starts.append(self.pid)

def draw(*args):
    sys.stderr.write(f"drawn by {os.getpid()}\\n")
    real_draw(*args)

forked.ChildCalls.start = start
changes.draw_changes = draw
from fuzzyslam.cli import main
try:
    main(sys.argv[1:])
except SystemExit as exc:
    code = exc.code
sys.stderr.write(f"starts {starts}\\n")
"""


@pytest.mark.slow  # end to end in subprocesses (the fast tier's minute)
def test_a_pose_run_forks_its_figure_process_before_its_imports(tmp_path, tiny) -> None:  # noqa: F811
    """``run --fix pose`` forks the figure process before it imports the stage (its
    matplotlib imported while this process starts: cli/run.py), and that process draws
    changes.png; with the change detection off in the config it is closed, nothing
    drawn."""
    import ast
    import subprocess

    from fuzzyslam.slam.prefetch import wanted

    if not wanted(True):
        pytest.skip("no second CPU: no figure process")
    # fuzzyslam.fixes.changes imported by the script, not fuzzyslam.slam.stage
    env = {**os.environ, "FUZZYSLAM_NO_PROGRESS": "1"}
    off = tmp_path / "no_changes.yaml"
    off.write_text(f"extends: {tiny.config}\nfixes:\n  detect_changes: false\n", encoding="utf-8")
    outs = {}
    for name, config in (("changes", tiny.config), ("none", off)):
        outs[name] = tmp_path / name
        p = subprocess.run(
            [sys.executable, "-c", EARLY_SCRIPT, "run", str(tiny.log), "-o", str(outs[name]),
             "--config", str(config), "--map", str(tiny.dir / "fgm"), "--fix", "pose",
             "--fix-from", "0"],
            env=env, capture_output=True, text=True, cwd=tmp_path, timeout=120,
        )  # fmt: skip
        assert p.returncode == 0, p.stderr
        lines = p.stderr.splitlines()
        stage_loaded, pid = ast.literal_eval(lines[-1].removeprefix("starts "))
        assert stage_loaded is False and pid is not None
        drawn = [ln for ln in lines if ln.startswith("drawn by")]
        assert drawn == ([f"drawn by {pid}"] if name == "changes" else [])
    assert (outs["changes"] / "changes.png").is_file()
    assert not (outs["none"] / "changes.png").exists()


def test_a_run_collects_its_young_generation_less_often(monkeypatch, tmp_path) -> None:
    """``run`` runs its stage with the garbage collector's ``GC_THRESHOLD`` (its input
    process forked meanwhile inherits it), and leaves the thresholds as they were."""
    import gc

    from test_robust_logs import cli

    from fuzzyslam.slam import stage

    seen = []
    monkeypatch.setattr(stage, "run", lambda *a, **k: seen.append(gc.get_threshold()) or {})
    outer = gc.get_threshold()  # (another test may have set reproduce's for this process)
    gc.set_threshold(700, 10, 10)  # Python's default
    try:
        code, _, err = cli("run", tmp_path / "log.mcap", "-o", tmp_path / "out", "--no-prefetch")
        after = gc.get_threshold()
    finally:
        gc.set_threshold(*outer)
    assert code == 0, err
    assert seen == [(10000, 10, 10)] and after == (700, 10, 10)
