"""Little-endian CDR decoders of the frequent ROS 2 messages (encoders: cdr_encode.py).

The decoders read the few types a log is mostly made of (wheel encoders, frames, sonar,
odometry, landmark detections, laser scans) 2-4x faster than rosbags' generic
deserializer (benchmarks/bench_read.py) and return the light message classes of
``streams/cdr_messages.py``, whose attribute names are the rosbags messages' names
(``header.stamp.sec``, ``pose.pose.position.x``, ...), so code reading either cannot
tell them apart. Arrays are numpy arrays of the rosbags dtypes: copies, except
``Image.data`` (a read-only view of the payload) and empty sequences (one shared
read-only empty array).

Layout (OMG CDR, the encoding of ROS 2 ``cdr`` messages): a 4-byte encapsulation
header (``00 01 00 00`` for little-endian CDR), then the fields in order, each primitive
aligned to its size counted from the end of that header; a string is a u32 length
(with the terminating NUL), its bytes and the NUL; a sequence is a u32 count then the
elements (a primitive sequence is aligned to its element size only when not empty);
a fixed array has no count. A payload that is truncated or inconsistent (a length past
the end, a string without its NUL, bytes left over) raises :class:`CdrError`.
"""

from __future__ import annotations

import struct
from collections.abc import Callable
from typing import Any

import numpy as np

# the block encoders of the estimates' log, at home in cdr_encode (imported from here too)
from fuzzyslam.streams.cdr_encode import (  # noqa: F401
    encode_pose_with_covariance_block,
    encode_tf_block,
)
from fuzzyslam.streams.cdr_messages import (
    F8,
    CameraInfo,
    Header,
    Image,
    JointState,
    LaserScan,
    Odometry,
    Point,
    Pose,
    PoseArray,
    PoseWithCovariance,
    Quaternion,
    Range,
    RegionOfInterest,
    TFMessage,
    Time,
    Transform,
    TransformStamped,
    Vector3,
)
from fuzzyslam.streams.typestore import deserialize

_U32 = struct.Struct("<I")
_STAMP_FRAME = struct.Struct("<iII")  # header.stamp sec, nanosec; frame_id length
_F64X7 = struct.Struct("<7d")
_F32X4 = struct.Struct("<4f")
_F32X7_U32 = struct.Struct("<7fI")
_U32X2 = struct.Struct("<II")


class CdrError(ValueError):
    """A CDR payload that is truncated or inconsistent."""


# -- readers of the parts ----------------------------------------------------------------
# Positions ``a`` below are absolute offsets in the payload; CDR alignment counts from
# offset 4 (after the encapsulation header), so "align a to k" is a += (4 - a) % k.


def _string(buf, a: int) -> tuple[str, int]:
    """A CDR string at ``a`` (4-aligned) and the offset after it."""
    (n,) = _U32.unpack_from(buf, a)
    end = a + 4 + n
    if n < 1 or end > len(buf) or buf[end - 1] != 0:
        raise CdrError(f"bad string of length {n} at offset {a} of {len(buf)} bytes")
    return str(buf[a + 4 : end - 1], "utf-8"), end


def _header(buf) -> tuple[Header, int]:
    """std_msgs/Header right after the encapsulation; the offset after it."""
    sec, nsec, n = _STAMP_FRAME.unpack_from(buf, 4)  # struct.error if too short
    end = 16 + n
    if buf[1] != 1 or buf[0] or n < 1 or end > len(buf) or buf[end - 1]:
        raise CdrError(f"not little-endian CDR or a bad frame_id (length {n}, {len(buf)} bytes)")
    return Header(Time(sec, nsec), str(buf[16 : end - 1], "utf-8") if n > 1 else ""), end


_F8 = F8
_F4 = np.dtype("<f4")
_EMPTY = {_F8: np.zeros(0, _F8), _F4: np.zeros(0, _F4)}  # shared: read-only
for _e in _EMPTY.values():
    _e.flags.writeable = False


def _sequence(buf, a: int, dtype: np.dtype) -> tuple[np.ndarray, int]:
    """A primitive sequence at ``a`` (4-aligned): count, then elements aligned to their
    size when there are any. Returns the array (a copy; a shared read-only array when
    empty) and the offset after it."""
    (count,) = _U32.unpack_from(buf, a)
    a += 4
    if not count:
        return _EMPTY[dtype], a
    size = dtype.itemsize
    a += (4 - a) % size
    end = a + size * count
    if end > len(buf):
        raise CdrError(f"array of {count} x {size} bytes at offset {a} past {len(buf)} bytes")
    return np.frombuffer(buf, dtype, count, a).copy(), end


def _end(buf, a: int) -> None:
    """The payload must end at ``a`` (up to 3 bytes of padding, as rosbags allows)."""
    if a > len(buf) or len(buf) - a > 3:
        raise CdrError(f"payload of {len(buf)} bytes, message ends at {a}")


def _pose(v) -> Pose:
    return Pose(Point(v[0], v[1], v[2]), Quaternion(v[3], v[4], v[5], v[6]))


# -- decoders ------------------------------------------------------------------------------


_STAMP = struct.Struct("<iI")
# the last Odometry layout decoded: (size, bytes 0-4, bytes 12-a, frame_id, child, a)
_odometry_layout: list = [None]


def decode_odometry(buf: bytes | memoryview) -> Odometry:
    """nav_msgs/Odometry: header, child_frame_id, pose (7 f64 + covariance[36]), twist
    (6 f64 + covariance[36]); the 85 float64 follow the string, aligned to 8.

    A payload of the size, encapsulation and frame_id/child_frame_id bytes of the last
    one decoded passes the same checks with the same offsets: only its stamp and numbers
    are read (:func:`decode_odometry_plain` is the whole decoder; a log's odometry
    messages all have one layout)."""
    lay = _odometry_layout[0]
    if lay is not None and len(buf) == lay[0] and buf[12 : lay[5]] == lay[2] and buf[:4] == lay[1]:
        sec, nsec = _STAMP.unpack_from(buf, 4)
        a = lay[5]
        pose = _pose(_F64X7.unpack_from(buf, a))
        raw = bytes(buf[a + 56 : a + 680])
        header = Header(Time(sec, nsec), lay[3])
        return Odometry(header, lay[4], PoseWithCovariance(pose, (raw, 0)), (raw, 288))
    msg, a = _odometry(buf)
    _odometry_layout[0] = (
        len(buf),
        bytes(buf[:4]),
        bytes(buf[12:a]),
        msg.header.frame_id,
        msg.child_frame_id,
        a,
    )
    return msg


def decode_odometry_plain(buf: bytes | memoryview) -> Odometry:
    """:func:`decode_odometry` without the layout cache (every check made)."""
    return _odometry(buf)[0]


def _odometry(buf: bytes | memoryview) -> tuple[Odometry, int]:
    """An Odometry and the offset of its 85 float64."""
    header, a = _header(buf)
    a += (4 - a) % 4
    child, a = _string(buf, a)
    a += (4 - a) % 8
    if a + 85 * 8 > len(buf):
        raise CdrError(f"Odometry of {len(buf)} bytes is truncated")
    if len(buf) - a - 680 > 3:
        raise CdrError(f"payload of {len(buf)} bytes, message ends at {a + 680}")
    pose = _pose(_F64X7.unpack_from(buf, a))
    raw = bytes(buf[a + 56 : a + 680])  # covariances and twist, decoded when read
    return Odometry(header, child, PoseWithCovariance(pose, (raw, 0)), (raw, 288)), a


def decode_pose_array(buf: bytes | memoryview) -> PoseArray:
    """geometry_msgs/PoseArray: header, sequence of Pose (7 float64 each, aligned to 8)."""
    header, a = _header(buf)
    a += (4 - a) % 4
    (count,) = _U32.unpack_from(buf, a)
    a += 4
    if not count:
        _end(buf, a)
        return PoseArray(header, [])
    a += (4 - a) % 8
    end = a + 56 * count
    if end > len(buf) or len(buf) - end > 3:
        raise CdrError(f"PoseArray of {count} poses in {len(buf)} bytes")
    return PoseArray(
        header,
        [
            Pose(Point(x, y, z), Quaternion(qx, qy, qz, qw))
            for x, y, z, qx, qy, qz, qw in _F64X7.iter_unpack(buf[a:end])
        ],
    )


def decode_laser_scan(buf: bytes | memoryview) -> LaserScan:
    """sensor_msgs/LaserScan: header, 7 float32 (angles, times, range limits), ranges and
    intensities (float32 sequences)."""
    header, a = _header(buf)
    a += (4 - a) % 4
    *f, n = _F32X7_U32.unpack_from(buf, a)
    a += 32
    end = a + 4 * n
    if end + 4 > len(buf):
        raise CdrError(f"LaserScan of {n} ranges past {len(buf)} bytes")
    ranges = np.frombuffer(buf, _F4, n, a).copy() if n else _EMPTY[_F4]
    intensities, a = _sequence(buf, end, _F4)
    _end(buf, a)
    return LaserScan(header, *f, ranges, intensities)


# the last JointState layout: (size, bytes 0-4, bytes 12-a (names, position count), a,
# frame_id, names, ((count offset, count bytes, data offset, count) per sequence))
_joint_state_layout: list = [None]


def decode_joint_state(buf: bytes | memoryview) -> JointState:
    """sensor_msgs/JointState: header, name (sequence of strings), position, velocity and
    effort (float64 sequences).

    A payload of the last one's size, encapsulation, frame_id, names and sequence counts
    passes the same checks with the same offsets: only its stamp and numbers are read
    (:func:`decode_joint_state_plain` is the whole decoder)."""
    lay = _joint_state_layout[0]
    if (
        lay is not None
        and len(buf) == lay[0]
        and buf[12 : lay[3]] == lay[2]
        and buf[:4] == lay[1]
        and (
            buf[lay[7] :] == lay[8]  # velocity and effort empty: their counts end the payload
            if lay[7]
            else all(buf[c : c + 4] == cb for c, cb, _, _ in lay[6][1:])
        )
    ):
        sec, nsec = _STAMP.unpack_from(buf, 4)
        if lay[7]:
            _, _, d, n = lay[6][0]
            pos = np.frombuffer(buf, _F8, n, d).copy() if n else _EMPTY[_F8]
            return JointState(Header(Time(sec, nsec), lay[4]), list(lay[5]), pos, *lay[9])
        arrays = [
            np.frombuffer(buf, _F8, n, d).copy() if n else _EMPTY[_F8] for _, _, d, n in lay[6]
        ]
        return JointState(Header(Time(sec, nsec), lay[4]), list(lay[5]), *arrays)
    msg, a, seqs = _joint_state(buf)
    counts = tuple((c, bytes(buf[c : c + 4]), d, n) for c, d, n in seqs)
    # with velocity and effort empty, the bytes from the velocity count on are all fixed
    tail = seqs[1][0] if seqs[1][2] == 0 and seqs[2][2] == 0 else 0
    _joint_state_layout[0] = (
        len(buf), bytes(buf[:4]), bytes(buf[12:a]), a, msg.header.frame_id, tuple(msg.name),
        counts, tail, bytes(buf[tail:]) if tail else b"", (msg.velocity, msg.effort),
    )  # fmt: skip
    return msg


def decode_joint_state_plain(buf: bytes | memoryview) -> JointState:
    """:func:`decode_joint_state` without the layout cache (every check made)."""
    return _joint_state(buf)[0]


def _joint_state(buf: bytes | memoryview) -> tuple[JointState, int, list]:
    """A JointState, the offset after its position count, and per sequence (count
    offset, data offset, count)."""
    header, a = _header(buf)
    a += (4 - a) % 4
    (count,) = _U32.unpack_from(buf, a)
    a += 4
    if count > len(buf) // 5:
        raise CdrError(f"JointState with {count} names in {len(buf)} bytes")
    names = []
    for _ in range(count):
        a += (4 - a) % 4
        s, a = _string(buf, a)
        names.append(s)
    seqs, arrays = [], []
    for _ in range(3):  # position, velocity, effort
        a += (4 - a) % 4
        (n,) = _U32.unpack_from(buf, a)
        data = a + 4 + ((4 - (a + 4)) % 8 if n else 0)
        seqs.append((a, data, n))
        arr, a = _sequence(buf, a, _F8)
        arrays.append(arr)
    _end(buf, a)
    return JointState(header, names, *arrays), seqs[0][0] + 4, seqs


def decode_image(buf: bytes | memoryview) -> Image:
    """sensor_msgs/Image: header, height, width, encoding, is_bigendian (u8), step, data
    (uint8 sequence, returned as a view of ``buf``)."""
    header, a = _header(buf)
    a += (4 - a) % 4
    height, width = _U32X2.unpack_from(buf, a)
    encoding, a = _string(buf, a + 8)
    if a >= len(buf):
        raise CdrError(f"Image of {len(buf)} bytes is truncated")
    big = buf[a]
    a += 1
    a += (4 - a) % 4
    step, count = _U32X2.unpack_from(buf, a)
    a += 8
    if a + count > len(buf):
        raise CdrError(f"Image data of {count} bytes past {len(buf)} bytes")
    _end(buf, a + count)
    data = np.frombuffer(buf, dtype=np.uint8, count=count, offset=a)
    return Image(header, height, width, encoding, big, step, data)


def decode_range(buf: bytes | memoryview) -> Range:
    """sensor_msgs/Range: header, radiation_type (u8), then four float32 aligned to 4:
    field_of_view, min_range, max_range, range; from ROS 2 Iron on (Jazzy, Kilted, ...)
    a fifth, variance, which is read past (the fixes model the sonar's noise
    themselves)."""
    header, a = _header(buf)
    if a >= len(buf):
        raise CdrError(f"Range of {len(buf)} bytes is truncated")
    kind = buf[a]
    a += 1
    a += (4 - a) % 4
    fov, lo, hi, r = _F32X4.unpack_from(buf, a)
    end = a + 16
    if len(buf) - end > 3:  # Iron's variance, or more than padding
        end += 4
        if len(buf) - end > 3:
            raise CdrError(f"payload of {len(buf)} bytes, message ends at {end}")
    return Range(header, kind, fov, lo, hi, r)


_U32X4 = struct.Struct("<4I")
_CAMERA_MATRICES = struct.Struct("<30d")  # k (9), r (9), p (12)


def decode_camera_info(buf: bytes | memoryview) -> CameraInfo:
    """sensor_msgs/CameraInfo: header, height, width (u32), distortion_model, d (float64
    sequence), k, r (float64[9]), p (float64[12]) aligned to 8, binning_x, binning_y,
    roi (four u32 and a bool)."""
    header, a = _header(buf)
    a += (4 - a) % 4
    height, width = _U32X2.unpack_from(buf, a)
    model, a = _string(buf, a + 8)
    a += (4 - a) % 4
    d, a = _sequence(buf, a, _F8)
    a += (4 - a) % 8
    m = np.frombuffer(buf, _F8, 30, a).copy()  # ValueError if too short
    a += 240
    a += (4 - a) % 4
    bx, by = _U32X2.unpack_from(buf, a)
    roi = _U32X4.unpack_from(buf, a + 8)
    a += 24
    if a >= len(buf):
        raise CdrError(f"CameraInfo of {len(buf)} bytes is truncated")
    rect = bool(buf[a])
    _end(buf, a + 1)
    return CameraInfo(header, height, width, model, d, m[:9], m[9:18], m[18:], bx, by,
                      RegionOfInterest(*roi, rect))  # fmt: skip


def decode_tf_message(buf: bytes | memoryview) -> TFMessage:
    """tf2_msgs/TFMessage: a sequence of geometry_msgs/TransformStamped (header,
    child_frame_id, translation and rotation as float64 aligned to 8)."""
    if buf[1] != 1 or buf[0]:
        raise CdrError("not little-endian CDR")
    (count,) = _U32.unpack_from(buf, 4)
    if count > len(buf) // 40:
        raise CdrError(f"TFMessage with {count} transforms in {len(buf)} bytes")
    a = 8
    out = []
    for _ in range(count):
        a += (4 - a) % 4
        sec, nsec = _STAMP.unpack_from(buf, a)
        frame, a = _string(buf, a + 8)
        a += (4 - a) % 4
        child, a = _string(buf, a)
        a += (4 - a) % 8
        v = _F64X7.unpack_from(buf, a)
        a += 56
        tf = Transform(Vector3(v[0], v[1], v[2]), Quaternion(v[3], v[4], v[5], v[6]))
        out.append(TransformStamped(Header(Time(sec, nsec), frame), child, tf))
    _end(buf, a)
    return TFMessage(out)


def decode_tf_messages(bufs: list[bytes]):
    """The transforms of little-endian CDR tf2_msgs/TFMessage payloads, as
    :func:`decode_tf_message` reads them (and ``log_setup.tf_frames`` takes them), at once
    for the payloads of one layout (the same length, transform count, frame names; a
    constant-rate /tf has one): each payload of a layout is checked against the first,
    which that decoder reads; their stamps and floats are read with numpy, the same
    bits. None if a payload is not little-endian or does not decode (``tf_frames``
    would count it undecodable), or past 64 layouts.

    Parameters
    ----------
    bufs : list of bytes
        The payloads, in log-time order.

    Returns
    -------
    (msg, names, (stamps, pair), xyq) or None
        Per transform, in order (message, then transform): its message's index (T,),
        the frame pairs (parent, child; slashes stripped) in order of first sight, the
        stamp sec + nanosec 1e-9 (T,) and the index of its pair in ``names`` (T,), and
        (x, y, qx, qy, qz, qw) (T, 6).
    """
    left = np.arange(len(bufs))
    lengths = np.fromiter((len(b) for b in bufs), dtype=np.int64, count=len(bufs))
    parts = []  # (message indices, transform index, pair, sec, nsec, values (n, 7))
    names: dict[tuple[str, str], int] = {}
    for _ in range(64):
        if not len(left):
            break
        first = bufs[left[0]]
        if first[:2] != b"\x00\x01":
            return None
        try:
            msg = decode_tf_message(first)
        except Exception:
            return None
        same = left[lengths[left] == len(first)]
        rows = np.frombuffer(b"".join(bufs[i] for i in same), np.uint8).reshape(len(same), -1)
        keep = np.all(rows[:, :8] == rows[0, :8], axis=1)  # encapsulation, count
        a = 8
        fields = []
        for ts in msg.transforms:  # decode_tf_message's offsets, its strings compared
            a += (4 - a) % 4
            stamp = a
            a += 8  # sec, nanosec
            for name in (ts.header.frame_id, ts.child_frame_id):
                a += (4 - a) % 4
                end = a + 4 + len(name.encode()) + 1
                keep &= np.all(rows[:, a:end] == rows[0, a:end], axis=1)
                a = end
            a += (4 - a) % 8
            fields.append((stamp, a, ts))
            a += 56
        same, rows = same[keep], rows[keep]
        for j, (stamp, at, ts) in enumerate(fields):
            pair = (str(ts.header.frame_id).lstrip("/"), str(ts.child_frame_id).lstrip("/"))
            sec = np.ascontiguousarray(rows[:, stamp : stamp + 4]).view("<i4").ravel()
            nsec = np.ascontiguousarray(rows[:, stamp + 4 : stamp + 8]).view("<u4").ravel()
            v = np.ascontiguousarray(rows[:, at : at + 56]).view("<f8")
            parts.append((same, j, names.setdefault(pair, len(names)), sec, nsec, v))
        left = np.setdiff1d(left, same, assume_unique=True)
    else:
        if len(left):
            return None
    if not parts:
        return np.zeros(0, int), [], (np.zeros(0), np.zeros(0, int)), np.zeros((0, 6))
    msg = np.concatenate([p[0] for p in parts])
    slot = np.concatenate([np.full(len(p[0]), p[1]) for p in parts])
    order = np.lexsort((slot, msg))  # message order, then the transforms' order
    pair = np.concatenate([np.full(len(p[0]), p[2]) for p in parts])[order]
    sec = np.concatenate([p[3] for p in parts])[order].astype(float)
    nsec = np.concatenate([p[4] for p in parts])[order].astype(float)
    v = np.concatenate([p[5] for p in parts])[order]
    stamps = sec + nsec * 1e-9  # messages.stamp_to_sec
    return msg[order], list(names), (stamps, pair), v[:, [0, 1, 3, 4, 5, 6]]


DECODERS: dict[str, Callable[[Any], Any]] = {
    "nav_msgs/msg/Odometry": decode_odometry,
    "geometry_msgs/msg/PoseArray": decode_pose_array,
    "sensor_msgs/msg/LaserScan": decode_laser_scan,
    "sensor_msgs/msg/JointState": decode_joint_state,
    "sensor_msgs/msg/Image": decode_image,
    "sensor_msgs/msg/Range": decode_range,
    "sensor_msgs/msg/CameraInfo": decode_camera_info,
    "tf2_msgs/msg/TFMessage": decode_tf_message,
}


def decoder(typename: str, slow: Callable[[Any], Any] | None = None) -> Callable[[Any], Any]:
    """The decoder of a (normalised) type name: a fast one for little-endian payloads of
    the types in ``DECODERS``, ``slow`` for the rest (big-endian, other types): by default
    rosbags with the typestore's definitions.

    The decoder raises an exception (``CdrError``, ``struct.error``, rosbags' errors) on a
    payload it cannot read.

    Parameters
    ----------
    typename : str
        The type name.
    slow : callable, optional
        CDR bytes -> message for what the fast decoders do not read (the log's own
        definition: ``typestore.file_deserializer``).

    Returns
    -------
    callable
    """
    fast = DECODERS.get(typename)
    if slow is None:

        def slow(buf):
            return deserialize(buf, typename)

    if fast is None:
        return slow

    def decode(buf):
        if buf[1] == 1 and buf[0] == 0:
            return fast(buf)
        return slow(buf)

    return decode
