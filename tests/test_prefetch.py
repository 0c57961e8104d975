"""``run`` with its events made in a forked child process (slam/prefetch.py, issue 16).

The second implementation is the one-process run: both paths on the same logs (the
sample log's frames, a real excerpt's detections, damaged and glitched logs, a log with
the aids' rings) must write the same files byte for byte, summary.json included but for
its wall time; an error raised in the child must reach the user as the same line and exit
code; and the child must be reaped on every way out (its pid no longer a child of the
test process), and die with a parent killed outright.
"""

from __future__ import annotations

import contextlib
import ctypes
import errno
import json
import math
import os
import pickle
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from test_robust_logs import chunk_index, cli, error_lines, leftovers, tiny  # noqa: F401
from test_run_e2e import write_robot_log

from fuzzyslam import cpus
from fuzzyslam.config import load_config
from fuzzyslam.errors import ConfigError, InputError
from fuzzyslam.slam import inputs as inputs_mod
from fuzzyslam.slam import prefetch, stage
from fuzzyslam.slam.inputs import READ_STATE, open_inputs

pytestmark = pytest.mark.skipif(
    not sys.platform.startswith("linux"), reason="the child process needs fork (Linux)"
)

ROOT = Path(__file__).resolve().parents[1]
SAMPLE = ROOT / "data" / "sample.mcap"
EXCERPT = ROOT / "data" / "real" / "mrclam6_excerpt" / "log.mcap"
TIMING = ("wall_time_s", "real_time_factor")  # summary.json's only run-to-run fields


@pytest.fixture
def forks(monkeypatch) -> list[int]:
    """The pids of the child processes forked during the test (``os.fork`` counted);
    ``stage.prefetch_wanted`` answers the request as is (the CPU count aside)."""
    pids: list[int] = []
    real = os.fork

    def fork() -> int:
        pid = real()
        if pid:
            pids.append(pid)
        return pid

    monkeypatch.setattr(os, "fork", fork)
    monkeypatch.setattr(stage, "prefetch_wanted", lambda requested: requested)
    return pids


def reaped(pid: int) -> bool:
    """``pid`` is no longer a child of this process (waited for, not a zombie)."""
    try:
        os.waitpid(pid, os.WNOHANG)
    except ChildProcessError:
        return True
    return False


def run_both(tmp_path: Path, forks: list[int], *args, children: int = 1) -> tuple[Path, Path, str]:
    """``fuzzyslam run ARGS`` with --prefetch and --no-prefetch: the two output
    directories and the child's stderr; asserts both succeed, ``children`` forked with
    --prefetch (the input process; a pose run's figure process too), none without."""
    outs = {}
    errs = {}
    tmp_path.mkdir(exist_ok=True)
    for mode in ("prefetch", "no-prefetch"):
        before = len(forks)
        out = tmp_path / mode
        code, _, err = cli("run", *args, "-o", out, f"--{mode}")
        assert code == 0, err
        assert len(forks) - before == (children if mode == "prefetch" else 0)
        outs[mode], errs[mode] = out, err
    assert all(reaped(pid) for pid in forks)
    assert errs["prefetch"] == errs["no-prefetch"]  # the notes on stderr
    return outs["prefetch"], outs["no-prefetch"], errs["prefetch"]


def assert_same_outputs(a: Path, b: Path) -> dict:
    """Every file of ``a`` and ``b`` byte for byte; summary.json but for its timing."""
    names = sorted(p.name for p in a.iterdir())
    assert names == sorted(p.name for p in b.iterdir())
    for name in names:
        if name != "summary.json":
            assert (a / name).read_bytes() == (b / name).read_bytes(), name
    sa, sb = (json.loads((d / "summary.json").read_text(encoding="utf-8")) for d in (a, b))
    for key in TIMING:
        sa.pop(key), sb.pop(key)
    assert sa == sb
    return sa


# -- the same outputs ---------------------------------------------------------------------


@pytest.mark.slow
def test_sample_log_outputs_are_the_same(tmp_path: Path, forks) -> None:
    """data/sample.mcap (camera frames, encoders): the same files either way."""
    a, b, _ = run_both(tmp_path, forks, SAMPLE)
    s = assert_same_outputs(a, b)
    assert s["counts"]["frames"] > 200 and s["trajectory_rows"] > 600


@pytest.fixture
def refused_fork(monkeypatch) -> list[int]:
    """``os.fork`` failing with EAGAIN (as under RLIMIT_NPROC); one entry per refusal."""
    refused: list[int] = []

    def refuse() -> int:
        refused.append(1)
        raise OSError(errno.EAGAIN, "Resource temporarily unavailable")

    monkeypatch.setattr(os, "fork", refuse)
    return refused


@pytest.mark.slow  # end to end, about 1 s: the fast tier stays under a minute
def test_a_refused_fork_is_the_one_process_run(
    tmp_path: Path, monkeypatch, refused_fork: list[int]
) -> None:
    """No process to spare (``fork`` failing with EAGAIN, as under RLIMIT_NPROC): the run
    makes its events itself, the same files as --no-prefetch."""
    monkeypatch.setattr(stage, "prefetch_wanted", lambda requested: requested)
    refused = refused_fork
    before = len(os.listdir("/proc/self/fd"))
    for mode in ("prefetch", "no-prefetch"):
        code, _, err = cli("run", SAMPLE, "-o", tmp_path / mode, f"--{mode}")
        assert code == 0, err
    assert_same_outputs(tmp_path / "prefetch", tmp_path / "no-prefetch")
    assert len(os.listdir("/proc/self/fd")) == before and refused == [1]


@pytest.mark.slow  # end to end, about 1 s: the fast tier stays under a minute
def test_real_excerpt_outputs_are_the_same(tmp_path: Path, forks) -> None:
    """A real log's PoseArray detections (odometry latency tap, noise estimate, own
    covariances) and Odometry poses (the glitch gate): the same files either way."""
    a, b, _ = run_both(tmp_path, forks, EXCERPT, "--config", "real_detections.yaml")
    s = assert_same_outputs(a, b)
    assert s["lamp_source"].startswith("detections") and s["counts"]["associated"] > 100
    assert "noise_estimate" in s and "odometry_delay_estimate" in s


@pytest.mark.slow  # end to end in subprocesses (the fast tier's minute)
def test_glitches_and_damage_come_back_from_the_child(tmp_path: Path, forks) -> None:
    """The child's reading state (glitch counts, first problem, the reader's damage) is
    the summary's: a glitched log, a log with a corrupt chunk (its index intact) and a
    log cut mid-chunk (read by the record walk)."""
    glitch = tmp_path / "glitch.mcap"
    write_robot_log(glitch, nan_at=100, back_at=200)
    a, b, _ = run_both(tmp_path / "g", forks, glitch)
    s = assert_same_outputs(a, b)
    assert s["warnings"]["nan_odometry"] == 1 and s["warnings"]["out_of_order"] == 1
    assert s["first_warning"]

    data = bytearray(SAMPLE.read_bytes())
    chunks = chunk_index(SAMPLE)
    at = chunks[3].chunk_start_offset + 5000
    data[at : at + 64] = bytes(64)
    bad = tmp_path / "bad_chunk.mcap"
    bad.write_bytes(bytes(data))
    s = assert_same_outputs(*run_both(tmp_path / "c", forks, bad)[:2])
    assert s["log_damage"]["damaged_records"] == 1 and not s["truncated_log"]

    cut = tmp_path / "cut.mcap"
    cut.write_bytes(SAMPLE.read_bytes()[: chunks[5].chunk_start_offset + 100_000])
    s = assert_same_outputs(*run_both(tmp_path / "t", forks, cut)[:2])
    assert s["truncated_log"] and s["log_damage"]["salvaged_messages"] > 0


def test_read_state_names_everything_reading_changes(tmp_path: Path) -> None:
    """Every public field of LogInputs that reading the events changes is in READ_STATE
    (what the child sends back), and the child's state equals the one-process reading's."""
    log = tmp_path / "glitch.mcap"
    write_robot_log(log, nan_at=100, back_at=200)
    cfg = load_config("paper")
    fresh, here, there = (open_inputs(log, cfg) for _ in range(3))
    list(here.events())
    with prefetch.input_events(there, child=True) as events:
        list(events)
    public = [k for k in vars(fresh) if not k.startswith("_") and k not in ("reader", "cfg")]
    changed = {k for k in public if pickle.dumps(vars(fresh)[k]) != pickle.dumps(vars(here)[k])}
    assert changed and changed <= set(READ_STATE)
    assert here.read_state() == there.read_state()


def test_the_child_waits_for_a_parent_that_lags(monkeypatch) -> None:
    """Memory is bounded by the pipe: with its default 64 KiB buffer (less than the
    sample log's 160 KB of pickled events) the child, ahead of a parent that does not
    read, sleeps in the pipe's write; the events then all come, those of one process."""
    monkeypatch.setattr(prefetch, "PIPE_BYTES", 0)
    cfg = load_config("paper")
    inputs = open_inputs(SAMPLE, cfg)
    with prefetch.input_events(inputs, child=True) as events:
        got = [next(events)]
        pid = int(Path(f"/proc/self/task/{os.getpid()}/children").read_text().split()[0])
        t_end = time.monotonic() + 30
        while "pipe_write" not in Path(f"/proc/{pid}/wchan").read_text():
            assert time.monotonic() < t_end, "the child never filled the pipe"
            time.sleep(0.01)
        assert Path(f"/proc/{pid}/stat").read_text().split()[2] == "S"  # asleep, not done
        got += list(events)
    want = list(open_inputs(SAMPLE, cfg).events())
    assert [pickle.dumps(e) for e in got] == [pickle.dumps(e) for e in want]
    assert reaped(pid)


@pytest.mark.slow  # end to end, about 1 s: the fast tier stays under a minute
def test_progress_sees_the_same_times(tmp_path: Path, forks, monkeypatch) -> None:
    """The progress bar (stderr) is driven by the events the filter takes, in the parent:
    the same sequence of updates either way, to the end of the log."""
    seen: dict[bool, list[float]] = {True: [], False: []}
    mode = {"child": True}
    monkeypatch.setattr(
        stage.Progress, "update_to", lambda self, t: seen[mode["child"]].append(round(t, 9))
    )
    cfg = load_config("paper")
    for child in (True, False):
        mode["child"] = child
        stage.run_stage(SAMPLE, tmp_path / str(child), cfg, prefetch=child)
    assert seen[True] == seen[False] and len(seen[True]) > 1000
    opened = open_inputs(SAMPLE, cfg)
    duration = opened.end - opened.start
    assert seen[True][-1] == pytest.approx(duration, abs=0.5)


DRAWING: dict = {}  # draw_noting_pid's file and the real draw_changes (set by the test)


def draw_noting_pid(path, fgm, found, *rest) -> None:
    """``changes.draw_changes`` that notes which process drew (module-level: the figure
    process is sent it by name)."""
    with open(DRAWING["log"], "a", encoding="utf-8") as fh:
        fh.write(f"{os.getpid()}\n")
    DRAWING["draw"](path, fgm, found, *rest)


@pytest.mark.slow
@pytest.mark.parametrize("fix", ["heading", "pose"])
def test_fixes_outputs_are_the_same(tmp_path: Path, forks, tiny, fix: str, monkeypatch) -> None:  # noqa: F811
    """With a map's fixes (from the log's start: the map was frozen at its end) the child
    also makes the rings, merged in time order, the heading aid's single-ring walls
    (``HeadingFixAid.ahead``), which the aid takes instead of computing them, and, for the
    pose aid and the change detector, the FLMs (``FlmAhead``): the same files (fixes'
    CSVs, ring statistics) either way. A pose run's changes.png is drawn by a second
    child (fuzzyslam/forked.py's ``ChildCalls``), the same PNG byte for byte."""
    from fuzzyslam.fixes import changes
    from fuzzyslam.fixes.heading import HeadingFixAid
    from fuzzyslam.fixes.heading_measure import FlmSource

    taken, seeded = [], []
    real, real_seed = HeadingFixAid.take_ahead, FlmSource.seed
    monkeypatch.setattr(
        HeadingFixAid, "take_ahead", lambda self, ring, v: taken.append(1) or real(self, ring, v)
    )
    monkeypatch.setattr(
        FlmSource, "seed", lambda self, ring, flm: seeded.append(1) or real_seed(self, ring, flm)
    )
    monkeypatch.setattr(prefetch, "ahead_wanted", lambda sent, taken: True)  # every ring
    drawn_by = tmp_path / "drawn_by"
    monkeypatch.setitem(DRAWING, "log", drawn_by)
    monkeypatch.setitem(DRAWING, "draw", changes.draw_changes)
    monkeypatch.setattr(changes, "draw_changes", draw_noting_pid)
    a, b, _ = run_both(
        tmp_path, forks, tiny.log, "--config", tiny.config,
        "--map", tiny.dir / "fgm", "--fix", fix, "--fix-from", "0",
        children=2 if fix == "pose" else 1,
    )  # fmt: skip
    s = assert_same_outputs(a, b)
    assert s["rings"]["rings"] > 100 and s["aids"]
    assert len(taken) == s["rings"]["rings"]  # every ring's wall came from the child
    assert len(seeded) == (2 * s["rings"]["rings"] if fix == "pose" else 0)  # pose, changes
    if fix == "pose":  # --prefetch: drawn by the figure process; --no-prefetch: here
        assert (a / "changes.png").is_file()
        pids = [int(x) for x in drawn_by.read_text(encoding="utf-8").split()]
        assert pids == [forks[0], os.getpid()]


ALTERNATE = [0]  # alternate_ahead's count of rings (the child's copy)


def alternate_ahead(sent: int, taken: int) -> bool:
    """``prefetch.ahead_wanted`` for every other ring, whatever the parent's backlog."""
    ALTERNATE[0] += 1
    return ALTERNATE[0] % 2 == 0


@pytest.mark.slow
def test_rings_without_ahead_are_computed_by_the_aids(
    tmp_path: Path,
    forks,
    tiny,  # noqa: F811
    monkeypatch,
) -> None:
    """Rings the child leaves to the parent (its backlog low: ``ahead_wanted``) are
    computed by the aids themselves: with every other ring sent without, the same files
    as the one-process run, and half the walls taken from the child."""
    from fuzzyslam.fixes.heading import HeadingFixAid

    taken = []
    real = HeadingFixAid.take_ahead
    monkeypatch.setattr(
        HeadingFixAid, "take_ahead", lambda self, ring, v: taken.append(1) or real(self, ring, v)
    )
    monkeypatch.setattr(prefetch, "ahead_wanted", alternate_ahead)
    a, b, _ = run_both(
        tmp_path, forks, tiny.log, "--config", tiny.config,
        "--map", tiny.dir / "fgm", "--fix", "pose", "--fix-from", "0", children=2,
    )  # fmt: skip
    s = assert_same_outputs(a, b)
    assert len(taken) == s["rings"]["rings"] // 2


@pytest.mark.slow
def test_a_pose_run_that_fails_reaps_both_children(
    tmp_path: Path,
    forks,
    tiny,  # noqa: F811
    monkeypatch,
) -> None:
    """The filter failing mid-run with the input and figure processes: the error as
    without them, no output, both children killed and reaped."""
    from fuzzyslam.slam import runner as runner_mod

    real = runner_mod.SlamRunner.ring

    def ring(self, ev):
        if self.counts["rings"] == 50:
            raise RuntimeError("filter bug")
        return real(self, ev)

    monkeypatch.setattr(runner_mod.SlamRunner, "ring", ring)
    got = []
    for mode in ("prefetch", "no-prefetch"):
        code, _, err = cli(
            "run", tiny.log, "--config", tiny.config, "--map", tiny.dir / "fgm",
            "--fix", "pose", "--fix-from", "0", "-o", tmp_path / mode, f"--{mode}",
        )  # fmt: skip
        got.append((code, error_lines(err)))
        assert not (tmp_path / mode).exists() and not leftovers(tmp_path)
    assert got[0] == got[1] and got[0][0] == 1
    assert len(forks) == 2 and all(reaped(pid) for pid in forks)


def test_the_parents_backlog_is_shared_with_the_child() -> None:
    """``Taken`` counts in a mapping the child sees (a fork's copy-on-write would not);
    ``ahead_wanted`` from a backlog of ``AHEAD_BACKLOG``."""
    import mmap

    taken = prefetch.Taken(mmap.mmap(-1, prefetch.Taken.SIZE))
    r, w = os.pipe()
    pid = os.fork()
    if pid == 0:  # the child reports what it sees once the parent has counted
        os.close(w)
        os.read(r, 1)
        os._exit(taken.count % 256)
    os.close(r)
    taken.add(300)
    taken.add(3)
    os.write(w, b"x")
    os.close(w)
    _, status = os.waitpid(pid, 0)
    assert os.waitstatus_to_exitcode(status) == 303 % 256 and taken.count == 303
    n = prefetch.AHEAD_BACKLOG
    assert prefetch.ahead_wanted(303 + n, 303) and not prefetch.ahead_wanted(302 + n, 303)


# -- errors -------------------------------------------------------------------------------


class TwoArgs(Exception):
    """An exception that does not survive pickling (its ``__init__`` takes two)."""

    def __init__(self, a: str, b: str) -> None:
        super().__init__(f"{a} and {b}")


RAISED = {
    "input": lambda path: InputError(path, "frame 50 is unreadable"),
    "config": lambda path: ConfigError(path, "slam.threshold: bad"),
    "oserror": lambda path: OSError(errno.EIO, "Input/output error", str(path)),
    "bug": lambda path: ValueError("a bug in the detector"),
    "unpicklable": lambda path: TwoArgs("one", "two"),
}


@pytest.mark.parametrize("kind", sorted(RAISED))
def test_errors_in_the_child_are_the_same_line_and_code(
    tmp_path: Path, forks, monkeypatch, kind: str
) -> None:
    """An exception raised while making the events (at the 50th frame) ends the run with
    the same exit code and the same line on stderr either way, after the filter took the
    same frames before it (those of the 49 read that the stamp-order buffer had released,
    slam/inputs.py REORDER_S); nothing written, the child reaped."""
    from fuzzyslam.slam import runner as runner_mod

    real = inputs_mod.LogInputs._frame
    calls = [0]
    taken = []
    real_frame = runner_mod.SlamRunner.frame
    monkeypatch.setattr(
        runner_mod.SlamRunner, "frame", lambda self, ev: taken.append(1) or real_frame(self, ev)
    )

    def frame(self, t, msg):
        calls[0] += 1
        if calls[0] == 50:
            raise RAISED[kind](self.reader.path)
        return real(self, t, msg)

    monkeypatch.setattr(inputs_mod.LogInputs, "_frame", frame)
    got = {}
    for mode in ("prefetch", "no-prefetch"):
        calls[0] = 0
        taken.clear()
        out = tmp_path / mode
        code, stdout, err = cli("run", SAMPLE, "-o", out, f"--{mode}")
        assert not out.exists() and not leftovers(tmp_path) and stdout == ""
        got[mode] = (code, error_lines(err), len(taken))
    assert len(forks) == 1 and reaped(forks[0])
    assert got["prefetch"] == got["no-prefetch"]
    code, lines, frames = got["prefetch"]
    assert len(lines) == 1 and 0 < frames <= 49
    assert code == {"bug": 1, "unpicklable": 1}.get(kind, 3)
    if kind == "unpicklable":
        assert "TwoArgs: one and two" in lines[0]


def test_error_after_the_events_uses_the_childs_first_problem(tmp_path: Path, forks) -> None:
    """Every frame of another encoding: the run's "no usable camera frame" error quotes
    the first problem, which the child met (its reading state came back)."""
    log = tmp_path / "rgb.mcap"
    write_robot_log(log, encoding="rgb8")
    got = []
    for mode in ("prefetch", "no-prefetch"):
        code, _, err = cli("run", log, "-o", tmp_path / mode, f"--{mode}")
        got.append((code, error_lines(err)))
    assert got[0] == got[1] and got[0][0] == 3 and "rgb8" in got[0][1][0]
    assert len(forks) == 1 and reaped(forks[0])


@pytest.mark.slow  # end to end, about 1 s: the fast tier stays under a minute
def test_parent_exception_and_ctrl_c_reap_the_child(tmp_path: Path, forks, monkeypatch) -> None:
    """The filter (in the parent) failing mid-run, or Ctrl-C there: the error as without
    the child, no output, the child killed and reaped."""
    from fuzzyslam.slam import runner as runner_mod

    real = runner_mod.SlamRunner.frame
    raised: list[BaseException] = []

    def frame(self, ev):
        if self.counts["frames"] == 100:
            raise raised[-1]
        return real(self, ev)

    monkeypatch.setattr(runner_mod.SlamRunner, "frame", frame)
    for exc, code in ((KeyboardInterrupt(), 130), (RuntimeError("filter bug"), 1)):
        raised.append(exc)
        got = []
        for mode in ("prefetch", "no-prefetch"):
            c, _, err = cli("run", SAMPLE, "-o", tmp_path / mode, f"--{mode}")
            got.append((c, error_lines(err)))
            assert not (tmp_path / mode).exists() and not leftovers(tmp_path)
        assert got[0] == got[1] and got[0][0] == code
    assert len(forks) == 2 and all(reaped(pid) for pid in forks)


def test_a_child_that_dies_is_an_error_not_a_hang(tmp_path: Path, monkeypatch) -> None:
    """The child killed from outside (the OOM killer) mid-run: the parent raises one
    error naming the log, and reaps it."""
    cfg = load_config("paper")
    inputs = open_inputs(SAMPLE, cfg)
    with pytest.raises(RuntimeError, match="ended without its events"):
        with prefetch.input_events(inputs, child=True) as events:
            for k, _ev in enumerate(events):
                if k == 10:
                    pid = int(Path("/proc/self/task").joinpath(str(os.getpid()), "children")
                              .read_text().split()[-1])  # fmt: skip
                    os.kill(pid, signal.SIGKILL)
    assert reaped(pid)


def test_wanted_is_off_where_it_must_be(monkeypatch) -> None:
    """Off when not asked, with FUZZYSLAM_PREFETCH=0, on one CPU, in a daemonic process;
    reproduce's steps (stage.run without ``prefetch``) never ask."""
    import inspect

    monkeypatch.setattr(os, "sched_getaffinity", lambda pid: {0, 1})
    monkeypatch.setattr(cpus, "cgroup_quota", lambda: math.inf)
    monkeypatch.delenv(prefetch.ENV, raising=False)
    assert prefetch.wanted(True) and not prefetch.wanted(False)
    monkeypatch.setattr(cpus, "cgroup_quota", lambda: 1.5)  # a container of 1.5 CPUs
    assert not prefetch.wanted(True)
    monkeypatch.setattr(cpus, "cgroup_quota", lambda: math.inf)
    for off in ("0", "off", "no", "false"):
        monkeypatch.setenv(prefetch.ENV, off)
        assert not prefetch.wanted(True)
    monkeypatch.delenv(prefetch.ENV)
    monkeypatch.setattr(os, "sched_getaffinity", lambda pid: {1})
    assert not prefetch.wanted(True)
    monkeypatch.setattr(os, "sched_getaffinity", lambda pid: {0, 1})
    import multiprocessing.process as mpp

    monkeypatch.setattr(mpp.current_process(), "_config", {"daemon": True})
    assert not prefetch.wanted(True)
    assert inspect.signature(stage.run).parameters["prefetch"].default is False


@pytest.mark.parametrize(
    "files, expect",
    [
        ({"cpu.max": "max 100000\n"}, math.inf),
        ({"cpu.max": "150000 100000\n"}, 1.5),
        ({"cpu/cpu.cfs_quota_us": "200000\n", "cpu/cpu.cfs_period_us": "100000\n"}, 2.0),
        ({"cpu/cpu.cfs_quota_us": "-1\n", "cpu/cpu.cfs_period_us": "100000\n"}, math.inf),
        ({"cpu.max": "garbage\n"}, math.inf),
        ({}, math.inf),
    ],
)
def test_cpu_quota_reads_cgroup_v1_and_v2(tmp_path, files, expect) -> None:
    """The cgroup's CPU quota: v2's cpu.max, v1's cfs quota / period, no limit = inf."""
    for name, text in files.items():
        (tmp_path / name).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / name).write_text(text)
    assert cpus.cgroup_quota(str(tmp_path)) == expect


def test_usable_cpus_is_the_affinity_capped_by_the_quota(monkeypatch) -> None:
    """The pool's size and the input process's condition: the affinity set's size, at
    most the cgroup's quota rounded down, at least 1."""
    for affinity, quota, expect in [(4, math.inf, 4), (4, 2.5, 2), (2, 8.0, 2), (2, 0.5, 1)]:
        monkeypatch.setattr(os, "sched_getaffinity", lambda pid, n=affinity: set(range(n)))
        monkeypatch.setattr(cpus, "cgroup_quota", lambda q=quota: q)
        assert cpus.usable_cpus() == expect


def test_input_error_pickles_whole() -> None:
    """InputError (and ConfigError) come back from the child as they were raised."""
    for exc in (InputError("/x.mcap", "bad"), ConfigError("/c.yaml", "slam.x: 3")):
        back = pickle.loads(pickle.dumps(exc))
        assert type(back) is type(exc) and str(back) == str(exc)
        assert (back.path, back.problem) == (exc.path, exc.problem)


# -- signals to the parent, and the parent killed -------------------------------------------

SLOW_RUN = """
import sys, time
from fuzzyslam.slam import runner
real = runner.SlamRunner.odometry
def odometry(self, ev):
    time.sleep(0.002)
    return real(self, ev)
runner.SlamRunner.odometry = odometry
sys.argv = ["fuzzyslam", "run", sys.argv[1], "-o", sys.argv[2], "--prefetch"]
from fuzzyslam.cli import entry
entry()
"""


@contextlib.contextmanager
def subreaper():
    """This process adopts its orphaned descendants (PR_SET_CHILD_SUBREAPER): a child
    that its parent left unreaped becomes ours to find."""
    libc = ctypes.CDLL(None, use_errno=True)
    if libc.prctl(36, 1, 0, 0, 0) != 0:
        pytest.skip("prctl(PR_SET_CHILD_SUBREAPER) refused")
    try:
        yield
    finally:
        libc.prctl(36, 0, 0, 0, 0)


def started_child(proc: subprocess.Popen, timeout: float = 60.0) -> int:
    """The pid of ``proc``'s child (the input process), once it exists."""
    path = Path(f"/proc/{proc.pid}/task/{proc.pid}/children")
    t_end = time.monotonic() + timeout
    while time.monotonic() < t_end:
        kids = path.read_text().split() if path.exists() else []
        if kids:
            return int(kids[0])
        assert proc.poll() is None, proc.stderr.read() if proc.stderr else ""
        time.sleep(0.005)
    raise AssertionError("no child process")


@pytest.mark.slow
@pytest.mark.parametrize(
    ("sig", "code"), [(signal.SIGTERM, 143), (signal.SIGINT, 130), (signal.SIGKILL, -9)]
)
def test_signals_to_the_parent(tmp_path: Path, sig: int, code: int) -> None:
    """SIGTERM or SIGINT to ``fuzzyslam run`` mid-run: its exit code, nothing written,
    its child reaped by it (none left for us, its subreaper). SIGKILL: the child ends
    with it (PR_SET_PDEATHSIG, or the pipe without a reader), adopted and reaped by us."""
    env = {**os.environ, "FUZZYSLAM_NO_PROGRESS": "1", "FUZZYSLAM_PREFETCH": "1"}
    out = tmp_path / "est"
    with subreaper():
        proc = subprocess.Popen(
            [sys.executable, "-c", SLOW_RUN, str(SAMPLE), str(out)],
            env=env, cwd=tmp_path, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        )  # fmt: skip
        child = started_child(proc)
        time.sleep(0.3)  # the filter under way
        os.kill(proc.pid, sig)
        _, err = proc.communicate(timeout=60)
        assert proc.returncode == code, err
        assert not out.exists()  # (SIGKILL leaves the staging directory: no handler)
        if sig == signal.SIGKILL:
            t_end = time.monotonic() + 10
            while True:  # adopted by us, it ends: SIGKILL from the kernel (PDEATHSIG) or,
                # if the parent's end of the pipe closed first, its write's broken pipe
                pid, status = os.waitpid(child, os.WNOHANG)
                if pid:
                    assert os.WIFSIGNALED(status) or os.WEXITSTATUS(status) == 0
                    break
                assert time.monotonic() < t_end, "the child outlived its parent"
                time.sleep(0.01)
        else:
            assert len(error_lines(err)) == 1 and not leftovers(tmp_path), err
            assert reaped(child)  # the parent waited for it: never ours


@pytest.mark.slow
def test_sigterm_to_a_pose_run_reaps_both_children(tmp_path: Path, tiny) -> None:  # noqa: F811
    """SIGTERM mid-run to ``fuzzyslam run --fix pose`` with its input and figure
    processes: exit 143, one error line, nothing written, both children reaped by it."""
    env = {**os.environ, "FUZZYSLAM_NO_PROGRESS": "1", "FUZZYSLAM_PREFETCH": "1"}
    out = tmp_path / "est"
    args = ["--config", str(tiny.config), "--map", str(tiny.dir / "fgm"), "--fix", "pose",
            "--fix-from", "0"]  # fmt: skip
    script = SLOW_RUN.replace('"--prefetch"]', '"--prefetch", *sys.argv[3:]]')
    with subreaper():
        proc = subprocess.Popen(
            [sys.executable, "-c", script, str(tiny.log), str(out), *args],
            env=env, cwd=tmp_path, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        )  # fmt: skip
        path = Path(f"/proc/{proc.pid}/task/{proc.pid}/children")
        t_end = time.monotonic() + 60
        kids: list[str] = []
        while len(kids) < 2:  # the figure process, then the input process
            assert time.monotonic() < t_end and proc.poll() is None, proc.stderr.read()
            kids = path.read_text().split() if path.exists() else []
            time.sleep(0.005)
        time.sleep(0.3)  # the filter under way
        os.kill(proc.pid, signal.SIGTERM)
        _, err = proc.communicate(timeout=60)
    assert proc.returncode == 143, err
    assert len(error_lines(err)) == 1 and not out.exists() and not leftovers(tmp_path), err
    assert all(reaped(int(pid)) for pid in kids)  # the parent waited for them: never ours


def test_flm_ahead_only_for_aids_that_read_every_ring() -> None:
    """The pose aid's FLM is built ahead only when it matches every ring (the paper's
    pose fixes); the building presets match every metre or 30 deg, and so the child
    builds none for them (it would cost more than the parent saves)."""
    from types import SimpleNamespace

    from fuzzyslam.fixes.base import FlmAhead
    from fuzzyslam.fixes.pose_aid import PoseFixAid

    built = []

    class Source:
        def __call__(self, ring, mounts):
            built.append(ring)
            return "flm"

        def seed(self, ring, flm):  # pragma: no cover - only its presence matters
            pass

    paper, building = load_config("paper").fixes, load_config("real_building_scan").fixes
    assert PoseFixAid.flm_every_ring(SimpleNamespace(params=paper))
    assert not PoseFixAid.flm_every_ring(SimpleNamespace(params=building))

    class Aid(FlmAhead):
        def __init__(self, every: bool) -> None:
            self.flm_source, self.every = Source(), every

        def flm_every_ring(self) -> bool:
            return self.every

    assert Aid(True).ahead("ring", None) == ("flm",) and built == ["ring"]
    assert Aid(False).ahead("ring2", None) is None and built == ["ring"]
