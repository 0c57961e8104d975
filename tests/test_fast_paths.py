"""The speed paths give the same floats as the general ones (outputs stay byte-identical).

Each test compares a fast path with a second implementation, bit for bit:
``se2.compose`` / ``wrap_angle`` on one pose or float against the array path,
``hough_accumulator`` (cached angle table, shifted second bincount) against the plain
accumulator (np.average centroid, clipped bins), ``EkfSlam.lamp_covs`` (a block view)
against fancy indexing of P, ``format_tum`` (Python floats) against numpy rows.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from fuzzyslam import se2
from fuzzyslam.maps.hough import hough_accumulator
from fuzzyslam.slam.ekf import EkfSlam


def test_compose_one_pose_equals_stacked():
    rng = np.random.default_rng(3)
    a = rng.normal(size=(500, 3)) * [5.0, 5.0, 4.0]
    b = rng.normal(size=(500, 3)) * [1.0, 1.0, 4.0]
    stacked = se2.compose(a, b)
    one = np.array([se2.compose(a[k], b[k]) for k in range(len(a))])
    assert np.array_equal(one, stacked)
    ja, jb = se2.jacobians_compose(a[0], b[0])
    c, s = np.cos(a[0, 2]), np.sin(a[0, 2])
    assert np.array_equal(ja[:2, 2], [-s * b[0, 0] - c * b[0, 1], c * b[0, 0] - s * b[0, 1]])
    assert np.array_equal(jb[:2, :2], [[c, -s], [s, c]])


def test_wrap_angle_float_equals_array():
    rng = np.random.default_rng(4)
    edges = [math.pi, -math.pi, 3 * math.pi, -3 * math.pi, 0.0, 2 * math.pi, 1e-300]
    edges += [np.nextafter(math.pi, 4.0), np.nextafter(-math.pi, -4.0)]
    x = np.concatenate([rng.uniform(-30.0, 30.0, 20000), edges])
    arr = se2.wrap_angle(x)
    one = np.array([se2.wrap_angle(float(v)) for v in x])
    assert np.array_equal(one, arr)
    assert np.array_equal([se2.wrap_angle(v) for v in x], arr)  # np.float64 items
    assert all(-math.pi < v <= math.pi for v in one)


def _plain_accumulator(x, y, w, theta_step, rho_step):
    """The accumulator written out plainly: np.average centroid, bins clipped to the
    plane, one bincount per tent side."""
    thetas = np.arange(0.0, np.pi, theta_step)
    if w.sum() > 0:
        centre = np.array([np.average(x, weights=w), np.average(y, weights=w)])
    else:
        centre = np.zeros(2)
    xc, yc = x - centre[0], y - centre[1]
    rmax = float(np.max(np.hypot(xc, yc))) + 2 * rho_step if len(x) else rho_step
    nr = int(np.ceil(2 * rmax / rho_step)) + 1
    r = xc[:, None] * np.cos(thetas)[None, :] + yc[:, None] * np.sin(thetas)[None, :] + rmax
    u = r / rho_step
    i0 = np.floor(u).astype(np.int64)
    f = u - i0
    nt = len(thetas)
    cols = np.broadcast_to(np.arange(nt), i0.shape)
    ww = np.broadcast_to(w[:, None], i0.shape)
    i0c, i1c = np.clip(i0, 0, nr - 1), np.clip(i0 + 1, 0, nr - 1)
    acc = np.bincount((i0c * nt + cols).ravel(), weights=(ww * (1 - f)).ravel(), minlength=nr * nt)
    acc += np.bincount((i1c * nt + cols).ravel(), weights=(ww * f).ravel(), minlength=nr * nt)
    return acc.reshape(nr, nt), centre


@pytest.mark.parametrize("n", [0, 1, 3, 40, 400])
def test_hough_accumulator_equals_plain(n):
    rng = np.random.default_rng(n)
    x, y = rng.normal(size=n) * 2.0, rng.normal(size=n) * 2.0
    for w in (rng.uniform(0.0, 1.0, n), np.zeros(n)):
        for theta_step, rho_step in ((np.deg2rad(0.5), 0.1), (np.deg2rad(2.0), 0.05)):
            plane = hough_accumulator(x, y, w, theta_step, rho_step)
            acc, centre = _plain_accumulator(x, y, w, theta_step, rho_step)
            assert np.array_equal(plane.acc, acc)
            assert np.array_equal(plane.centre, centre)


def test_lamp_covs_equals_fancy_indexing():
    rng = np.random.default_rng(5)
    ekf = EkfSlam([0.0, 0.0, 0.1], np.eye(3) * 1e-3, (1e-4, 1e-5, 1e-4, 1e-5), capacity=2)
    assert ekf.lamp_covs().shape == (0, 2, 2)
    for _ in range(9):  # grows past the capacity: P is a view of a larger array
        ekf.add_lamp(rng.normal(size=2), np.eye(2) * 1e-3)
        ekf.predict(0.2, 0.05)
    ekf.update_lamps([1, 4], ekf.predict_lamps([1, 4])[0] + 0.01, np.eye(4) * 1e-3)
    idx = ekf.m0 + 2 * np.arange(ekf.n_lamps)
    rows = idx[:, None, None] + np.array([0, 1])[None, :, None]
    cols = idx[:, None, None] + np.array([0, 1])[None, None, :]
    assert np.array_equal(ekf.lamp_covs(), ekf.P[rows, cols])


def test_format_tum_equals_numpy_rows():
    from fuzzyslam.se2 import yaw_to_quaternion
    from fuzzyslam.streams.tum import format_tum

    rng = np.random.default_rng(5)
    t = np.concatenate([rng.uniform(0.0, 2e9, 3000), [0.0, 1e-10, 1248444877.2400002]])
    poses = rng.normal(size=(len(t), 3)) * [50.0, 50.0, 4.0]
    poses[:4] = [[-0.0, 0.0, -0.0], [1e-7, -4e-7, np.pi], [np.inf, -np.inf, -np.pi], [1, 2, 3]]
    q = yaw_to_quaternion(poses[:, 2]).reshape(-1, 4)
    rows = np.column_stack([t, poses[:, 0], poses[:, 1], np.zeros(len(t)), q])
    plain = [
        "%.9f %.6f %.6f %.6f %.9f %.9f %.9f %.9f" % tuple(r)  # noqa: UP031 - numpy scalars
        for r in rows
    ]
    text = format_tum(t, poses)
    assert text == "\n".join(["# timestamp x y z qx qy qz qw", *plain]) + "\n"
    assert format_tum(np.zeros(0), np.zeros((0, 3))) == "# timestamp x y z qx qy qz qw\n"


@pytest.mark.parametrize("chunk_size", [4096, 1024 * 1024])
def test_lean_mcap_writer_equals_mcap_writer(chunk_size):
    import io

    from mcap.writer import CompressionType

    from fuzzyslam.streams.writer import _LeanWriter

    rng = np.random.default_rng(6)
    n = 3000
    cids = rng.integers(0, 3, n)
    times = np.sort(rng.integers(0, 10**12, n))
    times[::7] = times[::7] // 2  # log times out of order now and then
    sizes = rng.integers(0, 700, n)
    out = {}
    for lean in (True, False):
        f = io.BytesIO()
        w = _LeanWriter(f, chunk_size=chunk_size, compression=CompressionType.ZSTD)
        assert w.lean
        w.lean = lean
        w.start(profile="ros2", library="test")
        s = w.register_schema(name="a/msg/B", encoding="ros2msg", data=b"int32 x")
        ch = [
            w.register_channel(topic=f"/t{k}", message_encoding="cdr", schema_id=s)
            for k in range(3)
        ]
        w.add_metadata("m", {"k": "v"})
        for i in range(n):
            data = rng.bytes(int(sizes[i])) if lean else out["data"][i]
            if lean:
                out.setdefault("data", []).append(data)
            w.add_message(channel_id=ch[cids[i]], log_time=int(times[i]), data=data,
                          publish_time=int(times[i]) + 1, sequence=i)  # fmt: skip
        w.add_attachment(
            create_time=1, log_time=2, name="w.yaml", media_type="text/yaml", data=b"x"
        )
        w.finish()
        out[lean] = f.getvalue()
    assert out[True] == out[False]
    assert len(out[True]) > chunk_size or chunk_size > 10**5


def test_level_chunks_hold_what_mcap_writes():
    """_LeanWriter's chunks at ZSTD_LEVEL against mcap's own Writer (its default level):
    the same messages, metadata, attachment and statistics read back (CRCs checked), the
    same chunks (uncompressed size and CRC, times) and message indexes, each chunk the
    ZSTD_LEVEL compression of its bytes; only the compressed bytes differ."""
    import io

    import zstandard
    from mcap.reader import make_reader
    from mcap.records import Chunk, MessageIndex
    from mcap.stream_reader import StreamReader
    from mcap.writer import CompressionType, Writer

    from fuzzyslam.streams.writer import ZSTD_LEVEL, _LeanWriter

    rng = np.random.default_rng(8)
    n = 2000
    cids, sizes = rng.integers(0, 3, n), rng.integers(0, 900, n)
    datas = [rng.integers(0, 8, int(k), dtype=np.uint8).tobytes() for k in sizes]  # compressible
    files = {}
    for kind in (_LeanWriter, Writer):
        f = io.BytesIO()
        w = kind(f, chunk_size=64 * 1024, compression=CompressionType.ZSTD)
        w.start(profile="ros2", library="test")
        s = w.register_schema(name="a/msg/B", encoding="ros2msg", data=b"int32 x")
        ch = [
            w.register_channel(topic=f"/t{k}", message_encoding="cdr", schema_id=s)
            for k in range(3)
        ]
        w.add_metadata("m", {"k": "v"})
        for i in range(n):
            w.add_message(channel_id=ch[cids[i]], log_time=10 * i, data=datas[i],
                          publish_time=10 * i + 1, sequence=i)  # fmt: skip
        w.add_attachment(create_time=1, log_time=2, name="w.yaml", media_type="t", data=b"x")
        w.finish()
        files[kind] = f.getvalue()
    assert files[_LeanWriter] != files[Writer]  # another level: other compressed bytes

    def read(data: bytes):
        r = make_reader(io.BytesIO(data), validate_crcs=True)
        msgs = [(c.topic, m.log_time, m.publish_time, m.sequence, m.data)
                for _, c, m in r.iter_messages(log_time_order=False)]  # fmt: skip
        meta = [(m.name, m.metadata) for m in r.iter_metadata()]
        att = [(a.name, a.data, a.log_time) for a in r.iter_attachments()]
        return msgs, meta, att, r.get_summary().statistics

    def chunks(data: bytes):
        out = []
        for rec in StreamReader(io.BytesIO(data), emit_chunks=True).records:
            if isinstance(rec, Chunk):
                size = rec.uncompressed_size
                raw = zstandard.ZstdDecompressor().decompress(rec.data, max_output_size=size)
                out.append((rec.uncompressed_size, rec.uncompressed_crc, rec.message_start_time,
                            rec.message_end_time, raw))  # fmt: skip
                if data is files[_LeanWriter]:
                    assert rec.data == zstandard.ZstdCompressor(level=ZSTD_LEVEL).compress(raw)
            elif isinstance(rec, MessageIndex):
                out.append((rec.channel_id, rec.records))
        return out

    assert read(files[_LeanWriter]) == read(files[Writer])
    assert len(read(files[Writer])[0]) == n
    lean_chunks = chunks(files[_LeanWriter])
    assert lean_chunks == chunks(files[Writer]) and len(lean_chunks) > 10


def test_loop_at1_equals_at():
    from fuzzyslam.sim.world import Loop

    rng = np.random.default_rng(7)
    ang = np.sort(rng.uniform(0.0, 2 * np.pi, 9))
    pts = np.column_stack([20 * np.cos(ang), 12 * np.sin(ang)]) + rng.normal(0, 0.5, (9, 2))
    loop = Loop(pts)
    total = float(loop.cum[-1])
    s = rng.uniform(-3 * total, 3 * total, 20000)
    s = np.concatenate([s, loop.cum, -loop.cum, loop.cum + total, [0.0, -0.0, total, -total]])
    pt, tg = loop.at(s)
    one = np.array([loop.at1(float(v)) for v in s])
    assert np.array_equal(one[:, :2], pt) and np.array_equal(one[:, 2:], tg)


def _odometry_fields(msg) -> tuple:
    p, q = msg.pose.pose.position, msg.pose.pose.orientation
    tw = msg.twist.twist
    return (msg.header.stamp.sec, msg.header.stamp.nanosec, msg.header.frame_id,
            msg.child_frame_id, p.x, p.y, p.z, q.x, q.y, q.z, q.w, tw.linear.x,
            tw.angular.z, tuple(msg.pose.covariance), tuple(msg.twist.covariance))  # fmt: skip


def _decoded(fn, buf):
    try:
        return _odometry_fields(fn(buf))
    except Exception as exc:  # the same failure, by type
        return type(exc)


def test_odometry_layout_cache_equals_plain_decoder():
    """Payloads of one layout (fast path after the first), of other frame names of the
    same size, cut, and with damaged string lengths: the same messages or errors."""
    from fuzzyslam.streams import cdr
    from fuzzyslam.streams.cdr_encode import encode_odometry_block

    rng = np.random.default_rng(8)
    t = np.cumsum(rng.uniform(0.001, 0.05, 300)) + 1.2e9
    poses = rng.normal(size=(300, 3)) * [10.0, 10.0, 3.0]
    payloads = []
    for frame, child in (("odom", "base_link"), ("odom", "base_linl"), ("odoM", "base_link"),
                         ("", "b"), ("odom", "base_link")):  # fmt: skip
        payloads += encode_odometry_block(t, frame, child, poses, poses[:, 0], poses[:, 2])[:60]
    good = payloads[0]
    for k in range(40):
        bad = bytearray(good)
        bad[int(rng.integers(0, 40))] ^= 1 << int(rng.integers(0, 8))
        payloads += [bytes(bad), good[: len(good) - k], good, memoryview(good)]
    fast = [_decoded(cdr.decode_odometry, b) for b in payloads]
    plain = [_decoded(cdr.decode_odometry_plain, b) for b in payloads]
    assert fast == plain
    assert sum(isinstance(f, tuple) for f in fast) > 300
    assert sum(not isinstance(f, tuple) for f in fast) > 20


def test_sonar_rings_traced_together_equal_one_by_one():
    from fuzzyslam.sim import sonar
    from fuzzyslam.sim.params import SonarParams

    rng = np.random.default_rng(10)
    # a closed room with inner walls, the robot anywhere inside
    box = [[-6, -4, 6, -4], [6, -4, 6, 4], [6, 4, -6, 4], [-6, 4, -6, -4]]
    inner = np.column_stack([rng.uniform(-5, 5, (12, 2)), rng.uniform(-5, 5, (12, 2))])
    walls = np.vstack([box, inner]).astype(float)
    a = np.linspace(0.0, 2 * np.pi, 16, endpoint=False)
    mounts = np.column_stack([0.2 * np.cos(a), 0.2 * np.sin(a), a])
    poses = np.column_stack([rng.uniform(-5.5, 5.5, (40, 2)), rng.uniform(-np.pi, np.pi, 40)])
    for params in (SonarParams(), SonarParams(rays_per_cone=1, max_bounces=0)):
        many = sonar.ideal_ranges_many(walls, poses, mounts, params)
        one = np.array([sonar.ideal_ranges(walls, sonar.sensor_poses(p, mounts), params)
                        for p in poses])  # fmt: skip
        assert np.array_equal(many, one)
        assert np.isfinite(many).mean() > 0.2  # echoes, not only misses


def _joint_fields(fn, buf):
    try:
        m = fn(buf)
    except Exception as exc:  # the same failure, by type
        return type(exc)
    return (m.header.stamp.sec, m.header.stamp.nanosec, m.header.frame_id, tuple(m.name),
            m.position.tobytes(), m.velocity.tobytes(), m.effort.tobytes(),
            m.position.dtype.str)  # fmt: skip


def test_joint_state_layout_cache_equals_plain_decoder():
    """Joint states of one layout (fast path after the first), of other names of the same
    size, with velocities, cut, and with damaged bytes: the same messages or errors."""
    from fuzzyslam.streams import cdr
    from fuzzyslam.streams.cdr_encode import encode_joint_state_block
    from fuzzyslam.streams.typestore import msgtype, serialize

    rng = np.random.default_rng(11)
    t = np.cumsum(rng.uniform(0.001, 0.05, 100)) + 1.2e9
    payloads = []
    wheels = ["wheel_left_joint", "wheel_right_joint"]
    for names in (wheels, ["wheel_left_joint", "wheel_rigHt_joint"], ["a", "b", "c"], wheels):
        pos = rng.normal(size=(100, len(names))) * 100
        payloads += encode_joint_state_block(t, names, pos)[:50]
    js = msgtype("sensor_msgs/msg/JointState")
    hdr = msgtype("std_msgs/msg/Header")(
        stamp=msgtype("builtin_interfaces/msg/Time")(sec=5, nanosec=7), frame_id="f"
    )
    for k in range(20):  # with velocities and efforts of a few lengths
        n = k % 3
        msg = js(header=hdr, name=["x", "y"], position=rng.normal(size=2),
                 velocity=rng.normal(size=n), effort=rng.normal(size=2 - n))  # fmt: skip
        payloads += [serialize(msg, "sensor_msgs/msg/JointState")] * 2
    good = payloads[0]
    for k in range(40):
        bad = bytearray(good)
        bad[int(rng.integers(0, len(good)))] ^= 1 << int(rng.integers(0, 8))
        payloads += [bytes(bad), good[: len(good) - k], good, memoryview(good)]
    fast = [_joint_fields(cdr.decode_joint_state, b) for b in payloads]
    plain = [_joint_fields(cdr.decode_joint_state_plain, b) for b in payloads]
    assert fast == plain
    assert sum(isinstance(f, tuple) for f in fast) > 250
    assert sum(not isinstance(f, tuple) for f in fast) > 20
