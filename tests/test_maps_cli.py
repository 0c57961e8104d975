"""`fuzzyslam map` end to end on a short simulated log (true poses as the trajectory)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import yaml
from conftest import shared_dir

from fuzzyslam.cli import main
from fuzzyslam.maps.build import covered
from fuzzyslam.maps.mapio import load_fgm, load_references, read_pgm
from fuzzyslam.streams.messages import pose_of, range_msg, stamp_to_sec
from fuzzyslam.streams.reader import LogReader
from fuzzyslam.streams.tum import read_tum, write_tum
from fuzzyslam.streams.writer import LogWriter


def run_cli(args: list[str], capsys) -> tuple[int, str, str]:
    with pytest.raises(SystemExit) as exc:
        main(args)
    out, err = capsys.readouterr()
    return int(exc.value.code or 0), out, err


@pytest.fixture(scope="session")
def one_run_log(tmp_path_factory) -> tuple[Path, Path]:
    """A one-run simulated log and its ground truth as a TUM trajectory (once per test run:
    conftest.shared_dir)."""

    def build(d: Path) -> None:
        cfg = d / "one_run.yaml"
        cfg.write_text("extends: quick.yaml\nname: one_run\nscenario:\n  runs: 1\n")
        log = d / "one_run.mcap"
        with pytest.raises(SystemExit) as exc:
            main(["simulate", str(cfg), "-o", str(log)])
        assert exc.value.code == 0
        t, p = [], []
        for m in LogReader(log).messages(["/ground_truth/odom"]):
            t.append(m.t)
            p.append(pose_of(m.msg.pose.pose))
        write_tum(d / "truth.tum", np.array(t), np.array(p))

    d = shared_dir(tmp_path_factory, "maps-one-run", build)
    return d / "one_run.mcap", d / "truth.tum"


@pytest.fixture(scope="session")
def built_map(one_run_log, tmp_path_factory):
    log, tum = one_run_log

    def build(d: Path) -> None:
        with pytest.raises(SystemExit) as exc:
            main(["map", str(log), "--trajectory", str(tum), "-o", str(d / "fgm")])
        assert exc.value.code == 0

    return shared_dir(tmp_path_factory, "maps-built", build) / "fgm"


@pytest.mark.slow
def test_map_writes_every_output(built_map):
    out = built_map
    for name in (
        "fgm.npz",
        "fgm.yaml",
        "fgm.pgm",
        "references.yaml",
        "fgm.png",
        "conflict.png",
        "hough.png",
        "summary.json",
    ):
        assert (out / name).is_file(), name
    f = load_fgm(out / "fgm.npz")
    assert f.frozen and f.log_id.startswith("world-")
    m = f.map
    np.testing.assert_allclose(m.m_e + m.m_o + m.m_t + m.m_c, 1.0, atol=1e-5)
    meta = yaml.safe_load((out / "fgm.yaml").read_text())
    assert meta["mode"] == "trinary" and meta["negate"] == 0
    assert meta["origin"] == pytest.approx([m.grid.origin[0], m.grid.origin[1], 0.0], abs=1e-9)
    img = read_pgm(out / meta["image"])
    assert img.shape == m.grid.shape
    # top row of the picture is the map's largest y: the occupied cells agree after a flip
    occupied = np.flipud(img) == 0
    assert occupied.any() and np.all(m.pignistic_occupied()[occupied] > 0.65)


@pytest.mark.slow
def test_map_references_match_true_corridors(built_map):
    summary = json.loads((built_map / "summary.json").read_text())
    refs = load_references(built_map / "references.yaml")
    assert len(refs) == 4 == len(summary["reference_truth"])
    for r in refs:
        assert 0.0 <= r["angle"] < np.pi
        assert r["angle_deg"] == pytest.approx(np.rad2deg(r["angle"]))
    errors = [abs(t["error_deg"]) for t in summary["reference_truth"]]
    assert max(errors) < 0.5, errors
    assert {t["true_corridor"] for t in summary["reference_truth"]} == {
        "corridor_0",
        "corridor_1",
        "corridor_2",
        "corridor_3",
    }
    assert summary["wall_quality"]["recall"] > 0.9
    assert summary["readings_skipped"] == 0 and summary["readings_used"] > 1000


def test_help(capsys):
    code, out, _ = run_cli(["map", "--help"], capsys)
    assert code == 0
    for opt in ("--trajectory", "--until-run", "--until", "--skip-uncovered", "--config"):
        assert opt in out


@pytest.mark.slow
def test_trajectory_not_covering_the_rings(one_run_log, tmp_path, capsys):
    log, tum = one_run_log
    t, p = read_tum(tum)
    short = tmp_path / "short.tum"
    half = len(t) // 2
    write_tum(short, t[:half], p[:half])
    out = tmp_path / "fgm"
    code, _, err = run_cli(["map", str(log), "--trajectory", str(short), "-o", str(out)], capsys)
    assert code == 3 and "does not cover" in err and len(err.strip().splitlines()) == 1
    assert not out.exists()
    code, stdout, _ = run_cli(
        [
            "map",
            str(log),
            "--trajectory",
            str(short),
            "-o",
            str(out),
            "--skip-uncovered",
            "--no-figures",
            "--until-run",
            "1",
        ],
        capsys,
    )
    assert code == 0
    s = json.loads(stdout)
    assert s["readings_skipped"] > 0 and s["rings_skipped"] > 0
    assert (out / "fgm.npz").is_file()


@pytest.mark.slow
def test_unreadable_trajectory(one_run_log, tmp_path, capsys):
    log, _ = one_run_log
    bad = tmp_path / "bad.tum"
    bad.write_text("0 1 2\nnot a trajectory\n")
    out = tmp_path / "fgm"
    code, _, err = run_cli(["map", str(log), "--trajectory", str(bad), "-o", str(out)], capsys)
    assert code == 3 and "bad.tum" in err and len(err.strip().splitlines()) == 1
    assert not out.exists()


@pytest.mark.slow
def test_missing_sonar_stream(one_run_log, tmp_path, capsys):
    log, tum = one_run_log
    cfg = tmp_path / "nosonar.yaml"
    cfg.write_text("extends: quick.yaml\ntopics:\n  sonar_prefix: /nope/s\n")
    out = tmp_path / "fgm"
    code, _, err = run_cli(
        ["map", str(log), "--trajectory", str(tum), "-o", str(out), "--config", str(cfg)], capsys
    )
    assert code == 3 and "missing stream" in err and "/nope/s00" in err
    assert not out.exists()


def test_window_without_readings(tmp_path, capsys):
    """A log whose sonar rings all come after the window's end (the log itself starting
    before it: a window ending before the log's first message is refused as such)."""
    log = tmp_path / "late.mcap"
    with LogWriter(log) as w:
        w.write("/other", "sensor_msgs/msg/Range", range_msg(0.5, "x", 1.0, 0.4, 0.1, 6.0), 0.5)
        for t in (5.0, 5.25):
            for i in range(16):
                w.write(
                    f"/sonar/s{i:02d}",
                    "sensor_msgs/msg/Range",
                    range_msg(t, f"sonar_{i:02d}", 1.0, 0.436, 0.15, 6.5),
                    t,
                )
    tum = tmp_path / "t.tum"
    write_tum(tum, np.array([0.0, 10.0]), np.zeros((2, 3)))
    out = tmp_path / "fgm"
    code, _, err = run_cli(
        ["map", str(log), "--trajectory", str(tum), "-o", str(out), "--until", "1.0"], capsys
    )
    assert code == 3 and "no sonar readings" in err
    assert not out.exists()
    code, _, err = run_cli(
        ["map", str(log), "--trajectory", str(tum), "-o", str(out), "--until", "0.1"], capsys
    )
    assert code == 3 and "--until 0.1 s is before the log's first message at 0.500 s" in err
    assert not out.exists()


@pytest.mark.slow
def test_a_trajectory_evo_exports_from_the_log_builds_the_same_map(tmp_path, capsys):
    """The README's recipe for a map without truth.tum: ``evo_traj bag2 LOG.mcap TOPIC
    --save_as_tum`` (evo, a test extra, reads our MCAP directly) on the sample log's
    /ground_truth/odom gives the TUM file for ``map --trajectory``; its FGM equals the
    one built along the same topic (its header stamps) read by fuzzyslam's own reader
    and TUM writer (a second implementation), every mass within 1e-4 (our TUM rounds
    positions to the micrometre, evo's keeps every digit)."""
    import shutil
    import subprocess
    import sys

    evo = Path(sys.executable).with_name("evo_traj")
    if not evo.is_file():
        evo = shutil.which("evo_traj")
        if evo is None:
            pytest.skip("evo_traj not installed (the test extras)")
    log = Path(__file__).resolve().parents[1] / "data" / "sample.mcap"
    done = subprocess.run(
        [str(evo), "bag2", str(log), "/ground_truth/odom", "--save_as_tum"],
        cwd=tmp_path, capture_output=True, text=True, timeout=300,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    exported = tmp_path / "ground_truth_odom.tum"
    msgs = list(LogReader(log).messages(topics=["/ground_truth/odom"]))
    own = tmp_path / "own.tum"
    poses = np.array([pose_of(m.msg.pose.pose) for m in msgs])
    write_tum(own, np.array([stamp_to_sec(m.msg.header.stamp) for m in msgs]), poses)
    maps = []
    for name, traj in (("evo", exported), ("own", own)):
        out = tmp_path / name
        code, _, err = run_cli(
            ["map", str(log), "--trajectory", str(traj), "--config", "sample", "-o", str(out),
             "--no-figures"], capsys,
        )  # fmt: skip
        assert code == 0, err
        maps.append(load_fgm(out / "fgm.npz").map)
    for mass in ("m_e", "m_o", "m_t", "m_c"):  # 4e-5 measured
        assert np.abs(getattr(maps[0], mass) - getattr(maps[1], mass)).max() < 1e-4, mass
    assert maps[0].m_o.max() > 0.5  # walls were found


EXCERPT = Path(__file__).resolve().parents[1] / "data" / "carmen_fr079_excerpt"


def test_covered_at_unix_times():
    """A ring is on the trajectory only within a microsecond of a sample or between two
    close samples, at Unix times as at 0 s (numpy's relative isclose tolerance is hours
    at 1.6e9 s)."""
    for t0 in (0.0, 1.6e9):
        t = t0 + np.arange(0.0, 61.0, 0.2)
        tq = t0 + np.array([-5.0, 0.0, 30.1, 60.0, 60.0 + 4e-7, 61.0, 500.0])
        ok = covered(tq, t, max_gap=1.0)
        np.testing.assert_array_equal(ok, [False, True, True, True, True, False, False])


def test_short_trajectory_of_a_unix_time_log(tmp_path, capsys):
    """The committed Freiburg excerpt (Unix-time stamps) with a trajectory that ends
    halfway: one line naming the uncovered rings, exit 3, no output directory."""
    t, p = read_tum(EXCERPT / "truth.tum")
    short = tmp_path / "short.tum"
    write_tum(short, t[: len(t) // 2], p[: len(t) // 2])
    out = tmp_path / "fgm"
    args = ["map", str(EXCERPT / "log.mcap"), "--trajectory", str(short), "--ranges", "scan"]
    code, _, err = run_cli([*args, "-o", str(out)], capsys)
    line = err.strip().splitlines()[-1]
    assert code == 3 and "short.tum" in line and "does not cover laser scans" in line, err
    assert f"{t[len(t) // 2 - 1]:.2f} s)" in line  # the trajectory's end, to the 10 ms
    assert not out.exists()
    # the covered half maps, the rest said skipped
    code, stdout, _ = run_cli([*args, "--skip-uncovered", "--no-figures", "-o", str(out)], capsys)
    s = json.loads(stdout)
    assert code == 0 and s["rings_skipped"] > 0 and s["rings_used"] > 0
    scans = sum(1 for _ in LogReader(EXCERPT / "log.mcap").messages(["/scan"]))
    assert s["rings_used"] + s["rings_skipped"] == scans
