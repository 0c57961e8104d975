"""Little-endian CDR encoders of the messages written in bulk (simulated logs, estimates).

Each gives the bytes ``typestore.serialize`` gives for the message the builders of
``streams/messages.py`` make, several times faster: a message's fixed part (its frame
names, constants, zeros) is serialised once by rosbags as a template, and only what
changes from message to message is written into copies of it -- the header stamp
(seconds and nanoseconds at offsets 4 and 8, right after the encapsulation header, in
every message with a header first) and the values at the message's end, found from the
end (a primitive field or array at the end has no trailing padding). The block encoders
fill N rows at once through a numpy structured view of N template copies.
"""

from __future__ import annotations

import struct
from collections.abc import Sequence
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from fuzzyslam.se2 import yaw_to_quaternion
from fuzzyslam.stamps import split_ns, to_ns
from fuzzyslam.streams import messages as M
from fuzzyslam.streams.distro import DEFAULT_ROS_DISTRO
from fuzzyslam.streams.typestore import field_names, serialize

_U32 = struct.Struct("<I")
_STAMP = struct.Struct("<iI")
_F32 = struct.Struct("<f")
_F32X2 = struct.Struct("<2f")


def _stamps(t: np.ndarray) -> tuple[list[int], list[int]]:
    """(sec, nanosec) of stamps in seconds, rounded to ns as ``messages.stamp``."""
    ns = [to_ns(v) for v in np.asarray(t, dtype=float).tolist()]
    return [v // 1_000_000_000 for v in ns], [v % 1_000_000_000 for v in ns]


def restamp(cdr: bytes, t: float) -> bytes:
    """The CDR bytes of a message whose first field is a std_msgs/Header, stamped ``t``
    (s, rounded to ns as ``messages.stamp``) instead."""
    return cdr[:4] + _STAMP.pack(*split_ns(t)) + cdr[12:]


def _rows(template: bytes, t: np.ndarray, fields: list[tuple[int, object, object]]) -> list[bytes]:
    """N = len(t) copies of ``template`` stamped ``t``, each field (offset, numpy format,
    (N, ...) values) written at its offset; the N payloads."""
    size = len(template)
    n = len(t)
    names = ["sec", "nsec", *(f"f{k}" for k in range(len(fields)))]
    formats = ["<i4", "<u4", *(f for _, f, _ in fields)]
    offsets = [4, 8, *(o for o, _, _ in fields)]
    dt = np.dtype({"names": names, "formats": formats, "offsets": offsets, "itemsize": size})
    buf = np.frombuffer(template * n, dtype=np.uint8).copy()
    a = buf.view(dt)
    a["sec"], a["nsec"] = _stamps(t)
    for k, (_, _, values) in enumerate(fields):
        a[f"f{k}"] = values
    raw = buf.tobytes()
    return [raw[k * size : (k + 1) * size] for k in range(n)]


def encode_odometry_block(
    t: np.ndarray, frame: str, child: str, poses: np.ndarray, v: np.ndarray, w: np.ndarray
) -> list[bytes]:
    """nav_msgs/Odometry of ``messages.odometry(t[k], frame, child, poses[k], None, v[k],
    w[k])`` for every row k (no covariance).

    Parameters
    ----------
    t : (N,) stamps, s
    frame, child : header.frame_id and child_frame_id
    poses : (N, 3) x, y, theta (theta as a yaw quaternion)
    v, w : (N,) twist.linear.x (m/s) and twist.angular.z (rad/s)

    Returns
    -------
    N payloads. The pose (7 float64), its covariance (36), the twist (6) and its
    covariance (36) end the message: the pose starts 680 bytes before the end.
    """
    tpl = serialize(M.odometry(0.0, frame, child, np.zeros(3)), M.ODOMETRY)
    poses = np.asarray(poses, dtype=float).reshape(-1, 3)
    pose = np.zeros((len(poses), 7))
    pose[:, :2] = poses[:, :2]
    pose[:, 3:] = yaw_to_quaternion(poses[:, 2])
    end = len(tpl)
    return _rows(tpl, t, [(end - 680, ("<f8", (7,)), pose), (end - 336, "<f8", v),
                          (end - 296, "<f8", w)])  # fmt: skip


def encode_joint_state_block(
    t: np.ndarray, names: Sequence[str], positions: np.ndarray
) -> list[bytes]:
    """sensor_msgs/JointState of ``messages.joint_state(t[k], names, positions[k])`` for
    every row k: positions (N, len(names)) float64, velocity and effort empty (their two
    u32 counts end the message, after the positions)."""
    positions = np.asarray(positions, dtype=float).reshape(len(t), len(names))
    tpl = serialize(M.joint_state(0.0, list(names), np.zeros(len(names))), M.JOINT_STATE)
    at = len(tpl) - 8 - 8 * len(names)
    return _rows(tpl, t, [(at, ("<f8", (len(names),)), positions)])


@lru_cache(maxsize=256)
def _range_template(
    frame: str, fov: float, rmin: float, rmax: float, distro: str
) -> tuple[bytes, bytes, bool]:
    """The Range's bytes before the stamp and from the stamp's end to the range, and
    whether the distribution's Range has a variance after it."""
    tpl = serialize(M.range_msg(0.0, frame, 0.0, fov, rmin, rmax, 0.0, distro), M.RANGE, distro)
    variance = "variance" in field_names(M.RANGE, distro)
    # the range (float32) ends the message, or is followed by the variance (float32)
    return tpl[:4], tpl[12 : -8 if variance else -4], variance


def encode_ranges(
    t: float,
    frames: Sequence[str],
    r: Sequence[float],
    fov: float,
    rmin: float,
    rmax: float,
    variance: float | Sequence[float] = 0.0,
    distro: str = DEFAULT_ROS_DISTRO,
) -> list[bytes]:
    """sensor_msgs/Range of ``messages.range_msg(t, frames[j], r[j], fov, rmin, rmax,
    variance[j], distro)`` for every sonar j of one ring (one stamp).

    Parameters
    ----------
    t : float
        The stamp (s).
    frames : sequence of str
        The sonars' frames.
    r : sequence of float
        Their ranges (m).
    fov, rmin, rmax : float
        Field of view (rad), minimum and maximum range (m).
    variance : float or sequence of float
        The ranges' variances (m^2; one for all, or one per sonar; 0: unknown), written
        where the distribution's Range has the field (Iron on), else not.
    distro : str
        One of ``streams/distro.ROS_DISTROS`` (default Humble).

    Returns
    -------
    list of bytes
        One payload per sonar.
    """
    stamp = _STAMP.pack(*split_ns(t))
    r = np.asarray(r, dtype=float).tolist()
    var = np.broadcast_to(np.asarray(variance, dtype=float), (len(r),)).tolist()
    out = []
    for frame, rj, vj in zip(frames, r, var, strict=True):
        head, body, has_variance = _range_template(
            frame, float(fov), float(rmin), float(rmax), distro
        )
        tail = _F32X2.pack(rj, vj) if has_variance else _F32.pack(rj)
        out.append(head + stamp + body + tail)
    return out


@lru_cache(maxsize=16)
def _image_template(frame: str, height: int, width: int) -> bytes:
    tpl = serialize(M.image_mono8(0.0, frame, np.zeros((height, width), np.uint8)), M.IMAGE)
    return tpl[: len(tpl) - height * width]  # the pixels end the message


def encode_image_mono8(t: float, frame: str, img: np.ndarray) -> bytes:
    """sensor_msgs/Image of ``messages.image_mono8(t, frame, img)``: (H, W) uint8."""
    img = np.ascontiguousarray(img, dtype=np.uint8)
    return restamp(_image_template(frame, *img.shape), t) + img.tobytes()


def encode_pose_with_covariance_block(
    t: np.ndarray, poses: np.ndarray, cov: np.ndarray, frame: str
) -> list[bytes]:
    """Little-endian CDR of geometry_msgs/PoseWithCovarianceStamped for N rows at once
    (the bytes ``typestore.serialize_cdr`` gives for ``messages.pose_with_covariance``,
    ~10x faster).

    Parameters
    ----------
    t : (N,) stamps, s (rounded to ns as ``messages.stamp``)
    poses : (N, 3) x, y, theta (theta as a yaw quaternion)
    cov : (N, 6) covariance rows ``pxx pxy pxt pyy pyt ptt``, embedded at rows/columns
        x, y, yaw of the 6x6 (``messages.cov3_to_cov6``)
    frame : header.frame_id

    Returns
    -------
    N payloads. Layout: header.stamp sec i32, nanosec u32; frame_id u32 length (with
    NUL) + bytes + NUL; padding to 8; position x y z, orientation x y z w,
    covariance[36] float64.
    """
    name = frame.encode() + b"\0"
    pad = -(12 + len(name)) % 8
    dt = np.dtype(
        [
            ("encaps", "V4"),
            ("sec", "<i4"),
            ("nsec", "<u4"),
            ("flen", "<u4"),
            ("frame", f"V{len(name) + pad}"),
            ("pose", "<f8", (7,)),
            ("cov", "<f8", (36,)),
        ]
    )
    n = len(t)
    a = np.zeros(n, dtype=dt)
    a["encaps"] = b"\x00\x01\x00\x00"
    a["sec"], a["nsec"] = _stamps(t)
    a["flen"] = len(name)
    a["frame"] = name + b"\0" * pad
    a["pose"][:, :2] = poses[:, :2]
    a["pose"][:, 3:] = yaw_to_quaternion(poses[:, 2])
    c6 = a["cov"].reshape(n, 6, 6)
    c6[:, [0, 0, 0, 1, 1, 1, 5, 5, 5], [0, 1, 5, 0, 1, 5, 0, 1, 5]] = cov[
        :, [0, 1, 2, 1, 3, 4, 2, 4, 5]
    ]
    raw = a.tobytes()
    size = dt.itemsize
    return [raw[k * size : (k + 1) * size] for k in range(n)]


def encode_tf_block(
    t: np.ndarray, frames: list[tuple[str, str]], poses: list[np.ndarray]
) -> list[bytes]:
    """Little-endian CDR of tf2_msgs/TFMessage for N rows at once: row k holds one planar
    transform per (parent, child) of ``frames``, each stamped ``t[k]`` (the bytes
    ``typestore.serialize_cdr`` gives for ``messages.tf_message`` of
    ``messages.transform_stamped``, ~20x faster).

    Parameters
    ----------
    t : (N,) stamps, s (rounded to ns as ``messages.stamp``)
    frames : (parent, child) frame ids of the transforms, in order
    poses : one (N, 3) array of x, y, yaw (z = 0) per transform of ``frames``

    Returns
    -------
    N payloads. Layout per transform (offsets from the end of the encapsulation header):
    stamp sec i32, nanosec u32 (aligned to 4); frame_id and child_frame_id as u32 length
    (with NUL) + bytes + NUL (aligned to 4); translation x y z, rotation x y z w as
    float64 (aligned to 8); the sequence's u32 count first.
    """
    names, formats, offsets = [], [], []
    pos = 4  # the sequence count
    for k, (parent, child) in enumerate(frames):
        pos += -pos % 4
        names += [f"sec{k}", f"nsec{k}"]
        formats += ["<i4", "<u4"]
        offsets += [pos + 4, pos + 8]
        pos += 8
        for s in (parent, child):
            pos += -pos % 4
            pos += 4 + len(s.encode()) + 1
        pos += -pos % 8
        names.append(f"tf{k}")
        formats.append(("<f8", (7,)))
        offsets.append(pos + 4)
        pos += 56
    size = pos + 4
    template = bytearray(size)
    template[:4] = b"\x00\x01\x00\x00"
    template[4:8] = _U32.pack(len(frames))
    pos = 4
    for parent, child in frames:  # the strings and their lengths: the same in every row
        pos += -pos % 4 + 8
        for s in (parent, child):
            pos += -pos % 4
            b = s.encode() + b"\0"
            template[pos + 4 : pos + 8] = _U32.pack(len(b))
            template[pos + 8 : pos + 8 + len(b)] = b
            pos += 4 + len(b)
        pos += -pos % 8 + 56
    dt = np.dtype({"names": names, "formats": formats, "offsets": offsets, "itemsize": size})
    n = len(t)
    buf = np.frombuffer(bytes(template) * n, dtype=np.uint8).copy()  # padding kept
    a = buf.view(dt)
    sec, nsec = _stamps(t)
    for k, p in enumerate(poses):
        p = np.asarray(p, dtype=float).reshape(-1, 3)
        a[f"sec{k}"] = sec
        a[f"nsec{k}"] = nsec
        a[f"tf{k}"][:, :2] = p[:, :2]
        a[f"tf{k}"][:, 2] = 0.0
        a[f"tf{k}"][:, 3:] = yaw_to_quaternion(p[:, 2])
    raw = buf.tobytes()
    return [raw[k * size : (k + 1) * size] for k in range(n)]


# sentinels of the marker template: distinctive bit patterns, found in its bytes
_SENT_T, _SENT_ID = 1234.5, 0x7A5B3C1D
_SENT_XY, _SENT_SCALE = (1.2345678901e-3, -9.87654321e-2), (3.14159e-4, -2.71828e-5)


class _Cdr:
    """A little-endian CDR payload written field by field (alignment from offset 4)."""

    def __init__(self) -> None:
        self.b = bytearray(b"\x00\x01\x00\x00")

    def put(self, fmt: str, size: int, *values) -> None:
        self.b += bytes(-(len(self.b) - 4) % size) + struct.pack("<" + fmt, *values)

    def string(self, text: str) -> None:
        data = text.encode() + b"\0"
        self.put("I", 4, len(data))
        self.b += data


@dataclass(frozen=True, slots=True)
class MarkerSpec:
    """One visualization_msgs/Marker as ``messages.marker`` takes it (the same arguments,
    in its order): ``messages.marker(*astuple(spec))`` is the rosbags message whose bytes
    :func:`encode_marker_array` writes."""

    t: float  # stamp, s
    frame_id: str
    ns: str
    mid: int
    mtype: int  # 0 arrow, 2 sphere, 3 cylinder, 4 line strip, 5 line list, 9 text
    pose: tuple[float, float, float] = (0.0, 0.0, 0.0)  # x, y, yaw (a yaw quaternion)
    z: float = 0.0  # the pose's and the points' height
    scale: tuple[float, float, float] = (0.1, 0.1, 0.1)
    rgba: tuple[float, float, float, float] = (1.0, 1.0, 1.0, 1.0)
    points: np.ndarray | None = None  # (K, 2) x, y (at height z)
    text: str = ""
    action: int = 0


def encode_marker_array(markers: Sequence[MarkerSpec]) -> bytes:
    """Little-endian CDR of the visualization_msgs/MarkerArray (ROS 2 Humble, and Jazzy:
    the same fields) of ``messages.marker(*astuple(m))`` for each m, written field by
    field: the bytes ``typestore.serialize`` gives for it (tests/test_cdr.py), without the
    typestore (its import and set-up cost 0.1 s of a run's start).

    Parameters
    ----------
    markers : sequence of MarkerSpec
        The markers (no colours per point, texture, uv coordinates or mesh).

    Returns
    -------
    bytes
        The payload.
    """
    w = _Cdr()
    w.put("I", 4, len(markers))
    for m in markers:
        sec, nsec = split_ns(m.t)  # messages.stamp
        x, y, theta = m.pose
        z = float(m.z)
        w.put("iI", 4, sec, nsec)  # header
        w.string(m.frame_id)
        w.string(m.ns)
        w.put("iii", 4, int(m.mid), int(m.mtype), int(m.action))
        w.put("7d", 8, float(x), float(y), z, *yaw_to_quaternion(theta).tolist())
        w.put("3d", 8, *map(float, m.scale))
        w.put("4f", 4, *map(float, m.rgba))
        w.put("iI?", 4, 0, 0, False)  # lifetime, frame_locked
        pts = () if m.points is None else np.asarray(m.points, dtype=float).reshape(-1, 2).tolist()
        w.put("I", 4, len(pts))
        for px, py in pts:
            w.put("3d", 8, px, py, z)
        w.put("I", 4, 0)  # colors
        w.string("")  # texture_resource
        w.put("iI", 4, sec, nsec)  # texture: header, format, data
        w.string("")
        w.string("")
        w.put("I", 4, 0)
        w.put("I", 4, 0)  # uv_coordinates
        w.string(m.text)
        w.string("")  # mesh_resource
        w.string("")  # mesh_file: filename, data
        w.put("I", 4, 0)
        w.put("?", 1, False)  # mesh_use_embedded_materials
    return bytes(w.b)


def encode_occupancy_grid(
    t: float, frame_id: str, data: np.ndarray, resolution: float, origin: tuple[float, float]
) -> bytes:
    """Little-endian CDR of ``messages.occupancy_grid(t, frame_id, data, resolution,
    origin)`` (nav_msgs/OccupancyGrid), written field by field: the bytes
    ``typestore.serialize`` gives for it (tests/test_cdr.py).

    Parameters
    ----------
    t : float
        Stamp and map load time (s).
    frame_id : str
        The frame.
    data : ndarray of int8, shape (H, W)
        The cells (row 0 at the origin's y).
    resolution : float
        Cell size (m).
    origin : (float, float)
        The lower-left corner (m).

    Returns
    -------
    bytes
        The payload.
    """
    data = np.ascontiguousarray(data, dtype=np.int8)
    h, wd = data.shape
    sec, nsec = split_ns(t)
    w = _Cdr()
    w.put("iI", 4, sec, nsec)  # header
    w.string(frame_id)
    w.put("iIfII", 4, sec, nsec, float(resolution), wd, h)  # info: load time, size
    w.put("7d", 8, float(origin[0]), float(origin[1]), 0.0, *yaw_to_quaternion(0.0).tolist())
    w.put("I", 4, data.size)
    w.b += data.tobytes()
    return bytes(w.b)


@lru_cache(maxsize=16)
def _marker_layout(
    frame: str, ns: str, mtype: int, z: float, scale_z: float, rgba: tuple[float, ...]
) -> tuple[bytes, int, int, np.dtype] | None:
    """One Marker's bytes (``encode_marker_array``) with the padding to the next one, its
    length, the number of stamps in it, and the structured dtype of the numbers that
    change; None when a 3-marker array is not head + markers at that stride (then rosbags
    serialises)."""

    def one(i: int, t: float, xy, scale) -> MarkerSpec:
        return MarkerSpec(t, frame, ns, i, mtype, (*xy, 0.0), z, (*scale, scale_z), rgba)

    def ser(markers: list) -> bytes:
        return encode_marker_array(markers)

    s1 = ser([one(_SENT_ID, _SENT_T, _SENT_XY, _SENT_SCALE)])
    s3 = ser([one(_SENT_ID, _SENT_T, _SENT_XY, _SENT_SCALE)] * 3)
    body = s1[8:]
    stride = (len(s3) - len(s1)) // 2
    pad = s3[8 + len(body) : 8 + stride]
    if s3 != s3[:8] + (body + pad) * 2 + body or pad.strip(b"\0"):
        return None
    sec, nsec = split_ns(_SENT_T)
    stamps = [k for k in range(len(body) - 7) if body[k : k + 8] == _STAMP.pack(sec, nsec)]
    at_id = body.find(struct.pack("<i", _SENT_ID))
    at_pose = body.find(struct.pack("<2d", *_SENT_XY))
    at_scale = body.find(struct.pack("<2d", *_SENT_SCALE))
    if min(at_id, at_pose, at_scale) < 0 or not stamps:
        return None
    names = ["id", "pose", "scale"]
    formats: list = ["<i4", ("<f8", (7,)), ("<f8", (2,))]
    offsets = [at_id, at_pose, at_scale]
    for k, o in enumerate(stamps):
        names += [f"sec{k}", f"nsec{k}"]
        formats += ["<i4", "<u4"]
        offsets += [o, o + 4]
    dt = np.dtype({"names": names, "formats": formats, "offsets": offsets, "itemsize": stride})
    return body + pad, len(body), len(stamps), dt


def encode_markers(
    t: float,
    frame: str,
    ns: str,
    mtype: int,
    poses: np.ndarray,
    z: float,
    scales: np.ndarray,
    scale_z: float,
    rgba: tuple[float, float, float, float],
) -> bytes:
    """Little-endian CDR of the visualization_msgs/MarkerArray of ``messages.marker(t,
    frame, ns, k, mtype, poses[k], z, (*scales[k], scale_z), rgba)`` for k = 0..n-1 (ids
    0..n-1; no points, no text): the bytes ``typestore.serialize`` gives for it, from one
    Marker written by ``encode_marker_array`` as a template (the stamps, id, pose and scale written
    into n copies through a structured view).

    Parameters
    ----------
    t : float
        Stamp (s), rounded to ns as ``messages.stamp``.
    frame, ns : str
        header.frame_id and the markers' namespace.
    mtype : int
        Marker type (2 sphere, 3 cylinder).
    poses : ndarray, shape (n, 3)
        x, y, yaw (a yaw quaternion, as ``messages.marker``).
    z : float
        The poses' height.
    scales : ndarray, shape (n, 2)
        Scale x, y.
    scale_z : float
        Scale z.
    rgba : tuple of 4 float
        Colour.

    Returns
    -------
    bytes
        The payload.
    """
    poses = np.asarray(poses, dtype=float).reshape(-1, 3)
    n = len(poses)
    lay = _marker_layout(frame, ns, int(mtype), float(z), float(scale_z), tuple(map(float, rgba)))
    if lay is None:  # a layout the template does not fit: rosbags, marker by marker
        xs = [M.marker(t, frame, ns, k, mtype, tuple(poses[k]), z, (*scales[k], scale_z), rgba)
              for k in range(n)]  # fmt: skip
        return serialize(M.marker_array(xs), M.MARKER_ARRAY)
    block, size, n_stamps, dt = lay
    head = b"\x00\x01\x00\x00" + _U32.pack(n)
    if n == 0:
        return head
    buf = np.frombuffer(block * n, dtype=np.uint8).copy()
    a = buf.view(dt)
    a["id"] = np.arange(n)
    pose = a["pose"]
    pose[:, :2] = poses[:, :2]
    pose[:, 2] = z
    # one yaw at a time, as messages.marker (the same sin and cos calls)
    pose[:, 3:] = [yaw_to_quaternion(th) for th in poses[:, 2].tolist()]
    a["scale"] = np.asarray(scales, dtype=float).reshape(n, 2)
    sec, nsec = split_ns(t)
    for k in range(n_stamps):
        a[f"sec{k}"] = sec
        a[f"nsec{k}"] = nsec
    return head + buf.tobytes()[: len(block) * (n - 1) + size]
