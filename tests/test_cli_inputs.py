"""Inputs checked before the work and named as what they are (CLI audit 2): FIFOs given
as files, an output directory that holds an input, and what a stage tells on stderr
about its log (a freeze time past its end, a cut-off log)."""

from __future__ import annotations

import os
from pathlib import Path

import pytest
from conftest import shared_dir
from test_robust_logs import cli

from fuzzyslam import errors

MICRO = Path(__file__).parent / "micro.yaml"  # 1/10 lap
SAMPLE = Path(__file__).resolve().parents[1] / "data" / "sample.mcap"
TUM = "0.0 0 0 0 0 0 0 1\n1.0 0.1 0 0 0 0 0 1\n"


def one_error(err: str, named: Path, *words: str) -> None:
    """``err`` is one error line naming ``named``, holding ``words``."""
    (line,) = err.splitlines()
    assert line.startswith(f"fuzzyslam: error: {named}: "), err
    for w in words:
        assert w in line, err


@pytest.fixture(scope="module")
def micro(tmp_path_factory) -> tuple[Path, Path]:
    """(log, its true trajectory as TUM) of a short simulated log."""

    def build(d: Path) -> None:
        code, _, err = cli("simulate", MICRO, "-o", d / "log.mcap", "--truth-tum", d / "truth.tum")
        assert code == 0, err

    d = shared_dir(tmp_path_factory, "cli_inputs_micro", build)
    return d / "log.mcap", d / "truth.tum"


def test_map_calibration_and_landmarks_fifos_are_refused_first(tmp_path: Path) -> None:
    """``map --calibration FIFO`` is "not a regular file" (not "no such calibration
    file"), and ``--landmarks FIFO`` is refused before the log is even read."""
    fifo = tmp_path / "fifo"
    os.mkfifo(fifo)
    traj = tmp_path / "t.tum"
    traj.write_text(TUM, encoding="utf-8")
    base = ["map", tmp_path / "absent.mcap", "--trajectory", traj, "-o", tmp_path / "fgm"]
    code, out, err = cli(*base, "--calibration", fifo)
    assert code == errors.EXIT_INPUT and out == "", err
    one_error(err, fifo, "not a regular file", "--calibration")
    code, out, err = cli(*base, "--landmarks", fifo)
    assert code == errors.EXIT_INPUT and out == "", err
    one_error(err, fifo, "not a regular file", "--landmarks")
    code, _, err = cli(*base, "--calibration", tmp_path / "none.yaml")
    one_error(err, tmp_path / "none.yaml", "no such calibration file")
    assert not (tmp_path / "fgm").exists()


def test_map_landmarks_that_are_not_lamps_are_refused_first(tmp_path: Path) -> None:
    """``map --landmarks TRAJECTORY.tum`` (or another YAML): one line naming the file and
    what a landmarks file holds, before the log is read (here absent), nothing written;
    not a map without lamps and exit 0."""
    traj = tmp_path / "t.tum"
    traj.write_text(TUM, encoding="utf-8")
    other = tmp_path / "calibration.yaml"
    other.write_text("model: odom\nfactors: [1, 1]\n", encoding="utf-8")
    base = ["map", tmp_path / "absent.mcap", "--trajectory", traj, "-o", tmp_path / "fgm"]
    for wrong in (traj, other):
        code, out, err = cli(*base, "--landmarks", wrong)
        assert code == errors.EXIT_INPUT and out == "", err
        one_error(err, wrong, "not a landmarks file", "'landmarks: [{id, x, y}, ...]'")
    assert not (tmp_path / "fgm").exists()


@pytest.mark.parametrize("command", ["map", "evaluate"])
def test_output_that_is_a_file_is_refused_before_the_work(command: str, tmp_path: Path) -> None:
    """``-o FILE`` (an existing regular file): refused before the work, as ``run`` does,
    here before the log or truth is read (absent: its error would come first otherwise,
    and with a real one the output's only after the work); the file left as it was and no
    staging directory left behind."""
    traj = tmp_path / "t.tum"
    traj.write_text(TUM, encoding="utf-8")
    absent = tmp_path / "absent.mcap"
    out_file = tmp_path / "out"
    out_file.write_text("mine\n", encoding="utf-8")
    args = {
        "map": ["map", absent, "--trajectory", traj],
        "evaluate": ["evaluate", absent, traj],
    }[command]
    code, out, err = cli(*args, "-o", out_file)
    assert code == errors.EXIT_INPUT and out == "", err
    one_error(err, out_file, "not a directory")
    assert out_file.read_text(encoding="utf-8") == "mine\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out", "t.tum"]


def test_evaluate_fifo_trajectory_is_not_a_regular_file(tmp_path: Path) -> None:
    """A run directory whose trajectory.tum is a FIFO: "not a regular file" naming it,
    not "no trajectory.tum"."""
    truth = tmp_path / "truth.tum"
    truth.write_text(TUM, encoding="utf-8")
    est = tmp_path / "est"
    est.mkdir()
    os.mkfifo(est / "trajectory.tum")
    for args in ([est], [truth, "--compare", est]):
        code, out, err = cli("evaluate", truth, *args, "-o", tmp_path / "rep")
        assert code == errors.EXIT_INPUT and out == "", err
        one_error(err, est / "trajectory.tum", "not a regular file")
    assert not (tmp_path / "rep").exists()


def test_evaluate_into_its_map_directory_is_refused(tmp_path: Path) -> None:
    """``evaluate ... --map fgm -o fgm`` is refused as ``run`` refuses it; the map's
    directory is left as it was."""
    truth = tmp_path / "truth.tum"
    truth.write_text(TUM, encoding="utf-8")
    fgm = tmp_path / "fgm"
    fgm.mkdir()
    (fgm / "fgm.npz").write_bytes(b"map")
    code, out, err = cli("evaluate", truth, truth, "--map", fgm, "-o", fgm)
    assert code == errors.EXIT_INPUT and out == "", err
    one_error(err, fgm, "same as an input")
    assert sorted(p.name for p in fgm.iterdir()) == ["fgm.npz"]


def test_run_calibration_inside_its_output_is_refused_first(tmp_path: Path) -> None:
    """``run --calibration A/calibration.yaml -o A``: refused before the log is read
    (the run would replace its own input), A as it was."""
    a = tmp_path / "A"
    a.mkdir()
    (a / "calibration.yaml").write_text("mine\n", encoding="utf-8")
    code, out, err = cli("run", tmp_path / "absent.mcap", "-o", a,
                         "--calibration", a / "calibration.yaml")  # fmt: skip
    assert code == errors.EXIT_INPUT and out == "", err
    one_error(err, a / "calibration.yaml", "same as an input")
    assert (a / "calibration.yaml").read_text(encoding="utf-8") == "mine\n"


def test_run_calibration_csv_is_named_as_maps_input(tmp_path: Path) -> None:
    """``run --calibration RUN/calibration.csv`` (map's input, not run's): one line naming
    the file, saying a calibration.yaml was expected and the CSV is map's, without
    Python's own error text; nothing written."""
    import numpy as np

    from fuzzyslam.slam import calibration, calibration_files

    model = calibration.Calibration("wheels", 0.3, np.ones(3), np.eye(3) * 1e-4)
    csv_path = tmp_path / "r1" / "calibration.csv"
    csv_path.parent.mkdir()
    rows = [calibration_files.csv_row(t, model.factors, model.cov) for t in (0.0, 1.0)]
    calibration_files.write_csv(csv_path, model, rows)
    code, out, err = cli("run", SAMPLE, "-o", tmp_path / "est", "--calibration", csv_path)
    assert code == errors.EXIT_INPUT and out == "", err
    one_error(err, csv_path, "not a calibration.yaml", "'map --calibration'")
    assert "string indices" not in err and "not a calibration file (" not in err
    assert not (tmp_path / "est").exists()


@pytest.mark.slow
def test_map_until_after_the_log_is_noted(micro, tmp_path: Path) -> None:
    """``map --until T`` past the log's last message: the map is made, and one note on
    stderr says T is after the log's end (the summary records freeze_time T)."""
    log, truth = micro
    code, out, err = cli("map", log, "--trajectory", truth, "-o", tmp_path / "fgm",
                         "--config", MICRO, "--no-figures", "--until", "1e6")  # fmt: skip
    assert code == 0, err
    (line,) = err.splitlines()
    assert line.startswith(f"fuzzyslam: note: {log}: --until 1000000 s is after the log's last")
    assert '"freeze_time": 1000000.0' in out


@pytest.mark.slow
def test_run_on_a_cut_off_log_notes_the_loss(micro, tmp_path: Path) -> None:
    """``run`` on a log cut off at 60 %: exit 0 and one note saying how much was lost
    (the summary's log_damage)."""
    log, _ = micro
    cut = tmp_path / "cut.mcap"
    data = log.read_bytes()
    cut.write_bytes(data[: int(0.6 * len(data))])
    code, _, err = cli("run", cut, "-o", tmp_path / "est", "--config", MICRO)
    assert code == 0, err
    (line,) = err.splitlines()
    assert line.startswith(f"fuzzyslam: note: {cut}: the log is damaged or cut off: ")
    assert "bytes lost" in line and "log_damage" in line


def test_map_on_a_cut_off_log_notes_the_loss(micro, tmp_path: Path) -> None:
    """``map`` on a log cut off at 60 %: exit 0 and the one note ``run`` gives (the same
    wording), saying the map covers the intact part only (the summary's log_damage)."""
    log, truth = micro
    cut = tmp_path / "cut.mcap"
    data = log.read_bytes()
    cut.write_bytes(data[: int(0.6 * len(data))])
    code, out, err = cli("map", cut, "--trajectory", truth, "-o", tmp_path / "fgm",
                         "--config", MICRO, "--no-figures")  # fmt: skip
    assert code == 0, err
    (line,) = err.splitlines()
    assert line.startswith(f"fuzzyslam: note: {cut}: the log is damaged or cut off: ")
    assert "bytes lost" in line and "the map covers the intact part" in line
    assert '"truncated": true' in out
