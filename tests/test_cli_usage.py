"""Options and configs as the user types them (CLI audit 2): exponent floats, a FIFO as
config, the bare command, bounds and combinations of ``run``'s options, ``--set`` syntax,
and an interruption as one line."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from test_robust_logs import cli, error_lines

from fuzzyslam import errors
from fuzzyslam.errors import ConfigError, InputError

MICRO = Path(__file__).parent / "micro.yaml"  # 1/10 lap
FUZZYSLAM = [sys.executable, "-m", "fuzzyslam"]


def one_line(err: str, start: str, *words: str) -> str:
    """The one line of ``err``, which starts with ``start`` and holds ``words``."""
    (line,) = err.splitlines()
    assert line.startswith(start), err
    for w in words:
        assert w in line, err
    return line


def test_exponent_without_a_dot_is_a_number(tmp_path: Path) -> None:
    """``1e-3`` (YAML 1.1 reads it as a string) is the number 0.001 in a config, and
    ``2.5E3`` and ``-1e+2`` too; a quoted or plain word is still refused."""
    from fuzzyslam.config import load_config

    cfg = tmp_path / "c.yaml"
    cfg.write_text("extends: sample.yaml\nrobot:\n  wheel_noise: 1e-3\n", encoding="utf-8")
    assert load_config(str(cfg)).robot.wheel_noise == 0.001
    for text, want in (("2.5E3", 2500.0), ("-1e+2", -100.0), (".5e-1", 0.05)):
        from fuzzyslam.config import yaml_value

        assert yaml_value(text) == want
    for bad in ('"abc"', "abc", "'1e-3'"):
        cfg.write_text(f"extends: sample.yaml\nrobot:\n  wheel_noise: {bad}\n", encoding="utf-8")
        with pytest.raises(ConfigError, match="must be a number"):
            load_config(str(cfg))


def test_set_takes_an_exponent_without_a_dot() -> None:
    """``--set KEY=1e-3`` of reproduce and sweep: the number 0.001, checked as such."""
    from fuzzyslam.reproduce.overrides import check_grid, parse_one, parse_set

    assert parse_one("robot.wheel_noise=1e-3") == ("robot.wheel_noise", 0.001)
    key, values = parse_set("robot.wheel_noise=1e-3,2e-3")
    assert values == [0.001, 0.002]
    points = check_grid("sample.yaml", [(key, values)])
    assert [p.robot.wheel_noise for p in points] == [0.001, 0.002]
    with pytest.raises(ConfigError, match="must be a number"):
        check_grid("sample.yaml", [(key, ["abc"])])


def test_config_fifo_is_refused_at_once(tmp_path: Path) -> None:
    """A FIFO as config, with no writer: one line, exit 3, at once (it used to block in
    open() for ever)."""
    fifo = tmp_path / "cfg.yaml"
    os.mkfifo(fifo)
    env = dict(os.environ, FUZZYSLAM_NO_PROGRESS="1")
    for args in (["simulate", fifo, "-o", tmp_path / "x.mcap"],
                 ["run", tmp_path / "x.mcap", "-o", tmp_path / "e", "--config", fifo]):  # fmt: skip
        p = subprocess.run(
            [*FUZZYSLAM, *map(str, args)], env=env, capture_output=True, text=True, timeout=60
        )
        assert p.returncode == errors.EXIT_INPUT, p.stderr
        one_line(p.stderr, f"fuzzyslam: error: {fifo}: ", "not a regular file")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["cfg.yaml"]


def test_bare_command_prints_the_help() -> None:
    """``fuzzyslam`` alone: click's help as it is laid out (not one 1500-character usage
    error line), exit 2."""
    code, out, err = cli()
    assert code == errors.EXIT_USAGE and out == ""
    lines = err.splitlines()
    assert lines[0].startswith("Usage: fuzzyslam [OPTIONS] COMMAND")
    assert "usage error:" not in err and "Commands:" in lines and len(lines) > 20
    assert max(map(len, lines)) <= 100


def test_start_pose_beyond_the_configs_bound_is_a_usage_error(tmp_path: Path) -> None:
    """``--start-pose 1e300,0,0``: exit 2, one line giving the bound of slam.start_pose."""
    for pose in ("1e300,0,0", "0,-2e6,0", "0,0,1e7"):
        code, out, err = cli("run", tmp_path / "x.mcap", "-o", tmp_path / "e", "--start-pose", pose)
        assert code == errors.EXIT_USAGE and out == "", err
        one_line(err, "fuzzyslam run: usage error:", "--start-pose", "1e+06", pose)
    assert not (tmp_path / "e").exists()


def test_fix_from_without_a_map_is_a_usage_error(tmp_path: Path) -> None:
    """``run --fix-from 5`` without ``--map``: exit 2 (it was silently ignored)."""
    code, out, err = cli("run", tmp_path / "x.mcap", "-o", tmp_path / "e", "--fix-from", "5")
    assert code == errors.EXIT_USAGE and out == "", err
    one_line(err, "fuzzyslam run: usage error:", "--fix-from needs --map")


def test_set_syntax_errors_name_the_commands_own_form(tmp_path: Path) -> None:
    """reproduce's --set is KEY=VALUE (not sweep's grid form); an empty value of a grid
    is refused (not read as null); --seeds with --logs is a usage error (exit 2), not
    a file named by the glob."""
    code, _, err = cli("reproduce", "--set", "robot.wheel_noise", "-o", tmp_path / "rp")
    assert code == errors.EXIT_INPUT, err
    line = one_line(err, "fuzzyslam: error: --set robot.wheel_noise: ", "KEY=VALUE")
    assert "V1,V2" not in line
    code, _, err = cli("sweep", "sample.yaml", "--set", "robot.wheel_noise=0.001,,0.002",
                       "--seeds", "1", "-o", tmp_path / "sw")  # fmt: skip
    assert code == errors.EXIT_INPUT, err
    line = one_line(err, "fuzzyslam: error: --set robot.wheel_noise=0.001,,0.002: ", "empty value")
    assert "null" not in line
    code, _, err = cli("sweep", "sample.yaml", "--set", "robot.wheel_noise=0.1", "--seeds", "1",
                       "--logs", "x*", "-o", tmp_path / "sw")  # fmt: skip
    assert code == errors.EXIT_USAGE, err
    one_line(err, "fuzzyslam sweep: usage error: give --seeds or --logs, not both")
    assert sorted(tmp_path.iterdir()) == []
    with pytest.raises(InputError, match="empty value"):
        from fuzzyslam.reproduce.overrides import parse_set

        parse_set("a.b=1, ")


@pytest.mark.parametrize(
    ("exc", "code", "word"),
    [
        (KeyboardInterrupt, errors.EXIT_INTERRUPTED, "interrupted"),
        ("terminated", errors.EXIT_TERMINATED, "terminated"),
    ],
)
def test_interruption_is_one_line(monkeypatch, tmp_path: Path, exc, code: int, word: str) -> None:
    """Ctrl-C or SIGTERM inside a command: exactly one line on stderr (click printed an
    empty one before it), exit 130 or 143."""
    import fuzzyslam.sim.stage as stage
    from fuzzyslam.cli import Terminated

    def interrupted(*a, **k):
        raise Terminated() if exc == "terminated" else exc()

    monkeypatch.setattr(stage, "run", interrupted)
    rc, out, err = cli("simulate", MICRO, "-o", tmp_path / "x.mcap")
    assert rc == code and out == ""
    assert err == f"fuzzyslam: {word}; no partial outputs were kept\n"


@pytest.mark.slow
@pytest.mark.parametrize(
    ("sig", "code"),
    [(signal.SIGINT, errors.EXIT_INTERRUPTED), (signal.SIGTERM, errors.EXIT_TERMINATED)],
)
def test_signal_is_one_line(tmp_path: Path, sig: int, code: int) -> None:
    """A real SIGINT or SIGTERM 1.5 s into simulating the paper's log: stderr is the one
    line, nothing is left."""
    env = dict(os.environ, FUZZYSLAM_NO_PROGRESS="1")
    p = subprocess.Popen([*FUZZYSLAM, "simulate", "-o", "paper.mcap"], cwd=tmp_path, env=env,
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)  # fmt: skip
    time.sleep(1.5)
    assert p.poll() is None, "ended before the signal"
    p.send_signal(sig)
    _, err = p.communicate(timeout=60)
    assert p.returncode == code, err
    assert err.endswith("; no partial outputs were kept\n") and len(err.splitlines()) == 1, err
    assert error_lines(err) == err.splitlines()
    assert list(tmp_path.iterdir()) == []


def test_blas_held_to_one_thread_when_numpy_came_first():
    """A command called in-process, numpy loaded before the CLI set its BLAS variables
    (this test session: conftest imports it), runs with the CLI's one BLAS thread all the
    same (fuzzyslam.cli._blas_limits), so it computes the floats its own process would:
    more threads split a matrix product's sums differently, and the live map's matches
    amplify the last bits over a long run (measured on ACES: closed-loop mean 0.366 m in
    a fresh process, 0.379 m in-process with OpenBLAS's own threads)."""
    threadpoolctl = pytest.importorskip("threadpoolctl")
    import fuzzyslam.cli as cli_module

    assert cli_module._NUMPY_FIRST
    if cli_module._BLAS_USER_SET:
        pytest.skip("a BLAS thread variable is set in this environment: it wins")
    with cli_module._blas_limits():
        blas = [i for i in threadpoolctl.threadpool_info() if i["user_api"] == "blas"]
        assert blas and all(i["num_threads"] == 1 for i in blas)
