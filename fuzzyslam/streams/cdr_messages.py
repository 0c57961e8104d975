"""Light message classes returned by the CDR decoders of ``streams/cdr.py``.

Their attribute names are those of the ROS 2 message definitions (and of the rosbags
message classes): ``header.stamp.sec``, ``pose.pose.position.x``, ... Arrays are numpy
arrays of the rosbags dtypes. Parts a consumer seldom reads (an Odometry's twist and
covariances) are kept as bytes and decoded on first access.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

F8 = np.dtype("<f8")
_F64X6 = struct.Struct("<6d")


@dataclass(slots=True)
class Time:
    sec: int
    nanosec: int


@dataclass(slots=True)
class Header:
    stamp: Time
    frame_id: str


@dataclass(slots=True)
class Point:
    x: float
    y: float
    z: float


@dataclass(slots=True)
class Vector3:
    x: float
    y: float
    z: float


@dataclass(slots=True)
class Quaternion:
    x: float
    y: float
    z: float
    w: float


@dataclass(slots=True)
class Pose:
    position: Point
    orientation: Quaternion


class _Deferred:
    """Fields decoded on first access from a bytes copy of their part of the payload
    (what a consumer seldom reads, e.g. odometry covariances, costs nothing until read).
    A field holds its value, or a ``(raw bytes, offset)`` tuple not decoded yet."""

    __slots__ = ()
    _fields: ClassVar[tuple[str, ...]] = ()

    def __repr__(self) -> str:
        args = ", ".join(f"{k}={getattr(self, k)!r}" for k in self._fields)
        return f"{type(self).__name__}({args})"

    def __eq__(self, other: object) -> bool:
        if type(other) is not type(self):
            return NotImplemented
        return all(_equal(getattr(self, k), getattr(other, k)) for k in self._fields)

    __hash__ = None  # type: ignore[assignment]  # mutable, as the dataclasses


def _equal(a, b) -> bool:
    if isinstance(a, np.ndarray):
        return isinstance(b, np.ndarray) and np.array_equal(a, b)
    return bool(a == b)


def _covariance_field(name: str) -> property:
    def get(self) -> np.ndarray:
        v = getattr(self, name)
        if type(v) is tuple:
            v = np.frombuffer(v[0], F8, 36, v[1]).copy()
            setattr(self, name, v)
        return v

    def set_(self, value) -> None:
        setattr(self, name, value)

    return property(get, set_, doc="(36,) float64, row-major 6x6 (decoded on first access)")


class PoseWithCovariance(_Deferred):
    __slots__ = ("_covariance", "pose")
    _fields = ("pose", "covariance")
    covariance = _covariance_field("_covariance")

    def __init__(self, pose: Pose, covariance) -> None:
        self.pose = pose
        self._covariance = covariance


class TwistWithCovariance(_Deferred):
    __slots__ = ("_covariance", "twist")
    _fields = ("twist", "covariance")
    covariance = _covariance_field("_covariance")

    def __init__(self, twist: Twist, covariance) -> None:
        self.twist = twist
        self._covariance = covariance


@dataclass(slots=True)
class Twist:
    linear: Vector3
    angular: Vector3


class Odometry(_Deferred):
    """nav_msgs/Odometry (``twist`` and the covariances decoded on first access)."""

    __msgtype__: ClassVar[str] = "nav_msgs/msg/Odometry"
    __slots__ = ("_twist", "child_frame_id", "header", "pose")
    _fields = ("header", "child_frame_id", "pose", "twist")

    def __init__(self, header: Header, child_frame_id: str, pose: PoseWithCovariance, twist):
        self.header = header
        self.child_frame_id = child_frame_id
        self.pose = pose
        self._twist = twist

    @property
    def twist(self) -> TwistWithCovariance:
        v = self._twist
        if type(v) is tuple:
            raw, at = v
            t = _F64X6.unpack_from(raw, at)
            v = TwistWithCovariance(
                Twist(Vector3(t[0], t[1], t[2]), Vector3(t[3], t[4], t[5])), (raw, at + 48)
            )
            self._twist = v
        return v

    @twist.setter
    def twist(self, value: TwistWithCovariance) -> None:
        self._twist = value


@dataclass(slots=True)
class PoseArray:
    __msgtype__: ClassVar[str] = "geometry_msgs/msg/PoseArray"
    header: Header
    poses: list[Pose]


@dataclass(slots=True)
class LaserScan:
    __msgtype__: ClassVar[str] = "sensor_msgs/msg/LaserScan"
    header: Header
    angle_min: float
    angle_max: float
    angle_increment: float
    time_increment: float
    scan_time: float
    range_min: float
    range_max: float
    ranges: np.ndarray  # (N,) float32
    intensities: np.ndarray  # (N,) or (0,) float32


@dataclass(slots=True)
class JointState:
    __msgtype__: ClassVar[str] = "sensor_msgs/msg/JointState"
    header: Header
    name: list[str]
    position: np.ndarray  # float64
    velocity: np.ndarray
    effort: np.ndarray


@dataclass(slots=True)
class Image:
    __msgtype__: ClassVar[str] = "sensor_msgs/msg/Image"
    header: Header
    height: int
    width: int
    encoding: str
    is_bigendian: int
    step: int
    data: np.ndarray  # (step * height,) uint8, a read-only view of the payload


@dataclass(slots=True)
class Range:
    __msgtype__: ClassVar[str] = "sensor_msgs/msg/Range"
    ULTRASOUND: ClassVar[int] = 0
    INFRARED: ClassVar[int] = 1
    header: Header
    radiation_type: int
    field_of_view: float
    min_range: float
    max_range: float
    range: float


@dataclass(slots=True)
class RegionOfInterest:
    x_offset: int
    y_offset: int
    height: int
    width: int
    do_rectify: bool


@dataclass(slots=True)
class CameraInfo:
    __msgtype__: ClassVar[str] = "sensor_msgs/msg/CameraInfo"
    header: Header
    height: int
    width: int
    distortion_model: str
    d: np.ndarray  # float64
    k: np.ndarray  # (9,) float64
    r: np.ndarray  # (9,)
    p: np.ndarray  # (12,)
    binning_x: int
    binning_y: int
    roi: RegionOfInterest


@dataclass(slots=True)
class Transform:
    translation: Vector3
    rotation: Quaternion


@dataclass(slots=True)
class TransformStamped:
    header: Header
    child_frame_id: str
    transform: Transform


@dataclass(slots=True)
class TFMessage:
    __msgtype__: ClassVar[str] = "tf2_msgs/msg/TFMessage"
    transforms: list[TransformStamped]
