"""A short simulated recording: every message decodes (rosbags AND mcap-ros2), streams,
metadata, determinism, sensor consistency with ground truth, and CLI bad input."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest
from conftest import assert_offered_qos
from mcap.reader import make_reader
from mcap.records import Chunk, Message, Metadata
from mcap.stream_reader import StreamReader
from mcap_ros2.decoder import DecoderFactory
from rosbags.highlevel import AnyReader

from fuzzyslam.camera import CeilingCamera
from fuzzyslam.config import load_config
from fuzzyslam.se2 import inverse_transform_points, wrap_angle
from fuzzyslam.sim.record import simulate_to_mcap
from fuzzyslam.streams.logmeta import read_scenario, read_world
from fuzzyslam.streams.messages import image_to_array, pose_of
from fuzzyslam.streams.reader import LogReader
from fuzzyslam.streams.sonar import group_rings
from fuzzyslam.streams.topics import Topics

TINY = """\
extends: quick.yaml
name: tiny
scenario:
  runs: 2
  lap_fraction: 0.12
  lamp_failures:
    - {run: 2, lamps: [0, 1]}
  bumps:
    - {run: 1, fraction: 0.5, angle_deg: 10.0}
"""


def _cli(*args: str, cwd: Path | None = None) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-c", "from fuzzyslam.cli import main; main()", *args],
        capture_output=True,
        text=True,
        cwd=cwd,
        env={"FUZZYSLAM_NO_PROGRESS": "1", "MPLBACKEND": "Agg", "PATH": "/usr/bin:/bin"},
    )


@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    d = tmp_path_factory.mktemp("sim")
    cfg_path = d / "tiny.yaml"
    cfg_path.write_text(TINY)
    out = d / "tiny.mcap"
    res = _cli("simulate", str(cfg_path), "-o", str(out), "--seed", "4", "--preview",
               str(d / "tiny.png"), "--truth-tum", str(d / "truth.tum"))  # fmt: skip
    assert res.returncode == 0, res.stderr
    summary = json.loads(res.stdout)
    return {"dir": d, "config": cfg_path, "mcap": out, "summary": summary,
            "cfg": load_config(cfg_path, 4)}  # fmt: skip


def test_every_message_decodes_with_rosbags(tiny):
    n = 0
    with AnyReader([tiny["mcap"]]) as reader:
        assert_offered_qos(reader.connections)  # /tf_static latched, the sensors not
        for conn, _t, raw in reader.messages():
            msg = reader.deserialize(raw, conn.msgtype)
            assert msg is not None
            n += 1
    assert n == tiny["summary"]["messages_total"]
    # the distribution of its definitions and QoS format, as rosbag2 records it
    assert LogReader(tiny["mcap"]).metadata["rosbag2"] == {"ROS_DISTRO": "humble"}


def test_every_message_decodes_with_mcap_ros2(tiny):
    counts: dict[str, int] = {}
    with open(tiny["mcap"], "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        for _schema, channel, message, decoded in reader.iter_decoded_messages():
            assert decoded is not None
            if hasattr(decoded, "header"):  # MCAP log time = header stamp
                st = decoded.header.stamp
                assert message.log_time == st.sec * 1_000_000_000 + st.nanosec
            counts[channel.topic] = counts.get(channel.topic, 0) + 1
    assert counts == tiny["summary"]["messages"]


def test_streams_present_and_rings_share_a_stamp(tiny):
    topics = Topics()
    r = LogReader(tiny["mcap"])
    sonar = [topics.sonar(i) for i in range(16)]
    others = [topics.image, topics.camera_info, topics.joint_states, topics.odom]
    others += [topics.tf_static, topics.ground_truth, topics.events, topics.world_markers]
    r.require([*sonar, *others])
    counts = {t: r.counts[t] for t in sonar}
    assert len(set(counts.values())) == 1 and counts[sonar[0]] > 10
    rings = list(group_rings(r.messages(sonar), {t: i for i, t in enumerate(sonar)}, 16, 1e-6))
    assert len(rings) == counts[sonar[0]]
    assert all(np.all(np.isfinite(ring.ranges)) for ring in rings)
    dt = np.diff([ring.t for ring in rings])
    assert np.allclose(dt, 1.0 / tiny["cfg"].sonar.rate_hz)
    assert r.counts[topics.image] == r.counts[topics.camera_info]


def test_metadata_first_and_consistent(tiny):
    with open(tiny["mcap"], "rb") as f:
        first = []
        for rec in StreamReader(f).records:
            if isinstance(rec, (Chunk, Message)):
                break
            if isinstance(rec, Metadata):
                first.append(rec.name)
    assert first == ["rosbag2", "fuzzyslam.world", "fuzzyslam.scenario"]
    r = LogReader(tiny["mcap"])
    world, scen = read_world(r), read_scenario(r)
    assert len(world.lamps) == 15 and len(world.walls) == 8 and len(world.corridors) == 4
    assert [run for run, _a, _b in scen.run_intervals()] == [1, 2]
    kinds = [e.kind for e in scen.events]
    assert kinds.count("bump") == 1 and kinds.count("lamp_failure") == 1
    events = [json.loads(m.msg.data) for m in r.messages([Topics().events])]
    assert [e["kind"] for e in events] == kinds
    assert scen.duration == pytest.approx(r.end)
    # odometry and ground truth both start at the scenario's start pose
    gt = next(iter(r.messages([Topics().ground_truth])))
    od = next(iter(r.messages([Topics().odom])))
    assert np.allclose(pose_of(gt.msg.pose.pose), scen.start_pose)
    assert np.allclose(pose_of(od.msg.pose.pose), scen.start_pose)


@pytest.mark.slow
def test_same_seed_same_bytes_other_seed_differs(tiny, tmp_path):
    cfg = tiny["cfg"]
    a, b = tmp_path / "a.mcap", tmp_path / "b.mcap"
    simulate_to_mcap(cfg, a)
    same = a.read_bytes() == tiny["mcap"].read_bytes()  # a bool: no diff of megabytes
    assert same
    cfg.seed = 5
    simulate_to_mcap(cfg, b)
    assert a.read_bytes() != b.read_bytes()


def test_frames_show_the_true_lamps(tiny):
    """Blobs of a frame, un-projected with CameraInfo, land on the true lamps (GT pose)."""
    topics = Topics()
    r = LogReader(tiny["mcap"])
    world = read_world(r)
    lamps = world.lamp_array
    gt = {round(m.t, 6): pose_of(m.msg.pose.pose) for m in r.messages([topics.ground_truth])}
    info = next(iter(r.messages([topics.camera_info]))).msg
    cam = CeilingCamera.from_camera_info(info, world.ceiling_height)
    t_fail = min(e.t for e in read_scenario(r).events if e.kind == "lamp_failure")
    errs, counts = [], []
    for m in r.messages([topics.image]):
        pose = gt.get(round(m.t, 6))
        if pose is None:
            continue
        img = image_to_array(m.msg)
        _n, _lab, st, cents = cv2.connectedComponentsWithStats((img > 200).astype(np.uint8))
        x, y, w, h = st[1:, 0], st[1:, 1], st[1:, 2], st[1:, 3]
        inside = (x > 0) & (y > 0) & (x + w < img.shape[1]) & (y + h < img.shape[0])
        pts = cam.unproject(cents[1:][inside])  # blobs cut by the border are biased
        rel = inverse_transform_points(pose, lamps)
        for p in pts:
            errs.append(np.min(np.linalg.norm(rel - p, axis=1)))
        if m.t < t_fail:
            counts.append(int(inside.sum()))
    assert len(errs) > 20
    assert np.median(errs) < 0.01 and np.max(errs) < 0.05
    assert np.mean(np.array(counts) >= 2) > 0.95


def test_dead_reckoning_and_sonar_are_plausible(tiny):
    topics = Topics()
    r = LogReader(tiny["mcap"])
    gt = np.array([pose_of(m.msg.pose.pose) for m in r.messages([topics.ground_truth])])
    od = np.array([pose_of(m.msg.pose.pose) for m in r.messages([topics.odom])])
    err = np.hypot(*(od[:, :2] - gt[:, :2]).T)
    assert tiny["summary"]["dead_reckoning_end_error_m"] == pytest.approx(err[-1], abs=1e-3)
    # the bump is unseen by odometry: at least ~10 deg of heading error remains after it
    assert np.degrees(np.abs(wrap_angle(od[-1, 2] - gt[-1, 2]))) > 5.0
    # side sonars (+-90 deg) mostly read the corridor half-width minus the robot radius
    side = [m.msg.range for m in r.messages([topics.sonar(4), topics.sonar(12)])]
    expect = 1.0 - 0.225
    assert np.median(side) == pytest.approx(expect, abs=0.1)


def test_preview_and_summary(tiny):
    png = tiny["dir"] / "tiny.png"
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    s = tiny["summary"]
    assert s["file"] == str(tiny["mcap"]) and s["duration_s"] > 0
    assert 0.0 <= s["frames_two_lamps_fraction"] <= 1.0


def test_truth_tum_is_the_logs_ground_truth(tiny):
    """--truth-tum: the poses of /ground_truth/odom, every one, as TUM (for evo)."""
    from fuzzyslam.streams.tum import read_tum

    t, poses = read_tum(tiny["dir"] / "truth.tum")
    gt = [(m.t, *pose_of(m.msg.pose.pose))
          for m in LogReader(tiny["mcap"]).messages([Topics().ground_truth])]  # fmt: skip
    gt = np.array(gt)
    assert len(t) == len(gt) > 100 and tiny["summary"]["truth_tum"].endswith("truth.tum")
    assert np.allclose(t, gt[:, 0], atol=1e-9, rtol=0)
    # TUM: positions to the micrometre, quaternions to nine decimals
    assert np.allclose(poses[:, :2], gt[:, 1:3], atol=5.1e-7, rtol=0)
    assert np.allclose(wrap_angle(poses[:, 2] - gt[:, 3]), 0.0, atol=1e-8)


def test_help_explains_streams():
    res = _cli("simulate", "--help")
    assert res.returncode == 0
    for word in ("/sonar/s00", "--seed", "--preview", "--truth-tum", "fuzzyslam.world", "CONFIG"):
        assert word in res.stdout


@pytest.mark.parametrize(
    "case",
    ["missing", "malformed", "unknown_key", "bad_value", "no_dir", "out_is_input"],
)
def test_bad_input_one_line_no_file(tmp_path, case):
    cfg = tmp_path / "c.yaml"
    out = tmp_path / "out.mcap"
    if case == "missing":
        cfg = tmp_path / "nope.yaml"
    elif case == "malformed":
        cfg.write_text("scenario: [runs: 2\n")
    elif case == "unknown_key":
        cfg.write_text("extends: quick.yaml\nsonar:\n  rayz: 3\n")
    elif case == "bad_value":
        cfg.write_text("extends: quick.yaml\nscenario:\n  lamp_failures: [{run: 1, lamps: [99]}]\n")
    elif case == "no_dir":
        cfg.write_text("extends: quick.yaml\n")
        out = tmp_path / "missing_dir" / "out.mcap"
    elif case == "out_is_input":
        cfg.write_text("extends: quick.yaml\n")
        out = cfg
    before = cfg.read_bytes() if cfg.exists() else None
    res = _cli("simulate", str(cfg), "-o", str(out))
    assert res.returncode == 3
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and "error" in lines[0] and "Traceback" not in res.stderr
    assert str(cfg.name if case != "no_dir" else out.name) in lines[0]
    if case == "out_is_input":
        assert cfg.read_bytes() == before
    else:
        assert not out.exists()
    leftovers = [p for p in tmp_path.rglob("*") if p.name.endswith(".part")]
    assert leftovers == []


SIM_SECTIONS = ("world", "robot", "sonar", "camera", "scenario")


def test_sample_recording_matches_its_config():
    """data/sample.mcap is small, complete and made from the current configs/sample.yaml."""
    path = Path(__file__).resolve().parents[1] / "data" / "sample.mcap"
    assert path.stat().st_size < 5_000_000
    r = LogReader(path)
    assert read_world(r) is not None
    scen = read_scenario(r)
    cfg = load_config("sample", scen.seed)
    from fuzzyslam.config import config_to_dict

    now = config_to_dict(cfg)
    for section in SIM_SECTIONS:
        assert scen.config[section] == now[section], f"regenerate data/ ({section} changed)"
    assert r.counts[Topics().image] > 100 and scen.run_intervals()[0][0] == 1


def test_embedded_variants_load():
    for name in ("paper", "quick", "sample", "paper_bumps", "paper_dark"):
        cfg = load_config(name)
        assert cfg.scenario.runs >= 1
    bumps = load_config("paper_bumps").scenario.bumps
    assert sorted(b.run for b in bumps) == [1, 2, 3, 4, 5, 6]
    assert all(abs(b.angle_deg) == 10.0 for b in bumps)


@pytest.mark.slow
def test_sample_is_what_its_documented_command_makes(tmp_path: Path) -> None:
    """data/README.md's command regenerates data/sample.mcap and sample.png byte for
    byte (the embedded config metadata was stale before)."""
    import re

    from test_robust_logs import cli

    root = Path(__file__).resolve().parents[1]
    readme = (root / "data" / "README.md").read_text(encoding="utf-8")
    command = re.search(r"^\s+fuzzyslam (simulate .*)$", readme, re.MULTILINE)
    assert command is not None, "data/README.md no longer shows the simulate command"
    args = command.group(1).replace("data/", f"{tmp_path}/").split()
    code, _, err = cli(*args)
    assert code == 0, err
    for name in ("sample.mcap", "sample.png"):
        fresh, committed = (tmp_path / name).read_bytes(), (root / "data" / name).read_bytes()
        same = fresh == committed  # a bool: pytest's diff of megabytes takes minutes
        assert same, f"regenerate data/{name} with data/README.md's command"
