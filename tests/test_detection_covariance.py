"""Detections that carry their own covariance (vision_msgs/Detection3DArray, issue 12):
the message's x, y covariance is used per detection, the configured range-bearing model
where it carries none; checked on a copy of the committed real excerpt
(data/real/mrclam6_excerpt) whose PoseArray detections are rewritten as
Detection3DArray."""

from __future__ import annotations

import json
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from fuzzyslam.config import load_config
from fuzzyslam.slam.inputs import open_inputs
from fuzzyslam.slam.runner import Frame
from fuzzyslam.streams import messages as M
from fuzzyslam.streams.reader import LogReader
from fuzzyslam.streams.typestore import deserialize, serialize
from fuzzyslam.streams.writer import LogWriter

EXCERPT = Path(__file__).resolve().parents[1] / "data" / "real" / "mrclam6_excerpt" / "log.mcap"
TOPIC = "/landmark_detections"


def _rewrite(dst: Path, cov_of) -> list[np.ndarray]:
    """The excerpt with its detections as Detection3DArray, covariances ``cov_of(points)``
    ((N, 2, 2) or None for "unknown"); returns the covariances written, per message."""
    written = []
    with LogWriter(dst) as w:
        for m in LogReader(EXCERPT).messages():
            if m.topic != TOPIC:
                w.write(m.topic, m.typename, m.msg, m.t)
                continue
            pts = M.points_of_pose_array(m.msg)
            covs = cov_of(pts)
            written.append(covs)
            msg = M.detection3d_array(0.0, m.msg.header.frame_id, pts, covs)
            msg.header.stamp = m.msg.header.stamp
            w.write(m.topic, M.DETECTION3D_ARRAY, msg, m.t)
    return written


def _frames(log: Path, own: str = "floor") -> list[Frame]:
    cfg = load_config("real_detections.yaml")
    cfg = replace(cfg, slam=replace(cfg.slam, detection_own_covariance=own))
    inputs = open_inputs(log, cfg)
    return [e for e in inputs.events() if isinstance(e, Frame)]


def test_detection3d_round_trip() -> None:
    """Builder, CDR and reader agree: points and the x, y covariance block come back; an
    all-zero ("unknown") or indefinite covariance reads as NaN."""
    pts = np.array([[1.0, 2.0], [3.0, -1.0], [0.5, 0.5]])
    covs = np.array([[[0.04, 0.01], [0.01, 0.02]], np.zeros((2, 2)), [[0.01, 0.02], [0.02, 0.01]]])
    msg = M.detection3d_array(12.5, "base_link", pts, covs)
    back = deserialize(serialize(msg, M.DETECTION3D_ARRAY), M.DETECTION3D_ARRAY)
    z, c = M.detections_of(back)
    assert np.array_equal(z, pts)
    assert np.array_equal(c[0], covs[0])
    assert np.all(np.isnan(c[1])) and np.all(np.isnan(c[2]))  # unknown; not positive definite
    z, c = M.detections_of(M.pose_array(0.0, "base_link", pts))
    assert np.array_equal(z, pts) and np.all(np.isnan(c))


def test_own_covariance_is_used(tmp_path: Path) -> None:
    """Each frame's covariances are the message's where it has them (here four times the
    configured model, a value the model never gives), the model's where it has none."""
    slam = load_config("real_detections.yaml").slam
    log = tmp_path / "own.mcap"
    k = [0]

    def cov_of(pts):  # every other message brings its own covariance
        k[0] += 1
        return 4.0 * slam.detection_cov(pts) if k[0] % 2 else None

    written = _rewrite(log, cov_of)
    frames = _frames(log)
    base = _frames(EXCERPT)
    assert len(frames) == len(base) == len(written)
    n_own = 0
    for f, b, w in zip(frames, base, written, strict=True):
        assert np.array_equal(f.z, b.z)
        if w is None:
            assert np.array_equal(f.cov, b.cov)
        else:
            assert np.allclose(f.cov, w, rtol=1e-12, atol=0) and np.allclose(f.cov, 4 * b.cov)
            n_own += len(f.z)
    assert n_own > 50


def test_own_covariance_below_the_model_is_floored(tmp_path: Path) -> None:
    """A detector that claims a quarter of the model's variance along and across the line
    of sight: raised to the model exactly with ``floor`` (the default), taken as it is
    with ``use``, ignored with ``model``."""
    slam = load_config("real_detections.yaml").slam
    log = tmp_path / "small.mcap"
    written = _rewrite(log, lambda pts: 0.25 * slam.detection_cov(pts))
    base = _frames(EXCERPT)
    floored, used, model = (_frames(log, own) for own in ("floor", "use", "model"))
    assert len(floored) == len(used) == len(model) == len(base) == len(written) > 10
    for f, u, m, b, w in zip(floored, used, model, base, written, strict=True):
        assert np.allclose(f.cov, b.cov, rtol=1e-12, atol=1e-15)
        assert np.allclose(u.cov, w, rtol=1e-12, atol=0)
        assert np.array_equal(m.cov, b.cov)


def test_floor_adds_only_what_the_model_has_more_of() -> None:
    """``detection_cov_floored`` on random own covariances: C' - C is positive
    semidefinite, C' holds at least the model's variance along (u) and across (n) the
    line of sight, C' = C where C already did, and the covariance without its own (NaN)
    is the model's."""
    slam = load_config("real_detections.yaml").slam
    rng = np.random.default_rng(7)
    m = 400
    z = rng.uniform(-6.0, 6.0, (m, 2))
    a = rng.normal(0.0, 0.15, (m, 2, 2))
    own = a @ a.transpose(0, 2, 1) + 1e-6 * np.eye(2)
    own[::10] = np.nan
    cov, floored = slam.detection_cov_floored(z, own)
    model = slam.detection_cov(z)
    u = z / np.hypot(z[:, 0], z[:, 1])[:, None]
    n = np.stack([-u[:, 1], u[:, 0]], axis=1)
    has = ~np.isnan(own[:, 0, 0])
    assert np.array_equal(cov[~has], model[~has])
    d = cov[has] - own[has]
    assert np.linalg.eigvalsh(0.5 * (d + d.transpose(0, 2, 1))).min() > -1e-12
    for v in (u, n):
        q = np.einsum("ki,kij,kj->k", v, cov, v)
        assert np.all(q >= np.einsum("ki,kij,kj->k", v, model, v) * (1 - 1e-12))
    q_own = [np.einsum("ki,kij,kj->k", v, own, v) for v in (u, n)]
    q_mod = [np.einsum("ki,kij,kj->k", v, model, v) for v in (u, n)]
    held = has & (q_own[0] >= q_mod[0]) & (q_own[1] >= q_mod[1])
    assert np.array_equal(cov[held], own[held]) and 0 < floored == has.sum() - held.sum()


@pytest.mark.slow
def test_run_with_own_covariance_equals_model(tmp_path: Path) -> None:
    """``run`` on the Detection3DArray copy whose covariances equal the configured model
    writes the same trajectory as on the PoseArray original (a second path to one
    result), and counts the detections that brought their own covariance."""
    slam = load_config("real_detections.yaml").slam
    log = tmp_path / "same.mcap"
    _rewrite(log, slam.detection_cov)

    def run(src: Path, out: Path) -> dict:
        r = subprocess.run(
            [sys.executable, "-m", "fuzzyslam", "run", str(src), "--config",
             "real_detections.yaml", "-o", str(out)],
            capture_output=True, text=True, check=False,
        )  # fmt: skip
        assert r.returncode == 0, r.stderr
        return json.loads(r.stdout)

    a = run(EXCERPT, tmp_path / "a")
    b = run(log, tmp_path / "b")
    ta = np.loadtxt(tmp_path / "a" / "trajectory.tum")
    tb = np.loadtxt(tmp_path / "b" / "trajectory.tum")
    assert ta.shape == tb.shape and np.allclose(ta, tb, rtol=0, atol=1e-9)
    assert a["counts"]["detections_own_covariance"] == 0
    assert b["counts"]["detections_own_covariance"] == a["counts"]["detections"] > 100


# vision_msgs 2 (ROS 2 Foxy): the hypothesis' id and score on it, the tracking fields
FOXY_VISION = {
    "vision_msgs/msg/ObjectHypothesisWithPose": (
        "string id\nfloat64 score\ngeometry_msgs/PoseWithCovariance pose\n"
    ),
    "vision_msgs/msg/BoundingBox3D": "geometry_msgs/Pose center\ngeometry_msgs/Vector3 size\n",
    "vision_msgs/msg/Detection3D": (
        "std_msgs/Header header\nvision_msgs/ObjectHypothesisWithPose[] results\n"
        "vision_msgs/BoundingBox3D bbox\nsensor_msgs/PointCloud2 source_cloud\n"
        "bool is_tracking\nstring tracking_id\n"
    ),
    "vision_msgs/msg/Detection3DArray": (
        "std_msgs/Header header\nvision_msgs/Detection3D[] detections\n"
    ),
}


def test_detections_of_another_vision_msgs_release_are_read_by_the_logs_definition(
    tmp_path: Path,
) -> None:
    """A Foxy robot's Detection3DArray (vision_msgs 2: another layout than Humble's, its
    definition in the log's Schema record, as rosbag2 writes it) is decoded by the log's
    own definition: the same points and covariances as the Humble copy (they were all
    undecodable: no lamps, dead reckoning)."""
    from mcap.reader import make_reader
    from mcap.writer import Writer
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    slam = load_config("real_detections.yaml").slam
    humble = tmp_path / "humble.mcap"
    _rewrite(humble, slam.detection_cov)
    foxy = get_typestore(Stores.ROS2_FOXY)
    for name, text in FOXY_VISION.items():
        foxy.register(get_types_from_msg(text, name))
    t = foxy.types
    name = M.DETECTION3D_ARRAY
    schema_text, _ = foxy.generate_msgdef(name, ros_version=2)
    log = tmp_path / "foxy.mcap"
    with open(humble, "rb") as src, open(log, "wb") as dst:
        w = Writer(dst)
        w.start(profile="ros2")
        schemas: dict[int, int] = {}
        channels: dict[int, int] = {}
        for schema, channel, message in make_reader(src).iter_messages(log_time_order=True):
            data = message.data
            if channel.topic == TOPIC:
                msg = deserialize(data, name)  # the Humble copy, as Foxy would write it
                dets = [
                    t["vision_msgs/msg/Detection3D"](
                        header=d.header,
                        results=[
                            t["vision_msgs/msg/ObjectHypothesisWithPose"](
                                id=h.hypothesis.class_id,
                                score=h.hypothesis.score,
                                pose=h.pose,
                            )
                            for h in d.results
                        ],
                        bbox=d.bbox,
                        source_cloud=t["sensor_msgs/msg/PointCloud2"](
                            header=d.header,
                            height=0,
                            width=0,
                            fields=[],
                            is_bigendian=False,
                            point_step=0,
                            row_step=0,
                            data=np.zeros(0, np.uint8),
                            is_dense=True,
                        ),
                        is_tracking=False,
                        tracking_id="",
                    )
                    for d in msg.detections
                ]
                data = foxy.serialize_cdr(t[name](header=msg.header, detections=dets), name)
                text = schema_text
            else:
                text = schema.data.decode()
            key = (schema.name, text)
            if key not in schemas:
                schemas[key] = w.register_schema(schema.name, "ros2msg", text.encode())
            if channel.id not in channels:
                channels[channel.id] = w.register_channel(channel.topic, "cdr", schemas[key])
            w.add_message(channels[channel.id], message.log_time, bytes(data),
                          message.publish_time, message.sequence)  # fmt: skip
        w.finish()
    got, want = _frames(log), _frames(humble)
    assert len(got) == len(want) > 10
    for a, b in zip(got, want, strict=True):
        assert np.array_equal(a.z, b.z) and np.array_equal(a.cov, b.cov)


def test_one_type_name_with_two_definitions_decodes_each_channel_by_its_own(
    tmp_path: Path,
) -> None:
    """Two channels of one type name whose schemas differ (bags of two ROS releases
    merged): each channel's messages are decoded by its own schema, in a whole file and
    in the same file cut before its summary (one channel was lost, a different one
    each way)."""
    import struct

    from mcap.writer import Writer
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    name = "my_msgs/msg/Reading"
    defs = {"/a": "float32 value\n", "/b": "float64 value\nfloat64 variance\n"}
    log = tmp_path / "two.mcap"
    with open(log, "wb") as f:
        w = Writer(f)
        w.start(profile="ros2")
        ids = {}
        for topic, text in defs.items():
            sid = w.register_schema(name, "ros2msg", text.encode())
            ids[topic] = w.register_channel(topic, "cdr", sid)
        for k in range(3):
            for topic, text in defs.items():
                store = get_typestore(Stores.EMPTY)
                store.register(get_types_from_msg(text, name))
                cls = store.types[name]
                msg = cls(1.5 + k) if topic == "/a" else cls(2.5 + k, 0.25)
                t = (k + 1) * 10**9
                w.add_message(ids[topic], t, bytes(store.serialize_cdr(msg, name)), t)
        w.finish()
    raw = log.read_bytes()
    (summary_start,) = struct.unpack_from("<Q", raw, len(raw) - 8 - 20)
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(raw[:summary_start])
    for path in (log, cut):
        reader = LogReader(path)
        got = {(m.topic, round(float(m.msg.value), 6)) for m in reader.messages()}
        want = {("/a", 1.5 + k) for k in range(3)} | {("/b", 2.5 + k) for k in range(3)}
        assert got == want, path
        variances = [m.msg.variance for m in reader.messages(["/b"])]
        assert variances == [0.25] * 3
        assert reader.damage()["undecodable"] == 0
