"""``reproduce --scheduler``: the plan on a real Dask scheduler and two workers (issue 16),
progress lines when stderr is a file, clean reruns and ``--keep-logs``."""

from __future__ import annotations

import contextlib
import io
import json
import os
import shutil
import signal
import struct
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from conftest import shared_dir

from fuzzyslam.progress import PlanProgress
from fuzzyslam.reproduce.dask_preload import stages_loaded
from fuzzyslam.reproduce.execute import execute
from fuzzyslam.reproduce.plan import Step

BIN = Path(sys.executable).parent


def cli(
    *args: object, stderr=None, cwd: Path | None = None, env: dict | None = None
) -> subprocess.CompletedProcess:
    """``fuzzyslam ARGS`` with progress on (stderr a file or a pipe: the lines mode)."""
    env = {k: v for k, v in {**os.environ, **(env or {})}.items() if k != "FUZZYSLAM_NO_PROGRESS"}
    return subprocess.run(
        [sys.executable, "-m", "fuzzyslam", *map(str, args)],
        stdout=subprocess.PIPE,
        stderr=stderr if stderr is not None else subprocess.PIPE,
        text=True,
        cwd=cwd,
        env={**env, "MPLBACKEND": "Agg"},
    )


# --- progress lines (fast) ----------------------------------------------------------------


class Clock:
    def __init__(self) -> None:
        self.t = 100.0

    def __call__(self) -> float:
        return self.t


def test_plan_progress_lines_and_heartbeat(monkeypatch):
    """Not a terminal: a line per finished step (step, seed, seconds, done/total, where) and
    a heartbeat only after ``heartbeat_s`` seconds of silence."""
    monkeypatch.delenv("FUZZYSLAM_NO_PROGRESS", raising=False)
    out, clock = io.StringIO(), Clock()
    bar = PlanProgress(10.0, 3, "reproduce", heartbeat_s=30.0, stream=out, clock=clock)
    assert bar.mode == "lines"
    bar.line("3 steps on here; writing into /x/.out.abc.part")
    clock.t += 12.5
    bar.step_done("seed4/AB", 12.34, 1, "tcp://127.0.0.1:1234", 4.0)
    assert bar.timeout() == pytest.approx(30.0)
    clock.t += 29.0
    bar.heartbeat(1, [("seed4/C", 29.0)])  # 29 s of silence: nothing yet
    clock.t += 1.0
    bar.heartbeat(1, [("seed4/C", 30.0), ("seed4/D", 2.0)])
    lines = out.getvalue().splitlines()
    assert lines == [
        "reproduce: 3 steps on here; writing into /x/.out.abc.part",
        "reproduce: [1/3] seed4/AB done in 12.3 s (seed 4) on tcp://127.0.0.1:1234; 12 s elapsed",
        "reproduce: [1/3] running: seed4/C 30 s, seed4/D 2 s; 42 s elapsed",
    ]
    monkeypatch.setenv("FUZZYSLAM_NO_PROGRESS", "1")
    assert PlanProgress(1.0, 1, "x", stream=io.StringIO()).mode == "off"


def test_execute_writes_a_line_per_finished_step_to_a_file(tmp_path, monkeypatch, capsys):
    """Three real steps (``fuzzyslam --version``) on the local pool; stderr is not a TTY."""
    monkeypatch.delenv("FUZZYSLAM_NO_PROGRESS", raising=False)
    steps = [
        Step("seed0/a", ("--version",), (), 1.0, "version"),
        Step("seed0/b", ("--version",), ("seed0/a",), 1.0, "version"),
        Step("seed1/c", ("--version",), ("seed0/a",), 1.0, "version"),
    ]
    done = execute(steps, tmp_path, jobs=2, final=tmp_path / "final")
    assert set(done) == {"seed0/a", "seed0/b", "seed1/c"}
    assert all(r.ok and r.worker == "local" and r.pid != os.getpid() for r in done.values())
    lines = capsys.readouterr().err.splitlines()
    assert str(tmp_path) in lines[0] and "local pool of 2 processes" in lines[0]
    finished = [ln for ln in lines if " done in " in ln]
    assert [ln.split()[1] for ln in finished] == ["[1/3]", "[2/3]", "[3/3]"]
    assert finished[0].split()[2] == "seed0/a" and "(seed 0)" in finished[0]


def test_rerun_refuses_a_directory_that_is_not_a_reproduce_output(tmp_path):
    out = tmp_path / "mine"
    out.mkdir()
    (out / "thesis.tex").write_text("keep me")
    p = cli("reproduce", "--quick", "--seeds", "1", "-o", out)
    assert p.returncode == 3
    lines = [ln for ln in p.stderr.splitlines() if ln.startswith("fuzzyslam:")]
    assert len(lines) == 1 and "not a reproduce output" in lines[0], p.stderr
    assert (out / "thesis.tex").read_text() == "keep me"


@pytest.mark.slow  # end to end in subprocesses (the fast tier's minute)
def test_scheduler_unreachable_is_one_line(tmp_path):
    """One line, nothing written; Dask's connect timeout is taken from the environment."""
    p = cli("reproduce", "--quick", "--seeds", "1", "-o", tmp_path / "o",
            "--scheduler", "tcp://127.0.0.1:9",
            env={"DASK_DISTRIBUTED__COMM__TIMEOUTS__CONNECT": "1s"})  # fmt: skip
    assert p.returncode == 3
    lines = [ln for ln in p.stderr.splitlines() if ln.startswith("fuzzyslam:")]
    assert len(lines) == 1 and "Dask scheduler" in lines[0], p.stderr
    assert "after 1 s" in lines[0], lines[0]
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("command", ["reproduce", "sweep"])
def test_malformed_scheduler_address_and_ship_files_alone_are_usage_errors(tmp_path, command):
    """A malformed ``--scheduler`` (no port, a scheme Dask has not, no host, a port out of
    range) is a usage error naming the option, before anything connects (was exit 3, "what
    answered is not a Dask scheduler", though nothing answered); ``--ship-files`` without
    ``--scheduler`` too (was accepted and ignored). One line, exit 2, nothing written."""
    args = (["reproduce", "--quick", "--seeds", "1"] if command == "reproduce" else
            ["sweep", "quick", "--set", "robot.wheel_noise=0.01", "--seeds", "1"])  # fmt: skip
    cases = [(["--scheduler", a], "--scheduler") for a in
             ("nonsense", "http://127.0.0.1:8786", "tcp://127.0.0.1", "tcp://:8786",
              "tcp://127.0.0.1:99999", "127.0.0.1:87x6")]  # fmt: skip
    cases.append((["--ship-files"], "--ship-files needs --scheduler"))
    for extra, why in cases:
        p = cli(*args, "-o", tmp_path / "o", *extra)
        lines = [ln for ln in p.stderr.splitlines() if ln.strip()]
        assert p.returncode == 2 and len(lines) == 1, (extra, p.stderr)
        assert "usage error" in lines[0] and why in lines[0], lines[0]
        assert not (tmp_path / "o").exists()


def test_well_formed_scheduler_addresses_pass():
    """The forms Dask reads: tcp by default, its schemes, a name, IPv6 in brackets."""
    from fuzzyslam.cli import SCHEDULER_ADDRESS

    for a in ("tcp://10.0.0.1:8786", "10.0.0.1:8786", "tls://node-3.cluster:8786",
              "ws://[::1]:8786", "ucx://h_1:1", "inproc://10.0.0.1/123/1"):  # fmt: skip
        assert SCHEDULER_ADDRESS.convert(a, None, None) == a


@pytest.mark.slow  # waits out the connect timeout and its margin: 7 s
def test_an_address_that_is_no_dask_scheduler_is_one_line(tmp_path):
    """A server that accepts the connection and says nothing (a dashboard's port, any HTTP
    server) held the client's handshake for ever: now one line and exit 3 after the
    connect timeout and its margin; one that answers garbage is refused alike."""
    import socket
    import threading

    from fuzzyslam.reproduce.execute import CONNECT_MARGIN_S

    def serve(sock: socket.socket, reply: bytes) -> None:
        while True:
            try:
                conn, _ = sock.accept()
            except OSError:
                return
            conn.sendall(reply)  # then keeps the connection open, silent

    http = (
        b"HTTP/1.1 400 Bad Request\r\nContent-Type: text/plain\r\n"
        b"Content-Length: 11\r\nConnection: close\r\n\r\nBad Request"
    )  # a proxy's
    for reply, why in ((b"", "no Dask scheduler answered"),
                       (b"\xff" * 64, "not a Dask scheduler"),
                       (http, "not a Dask scheduler")):  # fmt: skip
        sock = socket.create_server(("127.0.0.1", 0))
        threading.Thread(target=serve, args=(sock, reply), daemon=True).start()
        port = sock.getsockname()[1]
        t0 = time.monotonic()
        p = cli("reproduce", "--quick", "--seeds", "1", "-o", tmp_path / "o",
                "--scheduler", f"tcp://127.0.0.1:{port}",
                env={"DASK_DISTRIBUTED__COMM__TIMEOUTS__CONNECT": "1s"})  # fmt: skip
        sock.close()
        lines = [ln for ln in p.stderr.splitlines() if ln.strip()]
        assert p.returncode == 3 and len(lines) == 1 and why in lines[0], p.stderr
        # the client's own reading of the reply (numpy's "Unable to allocate 3.07 EiB for
        # an array ...") is no message of ours
        assert "allocate" not in lines[0] and "array" not in lines[0], lines[0]
        assert time.monotonic() - t0 < 1.0 + CONNECT_MARGIN_S + 10.0
        assert not (tmp_path / "o").exists()


def test_stale_temporary_outputs_are_removed(tmp_path):
    """What a killed step left (a staging directory, a file's temporary) goes once every
    step has succeeded; the outputs stay."""
    from fuzzyslam.reproduce.execute import remove_stale_parts

    (tmp_path / "seed0" / "D").mkdir(parents=True)
    (tmp_path / "seed0" / "D" / "trajectory.tum").write_text("x")
    stale = tmp_path / "seed0" / ".D.abc123.part"
    stale.mkdir()
    (stale / ".estimates.mcap.xyz.part").write_bytes(b"half")
    (tmp_path / ".paper.mcap.q1w2.part").write_bytes(b"half")
    gone = remove_stale_parts(tmp_path)
    assert sorted(p.name for p in gone) == [".D.abc123.part", ".paper.mcap.q1w2.part"]
    left = sorted(p.relative_to(tmp_path).as_posix() for p in tmp_path.rglob("*"))
    assert left == ["seed0", "seed0/D", "seed0/D/trajectory.tum"]


@pytest.mark.slow
def test_sweep_logs_bad_arguments_are_one_line(tmp_path):
    """--logs with --seeds (a usage error: exit 2), a glob matching nothing, or a ros2 bag
    folder split in two files (exit 3): one line, nothing written."""
    (tmp_path / "a.mcap").write_bytes(b"")
    bag = tmp_path / "bags" / "split"
    bag.mkdir(parents=True)
    (bag / "metadata.yaml").write_text("rosbag2_bagfile_information: {}\n", encoding="utf-8")
    for name in ("split_0.mcap", "split_1.mcap"):
        (bag / name).write_bytes(b"")
    cases = ((["--seeds", "2", "--logs", tmp_path / "*.mcap"], "not both", 2),
             (["--logs", tmp_path / "none" / "*.mcap"], "matches no file", 3),
             (["--logs", tmp_path / "bags" / "*"], "split into 2 files", 3))  # fmt: skip
    for extra, why, code in cases:
        p = cli("sweep", "sample.yaml", "--set", "robot.wheel_noise=0.01", *extra,
                "-o", tmp_path / "sw")  # fmt: skip
        lines = [ln for ln in p.stderr.splitlines() if ln.startswith("fuzzyslam")]
        assert p.returncode == code and len(lines) == 1 and why in lines[0], p.stderr
        assert not (tmp_path / "sw").exists()


# --- a real Dask cluster (slow) -------------------------------------------------------------


@pytest.fixture(scope="module")
def dask_cluster(tmp_path_factory):
    """``dask scheduler`` and two ``dask worker`` processes on 127.0.0.1, as the README's
    recipe starts them, once for this module's tests (each test's outputs are in its own
    directory); yields (address, {worker address: pid}, the workers' homes' parent)."""
    from distributed import Client

    tmp_path = tmp_path_factory.mktemp("dask")
    sched_file = tmp_path / "scheduler.json"
    logs = tmp_path / "dask-logs"
    logs.mkdir()
    env = {**os.environ, "MPLBACKEND": "Agg"}
    procs = [
        subprocess.Popen(
            [BIN / "dask", "scheduler", "--host", "127.0.0.1", "--port", "0",
             "--no-dashboard", "--scheduler-file", sched_file],
            stdout=subprocess.DEVNULL, stderr=open(logs / "scheduler.log", "w"), env=env,
            start_new_session=True,  # a process group of its own, ended whole below
        )
    ]  # fmt: skip
    try:
        for _ in range(300):
            if sched_file.is_file() and sched_file.stat().st_size > 0:
                break
            time.sleep(0.1)
        for i in range(2):  # each in a working directory (and temp directory) of its own
            home = tmp_path / f"worker{i}"
            home.mkdir()
            procs.append(subprocess.Popen(
                [BIN / "dask", "worker", "--scheduler-file", sched_file, "--nthreads", "1",
                 "--nworkers", "1", "--host", "127.0.0.1", "--no-dashboard",
                 "--local-directory", home,
                 # the first worker with the README's preload, the second without
                 *(["--preload", "fuzzyslam.reproduce.dask_preload"] if i == 0 else [])],
                stdout=subprocess.DEVNULL, stderr=open(logs / f"worker{i}.log", "w"),
                env={**env, "TMPDIR": str(home)}, cwd=home, start_new_session=True,
            ))  # fmt: skip
        with Client(scheduler_file=str(sched_file), timeout=30) as client:
            client.wait_for_workers(2, timeout=60)
            pids = client.run(os.getpid)
            address = client.scheduler.address
            # before any step: which workers hold the stages' modules already
            loaded = client.run(stages_loaded)
            (tmp_path / "stages_at_start.json").write_text(json.dumps(loaded))
        yield address, pids, tmp_path
    finally:
        # SIGTERM to each process's own group: a worker's nanny and the worker process it
        # started (SIGTERM to the nanny alone: it waits 8 s for a worker that ran a step,
        # then kills it; an 8 s teardown of the module's last test)
        for p in reversed(procs):
            with contextlib.suppress(ProcessLookupError):
                os.killpg(p.pid, signal.SIGTERM)
        for p in reversed(procs):
            try:
                p.wait(timeout=20)
            except subprocess.TimeoutExpired:
                os.killpg(p.pid, signal.SIGKILL)
                p.wait()


@pytest.mark.slow
def test_dask_preload_imports_the_stages_at_worker_start(dask_cluster):
    """``--preload fuzzyslam.reproduce.dask_preload``: the worker started with it holds the
    stages before its first step; the one started without it does not."""
    _, pids, tmp_path = dask_cluster
    loaded = json.loads((tmp_path / "stages_at_start.json").read_text())
    assert sorted(loaded) == sorted(pids) and sorted(loaded.values()) == [False, True]


TIMING = ("seconds", "wall_time_s", "real_time_factor", "wall_s")


def _untimed(obj):
    """A JSON value without its timing fields (which differ between any two runs)."""
    if isinstance(obj, dict):
        return {k: _untimed(v) for k, v in obj.items() if not any(t in k for t in TIMING)}
    if isinstance(obj, list):
        return [_untimed(v) for v in obj]
    return obj


def _table(report: Path) -> list[str]:
    """The report's table rows, without the Cost rows (times)."""
    rows = [ln for ln in report.read_text().splitlines() if ln.startswith("| ")]
    return [ln for ln in rows if not ln.startswith(("| Cost", "| time"))]


LOCAL = ("reproduce", "--quick", "--paper-only", "--seeds", "2")


@pytest.fixture(scope="module")
def local_run(tmp_path_factory) -> Path:
    """``reproduce --quick --paper-only --seeds 2 --keep-logs`` on the local pool, once per
    test run (conftest.shared_dir): the reference both Dask runs are compared with."""

    def build(root: Path) -> None:
        p = cli(*LOCAL, "-o", root / "local", "--keep-logs")
        assert p.returncode == 0, p.stderr

    return shared_dir(tmp_path_factory, "dask-local-reproduce", build) / "local"


@pytest.mark.slow
def test_reproduce_on_dask_equals_the_local_run(tmp_path, dask_cluster, local_run):
    """``reproduce --quick --paper-only --seeds 2`` locally and with ``--scheduler``: same
    table, same files byte for byte (timing fields aside), every step on the two workers,
    a progress line per finished step in a redirected stderr, the old output replaced
    whole, the logs removed for two seeds unless ``--keep-logs``."""
    address, worker_pids, _ = dask_cluster
    args = LOCAL
    local, remote = local_run, tmp_path / "remote"
    # a previous reproduce output with a seed the new run does not have
    (remote / "seed7").mkdir(parents=True)
    (remote / "seed7" / "paper.mcap").write_bytes(b"old")
    (remote / "results.json").write_text("{}")
    with open(tmp_path / "stderr.txt", "w") as err:
        p = cli(*args, "-o", remote, "--scheduler", address, stderr=err)
    stderr = (tmp_path / "stderr.txt").read_text()
    assert p.returncode == 0, stderr

    # progress: the temporary tree named first, then one line per finished step
    results = json.loads((remote / "results.json").read_text())
    n = len(results["steps"])
    lines = stderr.splitlines()
    assert ".remote." in lines[0] and ".part" in lines[0] and address in lines[0]
    done = [ln for ln in lines if " done in " in ln]
    assert [ln.split()[1] for ln in done] == [f"[{i}/{n}]" for i in range(1, n + 1)]
    assert {ln.split()[2] for ln in done} == {s["key"] for s in results["steps"]}

    # every step ran on one of the two workers (address and pid), and both worked
    used = {(s["worker"], s["pid"]) for s in results["steps"]}
    assert used <= set(worker_pids.items())
    assert {w for w, _ in used} == set(worker_pids)
    assert results["info"]["engine"] == f"dask {address}"

    # clean outputs: old seed gone; logs removed for two seeds, kept with --keep-logs
    assert not (remote / "seed7").exists()
    assert not list(remote.glob("seed*/*.mcap"))
    assert len(list(local.glob("seed*/*.mcap"))) == 4

    # same results: the table rows, and every other file byte for byte
    assert _table(remote / "report.md") == _table(local / "report.md")
    files = sorted(f.relative_to(remote) for f in remote.glob("seed*/**/*") if f.is_file())
    assert len(files) > 20
    for rel in files:
        a, b = (local / rel).read_bytes(), (remote / rel).read_bytes()
        if rel.name == "summary.json":
            assert _untimed(json.loads(a)) == _untimed(json.loads(b)), rel
        else:
            assert a == b, rel
    ra = json.loads((local / "results.json").read_text())
    untimed_rows = [[r for r in res["rows"] if r["group"] != "Cost"] for res in (ra, results)]
    assert untimed_rows[0] == untimed_rows[1]


@pytest.mark.slow
def test_an_output_directory_a_worker_cannot_see_is_one_line(tmp_path, dask_cluster):
    """Workers must share the filesystem: a plan whose directory a worker does not see (a
    path absent there) stops with one line naming the path and the worker."""
    from fuzzyslam.errors import InputError
    from fuzzyslam.reproduce.execute import StepFailed

    address, workers, _ = dask_cluster
    root = tmp_path / "only-on-the-client"
    with pytest.raises(StepFailed) as exc:
        execute([Step("seed0/a", ("--version",), (), 1.0)], root, scheduler=address)
    msg = str(exc.value)
    assert "\n" not in msg and "is not visible on the worker" in msg
    assert str(root) in msg and any(w in msg for w in workers)
    assert exc.value.exit_code == InputError.exit_code
    assert "--ship-files" in msg  # what to do about it

    # reproduce's steps run in a temporary directory beside OUTDIR: the line names OUTDIR,
    # the user's path, never the temporary .part name (it did)
    staged = tmp_path / "elsewhere" / ".out.ib08f1q6.part"
    with pytest.raises(StepFailed) as exc:
        execute([Step("seed0/a", ("--version",), (), 1.0)], staged, scheduler=address,
                final=Path("results/out"))  # fmt: skip
    msg = str(exc.value)
    assert "results/out: the output directory is not visible on the worker" in msg, msg
    assert ".part" not in msg and "ib08f1q6" not in msg, msg


@pytest.mark.slow
def test_reproduce_ships_the_files_with_the_tasks(tmp_path, dask_cluster, local_run):
    """``--ship-files``: each step's inputs go to a worker as bytes, it runs in a private
    directory under the worker's own temp directory, and its outputs come back to the
    client; the same files byte for byte as the local run (timings aside), every step on
    the two workers (each in a working directory of its own).

    The local run is the shared two-seed one (``local_run``, logs kept); ``--seeds 1``
    here is its seed 0 (a seed's steps read only that seed's files), so the table's
    values are the local run's seed-0 values and seed0/ is the same files."""
    address, worker_pids, homes = dask_cluster
    args = ("reproduce", "--quick", "--paper-only", "--seeds", "1")
    local, remote = local_run, tmp_path / "remote"
    p = cli(*args, "-o", remote, "--scheduler", address, "--ship-files")
    assert p.returncode == 0, p.stderr
    assert "Warning" not in p.stderr and "Traceback" not in p.stderr  # one line per step
    results = json.loads((remote / "results.json").read_text())
    used = {(s["worker"], s["pid"]) for s in results["steps"]}
    assert used <= set(worker_pids.items()) and {w for w, _ in used} == set(worker_pids)
    ours = json.loads((local / "results.json").read_text())
    assert len(results["rows"]) == len(ours["rows"])
    for a, b in zip(ours["rows"], results["rows"], strict=True):
        assert (a["group"], a["measure"]) == (b["group"], b["measure"])
        if a["group"] != "Cost":  # times
            assert b["values"] == a["values"][:1], a["measure"]
    files = sorted(f.relative_to(local) for f in local.glob("seed0/**/*") if f.is_file())
    assert len(files) > 20
    assert files == sorted(f.relative_to(remote) for f in remote.glob("seed*/**/*")
                           if f.is_file())  # fmt: skip
    for rel in files:
        a, b = (local / rel).read_bytes(), (remote / rel).read_bytes()
        if rel.name == "summary.json":
            assert _untimed(json.loads(a)) == _untimed(json.loads(b)), rel
        else:
            assert a == b, rel
    # the workers' private step directories are gone; no output was written beside them
    assert not list(homes.glob("worker*/fuzzyslam-step.*"))


@pytest.mark.slow
def test_a_lost_worker_s_replacement_is_not_counted_as_a_step_at_once(tmp_path):
    """One worker (under its nanny) killed after the first finished step: Dask runs the
    step again on the worker the nanny starts in its place, at a new address. results.json
    lists both workers, but ``info.jobs`` and report.md say 1 step at once, the most that
    ran (they said 2 "worker processes": the workers that ran a step were counted)."""
    sched_file = tmp_path / "scheduler.json"
    env = {k: v for k, v in os.environ.items() if k != "FUZZYSLAM_NO_PROGRESS"}
    env["MPLBACKEND"] = "Agg"
    procs = [subprocess.Popen(
        [BIN / "dask", "scheduler", "--host", "127.0.0.1", "--port", "0", "--no-dashboard",
         "--scheduler-file", sched_file],
        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=env, start_new_session=True,
    )]  # fmt: skip
    try:
        for _ in range(300):
            if sched_file.is_file() and sched_file.stat().st_size > 0:
                break
            time.sleep(0.1)
        procs.append(subprocess.Popen(
            [BIN / "dask", "worker", "--scheduler-file", sched_file, "--nthreads", "1",
             "--nworkers", "1", "--host", "127.0.0.1", "--no-dashboard",
             "--local-directory", tmp_path],
            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=env,
            start_new_session=True,
        ))  # fmt: skip
        from distributed import Client

        with Client(scheduler_file=str(sched_file), timeout=30) as client:
            client.wait_for_workers(1, timeout=60)
            address = client.scheduler.address
            (first_pid,) = client.run(os.getpid).values()
        log = tmp_path / "stderr.txt"
        with open(log, "w") as err:
            run = _reproduce_past_a_step(address, tmp_path / "out", log, err, env)
            os.kill(first_pid, signal.SIGKILL)  # the worker process; its nanny starts another
            run.wait(timeout=600)
        assert run.returncode == 0, log.read_text()
        results = json.loads((tmp_path / "out" / "results.json").read_text())
        assert len({s["worker"] for s in results["steps"]}) == 2  # the lost one, its heir
        assert results["info"]["jobs"] == 1
        assert "at most 1 step at once" in (tmp_path / "out" / "report.md").read_text()
    finally:
        for p in reversed(procs):
            with contextlib.suppress(ProcessLookupError):
                os.killpg(p.pid, signal.SIGKILL)
            p.wait()


def _reproduce_past_a_step(address: str, out: Path, log: Path, err, env: dict):
    """``reproduce --quick --paper-only --seeds 1`` on the cluster at ``address``, its
    stderr into ``log`` (open as ``err``), returned once its first step has finished (or
    it has ended)."""
    run = subprocess.Popen(
        [sys.executable, "-m", "fuzzyslam", "reproduce", "--quick", "--paper-only",
         "--seeds", "1", "-o", out, "--scheduler", address],
        stdout=subprocess.PIPE, stderr=err, env=env,
    )  # fmt: skip
    for _ in range(600):
        if "[1/" in log.read_text() or run.poll() is not None:
            break
        time.sleep(0.1)
    return run


@pytest.mark.slow
def test_a_scheduler_that_goes_away_is_one_line(tmp_path):
    """The scheduler killed while steps run: one line naming it, exit 3 (was an internal
    error with Dask's tracebacks), and nothing left of the output."""
    sched_file = tmp_path / "scheduler.json"
    env = {k: v for k, v in os.environ.items() if k != "FUZZYSLAM_NO_PROGRESS"}
    env["MPLBACKEND"] = "Agg"  # progress lines on: the first finished step is seen
    sched = subprocess.Popen(
        [BIN / "dask", "scheduler", "--host", "127.0.0.1", "--port", "0", "--no-dashboard",
         "--scheduler-file", sched_file],
        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=env, start_new_session=True,
    )  # fmt: skip
    worker = None
    try:
        for _ in range(300):
            if sched_file.is_file() and sched_file.stat().st_size > 0:
                break
            time.sleep(0.1)
        worker = subprocess.Popen(
            [BIN / "dask", "worker", "--scheduler-file", sched_file, "--nthreads", "1",
             "--host", "127.0.0.1", "--no-dashboard", "--local-directory", tmp_path],
            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=env,
            start_new_session=True,
        )  # fmt: skip
        from distributed import Client

        with Client(scheduler_file=str(sched_file), timeout=30) as client:
            client.wait_for_workers(1, timeout=60)
            address = client.scheduler.address
        log = tmp_path / "stderr.txt"
        with open(log, "w") as err:
            run = _reproduce_past_a_step(address, tmp_path / "out", log, err, env)
            os.killpg(sched.pid, signal.SIGKILL)
            run.wait(timeout=120)
        lines = [ln for ln in log.read_text().splitlines() if ln.startswith("fuzzyslam:")]
        assert run.returncode == 3, log.read_text()
        assert len(lines) == 1 and "the Dask cluster failed" in lines[0], log.read_text()
        assert "Traceback" not in log.read_text()
        assert not (tmp_path / "out").exists() and not list(tmp_path.glob(".out.*"))
    finally:
        for p in (worker, sched):
            if p is not None:
                with contextlib.suppress(ProcessLookupError):
                    os.killpg(p.pid, signal.SIGKILL)
                p.wait()


# --- sweep (slow) ---------------------------------------------------------------------------


# 2 seeds: the table's statistics (mean, sd, min, max) are checked against numpy's over
# the seeds' metrics.json, which two seeds test as well as three (a third cost 9 steps);
# 2 values: each row is checked on its own, and a second row tests the grid as well as a
# third (which cost 6 steps)
SWEEP = ("sweep", "sample.yaml", "--set", "robot.wheel_noise=0.002,0.03", "--seeds", "2")
STEPS = 12  # 2 values x 2 seeds x (simulate, run, evaluate)


def _stats(values: list[float]) -> tuple[float, float, float, float]:
    """Mean, sample sd, min, max: the second computation of the sweep's table (numpy)."""
    a = np.asarray(values, dtype=float)
    return float(a.mean()), float(a.std(ddof=1)), float(a.min()), float(a.max())


@pytest.mark.slow
def test_sweep_killed_halfway_goes_on_and_skips_the_finished_steps(tmp_path):
    """2 values x 2 seeds of sample.yaml (12 steps); SIGTERM after 4 finished steps; the
    rerun skips them (counted) and writes the table and the figure; every row's mean, sd,
    min and max equal numpy's over the two evaluations' metrics.json."""
    out = tmp_path / "sw"
    env = {k: v for k, v in os.environ.items() if k != "FUZZYSLAM_NO_PROGRESS"}
    proc = subprocess.Popen([sys.executable, "-m", "fuzzyslam", *SWEEP, "-o", str(out)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env={**env, "MPLBACKEND": "Agg"})  # fmt: skip
    finished = 0
    assert proc.stderr is not None
    for line in proc.stderr:
        finished += " done in " in line
        if finished == 4:
            proc.send_signal(signal.SIGTERM)
            break
    _, rest = proc.communicate(timeout=120)
    assert proc.returncode == 143
    # the idle pool worker leaves quietly: the one line of a termination ends stderr
    assert "Traceback" not in rest
    assert rest.splitlines()[-1] == "fuzzyslam: terminated; no partial outputs were kept"
    recorded = len(list((out / ".sweep").glob("*.json")))
    assert recorded >= 4
    assert not (out / "sweep.md").exists()
    p = cli(*SWEEP, "-o", out)
    assert p.returncode == 0, p.stderr
    summary = json.loads(p.stdout)
    assert summary["steps"] == STEPS and summary["skipped"] == recorded
    assert summary["ran"] + summary["skipped"] == STEPS

    # the table: a row per value, each statistic recomputed from the per-seed files
    assert [r["values"] for r in summary["rows"]] == [{"robot.wheel_noise": v}
                                                      for v in (0.002, 0.03)]  # fmt: skip
    table = (out / "sweep.md").read_text().splitlines()
    rows = [ln for ln in table if ln.startswith("| 0.")]
    assert [ln.split(" | ")[0] for ln in rows] == ["| 0.002", "| 0.03"]
    for i, (r, line) in enumerate(zip(summary["rows"], rows, strict=True)):
        overall = [json.loads((out / f"g{i}/seed{s}/eval/metrics.json").read_text())
                   ["phases"]["overall"] for s in range(2)]  # fmt: skip
        expect = {
            "mean position error (cm)": _stats([100 * o["position_m"]["mean"] for o in overall]),
            "max position error (cm)": _stats([100 * o["position_m"]["max"] for o in overall]),
            "mean heading error (deg)": _stats([o["heading_deg"]["mean"] for o in overall]),
        }
        cells = line.strip("| ").split(" | ")[1:]
        for cell, (m, (mean, sd, lo, hi)) in zip(cells, expect.items(), strict=True):
            st = r["measures"][m]
            assert st["n"] == 2
            assert [st["mean"], st["sd"], st["min"], st["max"]] == pytest.approx(
                [mean, sd, lo, hi], rel=1e-12
            )
            assert cell == f"{mean:.2f}, {sd:.2f} [{lo:.2f}, {hi:.2f}]"
    # the seeds differ, so the statistics are not degenerate
    assert all(r["measures"]["mean position error (cm)"]["sd"] > 0 for r in summary["rows"])

    # one figure for the one swept key, a PNG of at least 150 dpi
    assert summary["figures"] == [str(out / "sweep_robot.wheel_noise.png")]
    png = (out / "sweep_robot.wheel_noise.png").read_bytes()
    assert png[:8] == b"\x89PNG\r\n\x1a\n"
    width, height = struct.unpack(">II", png[16:24])
    assert width >= 1500 and height >= 500  # 13.8 x 4 inches at 150 dpi

    # a third run changes nothing: every step skipped, the same table
    p = cli(*SWEEP, "-o", out)
    assert json.loads(p.stdout)["skipped"] == STEPS
    assert (out / "sweep.md").read_text().splitlines()[4:] == table[4:]


@pytest.mark.slow
def test_ctrl_c_to_a_sweeps_process_group_is_one_line_and_leaves_nothing(tmp_path):
    """Ctrl-C at a terminal reaches every process of the group: the sweep (one seed: a
    chain of 3 steps on 2 workers, so one worker is always idle) stops its running step,
    which removes its temporary outputs; exit 130, stderr ends with the one line, no
    traceback, no process of the group left and no temporary file."""
    out = tmp_path / "sw"
    env = {k: v for k, v in os.environ.items() if k != "FUZZYSLAM_NO_PROGRESS"}
    args = ("sweep", "sample.yaml", "--set", "robot.wheel_noise=0.01", "--seeds", "1")
    proc = subprocess.Popen([sys.executable, "-m", "fuzzyslam", *args, "-j", "2", "-o", str(out)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env={**env, "MPLBACKEND": "Agg"}, start_new_session=True)  # fmt: skip
    assert proc.stderr is not None
    for line in proc.stderr:
        if " done in " in line:  # the log is simulated; the run step has started
            os.killpg(proc.pid, signal.SIGINT)
            break
    _, rest = proc.communicate(timeout=60)
    assert proc.returncode == 130, rest
    assert "Traceback" not in rest
    assert rest.splitlines()[-1] == "fuzzyslam: interrupted; no partial outputs were kept"
    deadline = time.monotonic() + 10
    while True:  # the pool's workers are reaped by the sweep before it exits
        try:
            os.killpg(proc.pid, 0)
        except ProcessLookupError:
            break
        assert time.monotonic() < deadline, "a process of the sweep's group outlived it"
        time.sleep(0.05)
    assert not [p for p in tmp_path.rglob("*") if ".part" in p.name]


@pytest.mark.slow
def test_sweep_over_recorded_logs(tmp_path):
    """--logs: the sample log in two folders, one with a truth.tum beside it (evaluated
    aligned against it), one evaluated against its own ground truth; 2 values x 2 logs;
    a changed log is run again, the other steps are skipped."""
    import shutil

    from fuzzyslam.streams.messages import pose_of
    from fuzzyslam.streams.reader import LogReader
    from fuzzyslam.streams.tum import format_tum

    sample = Path(__file__).resolve().parents[1] / "data" / "sample.mcap"
    for d in ("a", "b"):
        (tmp_path / "runs" / d).mkdir(parents=True)
        shutil.copyfile(sample, tmp_path / "runs" / d / "log.mcap")
    msgs = list(LogReader(sample).messages(["/ground_truth/odom"]))
    t = np.array([m.t for m in msgs])
    poses = np.array([pose_of(m.msg.pose.pose) for m in msgs])
    (tmp_path / "runs" / "b" / "truth.tum").write_text(format_tum(t, poses))
    args = ("sweep", "sample.yaml", "--set", "slam.use_encoders=true,false",
            "--logs", tmp_path / "runs" / "*" / "log.mcap", "-o", tmp_path / "sw")  # fmt: skip
    p = cli(*args)
    assert p.returncode == 0, p.stderr
    summary = json.loads(p.stdout)
    assert summary["steps"] == 8 and summary["ran"] == 8 and summary["seeds"] == []
    units = ["log0_a_log", "log1_b_log"]
    for r in summary["rows"]:
        assert sorted(r["runs"]) == units and r["measures"]["mean position error (cm)"]["n"] == 2
    records = tmp_path / "sw" / ".sweep"
    cmd = json.loads((records / "g0__log1_b_log__eval.json").read_text())["command"]
    assert "truth.tum" in cmd and "--align" in cmd
    cmd = json.loads((records / "g0__log0_a_log__eval.json").read_text())["command"]
    assert "truth.tum" not in cmd and "logs/log0_a_log/log.mcap" in cmd  # a link in OUTDIR
    link = tmp_path / "sw" / "logs" / "log0_a_log" / "log.mcap"
    assert link.resolve() == (tmp_path / "runs" / "a" / "log.mcap").resolve()
    assert (tmp_path / "sw" / "sweep_slam.use_encoders.png").is_file()
    # a changed log: its steps run again, the other log's are skipped
    with open(tmp_path / "runs" / "a" / "log.mcap", "ab") as f:
        f.write(b"\0")  # after the MCAP footer: still a readable log, other bytes
    p = cli(*args)
    assert p.returncode == 0, p.stderr
    again = json.loads(p.stdout)
    assert again["ran"] == 4 and again["skipped"] == 4


@pytest.mark.slow
def test_sweep_over_logs_on_dask_equals_a_local_run_elsewhere(tmp_path, dask_cluster):
    """``sweep --logs 'runs/*/log.mcap'`` on the local pool in one folder, and in another
    with ``--scheduler`` (the workers in working directories of their own: the steps
    read the logs through OUTDIR's links, on the shared filesystem) and with
    ``--scheduler --ship-files`` (the links' bytes travel with the tasks): the same
    files, byte for byte but the timing fields, and every step on the workers."""
    from test_sweep_repeatable import MICRO, _snapshot

    address, worker_pids, _ = dask_cluster
    log = tmp_path / "micro.mcap"
    assert cli("simulate", MICRO, "-o", log).returncode == 0
    for d in ("L", "D"):
        for run in ("a", "b"):
            (tmp_path / d / "runs" / run).mkdir(parents=True)
            shutil.copyfile(log, tmp_path / d / "runs" / run / "log.mcap")
    args = ("sweep", MICRO, "--set", "slam.use_encoders=true,false", "--logs",
            "runs/*/log.mcap")  # fmt: skip
    p = cli(*args, "-o", "sw", cwd=tmp_path / "L")
    assert p.returncode == 0, p.stderr
    local = _snapshot(tmp_path / "L" / "sw")
    assert len([k for k in local if k.endswith("metrics.json")]) == 4
    for out, extra in (("sw", ()), ("shipped", ("--ship-files",))):
        p = cli(*args, "-o", out, "--scheduler", address, *extra, cwd=tmp_path / "D")
        assert p.returncode == 0, p.stderr
        done = [ln for ln in p.stderr.splitlines() if " done in " in ln]
        assert len(done) == 8 and all(any(w in ln for w in worker_pids) for ln in done)
        assert _snapshot(tmp_path / "D" / out) == local, out
