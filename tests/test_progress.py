"""Progress on stderr when it is not a terminal (a file or a pipe: CI, nohup)."""

from __future__ import annotations

import io
import os
import subprocess
import sys
from pathlib import Path

import pytest

from fuzzyslam.progress import Progress

DATA = Path(__file__).resolve().parents[1] / "data"


class Clock:
    def __init__(self) -> None:
        self.t = 100.0

    def __call__(self) -> float:
        return self.t


def test_lines_at_most_one_an_interval_and_done(monkeypatch):
    """The label, a percentage line only after ``interval_s`` of silence, ``done`` at the end."""
    monkeypatch.delenv("FUZZYSLAM_NO_PROGRESS", raising=False)
    out, clock = io.StringIO(), Clock()
    with Progress(200.0, "run: EKF-SLAM", stream=out, clock=clock, interval_s=30.0) as bar:
        assert bar.mode == "lines"
        for amount in range(1, 201):  # 1 s of clock per unit of work
            clock.t += 1.0
            bar.update_to(amount)
        bar.update_to(150.0)  # going back says nothing
    lines = out.getvalue().splitlines()
    # a line at 30, 60, ... 180 s of clock: every 30 units of the 200
    expect = [f"run: EKF-SLAM: {p:.0f} % after {s} s" for p, s in
              [(100 * s / 200, s) for s in range(30, 181, 30)]]  # fmt: skip
    assert lines == ["run: EKF-SLAM", *expect, "run: EKF-SLAM: done in 200.0 s"]


def test_no_done_line_after_an_error(monkeypatch):
    """An error is the command's own one line: the display does not claim the work done."""
    monkeypatch.delenv("FUZZYSLAM_NO_PROGRESS", raising=False)
    out = io.StringIO()
    with pytest.raises(ValueError), Progress(10.0, "map", stream=out, clock=Clock()):
        raise ValueError("bad ring")
    assert out.getvalue().splitlines() == ["map"]


def test_off_when_disabled_or_not_shown(monkeypatch):
    out = io.StringIO()
    monkeypatch.setenv("FUZZYSLAM_NO_PROGRESS", "1")
    with Progress(10.0, "x", stream=out) as bar:
        bar.update_to(5.0)
        assert bar.mode == "off"
    monkeypatch.delenv("FUZZYSLAM_NO_PROGRESS")
    with Progress(10.0, "x", show=False, stream=out) as bar:
        bar.update_to(5.0)
        assert bar.mode == "off"
    assert out.getvalue() == ""


@pytest.mark.slow
def test_run_with_stderr_in_a_file_says_when_it_is_done(tmp_path):
    """`fuzzyslam run` with stderr redirected to a file: its label, then ``done in``."""
    env = {k: v for k, v in os.environ.items() if k != "FUZZYSLAM_NO_PROGRESS"}
    err = tmp_path / "stderr.txt"
    with err.open("w") as f:
        p = subprocess.run(
            [sys.executable, "-m", "fuzzyslam", "run", str(DATA / "sample.mcap"),
             "-o", str(tmp_path / "est")],
            stdout=subprocess.PIPE, stderr=f, env=env, check=False,
        )  # fmt: skip
    assert p.returncode == 0
    lines = err.read_text().splitlines()
    assert lines[0] == "run: EKF-SLAM"
    assert lines[-1].startswith("run: EKF-SLAM: done in ") and lines[-1].endswith(" s")
