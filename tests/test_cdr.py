"""streams/cdr.py against rosbags' own serializer and deserializer.

Random messages (hypothesis: random values, empty and non-empty arrays, frame ids of
every length modulo 8 so that every alignment case occurs) are serialized by rosbags and
decoded by the fast decoders; the fields must be the originals. The block encoder's
bytes must be rosbags' bytes. Truncated or inconsistent payloads raise."""

from __future__ import annotations

import struct
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from fuzzyslam.streams import cdr, cdr_encode
from fuzzyslam.streams import messages as M
from fuzzyslam.streams.typestore import deserialize, msgtype, serialize, typestore

F64 = st.floats(allow_nan=False, width=64)
F32 = st.floats(allow_nan=False, width=32)
TEXT = st.text(alphabet=st.characters(min_codepoint=32, max_codepoint=0x24F), max_size=11)
# frame ids of every length modulo 8 (every alignment of the fields after them)
FRAMES = st.one_of(TEXT, st.integers(0, 16).map(lambda k: "f" * k))


def header(sec, nsec, frame):
    return msgtype("std_msgs/msg/Header")(
        stamp=msgtype("builtin_interfaces/msg/Time")(sec=sec, nanosec=nsec), frame_id=frame
    )


HEADERS = st.builds(header, st.integers(-(2**31), 2**31 - 1), st.integers(0, 2**32 - 1), FRAMES)


def f64_array(max_size=9):
    return st.lists(F64, max_size=max_size).map(lambda v: np.array(v, dtype=np.float64))


def f32_array(max_size=9):
    return st.lists(F32, max_size=max_size).map(lambda v: np.array(v, dtype=np.float32))


def point(v):
    return msgtype("geometry_msgs/msg/Point")(x=v[0], y=v[1], z=v[2])


def pose(v):
    q = msgtype("geometry_msgs/msg/Quaternion")(x=v[3], y=v[4], z=v[5], w=v[6])
    return msgtype("geometry_msgs/msg/Pose")(position=point(v), orientation=q)


POSES = st.lists(F64, min_size=7, max_size=7).map(pose)


def same(a, b) -> None:
    """Recursive field equality of a rosbags message and a decoded one."""
    fields = getattr(a, "__dataclass_fields__", None)
    if fields is not None:
        for name in (n for n in fields if not n.startswith("__")):
            same(getattr(a, name), getattr(b, name))
    elif isinstance(a, np.ndarray):
        assert isinstance(b, np.ndarray) and a.dtype == b.dtype
        assert np.array_equal(a, b)
    elif isinstance(a, list):
        assert len(a) == len(b)
        for x, y in zip(a, b, strict=True):
            same(x, y)
    else:
        assert a == b and type(a) is type(b)


def roundtrip(msg, typename: str):
    raw = serialize(msg, typename)
    got = cdr.DECODERS[typename](raw)
    same(msg, got)
    same(deserialize(raw, typename), got)
    return raw


@st.composite
def odometry(draw):
    v = draw(st.lists(F64, min_size=13, max_size=13))
    twist = msgtype("geometry_msgs/msg/Twist")(
        linear=msgtype("geometry_msgs/msg/Vector3")(x=v[7], y=v[8], z=v[9]),
        angular=msgtype("geometry_msgs/msg/Vector3")(x=v[10], y=v[11], z=v[12]),
    )
    cov = [np.array(draw(st.lists(F64, min_size=36, max_size=36))) for _ in range(2)]
    return msgtype(M.ODOMETRY)(
        header=draw(HEADERS),
        child_frame_id=draw(TEXT),
        pose=msgtype("geometry_msgs/msg/PoseWithCovariance")(pose=pose(v), covariance=cov[0]),
        twist=msgtype("geometry_msgs/msg/TwistWithCovariance")(twist=twist, covariance=cov[1]),
    )


@settings(max_examples=80, deadline=None)
@given(odometry())
def test_odometry(msg) -> None:
    roundtrip(msg, M.ODOMETRY)


@settings(max_examples=80, deadline=None)
@given(HEADERS, st.lists(POSES, max_size=4))
def test_pose_array(h, poses) -> None:
    roundtrip(msgtype(M.POSE_ARRAY)(header=h, poses=poses), M.POSE_ARRAY)


@settings(max_examples=80, deadline=None)
@given(HEADERS, st.lists(F32, min_size=7, max_size=7), f32_array(), f32_array())
def test_laser_scan(h, f, ranges, intensities) -> None:
    msg = msgtype("sensor_msgs/msg/LaserScan")(h, *f, ranges, intensities)
    roundtrip(msg, "sensor_msgs/msg/LaserScan")


@settings(max_examples=80, deadline=None)
@given(HEADERS, st.lists(TEXT, max_size=4), f64_array(), f64_array(), f64_array())
def test_joint_state(h, names, pos, vel, eff) -> None:
    msg = msgtype(M.JOINT_STATE)(header=h, name=names, position=pos, velocity=vel, effort=eff)
    roundtrip(msg, M.JOINT_STATE)


@settings(max_examples=80, deadline=None)
@given(
    HEADERS,
    st.integers(0, 2**32 - 1),
    st.integers(0, 2**32 - 1),
    TEXT,
    st.integers(0, 255),
    st.integers(0, 2**32 - 1),
    st.binary(max_size=40),
)
def test_image(h, height, width, encoding, big, step, data) -> None:
    msg = msgtype(M.IMAGE)(
        header=h,
        height=height,
        width=width,
        encoding=encoding,
        is_bigendian=big,
        step=step,
        data=np.frombuffer(data, dtype=np.uint8),
    )
    roundtrip(msg, M.IMAGE)


@settings(max_examples=80, deadline=None)
@given(HEADERS, st.integers(0, 255), st.lists(F32, min_size=4, max_size=4))
def test_range(h, kind, f) -> None:
    msg = msgtype(M.RANGE)(h, kind, *f)
    roundtrip(msg, M.RANGE)


@pytest.mark.slow
@settings(max_examples=80, deadline=None)
@given(HEADERS, st.integers(0, 255), st.lists(F32, min_size=5, max_size=5))
def test_range_of_iron_and_later_with_its_variance(h, kind, f) -> None:
    """From ROS 2 Iron on, Range ends with a float32 variance: a Jazzy robot's sonar
    messages (serialised by rosbags' Jazzy typestore) decode to the same fields (they
    were all refused as inconsistent: a Jazzy sonar log had no readings); a payload
    longer than the variance and its padding is still refused."""
    from rosbags.typesys import Stores, get_typestore

    jazzy = get_typestore(Stores.ROS2_JAZZY)
    t = jazzy.types
    hj = t["std_msgs/msg/Header"](
        stamp=t["builtin_interfaces/msg/Time"](sec=h.stamp.sec, nanosec=h.stamp.nanosec),
        frame_id=h.frame_id,
    )
    data = jazzy.serialize_cdr(t[M.RANGE](hj, kind, *f), M.RANGE)
    got = cdr.decode_range(data)
    assert (got.header.stamp.sec, got.header.stamp.nanosec, got.header.frame_id) == (
        h.stamp.sec,
        h.stamp.nanosec,
        h.frame_id,
    )
    assert got.radiation_type == kind
    want = np.array(f[:4], dtype=np.float32)
    got_f = [got.field_of_view, got.min_range, got.max_range, got.range]
    np.testing.assert_array_equal(np.array(got_f, dtype=np.float32), want)
    with pytest.raises(cdr.CdrError):
        cdr.decode_range(bytes(data) + bytes(4))


@settings(max_examples=100, deadline=None)
@given(
    st.lists(
        st.tuples(st.floats(0, 2e9), *(st.floats(-1e6, 1e6),) * 3, *(st.floats(-1e3, 1e3),) * 6),
        min_size=1,
        max_size=5,
    ),
    TEXT,
)
def test_pose_block_encoder_equals_rosbags(rows, frame) -> None:
    a = np.array(rows, dtype=float)
    t, poses, cov = a[:, 0], a[:, 1:4], a[:, 4:]
    got = cdr.encode_pose_with_covariance_block(t, poses, cov, frame)
    for k in range(len(t)):
        c = cov[k]
        cov3 = np.array([[c[0], c[1], c[2]], [c[1], c[3], c[4]], [c[2], c[4], c[5]]])
        ref = serialize(M.pose_with_covariance(t[k], frame, poses[k], cov3), M.POSE_COV_STAMPED)
        assert got[k] == ref


@settings(max_examples=60, deadline=None)
@given(
    st.floats(0, 2e9),
    st.lists(st.tuples(*(st.floats(-1e3, 1e3),) * 3, *(st.floats(1e-9, 1e2),) * 3), max_size=7),
    TEXT,
)
def test_marker_encoder_equals_rosbags(t, rows, frame) -> None:
    """encode_markers (one rosbags Marker as a template) gives rosbags' bytes for the
    MarkerArray of messages.marker, for 0 to 7 markers; and the run's lamp markers."""
    a = np.array(rows, dtype=float).reshape(-1, 6)
    poses, scales = a[:, :3], a[:, 3:5]
    rgba = (1.0, 0.8, 0.1, 0.8)
    got = cdr_encode.encode_markers(t, frame, "lamps", 2, poses, 2.5, scales, a[:1, 5].sum(), rgba)
    ref = [M.marker(t, frame, "lamps", k, 2, tuple(poses[k]), 2.5,
                    (*scales[k], a[:1, 5].sum()), rgba) for k in range(len(a))]  # fmt: skip
    assert got == serialize(M.marker_array(ref), M.MARKER_ARRAY)
    from fuzzyslam.slam.markers import lamp_markers, lamp_markers_cdr

    covs = np.einsum(
        "nij,nkj->nik", a[:, None, 3:5] * [[1.0], [0.5]], a[:, None, 3:5] * [[1.0], [0.5]]
    )
    covs = covs + np.eye(2) * a[:, 5:6, None]
    lamps = poses[:, :2]
    assert lamp_markers_cdr(t, lamps, covs) == serialize(
        lamp_markers(t, lamps, covs), M.MARKER_ARRAY
    )
    assert cdr_encode._marker_layout("map", "lamps", 2, 2.5, 0.02, rgba) is not None  # no fallback


ROWS = st.lists(st.tuples(st.floats(0, 2e9), *(st.floats(-1e6, 1e6),) * 5), min_size=1,
                max_size=5)  # fmt: skip


SPECS = st.builds(
    cdr_encode.MarkerSpec,
    st.floats(0, 2e9),
    FRAMES,
    TEXT,
    st.integers(-(2**31), 2**31 - 1),
    st.integers(0, 11),
    st.tuples(F64, F64, st.floats(-10, 10)),
    F64,
    st.tuples(F64, F64, F64),
    st.tuples(F32, F32, F32, F32),
    st.one_of(st.none(), st.lists(st.tuples(F64, F64), max_size=5).map(np.array)),
    TEXT,
    st.integers(0, 3),
)


@settings(max_examples=100, deadline=None)
@given(st.lists(SPECS, max_size=4))
def test_marker_array_encoder_equals_rosbags(specs) -> None:
    """encode_marker_array (field by field) gives rosbags' bytes for the MarkerArray of
    messages.marker of the same arguments: any frame and namespace length (every
    alignment), points or none, text, action."""
    from dataclasses import astuple

    ref = M.marker_array([M.marker(*astuple(m)) for m in specs])
    assert cdr_encode.encode_marker_array(specs) == serialize(ref, M.MARKER_ARRAY)


@settings(max_examples=60, deadline=None)
@given(
    st.floats(0, 2e9),
    FRAMES,
    st.integers(0, 6).flatmap(
        lambda h: st.integers(0, 6).flatmap(
            lambda w: st.lists(st.integers(-128, 127), min_size=h * w, max_size=h * w).map(
                lambda v: np.array(v, dtype=np.int8).reshape(h, w)
            )
        )
    ),
    F32,
    st.tuples(F64, F64),
)
def test_occupancy_grid_encoder_equals_rosbags(t, frame, data, resolution, origin) -> None:
    """encode_occupancy_grid gives rosbags' bytes for messages.occupancy_grid."""
    ref = M.occupancy_grid(t, frame, data, resolution, origin)
    got = cdr_encode.encode_occupancy_grid(t, frame, data, resolution, origin)
    assert got == serialize(ref, M.OCCUPANCY_GRID)


@settings(max_examples=30, deadline=None)
@given(ROWS, TEXT, TEXT)
def test_simulation_encoders_equal_rosbags(rows, frame, child) -> None:
    """The encoders of simulated logs (streams/cdr_encode.py) give rosbags' bytes for the
    messages of the builders: odometry, joint states, a sonar ring, images, a restamp."""
    a = np.array(rows, dtype=float)
    t, poses, v, w = a[:, 0], a[:, 1:4], a[:, 4], a[:, 5]
    got = cdr_encode.encode_odometry_block(t, frame, child, poses, v, w)
    names = [frame, child, "wheel"]
    joints = cdr_encode.encode_joint_state_block(t, names, a[:, 1:4])
    for k in range(len(t)):
        ref = M.odometry(t[k], frame, child, poses[k], None, v[k], w[k])
        assert got[k] == serialize(ref, M.ODOMETRY)
        assert joints[k] == serialize(M.joint_state(t[k], names, a[k, 1:4]), M.JOINT_STATE)
    frames = [frame, child, frame + child]
    ring = cdr_encode.encode_ranges(t[0], frames, np.abs(a[0, 1:4]), 0.4, 0.1, 5.0)
    for j, data in enumerate(ring):
        ref = M.range_msg(t[0], frames[j], abs(a[0, 1 + j]), 0.4, 0.1, 5.0)
        assert data == serialize(ref, M.RANGE)
    shape = (1 + len(frame) % 4, 1 + len(child) % 5)  # odd sizes: no padding at the end
    img = np.arange(shape[0] * shape[1], dtype=np.uint8).reshape(shape)
    assert cdr_encode.encode_image_mono8(t[-1], frame, img) == serialize(
        M.image_mono8(t[-1], frame, img), M.IMAGE)  # fmt: skip
    info = serialize(M.camera_info(0.0, frame, 64, 48, 50.0, 32.0, 24.0), M.CAMERA_INFO)
    assert cdr_encode.restamp(info, t[-1]) == serialize(
        M.camera_info(t[-1], frame, 64, 48, 50.0, 32.0, 24.0), M.CAMERA_INFO)  # fmt: skip


def _same_fields(fast, ref) -> None:
    """Every field of a light message (recursively) equals the rosbags message's."""
    for name in fast.__dataclass_fields__:
        a, b = getattr(fast, name), getattr(ref, name)
        if isinstance(a, np.ndarray):
            assert a.dtype == b.dtype and np.array_equal(a, b), name
        elif isinstance(a, list):
            assert len(a) == len(b), name
            for x, y in zip(a, b, strict=True):
                _same_fields(x, y)
        elif hasattr(a, "__dataclass_fields__"):
            _same_fields(a, b)
        else:
            assert type(a) is type(b) and a == b, name


@settings(max_examples=60, deadline=None)
@given(st.floats(0, 2e9), TEXT, TEXT, st.integers(1, 5000), st.integers(1, 5000),
       st.lists(st.tuples(TEXT, TEXT, *(st.floats(-1e6, 1e6),) * 4), max_size=4))  # fmt: skip
def test_camera_info_and_tf_decoders_equal_rosbags(t, frame, model, w, h, tfs) -> None:
    """decode_camera_info / decode_tf_message: rosbags' messages field by field (the
    distortion's length 0 to 5, odd frame names), and an error on a cut payload."""
    info = M.camera_info(t, frame, w, h, 50.0 + w, w / 2.0, h / 3.0)
    info.distortion_model = model
    info.d = np.arange(len(model) % 6, dtype=float) / 7.0
    info.binning_x, info.roi.do_rectify = w % 3, bool(h % 2)
    tf = M.tf_message([M.transform_stamped(t, p, c, x, y, z, yaw) for p, c, x, y, z, yaw in tfs])
    for typename, msg, fn in ((M.CAMERA_INFO, info, cdr.decode_camera_info),
                              (M.TF_MESSAGE, tf, cdr.decode_tf_message)):  # fmt: skip
        data = serialize(msg, typename)
        _same_fields(cdr.decoder(typename)(data), deserialize(data, typename))
        if len(data) > 12:
            with pytest.raises((cdr.CdrError, struct.error, ValueError)):
                fn(data[: len(data) - 5])


def test_msgdefs_are_the_typestores() -> None:
    """streams/msgdefs.py holds the typestore's definition text of each of its types."""
    from fuzzyslam.streams.msgdefs import MSGDEFS

    for name, text in MSGDEFS.items():
        assert typestore().generate_msgdef(name, ros_version=2)[0] == text


@settings(max_examples=100, deadline=None)
@given(odometry(), st.data())
def test_truncated_or_inconsistent_payload_raises(msg, data) -> None:
    """Any cut of a payload raises (CdrError or struct.error, both counted as undecodable
    by the reader); so does a length field pointing past the end."""
    raw = serialize(msg, M.ODOMETRY)
    cut = data.draw(st.integers(0, len(raw) - 4))
    with pytest.raises((cdr.CdrError, struct.error)):
        cdr.decode_odometry(raw[:cut])
    bad = bytearray(raw)
    bad[12:16] = struct.pack("<I", len(raw))  # frame_id longer than the payload
    with pytest.raises(cdr.CdrError):
        cdr.decode_odometry(bytes(bad))


@pytest.mark.parametrize("typename", sorted(cdr.DECODERS))
def test_big_endian_goes_through_rosbags(typename) -> None:
    """A big-endian payload is decoded by rosbags: the same message as little-endian."""
    msg = _default(typename)
    le = serialize(msg, typename)
    be = bytes(typestore().serialize_cdr(msg, typename, little_endian=False))
    assert be[1] == 0 and le[1] == 1
    same(deserialize(le, typename), cdr.decoder(typename)(be))
    same(msg, cdr.decoder(typename)(le))


def _default(typename: str):
    h = header(1, 2, "abc")
    z = np.zeros(0)
    return {
        M.ODOMETRY: lambda: msgtype(M.ODOMETRY)(
            h,
            "base",
            msgtype("geometry_msgs/msg/PoseWithCovariance")(pose([0.5] * 7), np.ones(36)),
            msgtype("geometry_msgs/msg/TwistWithCovariance")(
                msgtype("geometry_msgs/msg/Twist")(
                    msgtype("geometry_msgs/msg/Vector3")(1.0, 2.0, 3.0),
                    msgtype("geometry_msgs/msg/Vector3")(4.0, 5.0, 6.0),
                ),
                np.ones(36),
            ),
        ),
        M.POSE_ARRAY: lambda: msgtype(M.POSE_ARRAY)(h, [pose([1.0] * 7)]),
        "sensor_msgs/msg/LaserScan": lambda: msgtype("sensor_msgs/msg/LaserScan")(
            h, *([1.0] * 7), np.ones(3, np.float32), np.zeros(0, np.float32)
        ),
        M.JOINT_STATE: lambda: msgtype(M.JOINT_STATE)(h, ["a", "bc"], np.ones(2), z, z),
        M.IMAGE: lambda: msgtype(M.IMAGE)(h, 1, 2, "mono8", 0, 2, np.ones(2, np.uint8)),
        M.RANGE: lambda: msgtype(M.RANGE)(h, 1, 0.5, 0.25, 5.0, 2.0),
        M.CAMERA_INFO: lambda: M.camera_info(1.5, "abc", 64, 48, 50.0, 32.0, 24.0),
        M.TF_MESSAGE: lambda: M.tf_message([M.transform_stamped(1.5, "m", "o", 1, 2, 3, 0.5)]),
    }[typename]()


# the real logs beside the checkout (../shared), or beside its parent for a worktree
REAL = next(
    (
        p / "shared" / "data" / "real"
        for p in Path(__file__).resolve().parents[1:4]
        if (p / "shared" / "data" / "real").is_dir()
    ),
    Path("/nonexistent"),
)


@pytest.mark.slow
@pytest.mark.parametrize("name", ["mrclam6-robot2", "carmen-fr079"])
def test_real_logs_read_as_mcap_and_rosbags_read_them(name) -> None:
    """On a real log (skipped when absent): the first 3000 messages of every topic read by
    LogReader equal those of the mcap library + rosbags, with Unix-time stamps kept to
    the nanosecond (``t_ns``)."""
    from mcap.reader import make_reader

    from fuzzyslam.streams.reader import LogReader

    log = REAL / name / "log.mcap"
    if not log.exists():
        pytest.skip(f"{log} absent")
    got = [m for m, _ in zip(LogReader(log).messages(), range(3000), strict=False)]
    with open(log, "rb") as f:
        it = make_reader(f).iter_messages(log_time_order=True)
        ref = [
            (c.topic, m.log_time, deserialize(m.data, s.name))
            for (s, c, m), _ in zip(it, got, strict=False)
        ]
    assert [(m.topic, m.t_ns) for m in got] == [(t, ns) for t, ns, _ in ref]
    assert got[0].t_ns > 10**18 and got[0].t == got[0].t_ns / 1e9  # Unix time, exact ns
    for m, (_, _, msg) in zip(got, ref, strict=True):
        same(msg, m.msg)
