"""The config a stage takes without --config: the preset for the kind of robot the log
records (fuzzyslam/presets.py), the map's own with ``run --map``, and the summaries'
``config``.

Logs: the committed MRCLAM excerpt (data/real/mrclam6_excerpt: odometry and PoseArray
landmark detections), the CARMEN excerpt (data/carmen_fr079_excerpt: a laser and a
9-sonar ring, no lamps) and the simulated sample (data/sample.mcap).
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from conftest import run_cli

from fuzzyslam.presets import ConfigChoice, choose, resolve

ROOT = Path(__file__).resolve().parents[1]
MRCLAM = ROOT / "data" / "real" / "mrclam6_excerpt" / "log.mcap"
CARMEN = ROOT / "data" / "carmen_fr079_excerpt"
SAMPLE = ROOT / "data" / "sample.mcap"

ODOM = {"/odom": "nav_msgs/msg/Odometry"}
RANGE, SCAN = "sensor_msgs/msg/Range", "sensor_msgs/msg/LaserScan"
RING = {f"/sonar/s{i:02d}": RANGE for i in (0, 1, 2, 12, 13)}


@pytest.mark.parametrize(
    ("topics", "simulated", "ranges", "preset"),
    [
        ({**ODOM, **RING}, True, None, "paper"),  # simulated: its scenario's config
        ({**ODOM, "/ceiling_camera/image_raw": "sensor_msgs/msg/Image", **RING}, False, None,
         "paper"),
        ({**ODOM, "/ceiling_camera/image_raw/compressed": "sensor_msgs/msg/CompressedImage"},
         False, None, "paper"),
        ({**ODOM, "/ceiling_camera/detections": "geometry_msgs/msg/PoseArray"}, False, None,
         "paper"),
        ({**ODOM, "/landmark_detections": "geometry_msgs/msg/PoseArray"}, False, None,
         "real_detections"),
        ({**ODOM, "/landmark_detections": "vision_msgs/msg/Detection3DArray", **RING}, False,
         None, "real_detections"),
        ({**ODOM, **RING, "/scan": SCAN}, False, None, "real_building_sonar"),
        ({**ODOM, **RING, "/scan": SCAN}, False, "scan", "real_building_scan"),
        ({**ODOM, "/scan": SCAN}, False, None, "real_building_scan"),
        ({**ODOM, **RING}, False, "sonar", "real_building_sonar"),
        # the right names with other types, or the right types under other names: none
        ({**ODOM, "/landmark_detections": "std_msgs/msg/String"}, False, None, "paper"),
        ({**ODOM, "/scan": "sensor_msgs/msg/PointCloud2"}, False, None, "paper"),
        ({**ODOM, "/sonar/s00": SCAN}, False, None, "paper"),
        ({**ODOM, "/sonar/front": RANGE}, False, None, "paper"),
        ({**ODOM, "/scan": SCAN}, False, "sonar", "paper"),  # the stage then names /sonar/sNN
        (ODOM, False, None, "paper"),
    ],
)  # fmt: skip
def test_the_preset_follows_the_rules(topics, simulated, ranges, preset) -> None:
    """Each rule of presets.choose, and the near misses that must not match it."""
    name, why = choose(topics, simulated, ranges)
    assert name == preset, why
    assert why


def test_a_given_config_comes_first_as_given(tmp_path, monkeypatch) -> None:
    """--config wins over the map and the log, recorded as given (a summary does not
    name the folder it was made in); a map also records its file from the map's folder
    (``file_from_map``), an embedded name as it is."""
    (tmp_path / "mine.yaml").write_text("extends: real_detections\nname: mine\n")
    monkeypatch.chdir(tmp_path)
    got = resolve("mine.yaml", CARMEN / "log.mcap", tmp_path)
    assert got == ConfigChoice("mine.yaml", "--config")
    assert got.as_dict("mine") == {"name": "mine", "source": "mine.yaml", "chosen_by": "--config"}
    assert got.as_dict("mine", tmp_path / "maps" / "fgm")["file_from_map"] == "../../mine.yaml"
    assert "file_from_map" not in ConfigChoice("quick", "--config").as_dict("quick", tmp_path)
    assert resolve("quick", MRCLAM) == ConfigChoice("quick", "--config")


def test_a_map_passes_its_config_on_while_it_can_be_loaded(tmp_path, monkeypatch) -> None:
    """``run --map`` without --config takes the map's config: an embedded name, or a
    file found from the map's folder (the tree moved, the run started elsewhere) or where
    it was given; a file since removed, or a map whose summary has no config (older
    code), leaves the choice to the log's streams."""
    fgm = tmp_path / "tree" / "fgm"
    fgm.mkdir(parents=True)

    def with_config(config) -> ConfigChoice:
        summary = {"config": config} if config is not None else {"log": "x"}
        (fgm / "summary.json").write_text(json.dumps(summary))
        return resolve(None, CARMEN / "log.mcap", fgm)

    got = with_config({"source": "real_building_scan"})
    assert got == ConfigChoice("real_building_scan", f"the map's config ({fgm})")
    mine = tmp_path / "tree" / "mine.yaml"
    mine.write_text("extends: real_building_scan\n")
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    monkeypatch.chdir(elsewhere)  # "mine.yaml" as given does not resolve from here
    got = with_config({"source": "mine.yaml", "file_from_map": "../mine.yaml"})
    assert Path(got.source).resolve() == mine.resolve()
    assert with_config({"source": str(mine)}).source == str(mine)  # an absolute path given
    mine.unlink()
    for gone in ({"source": str(mine)}, {"source": "mine.yaml", "file_from_map": "../mine.yaml"},
                 None, {"source": 7}, ["not a mapping"]):  # fmt: skip
        got = with_config(gone)
        assert got.source == "real_building_sonar", gone  # the log's ring
        assert got.why.startswith("the log's streams: 9 sonars")


def test_a_log_that_cannot_be_read_leaves_the_default(tmp_path) -> None:
    """No log (or not an MCAP): the default, and the stage's own read says what is wrong."""
    assert resolve(None, tmp_path / "absent.mcap") == ConfigChoice("paper", "default")
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(b"not an mcap")
    assert resolve(None, bad) == ConfigChoice("paper", "default")


def test_a_simulated_log_keeps_the_paper_config(tmp_path, capsys) -> None:
    """The sample (a simulated log, lamps and 16 sonars): paper, without a note; the
    summary records it."""
    code, s, err = run_cli(["run", str(SAMPLE), "-o", str(tmp_path / "r")], capsys)
    assert code == 0, err
    assert "no --config" not in err
    assert s["config"] == {"name": "paper", "source": "paper",
                           "chosen_by": "the log's streams: a simulated log"}  # fmt: skip


@pytest.mark.slow
def test_a_landmark_log_runs_as_with_its_preset(tmp_path, capsys) -> None:
    """The MRCLAM excerpt without --config: real_detections (said on stderr, in the
    summary), the same trajectory byte for byte as with --config real_detections; with
    the default paper config it would be dead reckoning."""
    code, auto, err = run_cli(["run", str(MRCLAM), "-o", str(tmp_path / "auto")], capsys)
    assert code == 0, err
    (line,) = [x for x in err.splitlines() if "no --config" in x]
    assert str(MRCLAM) in line and "real_detections" in line and "/landmark_detections" in line
    assert auto["config"]["name"] == "real_detections"
    assert auto["config"]["chosen_by"].startswith("the log's streams: landmark detections")
    assert auto["lamp_source"].startswith("detections")
    args = ["run", str(MRCLAM), "--config", "real_detections", "-o", str(tmp_path / "given")]
    code, given, err = run_cli(args, capsys)
    assert code == 0 and "no --config" not in err, err
    assert given["config"] == {"name": "real_detections", "source": "real_detections",
                               "chosen_by": "--config"}  # fmt: skip
    for name in ("trajectory.tum", "landmarks.yaml", "covariance.csv"):
        assert (tmp_path / "auto" / name).read_bytes() == (tmp_path / "given" / name).read_bytes()
    code, paper, _ = run_cli(["run", str(MRCLAM), "--config", "paper", "-o", str(tmp_path / "p")],
                             capsys)  # fmt: skip
    assert code == 0 and paper["lamp_source"].startswith("none")


@pytest.mark.slow
@pytest.mark.parametrize("ranges", ["sonar", "scan"])
def test_a_building_log_maps_and_localises_with_its_preset(ranges, tmp_path, capsys) -> None:
    """The CARMEN excerpt without --config: ``map`` takes the sonar preset (the ring, as
    --ranges chooses by default) or, with --ranges scan, the laser's; ``run --map`` then
    takes the map's config. Maps and trajectories are byte for byte those of the
    presets given by name."""
    log, truth = str(CARMEN / "log.mcap"), str(CARMEN / "truth.tum")
    preset = f"real_building_{ranges}"
    pick = ["--ranges", "scan"] if ranges == "scan" else []
    out = {}
    for how, cfg in (("auto", []), ("given", ["--config", preset])):
        fgm = tmp_path / f"fgm_{how}"
        code, s, err = run_cli(
            ["map", log, "--trajectory", truth, *pick, *cfg, "--no-figures", "-o", str(fgm)],
            capsys,
        )
        assert code == 0, err
        assert s["config"]["name"] == preset and s["range_sensor"]["kind"] == ranges
        assert ("no --config" in err) == (how == "auto")
        # the run reads the map's config (its ranges too) with no option but --map
        code, r, err = run_cli(
            ["run", log, "--map", str(fgm), "--fix", "pose", "--fix-from", "0", *cfg,
             "-o", str(tmp_path / f"run_{how}")],
            capsys,
        )  # fmt: skip
        assert code == 0, err
        assert r["config"]["name"] == preset and r["range_sensor"]["kind"] == ranges
        out[how] = (s, r, err)
    assert out["auto"][1]["config"]["chosen_by"] == f"the map's config ({tmp_path / 'fgm_auto'})"
    assert "from the map's config" in out["auto"][2]
    for a, b in (("fgm_auto/fgm.npz", "fgm_given/fgm.npz"),
                 ("run_auto/trajectory.tum", "run_given/trajectory.tum")):  # fmt: skip
        assert (tmp_path / a).read_bytes() == (tmp_path / b).read_bytes()


def test_the_help_says_how_the_default_is_chosen(capsys) -> None:
    """run and map --help name the presets; evaluate keeps the paper default."""
    from fuzzyslam.cli import main

    for cmd, words in (("run", ["map's config", "real_building_scan"]),
                       ("map", ["real_detections", "real_building_sonar"]),
                       ("evaluate", ["paper.yaml"])):  # fmt: skip
        with pytest.raises(SystemExit):
            main([cmd, "--help"])
        text = " ".join(capsys.readouterr().out.split())
        for w in words:
            assert w in text, (cmd, w)


@pytest.mark.slow
def test_streams_under_other_names_are_named_with_the_config_that_reads_them(
    tmp_path, capsys
) -> None:
    """The MRCLAM excerpt with its detections on /markers: no preset reads it, so the run
    is dead reckoning, and the note names the stream and the config that reads it; that
    config, written as the note says, gives the trajectory of the original log with
    real_detections, byte for byte."""
    import re

    from test_robust_logs import rewrite

    log = tmp_path / "renamed.mcap"

    def rename(m):
        topic = "/markers" if m.topic == "/landmark_detections" else m.topic
        return [(topic, m.typename, m.msg, m.t)]

    rewrite(MRCLAM, log, rename)
    code, s, err = run_cli(["run", str(log), "-o", str(tmp_path / "dr")], capsys)
    assert code == 0 and s["lamp_source"].startswith("none"), err
    (line,) = [x for x in err.splitlines() if "dead reckoning" in x]
    extends, topics = re.search(r"'(extends: \w+)' and '(topics: \{[^}]+\})'", line).groups()
    assert "/markers (PoseArray" in line
    (tmp_path / "mine.yaml").write_text(f"{extends}\n{topics}\n")
    code, s, err = run_cli(
        ["run", str(log), "--config", str(tmp_path / "mine.yaml"), "-o", str(tmp_path / "m")],
        capsys,
    )
    assert code == 0 and s["lamp_source"] == "detections (/markers)", err
    args = ["run", str(MRCLAM), "--config", "real_detections", "-o", str(tmp_path / "orig")]
    assert run_cli(args, capsys)[0] == 0
    orig = (tmp_path / "orig" / "trajectory.tum").read_bytes()
    assert (tmp_path / "m" / "trajectory.tum").read_bytes() == orig


@pytest.mark.slow
def test_a_failing_command_still_says_one_line(tmp_path) -> None:
    """The chosen preset is said once the log and its sensors are found: ``map`` on the
    landmark excerpt (real_detections chosen, no range sensor) and ``run`` on it with
    its odometry renamed fail with the error alone; the same ``map`` on the building
    excerpt says its preset."""
    from test_robust_logs import cli, rewrite

    traj = tmp_path / "t.tum"
    traj.write_text("0 0 0 0 0 0 0 1\n1e10 0 0 0 0 0 0 1\n")
    code, out, err = cli("map", MRCLAM, "--trajectory", traj, "-o", tmp_path / "m")
    assert code == 3 and out == "", err
    (line,) = err.splitlines()
    assert "missing stream(s)" in line and "no --config" not in line
    log = tmp_path / "odom.mcap"
    rewrite(MRCLAM, log, lambda m: [("/wheel" if m.topic == "/odom" else m.topic,
                                     m.typename, m.msg, m.t)])  # fmt: skip
    code, out, err = cli("run", log, "-o", tmp_path / "r")
    assert code == 3 and out == "", err
    (line,) = err.splitlines()
    assert "missing stream(s) /odom" in line
    code, _, err = cli("map", CARMEN / "log.mcap", "--trajectory", CARMEN / "truth.tum",
                       "--no-figures", "-o", tmp_path / "b")  # fmt: skip
    assert code == 0, err
    assert "no --config: real_building_sonar, from the log's streams: 9 sonars" in err
