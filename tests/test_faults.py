"""Faults injected for real (issue 14, classes 1, 2 and 7): a disk that fills up (a file
size limit set with RLIMIT_FSIZE in a child process, or a small tmpfs when mounting is
allowed), Ctrl-C inside the MCAP writer's ``finish``, FIFOs and sockets as outputs, and
unreadable inputs. Every one is exit 3 (130 for Ctrl-C) with one line naming the user's
path, and a previous output is left whole: the old file or directory, never a mix."""

from __future__ import annotations

import contextlib
import os
import resource
import shutil
import socket
import subprocess
import sys
import tempfile
from collections.abc import Iterator
from pathlib import Path

import pytest
from test_robust_logs import cli, error_lines, leftovers

from fuzzyslam import errors

pytestmark = pytest.mark.slow  # faults injected into whole CLI runs (tmpfs, size limits)

MICRO_YAML = (Path(__file__).parent / "micro.yaml").read_text(encoding="utf-8")  # 1/10 lap
ENV = {**os.environ, "FUZZYSLAM_NO_PROGRESS": "1", "MPLBACKEND": "Agg"}


@pytest.fixture(scope="module")
def micro(tmp_path_factory) -> tuple[Path, Path, Path]:
    """(config, log, run directory) of a short simulated log."""
    d = tmp_path_factory.mktemp("faults")
    cfg = d / "micro.yaml"
    cfg.write_text(MICRO_YAML, encoding="utf-8")
    log = d / "micro.mcap"
    code, _, err = cli("simulate", cfg, "-o", log)
    assert code == 0, err
    code, _, err = cli("run", log, "-o", d / "est", "--config", cfg)
    assert code == 0, err
    return cfg, log, d / "est"


def limited(args: list[object], fsize: int, cwd: Path) -> tuple[int, str]:
    """Run fuzzyslam ARGS in a child process whose files may not grow past ``fsize``
    bytes (writes beyond fail with EFBIG, as on a full disk): (exit code, stderr)."""

    def limit() -> None:
        resource.setrlimit(resource.RLIMIT_FSIZE, (fsize, fsize))

    p = subprocess.run(
        [sys.executable, "-m", "fuzzyslam", *map(str, args)],
        cwd=cwd, env=ENV, preexec_fn=limit, capture_output=True, text=True, timeout=120,
    )  # fmt: skip
    return p.returncode, p.stderr


def snapshot(folder: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in sorted(folder.iterdir())}


def assert_one_line(err: str, named: Path | str, *words: str) -> None:
    lines = error_lines(err)
    assert len(lines) == 1, err
    assert lines[0].startswith(f"fuzzyslam: error: {named}"), err
    assert ".part" not in lines[0], err
    for w in words:
        assert w in lines[0], err


@pytest.mark.parametrize("fsize", [0, 1, 4096, 60_000, 400_000])
def test_disk_full_simulate_keeps_the_old_log(micro, tmp_path: Path, fsize: int) -> None:
    """simulate onto an existing, complete log with the file size limit hit at several
    points (header, first chunk, mid-file, the summary at the end): exit 3, one line
    naming the log and "no space left", the old log byte-identical, no temporary."""
    cfg, log, _ = micro
    out = tmp_path / "old.mcap"
    shutil.copyfile(log, out)
    before = out.read_bytes()
    assert len(before) > fsize
    code, err = limited(["simulate", cfg, "-o", out, "--seed", "3"], fsize, tmp_path)
    assert code == errors.EXIT_INPUT, err
    assert_one_line(err, out, "no space left")
    assert out.read_bytes() == before and not leftovers(tmp_path)


@pytest.mark.parametrize("fraction", [0.0, 0.05, 0.4, 0.95])
def test_disk_full_run_keeps_the_old_directory(micro, tmp_path: Path, fraction: float) -> None:
    """run into an existing output directory with the limit hit while its files are
    written (a fraction of its largest file): exit 3 naming the output (not a
    temporary), the directory exactly as it was."""
    cfg, log, est = micro
    fsize = int(fraction * max(p.stat().st_size for p in est.iterdir()))
    out = tmp_path / "est"
    shutil.copytree(est, out)
    (out / "trajectory.tum").write_text("0 0 0 0 0 0 0 1\n", encoding="utf-8")
    (out / "notes.txt").write_text("mine\n", encoding="utf-8")
    before = snapshot(out)
    code, err = limited(["run", log, "-o", out, "--config", cfg], fsize, tmp_path)
    assert code == errors.EXIT_INPUT, err
    assert_one_line(err, out, "no space left")
    assert snapshot(out) == before and not leftovers(tmp_path)


def test_disk_full_map_and_evaluate(micro, tmp_path: Path) -> None:
    """map and evaluate on a full disk: exit 3, one line, nothing left behind."""
    cfg, log, est = micro
    for args, out in (
        (["map", log, "--trajectory", est / "trajectory.tum", "--config", cfg], tmp_path / "f"),
        (["evaluate", log, est], tmp_path / "r"),
    ):
        code, err = limited([*args, "-o", out], 3000, tmp_path)
        assert code == errors.EXIT_INPUT, err
        assert_one_line(err, out, "no space left")
        assert not out.exists() and not leftovers(tmp_path)


@contextlib.contextmanager
def small_tmpfs(size: str) -> Iterator[Path]:
    """A tmpfs of ``size`` mounted on a fresh temporary directory (root only)."""
    d = Path(tempfile.mkdtemp(prefix="fs-"))
    try:
        r = subprocess.run(
            ["mount", "-t", "tmpfs", "-o", f"size={size}", "tmpfs", str(d)], capture_output=True
        )
        if r.returncode != 0:
            pytest.skip("cannot mount a tmpfs here (not root)")
        try:
            yield d
        finally:
            subprocess.run(["umount", str(d)], check=True)
    finally:
        d.rmdir()


def test_full_tmpfs_keeps_the_old_log(micro, tmp_path: Path) -> None:
    """A real full disk: a tmpfs whose free space is smaller than the new log but larger
    than the old one. simulate fails with exit 3 and the old log stays whole."""
    cfg, log, _ = micro
    with small_tmpfs("900k") as fs:
        out = fs / "log.mcap"
        out.write_bytes(log.read_bytes()[:300_000])  # stands for an old, smaller log
        before = out.read_bytes()
        code, err = limited(["simulate", cfg, "-o", out], 2**40, tmp_path)
        assert code == errors.EXIT_INPUT, err
        assert_one_line(err, out, "no space left on device")
        assert out.read_bytes() == before and not leftovers(fs)


def test_ctrl_c_inside_finish_keeps_the_old_log(micro, monkeypatch, tmp_path: Path) -> None:
    """Ctrl-C while the MCAP writer finishes the file (summary, index): exit 130 and the
    old log unchanged (the temporary was renamed into place before)."""
    from mcap.writer import Writer

    cfg, log, _ = micro
    out = tmp_path / "old.mcap"
    shutil.copyfile(log, out)
    before = out.read_bytes()

    def interrupted(self) -> None:
        raise KeyboardInterrupt

    monkeypatch.setattr(Writer, "finish", interrupted)
    code, _, err = cli("simulate", cfg, "-o", out, "--seed", "5")
    assert code == errors.EXIT_INTERRUPTED, err
    assert out.read_bytes() == before and not leftovers(tmp_path)


def special_files(folder: Path) -> dict[str, Path]:
    fifo = folder / "fifo"
    os.mkfifo(fifo)
    sock = Path(tempfile.mkdtemp(prefix="s", dir="/tmp")) / "sock"  # short: AF_UNIX limit
    s = socket.socket(socket.AF_UNIX)
    s.bind(str(sock))
    s.close()
    return {"fifo": fifo, "socket": sock}


@pytest.mark.parametrize("kind", ["fifo", "socket"])
def test_special_files_are_never_replaced(micro, tmp_path: Path, kind: str) -> None:
    """A FIFO or a socket as the output of every command (and as a file inside an output
    directory): exit 3, one line naming it, and it is still the same special file."""
    cfg, log, est = micro
    special = special_files(tmp_path)[kind]
    try:
        inside = tmp_path / "est"
        inside.mkdir()
        os.symlink(special, inside / "trajectory.tum")  # the file run would write
        for args, named in (
            (["simulate", cfg, "-o", special], special),
            (["simulate", cfg, "-o", tmp_path / "x.mcap", "--preview", special], special),
            (["run", log, "--config", cfg, "-o", special], special),
            (["map", log, "--trajectory", est / "trajectory.tum", "-o", special], special),
            (["evaluate", log, est, "-o", special], special),
            (["run", log, "--config", cfg, "-o", inside], inside / "trajectory.tum"),
        ):
            ino = special.stat().st_ino
            code, out, err = cli(*args)
            assert code == errors.EXIT_INPUT, err
            assert_one_line(err, named, "not a regular file")
            st = special.stat()
            assert st.st_ino == ino and not os.path.isfile(special)
            assert out == "" and not leftovers(tmp_path)
        assert not (tmp_path / "x.mcap").exists()
    finally:
        shutil.rmtree(special.parent) if kind == "socket" else None


def test_directory_is_replaced_whole(tmp_path: Path) -> None:
    """OutputDir swaps the directory in one step: the stage's stale outputs (``owns``)
    go, the user's other files stay, and a failure while moving leaves the old set."""
    from fuzzyslam.fileio import OutputDir

    out = tmp_path / "est"
    out.mkdir()
    (out / "trajectory.tum").write_text("old", encoding="utf-8")
    (out / "heading_fixes.csv").write_text("old", encoding="utf-8")
    (out / "notes.txt").write_text("mine", encoding="utf-8")
    with OutputDir(out, owns=("heading_fixes.csv",)) as tmp:
        (tmp / "trajectory.tum").write_text("new", encoding="utf-8")
    assert snapshot(out) == {"notes.txt": b"mine", "trajectory.tum": b"new"}
    assert not leftovers(tmp_path)


def test_unreadable_log_is_one_line(micro, tmp_path: Path) -> None:
    """A log the user may not read (run as nobody when we are root): exit 3, one line
    naming it (click's usage text, exit 2, before)."""
    _cfg, log, est = micro
    if os.geteuid() != 0:
        pytest.skip("needs root to switch to an unprivileged user")
    tmp_path = Path(tempfile.mkdtemp(prefix="unreadable-", dir="/tmp"))  # nobody may enter
    tmp_path.chmod(0o777)
    bad = tmp_path / "secret.mcap"
    shutil.copyfile(log, bad)
    bad.chmod(0)
    est = Path(shutil.copytree(est, tmp_path / "est"))
    probe = subprocess.run(
        ["setpriv", "--reuid=65534", "--regid=65534", "--clear-groups",
         sys.executable, "-c", "import fuzzyslam"],
        cwd=tmp_path, env=ENV, capture_output=True, text=True, timeout=60,
    )  # fmt: skip
    if probe.returncode != 0:  # e.g. a checkout in a folder only root may enter
        shutil.rmtree(tmp_path)
        pytest.skip("the unprivileged user cannot import fuzzyslam from this checkout")
    for args in (["run", bad, "-o", "o"], ["map", bad, "--trajectory", est / "trajectory.tum",
                                          "-o", "o"], ["evaluate", bad, est, "-o", "o"]):
        p = subprocess.run(
            ["setpriv", "--reuid=65534", "--regid=65534", "--clear-groups",
             sys.executable, "-m", "fuzzyslam", *map(str, args)],
            cwd=tmp_path, env={**ENV, "MPLCONFIGDIR": str(tmp_path)}, capture_output=True,
            text=True, timeout=60,
        )  # fmt: skip
        assert p.returncode == errors.EXIT_INPUT, p.stderr
        assert_one_line(p.stderr, bad, "not readable")
    shutil.rmtree(tmp_path)


# -- damaged maps (class 6) ---------------------------------------------------------------


@pytest.fixture(scope="module")
def micro_map(micro, tmp_path_factory) -> Path:
    cfg, log, est = micro
    out = tmp_path_factory.mktemp("micro_map") / "fgm"
    code, _, err = cli(
        "map", log, "--trajectory", est / "trajectory.tum", "--config", cfg, "-o", out,
        "--no-figures", "--until", "10",
    )  # fmt: skip
    assert code == 0, err
    return out


def test_inputs_inside_the_output_directory_are_kept(micro, micro_map, tmp_path: Path) -> None:
    """Outputs that would replace what the command reads: run into its --map directory,
    run into the directory of its --calibration file, map into the run directory its
    trajectory comes from. Each is exit 3 with one line, and the directory unchanged."""
    cfg, log, est = micro
    fgm = tmp_path / "fgm"
    shutil.copytree(micro_map, fgm)
    run_dir = tmp_path / "est"
    shutil.copytree(est, run_dir)
    assert (run_dir / "calibration.yaml").is_file()
    cases = (
        (["run", log, "--config", cfg, "--map", fgm, "--fix", "heading", "-o", fgm], fgm),
        (["run", log, "--config", cfg, "--calibration", run_dir / "calibration.yaml",
          "-o", run_dir], run_dir),
        (["map", log, "--trajectory", run_dir / "trajectory.tum", "--config", cfg,
          "--no-figures", "--until", "10", "-o", run_dir], run_dir),
    )  # fmt: skip
    for args, folder in cases:
        before = snapshot(folder)
        code, _, err = cli(*args)
        assert code == errors.EXIT_INPUT, err
        assert len(error_lines(err)) == 1, err
        assert snapshot(folder) == before and not leftovers(folder)


def damaged(src: Path, dst: Path, **changes: object) -> Path:
    """A copy of the map directory ``src`` with fgm.npz's entries replaced."""
    import numpy as np

    shutil.copytree(src, dst)
    with np.load(src / "fgm.npz", allow_pickle=False) as z:
        entries = {k: z[k] for k in z.files}
    entries.update({k: np.asarray(v) for k, v in changes.items()})
    with open(dst / "fgm.npz", "wb") as f:
        np.savez_compressed(f, **entries)
    return dst


DAMAGE = {
    "resolution 0": {"resolution": 0.0},
    "resolution negative": {"resolution": -0.1},
    "resolution nan": {"resolution": float("nan")},
    "resolution 1e-9": {"resolution": 1e-9},
    "origin nan": {"origin": [float("nan"), 0.0]},
    "origin inf": {"origin": [0.0, float("inf")]},
    "shape huge": {"shape": [10**9, 10**9]},
    "shape negative": {"shape": [-5, 10]},
    "freeze time nan": {"freeze_time": float("nan")},
}


@pytest.mark.parametrize("kind", sorted(DAMAGE))
def test_damaged_map_is_refused(micro, micro_map, tmp_path: Path, kind: str) -> None:
    """run --map (pose and heading fixes) and evaluate --map on an fgm.npz with a bad
    resolution, origin, shape or freeze time: exit 3 naming fgm.npz, in a second."""
    import time

    cfg, log, est = micro
    bad = damaged(micro_map, tmp_path / "bad", **DAMAGE[kind])
    for args in (
        ["run", log, "--config", cfg, "--map", bad, "--fix", "pose", "-o", tmp_path / "o"],
        ["run", log, "--config", cfg, "--map", bad, "--fix", "heading", "-o", tmp_path / "o"],
        ["evaluate", log, est, "--map", bad, "-o", tmp_path / "r"],
    ):
        t0 = time.perf_counter()
        code, out, err = cli(*args)
        assert code == errors.EXIT_INPUT, err
        assert_one_line(err, bad / "fgm.npz")
        assert time.perf_counter() - t0 < 5.0 and out == ""
        assert not (tmp_path / "o").exists() and not (tmp_path / "r").exists()


@pytest.mark.parametrize("until", ["nan", "inf", "-inf", "1e300", "-1"])
def test_map_until_not_finite_is_refused(micro, tmp_path: Path, until: str) -> None:
    """map --until nan/inf wrote a map that run --map then refused: now a usage error
    and no map."""
    cfg, log, est = micro
    code, _, err = cli(
        "map", log, "--trajectory", est / "trajectory.tum", "--config", cfg, "--until", until,
        "-o", tmp_path / "fgm", "--no-figures",
    )  # fmt: skip
    assert code == errors.EXIT_USAGE and "--until" in err
    assert not (tmp_path / "fgm").exists()


@pytest.mark.parametrize("when", ["nan", "inf", "1e300", "-1"])
def test_fix_from_not_finite_is_a_usage_error(micro, micro_map, tmp_path: Path, when: str):
    """run --fix-from nan/inf/1e300 crashed (exit 1, converting to an integer)."""
    cfg, log, _ = micro
    code, _, err = cli("run", log, "--config", cfg, "--map", micro_map, "--fix", "pose",
                       "--fix-from", when, "-o", tmp_path / "o")
    assert code == errors.EXIT_USAGE and "--fix-from" in err, err
    assert not (tmp_path / "o").exists()


def test_unusable_map_is_not_written(tmp_path: Path) -> None:
    """save_fgm validates what it writes: a NaN freeze time on a frozen map, a zero
    resolution, NaN masses are refused and no file appears."""
    import numpy as np

    from fuzzyslam.errors import InputError
    from fuzzyslam.maps.grid import BeliefMap, Grid
    from fuzzyslam.maps.mapio import load_fgm, save_fgm

    good = BeliefMap.vacuous(Grid((0.0, 0.0), 0.1, (4, 5)))
    save_fgm(tmp_path / "ok.npz", good, True, 3.0, "x")
    assert load_fgm(tmp_path / "ok.npz").freeze_time == 3.0
    nan_mass = good.copy()
    nan_mass.m_o[1, 1] = np.nan
    for bm, t in (
        (good, float("nan")),
        (BeliefMap.vacuous(Grid((0.0, 0.0), 0.0, (4, 5))), 1.0),
        (nan_mass, 1.0),
    ):
        with pytest.raises(InputError, match="unusable map"):
            save_fgm(tmp_path / "bad.npz", bm, True, t, "x")
        assert not (tmp_path / "bad.npz").exists()


# -- evaluate says what its numbers do not cover (class 4) -------------------------------


def test_evaluate_reports_partial_truth_and_log_damage(micro, tmp_path: Path) -> None:
    """A truth covering 30 % of the estimate, and a truth log with a corrupt chunk:
    evaluate still runs (exit 0) but its summary carries the coverage, log_damage and a
    warning for each (it evaluated the 30 % without a word before)."""
    import json

    from mcap.reader import make_reader

    _cfg, log, est = micro
    rows = (est / "trajectory.tum").read_text(encoding="utf-8").splitlines()
    data = [r for r in rows if r and not r.startswith("#")]
    cut = tmp_path / "truth30.tum"
    cut.write_text("\n".join(data[: int(0.3 * len(data))]) + "\n", encoding="utf-8")
    code, out, err = cli("evaluate", cut, est, "-o", tmp_path / "r1")
    assert code == 0, err
    s = json.loads(out)
    assert 0.25 < s["truth_coverage"] < 0.35
    assert any("covers only" in w for w in s["warnings"])
    assert "covers only" in (tmp_path / "r1" / "report.md").read_text(encoding="utf-8")

    code, out, err = cli("evaluate", log, est, "-o", tmp_path / "r0")
    assert code == 0, err
    s = json.loads(out)
    assert s["warnings"] == [] and s["truth_coverage"] > 0.99
    assert s["log_damage"]["damaged_records"] == 0

    bad = tmp_path / "corrupt.mcap"
    shutil.copyfile(log, bad)
    with open(log, "rb") as f:
        offsets = sorted(c.chunk_start_offset for c in make_reader(f).get_summary().chunk_indexes)
    with open(bad, "r+b") as f:
        f.seek(offsets[len(offsets) // 2] + 200)
        f.write(b"\xff" * 64)
    code, out, err = cli("evaluate", bad, est, "-o", tmp_path / "r2")
    assert code == 0, err
    s = json.loads(out)
    assert s["log_damage"]["damaged_records"] >= 1
    assert any("damaged" in w for w in s["warnings"])


def test_working_directory_as_output_is_filled_in_place(tmp_path: Path, monkeypatch) -> None:
    """The working directory cannot be swapped (the shell would be left in a removed
    directory): its files are replaced one by one, and it stays the same directory."""
    from fuzzyslam.fileio import OutputDir

    out = tmp_path / "here"
    out.mkdir()
    (out / "a.txt").write_text("old", encoding="utf-8")
    ino = out.stat().st_ino
    monkeypatch.chdir(out)
    with OutputDir(".") as tmp:
        (tmp / "a.txt").write_text("new", encoding="utf-8")
    assert out.stat().st_ino == ino and Path.cwd().resolve() == out.resolve()
    assert snapshot(out) == {"a.txt": b"new"} and not leftovers(tmp_path)


def test_mount_point_as_output_is_filled_in_place(micro, tmp_path: Path) -> None:
    """A mount point as the output directory (another file system than its parent, so
    nothing can be renamed into it from outside): run fills it in place from a staging
    directory inside it, replaces the stage's stale optional outputs and keeps the user's
    files; the same run into a plain directory gives the same files."""
    cfg, log, _ = micro
    plain = tmp_path / "plain"
    code, _, err = cli("run", log, "-o", plain, "--config", cfg)
    assert code == 0, err
    with small_tmpfs("20m") as fs:
        (fs / "notes.txt").write_text("mine", encoding="utf-8")
        (fs / "heading_fixes.csv").write_text("stale", encoding="utf-8")  # a run with --map
        code, _, err = cli("run", log, "-o", fs, "--config", cfg)
        assert code == 0, err
        got = snapshot(fs)
        assert got.pop("notes.txt") == b"mine" and "heading_fixes.csv" not in got
        want = snapshot(plain)
        assert sorted(got) == sorted(want) and not leftovers(fs)
        for name in ("trajectory.tum", "landmarks.yaml", "covariance.csv"):
            assert got[name] == want[name], name


def test_read_only_output_names_the_users_path(micro, tmp_path: Path) -> None:
    """An output in a read-only file system: exit 3 and one line naming the user's path
    (not the temporary .part name), for a file (simulate) and a directory (run, also a
    read-only mount point as the output directory itself)."""
    cfg, log, _ = micro
    with small_tmpfs("1m") as fs:
        subprocess.run(["mount", "-o", "remount,ro", str(fs)], check=True)
        for args, out in (
            (["simulate", cfg], fs / "x.mcap"),
            (["run", log, "--config", cfg], fs / "est"),
            (["run", log, "--config", cfg], fs),
        ):
            code, _, err = cli(*args, "-o", out)
            assert code == errors.EXIT_INPUT, err
            assert_one_line(err, out, "read-only file system")


def test_map_of_a_path_too_large_is_refused(micro, tmp_path: Path) -> None:
    """A trajectory jumping 1e7 m away would make a map of 10^9 cells (23 GB before):
    exit 3 naming the trajectory, at once."""
    import time

    import numpy as np

    cfg, log, _ = micro
    t = np.arange(0.0, 40.0, 0.05)
    x = np.where(t > 3.0, 1e7, 0.0)
    tum = tmp_path / "far.tum"
    zero = np.zeros_like(t)
    np.savetxt(tum, np.column_stack([t, x, zero, zero, zero, zero, zero, zero + 1]), fmt="%.6f")
    t0 = time.perf_counter()
    code, _, err = cli("map", log, "--trajectory", tum, "--config", cfg, "-o", tmp_path / "f",
                       "--no-figures")
    assert code == errors.EXIT_INPUT, err
    assert_one_line(err, tum, "cells")
    assert time.perf_counter() - t0 < 10.0 and not (tmp_path / "f").exists()


def test_log_and_preview_are_replaced_together(micro, tmp_path: Path) -> None:
    """simulate --preview on a disk with room for the new log but not for the preview:
    exit 3 naming the preview, and the old log is kept (not a new log beside an old
    preview)."""
    cfg, log, _ = micro
    code, _, err = cli("simulate", cfg, "-o", tmp_path / "n.mcap", "--preview", tmp_path / "n.png")
    assert code == 0, err
    png = (tmp_path / "n.png").stat().st_size
    need = log.stat().st_size + 8192  # the new log and the small old files, in pages
    with small_tmpfs(f"{(need + png // 2) // 4096 * 4}k") as fs:
        out, prev = fs / "log.mcap", fs / "log.png"
        out.write_bytes(b"old log")
        prev.write_bytes(b"old png")
        code, err = limited(["simulate", cfg, "-o", out, "--preview", prev], 2**40, tmp_path)
        assert code == errors.EXIT_INPUT, err
        assert_one_line(err, prev, "no space left")
        assert out.read_bytes() == b"old log" and prev.read_bytes() == b"old png"
        assert not leftovers(fs)


def test_map_without_references_names_its_file(micro, tmp_path: Path) -> None:
    """Heading fixes from a map with no corridor references (built over the first 5 s: a
    path shorter than a corridor segment): the error names the map's references.yaml,
    not a bare "references.yaml"."""
    cfg, log, est = micro
    fgm = tmp_path / "fgm"
    code, _, err = cli("map", log, "--trajectory", est / "trajectory.tum", "--config", cfg,
                       "-o", fgm, "--no-figures", "--until", "5")
    assert code == 0, err
    code, _, err = cli("run", log, "--config", cfg, "--map", fgm, "--fix", "heading",
                       "-o", tmp_path / "o")
    assert code == errors.EXIT_INPUT, err
    assert_one_line(err, fgm / "references.yaml", "no corridor references")
