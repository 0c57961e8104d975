"""What a viewer replays (issue 17): /tf, /map, the fixes and fgm.mcap.

Every message of the new topics is decoded by both rosbags (AnyReader) and
mcap-ros2-support (the decoder Foxglove's parsers follow, which reject ``MSG: pkg/msg/T``
in a schema); the /tf tree is map -> odom -> base_link at every pose and composes to
/slam/pose; /map's size and origin are the nav2 fgm.yaml's.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import test_fixes_sim
import yaml
from click.testing import CliRunner
from conftest import assert_offered_qos, shared_dir
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from rosbags.highlevel import AnyReader

from fuzzyslam.cli import _register, cli
from fuzzyslam.config import load_config
from fuzzyslam.maps import mapio
from fuzzyslam.maps.grid import BeliefMap, Grid
from fuzzyslam.maps.viewer import conflict_values, fgm_messages, occupancy_values
from fuzzyslam.se2 import compose, wrap_angle
from fuzzyslam.streams import cdr
from fuzzyslam.streams import messages as M
from fuzzyslam.streams.typestore import serialize
from fuzzyslam.streams.writer import LogWriter

_register()

dark_case = test_fixes_sim.dark_case  # the session fixture the chain below starts from


def decode_both(path: Path) -> dict[str, list]:
    """topic -> messages decoded by mcap-ros2-support; every message also decodes with
    rosbags (the same count per topic), and no schema names a dependency ``pkg/msg/T``."""
    out: dict[str, list] = {}
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        for schema in reader.get_summary().schemas.values():
            text = schema.data.decode()
            deps = [ln for ln in text.splitlines() if ln.startswith("MSG: ")]
            assert all(ln.count("/") == 1 for ln in deps), (schema.name, deps)
        for _s, channel, _m, decoded in reader.iter_decoded_messages(log_time_order=True):
            out.setdefault(channel.topic, []).append(decoded)
    counts: dict[str, int] = {}
    with AnyReader([Path(path)]) as r:
        assert_offered_qos(r.connections)
        for conn, _t, raw in r.messages():
            assert r.deserialize(raw, conn.msgtype) is not None
            counts[conn.topic] = counts.get(conn.topic, 0) + 1
    assert counts == {k: len(v) for k, v in out.items()}
    return out


def test_tf_block_encoder_equals_rosbags() -> None:
    rng = np.random.default_rng(1)
    t = np.array([0.0, 0.2, 12.345678901, 1.7e9 + 0.25])
    a, b = rng.uniform(-50, 50, (4, 3)), rng.uniform(-50, 50, (4, 3))
    frames = [("map", "odom"), ("odom", "base_link")]
    got = cdr.encode_tf_block(t, frames, [a, b])
    for k in range(len(t)):
        ref = M.tf_message(
            [M.transform_stamped(t[k], p, c, x[k, 0], x[k, 1], 0.0, x[k, 2])
             for (p, c), x in zip(frames, (a, b), strict=True)]
        )  # fmt: skip
        assert got[k] == serialize(ref, M.TF_MESSAGE)
    assert cdr.encode_tf_block(np.zeros(0), frames, [np.zeros((0, 3))] * 2) == []


def _small_map() -> BeliefMap:
    g = Grid((-3.25, 1.5), 0.05, (40, 70))
    rng = np.random.default_rng(2)
    m = rng.dirichlet(np.ones(4), size=g.shape).astype(np.float32)  # e, o, t, c per cell
    bm = BeliefMap(g, *(np.ascontiguousarray(m[..., k]) for k in range(4)))
    bm.m_t[:5] = 1.0  # never seen: unknown
    bm.m_e[:5] = bm.m_o[:5] = bm.m_c[:5] = 0.0
    return bm


def test_nav2_yaml_writes_the_origin_without_float_noise(tmp_path) -> None:
    """fgm.yaml's origin as a person (and nav2's map_server) reads it: a grid origin of
    -0.1 * 257 (-25.700000000000003) and 0.1 + 0.2 is written -25.7 and 0.3, within
    1e-9 m of the grid's; -0.0 as 0.0."""
    for origin, want in (((-0.1 * 257, 0.1 + 0.2), "- -25.7\n- 0.3\n"),
                         ((-0.0, 1.5), "- 0.0\n- 1.5\n")):  # fmt: skip
        g = Grid(origin, 0.1, (4, 6))
        bm = BeliefMap(g, *(np.full(g.shape, 0.25, dtype=np.float32) for _ in range(4)))
        mapio.save_nav2(tmp_path / "fgm.yaml", tmp_path / "fgm.pgm", bm)
        text = (tmp_path / "fgm.yaml").read_text(encoding="utf-8")
        assert f"resolution: 0.1\norigin:\n{want}- 0.0\n" in text, text
        nav2 = yaml.safe_load(text)
        assert nav2["origin"][:2] == pytest.approx(list(origin), abs=1e-9)


def test_fgm_messages_decode_and_match_nav2(tmp_path) -> None:
    bm = _small_map()
    mapio.save_nav2(tmp_path / "fgm.yaml", tmp_path / "fgm.pgm", bm)
    poly = np.array([[-3.0, 2.0], [0.0, 2.0], [0.0, 3.0], [-3.0, 3.0]])
    topics = load_config("quick").topics
    with LogWriter(tmp_path / "fgm.mcap") as w:
        refs = [(0, "c0", 0.1, poly), (1, "c1", np.deg2rad(-4.62), poly)]
        for topic, typename, msg, t in fgm_messages(bm, refs, 5.0, topics):
            w.write(topic, typename, msg, t)
    msgs = decode_both(tmp_path / "fgm.mcap")
    assert sorted(msgs) == ["/map", "/map_conflict", "/map_references"]
    nav2 = yaml.safe_load((tmp_path / "fgm.yaml").read_text())
    pgm = mapio.read_pgm(tmp_path / "fgm.pgm")
    for topic, values in (("/map", occupancy_values(bm)), ("/map_conflict", conflict_values(bm))):
        (grid,) = msgs[topic]
        info = grid.info
        assert (info.width, info.height) == (pgm.shape[1], pgm.shape[0])
        assert info.resolution == pytest.approx(nav2["resolution"])
        assert [info.origin.position.x, info.origin.position.y] == pytest.approx(nav2["origin"][:2])
        data = np.asarray(grid.data, dtype=np.int8).reshape(info.height, info.width)
        assert np.array_equal(data, values)
        assert data.min() >= -1 and data.max() <= 100
    # row 0 is the lowest y: the PGM's bottom row; unknown there as in the PGM
    occ = np.asarray(msgs["/map"][0].data, dtype=np.int8).reshape(pgm.shape)
    assert np.all(occ[:5] == -1) and np.all(pgm[-5:] == mapio.PGM_UNKNOWN)
    assert np.all(occupancy_values(bm)[5:][pgm[::-1][5:] == mapio.PGM_OCCUPIED] >= 65)
    texts = [m.text for m in msgs["/map_references"][0].markers if m.type == 9]
    assert texts == ["c0 5.73 deg", "c1 175.38 deg"]  # a line's direction, in [0, 180)


# -- end to end: simulate | run | map | run --map --fix ----------------------------------


def invoke(args: list) -> dict:
    res = CliRunner().invoke(cli, [str(a) for a in args], catch_exceptions=False)
    assert res.exit_code == 0, res.output
    return json.loads(res.stdout)


@pytest.fixture(scope="module")
def chain(dark_case, tmp_path_factory) -> Path:
    """simulate, run, map, run --fix heading|pose, once per test run (conftest.shared_dir).

    The log, run A, the map and the pose-fix run are test_fixes_sim's ``dark_case`` (the
    quick world, every lamp off in run 2, a box and a person): the same chain of commands,
    built once for both modules; the heading-fix run is added here."""
    log, dark, _ = dark_case

    def build(tmp: Path) -> None:
        for name in ("log.mcap", "scenario.yaml", "A", "fgm", "pose"):
            (tmp / name).symlink_to(dark / name)
        invoke(["run", log, "-o", tmp / "heading", "--config", dark / "scenario.yaml",
                "--map", dark / "fgm", "--fix", "heading"])  # fmt: skip

    return shared_dir(tmp_path_factory, "viewer-chain", build)


def _stamp(h) -> tuple[int, int]:
    return (h.stamp.sec, h.stamp.nanosec)


def log_odom_to_base(log: Path) -> dict[tuple[int, int], np.ndarray]:
    """The log's own /tf odom -> base_link (the simulated robot's dead reckoning, as a
    robot's driver broadcasts it), by stamp."""
    out = {}
    for m in decode_both(log)["/tf"]:
        assert [(x.header.frame_id, x.child_frame_id) for x in m.transforms] == [
            ("odom", "base_link")
        ]
        out[_stamp(m.transforms[0].header)] = M.planar_transforms(m)["base_link"][1]
    return out


def _tf_tree(tf_msgs, pose_msgs, odom_to_base: dict) -> None:
    """Every /tf message of the estimates: map -> odom only (the log carries odom ->
    base_link, so it is not written twice), at the stamp of a /slam/pose, composing with
    the log's odom -> base_link of that stamp to that pose (the correction is computed
    against the log's odom -> base_link, not the run's own dead reckoning): one tree
    over both files."""
    assert len(tf_msgs) == len(pose_msgs) > 100
    for tf, pose in zip(tf_msgs, pose_msgs, strict=True):
        ts = tf.transforms
        assert [(x.header.frame_id, x.child_frame_id) for x in ts] == [("map", "odom")]
        assert _stamp(ts[0].header) == _stamp(pose.header)
        est = compose(M.planar_transforms(tf)["odom"][1], odom_to_base[_stamp(pose.header)])
        ref = M.pose_of(pose.pose.pose)
        assert est[:2] == pytest.approx(ref[:2], abs=1e-6)
        assert abs(wrap_angle(est[2] - ref[2])) < 1e-6


@pytest.mark.slow
def test_run_estimates_have_a_connected_tf_tree(chain) -> None:
    # the log's sensors hang under base_link (/tf_static), base_link under odom (the
    # log's /tf), odom under map (the estimates' /tf): map -> odom -> base_link ->
    # sonar_NN, ceiling_camera
    static = decode_both(chain / "log.mcap")["/tf_static"]
    parents = {(x.header.frame_id, x.child_frame_id) for m in static for x in m.transforms}
    assert len(parents) == 17 and {p for p, _c in parents} == {"base_link"}
    odom_to_base = log_odom_to_base(chain / "log.mcap")
    msgs = decode_both(chain / "A" / "estimates.mcap")
    assert {"/tf", "/slam/pose", "/slam/landmarks"} <= set(msgs)
    _tf_tree(msgs["/tf"], msgs["/slam/pose"], odom_to_base)
    # the log's odom -> base_link is the dead reckoning of odometry.tum at its times
    odo = np.loadtxt(chain / "A" / "odometry.tum")
    t = np.array([s + ns * 1e-9 for s, ns in odom_to_base])
    k = np.searchsorted(odo[:, 0], t + 1e-6, "right") - 1
    got = np.array(list(odom_to_base.values()))[:, :2]
    assert np.allclose(got, odo[k, 1:3], atol=1e-6)
    # the map -> odom correction is not the identity (the lamps corrected the drift)
    corr = np.array([M.planar_transforms(m)["odom"][1] for m in msgs["/tf"]])
    assert np.abs(corr[-1, :2]).max() > 1e-3


@pytest.mark.slow
def test_run_with_a_map_shows_map_and_fixes(chain) -> None:
    nav2 = yaml.safe_load((chain / "fgm" / "fgm.yaml").read_text())
    pgm = mapio.read_pgm(chain / "fgm" / nav2["image"])
    for fix, topic in (("heading", "/slam/heading_fixes"), ("pose", "/slam/pose_fixes")):
        msgs = decode_both(chain / fix / "estimates.mcap")
        _tf_tree(msgs["/tf"], msgs["/slam/pose"], log_odom_to_base(chain / "log.mcap"))
        (grid,) = msgs["/map"]
        info = grid.info
        assert (info.width, info.height) == (pgm.shape[1], pgm.shape[0])
        assert info.resolution == pytest.approx(nav2["resolution"])
        origin = [info.origin.position.x, info.origin.position.y]
        assert origin == pytest.approx(nav2["origin"][:2])
        fixes = msgs[topic]
        colours = {(m.markers[0].color.r, m.markers[0].color.g) for m in fixes}
        assert len(fixes) > 10 and len(colours) >= 1
        rows = list(
            csv_rows(chain / fix / ("heading_fixes.csv" if fix == "heading" else "pose_fixes.csv"))
        )
        accepted = sum(r["accepted"] == "1" for r in rows)
        green = sum(m.markers[0].color.g > 0.6 for m in fixes)
        assert green == accepted > 0
        # the corridor labels are fgm.mcap's: each angle in [0, 180) deg as references.yaml
        # says it (the run once printed the reloaded -4.62 for 175.38)
        assert _labels(msgs) == _labels(decode_both(chain / "fgm" / "fgm.mcap"))
        # the map first in the file (a reader in file order sees it before any pose)
        with open(chain / fix / "estimates.mcap", "rb") as f:
            order = [c.topic for _s, c, _m in make_reader(f).iter_messages(log_time_order=False)]
        assert order[:3] == ["/map", "/map_conflict", "/map_references"]
        assert order.count("/map") == 1


def _labels(msgs: dict) -> list[str]:
    return [m.text for m in msgs["/map_references"][0].markers if m.type == 9]


def csv_rows(path: Path):
    import csv

    with open(path, newline="") as f:
        yield from csv.DictReader(f)


@pytest.mark.slow
def test_map_writes_fgm_mcap(chain) -> None:
    nav2 = yaml.safe_load((chain / "fgm" / "fgm.yaml").read_text())
    pgm = mapio.read_pgm(chain / "fgm" / nav2["image"])
    msgs = decode_both(chain / "fgm" / "fgm.mcap")
    assert sorted(msgs) == ["/map", "/map_conflict", "/map_references"]
    for topic in ("/map", "/map_conflict"):
        info = msgs[topic][0].info
        assert (info.width, info.height) == (pgm.shape[1], pgm.shape[0])
        assert [info.origin.position.x, info.origin.position.y] == pytest.approx(nav2["origin"][:2])
    refs = yaml.safe_load((chain / "fgm" / "references.yaml").read_text())["references"]
    want = [f"{r['name']} {r['angle_deg'] % 180.0:.2f} deg" for r in refs]
    assert _labels(msgs) == want and len(want) > 0


def test_foxglove_layout_names_the_topics_written() -> None:
    """docs/foxglove_layout.json: a 3D panel in the map frame showing every topic run and
    map write for a viewer, plots of topics that exist (the default topic names, or the
    layout's own user script's output)."""
    import re
    from dataclasses import asdict

    layout = json.loads((Path(__file__).parents[1] / "docs" / "foxglove_layout.json").read_text())
    topics = asdict(load_config("quick").topics)
    known = set(topics.values())
    (script,) = layout["userNodes"].values()
    out = re.search(r'export const output = "([^"]+)"', script["sourceCode"]).group(1)
    inputs = re.search(r"export const inputs = \[([^\]]*)\]", script["sourceCode"]).group(1)
    assert set(re.findall(r'"([^"]+)"', inputs)) == {topics["slam_pose"], topics["ground_truth"]}
    panels = layout["configById"]
    (three_d,) = [v for k, v in panels.items() if k.startswith("3D!")]
    assert three_d["followTf"] == "map"
    shown = set(three_d["topics"])
    assert shown <= known
    viewer = ("map", "map_conflict", "map_references", "slam_pose", "slam_landmarks",
              "heading_fixes", "pose_fixes", "slam_changes", "ground_truth")  # fmt: skip
    assert {topics[k] for k in viewer} <= shown
    plots = [v for k, v in panels.items() if k.startswith("Plot!")]
    assert len(plots) == 3
    for p in plots:
        for path in p["paths"]:
            assert path["value"].split(".")[0] in known | {out}, path["value"]
            assert path["label"]
    # every panel named in the layout tree has a configuration
    names = re.findall(r'"((?:3D|Plot)![^"]+)"', json.dumps(layout["layout"]))
    assert sorted(names) == sorted(panels)
