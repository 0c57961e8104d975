"""Robustness of every command (issue 7): bad configs and files are one line naming
the file with exit code 3, usage errors 2, internal failures 1 (``--debug`` shows
the traceback), Ctrl-C 130 and SIGTERM 143 leave no partial output, and an input
is never overwritten. The exit-code scheme is the one of ``fuzzyslam.errors``."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from test_robust_logs import TINY_YAML, cli, error_lines, leftovers

from fuzzyslam import errors

FUZZYSLAM = [sys.executable, "-m", "fuzzyslam"]


@pytest.fixture(scope="module")
def tiny_log(tmp_path_factory) -> tuple[Path, Path]:
    d = tmp_path_factory.mktemp("robust_cli")
    cfg = d / "tiny.yaml"
    cfg.write_text(TINY_YAML, encoding="utf-8")
    log = d / "tiny.mcap"
    code, _, err = cli("simulate", cfg, "-o", log)
    assert code == 0, err
    return cfg, log


def test_help_documents_the_exit_codes() -> None:
    code, out, _ = cli("--help")
    assert code == errors.EXIT_OK
    for c in (errors.EXIT_INTERNAL, errors.EXIT_USAGE, errors.EXIT_INPUT, errors.EXIT_INTERRUPTED):
        assert f"  {c} " in out
    for cmd in ("simulate", "run", "map", "evaluate"):
        code, out, _ = cli(cmd, "--help")
        assert code == 0 and "Usage:" in out


BAD_CONFIGS = {
    "unknown key": "extends: quick.yaml\nscenario: {runz: 2}\n",
    "wrong type": "extends: quick.yaml\nscenario: {runs: two}\n",
    "out of range": "extends: quick.yaml\nscenario: {runs: 0}\n",
    "bad choice": "extends: quick.yaml\nfixes: {mode: bogus}\n",
    "negative seed": "extends: quick.yaml\nseed: -4\n",
    "malformed yaml": "extends: quick.yaml\nscenario: [1, 2\n",
    "not a mapping": "- a list\n",
    "unknown section": "extends: quick.yaml\nslamm: {}\n",
    "cycle": "extends: bad.yaml\n",
}


@pytest.mark.parametrize("kind", sorted(BAD_CONFIGS))
def test_bad_config_is_one_line_naming_the_file(kind: str, tmp_path: Path, tiny_log) -> None:
    cfg = tmp_path / "bad.yaml"
    cfg.write_text(BAD_CONFIGS[kind], encoding="utf-8")
    out = tmp_path / "out.mcap"
    for args in (["simulate", cfg, "-o", out], ["run", tiny_log[1], "-o", tmp_path / "est",
                                                 "--config", cfg]):  # fmt: skip
        code, stdout, stderr = cli(*args)
        lines = error_lines(stderr)
        assert code == errors.EXIT_INPUT, stderr
        assert len(lines) == 1 and lines[0].startswith(f"fuzzyslam: error: {cfg}: "), lines
        assert stdout == ""
        assert not out.exists() and not (tmp_path / "est").exists() and not leftovers(tmp_path)


def test_missing_config_and_missing_log(tmp_path: Path, tiny_log) -> None:
    code, _, stderr = cli("simulate", tmp_path / "nope.yaml", "-o", tmp_path / "x.mcap")
    assert code == 3 and error_lines(stderr)[0].startswith(f"fuzzyslam: error: {tmp_path}")
    code, _, stderr = cli("run", tmp_path / "nope.mcap", "-o", tmp_path / "est")
    assert code == 3
    assert error_lines(stderr) == [
        f"fuzzyslam: error: {tmp_path / 'nope.mcap'}: log does not exist"
    ]
    code, _, stderr = cli("run", tmp_path, "-o", tmp_path / "est")
    assert code == 3 and "folder with no .mcap file" in stderr and len(error_lines(stderr)) == 1
    code, _, stderr = cli(
        "map", tiny_log[1], "--trajectory", tmp_path / "none.tum", "-o", tmp_path / "fgm"
    )
    assert code == 3 and len(error_lines(stderr)) == 1 and "none.tum" in stderr
    assert not leftovers(tmp_path) and not (tmp_path / "fgm").exists()


def test_usage_errors_exit_2(tmp_path: Path, tiny_log) -> None:
    """A usage error is exit 2 and one line naming the command and where its help is."""
    code, _, stderr = cli("run", tiny_log[1])  # no -o
    assert code == errors.EXIT_USAGE and "Missing option" in stderr
    assert error_lines(stderr) == [
        "fuzzyslam run: usage error: Missing option '-o' / '--output'. "
        "(see 'fuzzyslam run --help')"
    ]
    code, _, stderr = cli("simulate", "-o", tmp_path / "x.mcap", "--seed", "-1")
    assert code == errors.EXIT_USAGE and not (tmp_path / "x.mcap").exists()
    assert len(error_lines(stderr)) == 1 and "--seed" in stderr
    code, _, stderr = cli("nosuchcommand")
    assert code == errors.EXIT_USAGE and len(error_lines(stderr)) == 1


def test_inputs_are_never_overwritten(tmp_path: Path, tiny_log) -> None:
    """Output == input is refused (exit 3, input byte-identical), also when the output
    directory holds the input under an output's name."""
    cfg, log = tiny_log
    before = log.read_bytes()
    code, _, stderr = cli("simulate", cfg, "-o", cfg)
    assert code == 3 and "input" in stderr and cfg.read_text(encoding="utf-8") == TINY_YAML
    d = tmp_path / "est"
    d.mkdir()
    inside = d / "estimates.mcap"  # 'run' writes estimates.mcap into its output directory
    inside.write_bytes(before)
    code, _, stderr = cli("run", inside, "-o", d, "--config", cfg)
    assert code == 3 and len(error_lines(stderr)) == 1 and "overwrite an input" in stderr
    assert inside.read_bytes() == before
    assert sorted(p.name for p in d.iterdir()) == ["estimates.mcap"]
    code, _, stderr = cli("run", log, "-o", log)
    assert code == 3 and log.read_bytes() == before


def _child(args: list, cwd: Path, close: int | None = None, env_progress: bool = False):
    """Start ``fuzzyslam ARGS`` with stdout piped (its read end closed at once when
    ``close`` is None) or descriptor ``close`` closed in the child; (exit code, stderr)."""
    env = {**os.environ}
    if not env_progress:
        env["FUZZYSLAM_NO_PROGRESS"] = "1"
    pre = None if close is None else (lambda: os.close(close))
    p = subprocess.Popen(
        [*FUZZYSLAM, *map(str, args)], cwd=cwd, env=env, preexec_fn=pre,
        stdout=subprocess.PIPE if close is None else None, stderr=subprocess.PIPE,
    )  # fmt: skip
    if close is None:
        p.stdout.close()  # the reader goes away before the summary is written
    _, err = p.communicate(timeout=120)
    return p.returncode, err.decode()


@pytest.mark.slow  # fault injection: subprocesses and pipes closed under them
def test_reader_gone_or_stream_closed_is_not_a_failure(tmp_path: Path, tiny_log) -> None:
    """A summary nobody reads (the pipe's reader gone, ``| true``), stdout closed
    (``>&-``) or stderr closed (``2>&-``, with progress on): exit 0, nothing on stderr
    but progress, and the outputs written as by a plain run."""
    cfg, log = tiny_log
    code, _, err = cli("run", log, "-o", tmp_path / "plain", "--config", cfg)
    assert code == 0, err
    want = (tmp_path / "plain" / "trajectory.tum").read_bytes()
    for name, close in (("gone", None), ("stdout", 1), ("stderr", 2)):
        out = tmp_path / name
        code, err = _child(["run", log, "-o", out, "--config", cfg], tmp_path, close, True)
        assert code == errors.EXIT_OK, err
        assert "error" not in err and "Traceback" not in err, err
        assert (out / "trajectory.tum").read_bytes() == want
    code, err = _child(["--help"], tmp_path)
    assert code == errors.EXIT_OK and not err


def test_internal_error_is_one_line_and_debug_shows_traceback(monkeypatch, tmp_path: Path):
    import fuzzyslam.sim.record as record

    def boom(*a, **k):
        raise RuntimeError("simulated bug\nsecond line")

    monkeypatch.setattr(record, "simulate_to_mcap", boom)
    out = tmp_path / "x.mcap"
    code, _, stderr = cli("simulate", "quick", "-o", out)
    assert code == errors.EXIT_INTERNAL
    assert error_lines(stderr) == [
        "fuzzyslam: internal error: RuntimeError: simulated bug (rerun with --debug for the "
        "traceback)"
    ]
    for args in (["--debug", "simulate", "quick", "-o", out], ["simulate", "quick", "-o", out,
                                                               "--debug"]):  # fmt: skip
        code, _, stderr = cli(*args)
        assert code == errors.EXIT_INTERNAL
        assert "Traceback (most recent call last)" in stderr and "in boom" in stderr
    assert not out.exists() and not leftovers(tmp_path)


def test_os_error_on_a_file_is_one_line_exit_3(monkeypatch, tmp_path: Path) -> None:
    import fuzzyslam.sim.record as record

    def denied(*a, **k):
        raise PermissionError(13, "Permission denied", str(tmp_path / "x.mcap"))

    monkeypatch.setattr(record, "simulate_to_mcap", denied)
    code, _, stderr = cli("simulate", "quick", "-o", tmp_path / "x.mcap")
    assert code == errors.EXIT_INPUT
    assert error_lines(stderr) == [f"fuzzyslam: error: {tmp_path / 'x.mcap'}: Permission denied"]


def _interrupt(args: list[str], cwd: Path, sig: int, after: float) -> tuple[int, str]:
    env = dict(os.environ, FUZZYSLAM_NO_PROGRESS="1")
    p = subprocess.Popen(
        [*FUZZYSLAM, *args], cwd=cwd, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE
    )
    time.sleep(after)
    assert p.poll() is None, "the command ended before it could be interrupted"
    p.send_signal(sig)
    _, err = p.communicate(timeout=60)
    return p.returncode, err.decode()


@pytest.mark.slow  # fault injection: a signal to a running simulate
@pytest.mark.parametrize(
    ("sig", "code"),
    [(signal.SIGINT, errors.EXIT_INTERRUPTED), (signal.SIGTERM, errors.EXIT_TERMINATED)],
)
def test_interrupted_simulate_leaves_nothing(tmp_path: Path, sig: int, code: int) -> None:
    """Ctrl-C (SIGINT) or SIGTERM ~1 s into simulating the paper's six runs (~12 s):
    exit 130/143, one line, and neither the recording nor a temporary file exists."""
    rc, err = _interrupt(["simulate", "-o", "paper.mcap"], tmp_path, sig, 1.5)
    assert rc == code, err
    assert error_lines(err)[-1].endswith("no partial outputs were kept")
    assert list(tmp_path.iterdir()) == []


def test_interrupted_run_keeps_the_previous_outputs(monkeypatch, tmp_path: Path, tiny_log):
    """Ctrl-C while 'run' writes its files into an existing output directory: exit 130,
    the directory is exactly as it was and no temporary is left."""
    import fuzzyslam.slam.stage as stage

    cfg, log = tiny_log
    d = tmp_path / "est"
    d.mkdir()
    (d / "trajectory.tum").write_text("0 0 0 0 0 0 0 1\n", encoding="utf-8")
    (d / "notes.txt").write_text("mine\n", encoding="utf-8")
    before = {p.name: p.read_bytes() for p in d.iterdir()}
    real = stage.write_outputs

    def interrupted(tmp, *a, **k):
        real(tmp, *a, **k)  # every file written to the temporary directory, then Ctrl-C
        raise KeyboardInterrupt

    monkeypatch.setattr(stage, "write_outputs", interrupted)
    code, out, err = cli("run", log, "-o", d, "--config", cfg)
    assert code == errors.EXIT_INTERRUPTED and out == ""
    assert error_lines(err) == ["fuzzyslam: interrupted; no partial outputs were kept"]
    assert {p.name: p.read_bytes() for p in d.iterdir()} == before
    assert not leftovers(tmp_path)
    monkeypatch.setattr(stage, "write_outputs", real)
    code, out, _ = cli("run", log, "-o", d, "--config", cfg)
    assert code == 0 and (d / "trajectory.tum").read_bytes() != before["trajectory.tum"]
    assert (d / "notes.txt").read_bytes() == before["notes.txt"]


def test_output_in_a_missing_directory(tmp_path: Path, tiny_log) -> None:
    cfg, log = tiny_log
    for args, named in (
        (["simulate", cfg, "-o", tmp_path / "no" / "x.mcap"], tmp_path / "no" / "x.mcap"),
        (["run", log, "-o", tmp_path / "no" / "est", "--config", cfg], tmp_path / "no" / "est"),
    ):
        code, _, stderr = cli(*args)
        lines = error_lines(stderr)
        assert code == 3 and len(lines) == 1 and lines[0].startswith(f"fuzzyslam: error: {named}")
        assert "does not exist" in lines[0]
    assert sorted(tmp_path.iterdir()) == []


def test_outputs_move_into_place_whole(tmp_path: Path) -> None:
    """A new output directory appears by one rename with the usual permissions; a
    Ctrl-C while outputs move into an existing one is delivered only after the move."""
    from fuzzyslam.fileio import OutputDir

    fresh = tmp_path / "fresh"
    with OutputDir(fresh) as tmp:
        (tmp / "a.txt").write_text("a", encoding="utf-8")
    umask = os.umask(0)
    os.umask(umask)
    assert fresh.stat().st_mode & 0o777 == 0o777 & ~umask
    assert [p.name for p in fresh.iterdir()] == ["a.txt"] and not leftovers(tmp_path)

    # a single file written through atomic_path gets a file's usual mode, not mkstemp's 0600
    from fuzzyslam.fileio import atomic_path

    with atomic_path(tmp_path / "one.txt") as part:
        part.write_text("x", encoding="utf-8")
    assert (tmp_path / "one.txt").stat().st_mode & 0o777 == 0o666 & ~umask
    (tmp_path / "one.txt").unlink()

    import fuzzyslam.fileio as fileio

    real_move = OutputDir._move

    def move_with_interrupt(self, items):
        os.kill(os.getpid(), signal.SIGINT)  # arrives while the files move
        real_move(self, items)

    old = fresh / "a.txt"
    with pytest.raises(KeyboardInterrupt):
        with pytest.MonkeyPatch.context() as mp:
            mp.setattr(fileio.OutputDir, "_move", move_with_interrupt)
            with OutputDir(fresh) as tmp:
                for name in ("a.txt", "b.txt", "c.txt"):
                    (tmp / name).write_text("new", encoding="utf-8")
    # the interrupt came after every file was in place: no mix of old and new
    assert sorted(p.name for p in fresh.iterdir()) == ["a.txt", "b.txt", "c.txt"]
    assert all(p.read_text(encoding="utf-8") == "new" for p in fresh.iterdir())
    assert old.read_text(encoding="utf-8") == "new" and not leftovers(tmp_path)


@pytest.mark.parametrize("command", ["map_log", "map_trajectory", "evaluate_truth", "evaluate_est"])
def test_junk_inputs_of_every_command(command: str, tmp_path: Path, tiny_log) -> None:
    """Random bytes, a text file or a wrong TUM given to map and evaluate: exit 3, one
    line naming that file, no output."""
    _cfg, log = tiny_log
    junk = tmp_path / "junk.bin"
    junk.write_bytes(bytes(range(256)) * 8)
    tum = tmp_path / "bad.tum"
    tum.write_text("0 1 2\n", encoding="utf-8")
    good_tum = tmp_path / "ok.tum"
    good_tum.write_text("0 5 0 0 0 0 0 1\n1000 5 0 0 0 0 0 1\n", encoding="utf-8")
    out = tmp_path / "out"
    args, named = {
        "map_log": (["map", junk, "--trajectory", good_tum], junk),
        "map_trajectory": (["map", log, "--trajectory", tum], tum),
        "evaluate_truth": (["evaluate", junk, good_tum], junk),
        "evaluate_est": (["evaluate", log, tum], tum),
    }[command]
    code, stdout, stderr = cli(*args, "-o", out)
    lines = error_lines(stderr)
    assert code == 3, stderr
    assert len(lines) == 1 and lines[0].startswith(f"fuzzyslam: error: {named}: ")
    assert stdout == "" and not out.exists() and not leftovers(tmp_path)


# fuzzyslam's entry with an exit handler that notes the interpreter's finalisation
FINALISED = """
import atexit, sys
atexit.register(lambda: sys.stderr.write("FINALISED\\n"))
from fuzzyslam.cli import entry
sys.argv[0] = "fuzzyslam"
entry()
"""


@pytest.mark.slow
def test_a_run_leaves_without_the_interpreters_finalisation(tmp_path: Path, tiny_log) -> None:
    """``run`` (cli.LEAVE_AT_ONCE) exits at once when done, its exit handlers not run,
    with its summary written out in full, its outputs in place and its exit code kept
    (0, or 3 for a missing log); other commands finalise as usual."""
    import json

    cfg, log = tiny_log
    out, missing = tmp_path / "est", str(tmp_path / "missing.mcap")
    cases = [
        (["run", str(log), "-o", str(out), "--config", str(cfg)], errors.EXIT_OK, False),
        (["run", missing, "-o", str(tmp_path / "x")], errors.EXIT_INPUT, False),
        (["simulate", "--help"], errors.EXIT_OK, True),
    ]  # fmt: skip
    for args, code, finalised in cases:
        p = subprocess.run(
            [sys.executable, "-c", FINALISED, *args], capture_output=True, text=True,
            cwd=tmp_path, env={**os.environ, "FUZZYSLAM_NO_PROGRESS": "1"}, timeout=120,
        )  # fmt: skip
        assert p.returncode == code, p.stderr
        assert ("FINALISED" in p.stderr) == finalised, (args, p.stderr)
        if args[0] == "run" and code == errors.EXIT_OK:
            assert json.loads(p.stdout)["trajectory_rows"] > 0
            assert (out / "trajectory.tum").is_file() and not leftovers(tmp_path)
        elif args[0] == "run":
            assert "missing.mcap" in p.stderr


@pytest.mark.slow  # end to end, about 1 s: the fast tier stays under a minute
def test_a_profiled_run_writes_its_profile(tmp_path: Path, tiny_log) -> None:
    """Under ``python -m cProfile -o`` a run is let finish as Python does, so that the
    profile (written after the command returns) exists: the fast exit is only for runs
    nothing watches."""
    import pstats

    cfg, log = tiny_log
    prof = tmp_path / "run.prof"
    p = subprocess.run(
        [sys.executable, "-m", "cProfile", "-o", str(prof), "-m", "fuzzyslam", "run",
         str(log), "-o", str(tmp_path / "est"), "--config", str(cfg)],
        capture_output=True, text=True, cwd=tmp_path, timeout=120,
        env={**os.environ, "FUZZYSLAM_NO_PROGRESS": "1"},
    )  # fmt: skip
    assert p.returncode == 0, p.stderr
    assert pstats.Stats(str(prof)).total_calls > 0
