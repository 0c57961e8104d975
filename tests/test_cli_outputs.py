"""Outputs complete or absent, never mixed, and stderr as best effort (CLI audit 2):
``simulate --preview --truth-tum`` renames its files only when every one is complete, and
a full disk under stderr (progress, notes) never fails a run nor is blamed on an output."""

from __future__ import annotations

import errno
import os
import subprocess
import sys
from pathlib import Path

import pytest
from test_faults import small_tmpfs
from test_robust_logs import cli, error_lines, leftovers

from fuzzyslam import errors
from fuzzyslam.fileio import atomic_path

MICRO = Path(__file__).parent / "micro.yaml"  # 1/10 lap


def _three(folder: Path) -> tuple[Path, Path, Path]:
    return folder / "log.mcap", folder / "world.png", folder / "truth.tum"


def _simulate(log: Path, png: Path, tum: Path, seed: int) -> tuple[int, str]:
    code, _, err = cli(
        "simulate", MICRO, "-o", log, "--preview", png, "--truth-tum", tum, "--seed", seed
    )
    return code, err


@pytest.mark.slow
def test_simulate_truth_failure_keeps_every_old_output(tmp_path: Path, monkeypatch) -> None:
    """The truth TUM cannot be written (disk full): exit 3, one line naming the TUM and
    "nothing was replaced", and the log, the preview and the TUM all the old seed's (the
    preview used to be renamed before the TUM was written)."""
    import fuzzyslam.sim.record as record

    log, png, tum = _three(tmp_path)
    code, err = _simulate(log, png, tum, 0)
    assert code == 0, err
    before = {p: p.read_bytes() for p in (log, png, tum)}

    def full_disk(plan, path) -> None:  # as write_truth_tum, on a full disk
        with atomic_path(path) as tmp:
            Path(tmp).write_text("# timestamp", encoding="utf-8")
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(record, "write_truth_tum", full_disk)
    code, err = _simulate(log, png, tum, 1)
    assert code == errors.EXIT_INPUT, err
    (line,) = error_lines(err)
    assert line.startswith(f"fuzzyslam: error: {tum}: cannot write: no space left"), err
    assert "nothing was replaced" in line and ".part" not in line, err
    assert {p: p.read_bytes() for p in (log, png, tum)} == before
    assert not leftovers(tmp_path)


@pytest.mark.slow
def test_simulate_outputs_all_new_on_success(tmp_path: Path) -> None:
    """The three files of a second seed replace the first's together."""
    log, png, tum = _three(tmp_path)
    assert _simulate(log, png, tum, 0)[0] == 0
    before = {p: p.read_bytes() for p in (log, png, tum)}
    code, err = _simulate(log, png, tum, 1)
    assert code == 0, err
    assert all(p.read_bytes() != before[p] for p in (log, png, tum))
    assert not leftovers(tmp_path)


def _fill(folder: Path, leave: int) -> None:
    """Fill the file system of ``folder`` but ``leave`` bytes."""
    st = os.statvfs(folder)
    free = st.f_bavail * st.f_frsize
    if free > leave:
        (folder / "filler").write_bytes(b"\0" * (free - leave))


@pytest.mark.slow
def test_simulate_truth_on_a_full_tmpfs_keeps_every_old_output(tmp_path: Path) -> None:
    """The same on a real full disk: the truth TUM on a small tmpfs with 8 KiB left."""
    log, png, _ = _three(tmp_path)
    with small_tmpfs("256k") as fs:
        tum = fs / "truth.tum"
        code, err = _simulate(log, png, tum, 0)
        assert code == 0, err
        before = {p: p.read_bytes() for p in (log, png, tum)}
        _fill(fs, 8192)
        code, err = _simulate(log, png, tum, 1)
        assert code == errors.EXIT_INPUT, err
        (line,) = error_lines(err)
        assert line.startswith(f"fuzzyslam: error: {tum}: cannot write: no space left"), err
        assert {p: p.read_bytes() for p in (log, png, tum)} == before
        assert not leftovers(tmp_path) and not leftovers(fs)


class _FullDisk:
    """A text stream on a full disk: every write and flush fails with ENOSPC (its
    descriptor a real file, for the null device to be put on)."""

    def __init__(self, fd: int) -> None:
        self.fd = fd

    def write(self, text: str) -> int:
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    def flush(self) -> None:
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    def fileno(self) -> int:
        return self.fd


def test_stderr_on_a_full_disk_is_best_effort(tmp_path: Path) -> None:
    """stderr's QuietPipe drops a write that fails for any OSError (a full disk), once
    and for all; stdout's still raises it (the summary is an output: exit 3)."""
    from fuzzyslam.cli.std import QuietPipe
    from fuzzyslam.progress import Progress

    with open(tmp_path / "err.txt", "w") as f:
        err = QuietPipe(_FullDisk(f.fileno()), best_effort=True)
        assert err.write("simulate\n") == len("simulate\n") and err.broken
        err.flush()
        with Progress(10.0, "run", stream=_FullDisk(f.fileno())) as bar:  # lines mode
            bar.update_to(5.0)
        out = QuietPipe(_FullDisk(f.fileno()))
        with pytest.raises(OSError):
            out.write("{}\n")


@pytest.mark.slow
def test_full_disk_under_stderr_does_not_fail_the_run(tmp_path: Path) -> None:
    """``2>FILE`` on a full tmpfs, progress on: simulate and run exit 0 with complete
    outputs (the first progress line used to fail them, blamed on an output file)."""
    env = {k: v for k, v in os.environ.items() if k != "FUZZYSLAM_NO_PROGRESS"}
    log, est = tmp_path / "log.mcap", tmp_path / "est"
    with small_tmpfs("64k") as fs:
        with open(fs / "err.txt", "w") as err:
            _fill(fs, 0)
            for args in (["simulate", MICRO, "-o", log], ["run", log, "-o", est]):
                p = subprocess.run(
                    [sys.executable, "-m", "fuzzyslam", *map(str, args)],
                    env=env, stdout=subprocess.PIPE, stderr=err, text=True, timeout=120,
                )  # fmt: skip
                assert p.returncode == 0, (args, p.stdout)
                assert p.stdout.startswith("{")
        assert (fs / "err.txt").stat().st_size == 0  # nothing could be said
    assert log.stat().st_size > 0 and (est / "trajectory.tum").stat().st_size > 0
    assert not leftovers(tmp_path)
