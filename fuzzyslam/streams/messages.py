"""Build and read the ROS 2 messages fuzzyslam uses (the one place for message layout).

Builders take plain numbers and numpy arrays and return rosbags message objects;
readers take message objects and return plain numbers and arrays.
"""

from __future__ import annotations

import json
from typing import Any

import numpy as np

from fuzzyslam.se2 import quaternion_to_yaw, yaw_to_quaternion
from fuzzyslam.stamps import split_ns
from fuzzyslam.streams.distro import DEFAULT_ROS_DISTRO
from fuzzyslam.streams.typestore import field_names, msgtype

RANGE = "sensor_msgs/msg/Range"
LASER_SCAN = "sensor_msgs/msg/LaserScan"
IMAGE = "sensor_msgs/msg/Image"
COMPRESSED_IMAGE = "sensor_msgs/msg/CompressedImage"
CAMERA_INFO = "sensor_msgs/msg/CameraInfo"
JOINT_STATE = "sensor_msgs/msg/JointState"
ODOMETRY = "nav_msgs/msg/Odometry"
OCCUPANCY_GRID = "nav_msgs/msg/OccupancyGrid"
POSE_COV_STAMPED = "geometry_msgs/msg/PoseWithCovarianceStamped"
POSE_ARRAY = "geometry_msgs/msg/PoseArray"
DETECTION3D_ARRAY = "vision_msgs/msg/Detection3DArray"
MARKER_ARRAY = "visualization_msgs/msg/MarkerArray"
TF_MESSAGE = "tf2_msgs/msg/TFMessage"
STRING = "std_msgs/msg/String"


def stamp(t: float) -> Any:
    """builtin_interfaces/Time from seconds (:func:`fuzzyslam.stamps.split_ns`)."""
    sec, nanosec = split_ns(t)
    return msgtype("builtin_interfaces/msg/Time")(sec=sec, nanosec=nanosec)


def stamp_to_sec(s: Any) -> float:
    return s.sec + s.nanosec * 1e-9


def header(t: float, frame_id: str) -> Any:
    return msgtype("std_msgs/msg/Header")(stamp=stamp(t), frame_id=frame_id)


def _pose_msg(x: float, y: float, theta: float, z: float = 0.0) -> Any:
    q = yaw_to_quaternion(theta)
    point = msgtype("geometry_msgs/msg/Point")(x=float(x), y=float(y), z=float(z))
    quat = msgtype("geometry_msgs/msg/Quaternion")(
        x=float(q[0]), y=float(q[1]), z=float(q[2]), w=float(q[3])
    )
    return msgtype("geometry_msgs/msg/Pose")(position=point, orientation=quat)


def pose_of(pose_msg: Any) -> np.ndarray:
    """(x, y, theta) of a geometry_msgs/Pose."""
    o = pose_msg.orientation
    yaw = quaternion_to_yaw([o.x, o.y, o.z, o.w])
    return np.array([pose_msg.position.x, pose_msg.position.y, yaw])


def cov3_to_cov6(cov3: np.ndarray | None) -> np.ndarray:
    """Embed a 3x3 (x, y, theta) covariance in ROS's row-major 6x6 (x y z roll pitch yaw)."""
    c6 = np.zeros((6, 6))
    if cov3 is not None:
        idx = [0, 1, 5]
        c6[np.ix_(idx, idx)] = np.asarray(cov3, dtype=float)
    return c6.reshape(36)


def cov6_to_cov3(cov36: Any) -> np.ndarray:
    c6 = np.asarray(cov36, dtype=float).reshape(6, 6)
    idx = [0, 1, 5]
    return c6[np.ix_(idx, idx)].copy()


def range_msg(
    t: float,
    frame_id: str,
    r: float,
    fov: float,
    rmin: float,
    rmax: float,
    variance: float = 0.0,
    distro: str = DEFAULT_ROS_DISTRO,
) -> Any:
    """sensor_msgs/Range, radiation ULTRASOUND, of the typestore of ``distro``.

    Parameters
    ----------
    t : float
        Stamp (s).
    frame_id : str
        The sonar's frame.
    r, fov, rmin, rmax : float
        Range, field of view (rad), minimum and maximum range.
    variance : float
        The range's variance (m^2; 0: unknown), in the message where the distribution's
        Range has the field (Iron on: Jazzy), else not.
    distro : str
        One of ``streams/distro.ROS_DISTROS`` (default Humble).

    Returns
    -------
    object
        The rosbags message.
    """
    fields = {"variance": float(variance)} if "variance" in field_names(RANGE, distro) else {}
    return msgtype(RANGE, distro)(
        header=header(t, frame_id),
        radiation_type=0,
        field_of_view=float(fov),
        min_range=float(rmin),
        max_range=float(rmax),
        range=float(r),
        **fields,
    )


def laser_scan(
    t: float,
    frame_id: str,
    ranges: np.ndarray,
    angle_min: float,
    angle_increment: float,
    range_min: float = 0.05,
    range_max: float = 40.0,
    time_increment: float = 0.0,
) -> Any:
    """sensor_msgs/LaserScan of ``ranges`` (N,) from ``angle_min`` by ``angle_increment``
    (rad), beam k taken ``k * time_increment`` s after the stamp, no intensities (float32
    as the message holds them).

    Parameters
    ----------
    t : float
        Stamp (s).
    frame_id : str
        The laser's frame.
    ranges : ndarray, shape (N,)
        Ranges (m); inf and NaN as sensor_msgs/LaserScan defines them.
    angle_min, angle_increment : float
        First beam's angle and the step (rad; a negative step lists beams clockwise).
    range_min, range_max : float
        The valid range interval (m).
    time_increment : float
        Time between beams (s; 0: the scan at once); ``scan_time`` is N times it.

    Returns
    -------
    sensor_msgs/msg/LaserScan
    """
    r = np.asarray(ranges, dtype=np.float32)
    return msgtype(LASER_SCAN)(
        header=header(t, frame_id),
        angle_min=np.float32(angle_min),
        angle_max=np.float32(angle_min + angle_increment * (len(r) - 1)),
        angle_increment=np.float32(angle_increment),
        time_increment=np.float32(time_increment),
        scan_time=np.float32(time_increment * len(r)),
        range_min=np.float32(range_min),
        range_max=np.float32(range_max),
        ranges=r,
        intensities=np.zeros(0, dtype=np.float32),
    )


def image_mono8(t: float, frame_id: str, img: np.ndarray) -> Any:
    """sensor_msgs/Image, encoding mono8, from a (H, W) uint8 array."""
    img = np.ascontiguousarray(img, dtype=np.uint8)
    h, w = img.shape
    return msgtype(IMAGE)(
        header=header(t, frame_id),
        height=h,
        width=w,
        encoding="mono8",
        is_bigendian=0,
        step=w,
        data=img.reshape(-1),
    )


# sensor_msgs/image_encodings.hpp (REP 104's image encodings; cv_bridge's conversions):
# encoding -> (channels, bytes per channel, the cv2.cvtColor code to grey or None). The
# OpenCV names of the Bayer codes are the ROS ones (BayerRGGB2GRAY is BayerBG2GRAY,
# cv_bridge's choice for bayer_rggb8); 8UC3/8UC4 are OpenCV's BGR/BGRA order, as in
# cv_bridge. Filled at the first frame that needs OpenCV (:func:`_grey_codes`).
_GREY_CODES: dict[str, tuple[int, int, int | None]] = {}
# planar YUV 4:2:0 / 4:4:4 with the luma plane first: the grey image is its first H rows
_LUMA_FIRST = ("nv12", "nv21", "nv24", "i420", "yv12")
# image_transport's compressed formats: the image's own encoding, then the codec
# ("bgr8; jpeg compressed bgr8", "mono8; png compressed", or "jpeg" alone)
COMPRESSED_DEPTH = "compresseddepth"  # compressed_depth_image_transport: a depth map


def _grey_codes() -> dict[str, tuple[int, int, int | None]]:
    """The encodings :func:`image_to_array` converts (besides mono8), with their layout
    and ``cv2.cvtColor`` code (OpenCV imported on first use: a log of mono8 frames never
    needs it here)."""
    if not _GREY_CODES:
        import cv2

        rgb = {"bgr": cv2.COLOR_BGR2GRAY, "rgb": cv2.COLOR_RGB2GRAY}
        rgba = {"bgra": cv2.COLOR_BGRA2GRAY, "rgba": cv2.COLOR_RGBA2GRAY}
        bayer = {
            "rggb": cv2.COLOR_BayerRGGB2GRAY,
            "bggr": cv2.COLOR_BayerBGGR2GRAY,
            "gbrg": cv2.COLOR_BayerGBRG2GRAY,
            "grbg": cv2.COLOR_BayerGRBG2GRAY,
        }
        codes: dict[str, tuple[int, int, int | None]] = {"mono16": (1, 2, None)}
        codes["16uc1"] = codes["mono16"]
        for bits, size in (("8", 1), ("16", 2)):
            codes |= {f"{k}{bits}": (3, size, c) for k, c in rgb.items()}
            codes |= {f"{k}{bits}": (4, size, c) for k, c in rgba.items()}
            codes |= {f"bayer_{k}{bits}": (1, size, c) for k, c in bayer.items()}
            codes[f"{bits}uc3"] = (3, size, cv2.COLOR_BGR2GRAY)
            codes[f"{bits}uc4"] = (4, size, cv2.COLOR_BGRA2GRAY)
        # YUV 4:2:2, two bytes a pixel: ROS's "yuv422" is UYVY, "yuv422_yuy2" YUYV
        for name in ("yuv422", "uyvy", "yuv422_uyvy"):
            codes[name] = (2, 1, cv2.COLOR_YUV2GRAY_UYVY)
        for name in ("yuyv", "yuv422_yuy2", "yuy2"):
            codes[name] = (2, 1, cv2.COLOR_YUV2GRAY_YUY2)
        _GREY_CODES.update(codes)
    return _GREY_CODES


def _rows(msg: Any, h: int, w: int, row_bytes: int) -> np.ndarray:
    """The (h, row_bytes) uint8 pixel bytes of an Image, each row cut from its
    ``step``; ValueError when the data does not hold them."""
    step = int(msg.step)
    data = np.asarray(msg.data, dtype=np.uint8)
    if h <= 0 or w <= 0 or step < row_bytes or data.size < h * step:
        said = f"image of {data.size} bytes does not match {w}x{h} {msg.encoding} (step {step}"
        if w > 0 and row_bytes > w and step >= w and data.size >= h * step:
            # data laid out with fewer bytes a pixel than the encoding has: mislabelled
            per = step // w
            like = ", mono8's layout" if per == 1 else ""
            said += f": {per} byte(s) a pixel{like}; {msg.encoding} has {row_bytes // w}"
        raise ValueError(said + ")")
    return data[: h * step].reshape(h, step)[:, :row_bytes]


def image_to_array(msg: Any) -> np.ndarray:
    """The 8-bit grey image of a sensor_msgs/Image, as the lamp detector thresholds it.

    mono8 / 8UC1 frames are used as they are (a view of the message's data). The other
    common encodings of REP 104's ``sensor_msgs/image_encodings.hpp`` are converted with
    OpenCV (``cv2.cvtColor``, no loop over pixels), as cv_bridge does:

    - colour (bgr8, rgb8, bgra8, rgba8, 8UC3 and 8UC4 as BGR/BGRA, and their 16-bit
      forms): the luma Y = 0.299 R + 0.587 G + 0.114 B (``COLOR_BGR2GRAY`` and its
      kin), so a grey frame (R = G = B = v) gives v exactly;
    - Bayer mosaics (bayer_rggb8, bayer_bggr8, bayer_gbrg8, bayer_grbg8, and 16-bit):
      demosaiced to grey (``COLOR_BayerRGGB2GRAY`` ...);
    - YUV 4:2:2 (yuv422 = UYVY, uyvy, yuyv, yuv422_yuy2): the Y channel
      (``COLOR_YUV2GRAY_UYVY``, ``COLOR_YUV2GRAY_YUY2``); NV12, NV21, NV24, I420 and
      YV12: their luma plane, the first ``height`` rows;
    - 16 bits a channel (mono16, 16UC1, bgr16, ...; ``is_bigendian`` honoured): scaled to
      8 bits by their high byte, ``v >> 8`` (65535 -> 255), the grey level a camera's
      16-bit output of the same exposure would have at 8 bits. A camera that puts 10 or
      12 significant bits in the low end of a 16-bit word gives dark frames so: record
      it as mono8 or scale ``slam.threshold`` down accordingly.

    Parameters
    ----------
    msg : sensor_msgs/Image
        The frame (height, width, encoding, is_bigendian, step, data).

    Returns
    -------
    ndarray of uint8, shape (H, W)

    Raises
    ------
    ValueError
        On an encoding it does not convert (float or signed depth images, an unknown
        name) or data that does not hold height rows of ``step`` bytes.

    References
    ----------
    REP 104 and ``sensor_msgs/image_encodings.hpp`` (the encoding names); OpenCV,
    "Color conversions", https://docs.opencv.org/4.x/de/d25/imgproc_color_conversions.html
    """
    enc = msg.encoding
    h, w = int(msg.height), int(msg.width)
    if enc in ("mono8", "8UC1"):
        return _rows(msg, h, w, w)
    key = str(enc).strip().lower()
    if key in _LUMA_FIRST:
        return _rows(msg, h, w, w)
    layout = _grey_codes().get(key)
    if layout is None:
        raise ValueError(
            f"unsupported image encoding '{enc}' (mono8, mono16, bgr8, rgb8, bgra8, rgba8, "
            "yuv422, yuyv, nv12, bayer_* and their 16-bit forms are read)"
        )
    channels, size, code = layout
    rows = _rows(msg, h, w, w * channels * size)
    if size == 2:
        big = bool(msg.is_bigendian)
        rows = np.ascontiguousarray(rows).view(">u2" if big else "<u2")
        if rows.dtype != np.uint16:  # not the machine's byte order: OpenCV needs it
            rows = rows.astype(np.uint16)
    img = rows.reshape(h, w, channels) if channels > 1 else rows
    if code is not None:
        import cv2

        img = cv2.cvtColor(np.ascontiguousarray(img), code)
    if size == 2:
        return (img >> 8).astype(np.uint8)
    return img


def compressed_to_array(msg: Any) -> np.ndarray:
    """The 8-bit grey image of a sensor_msgs/CompressedImage (image_transport's
    ``compressed`` plugin: JPEG or PNG; any format ``cv2.imdecode`` reads).

    Decoded with ``cv2.imdecode(data, IMREAD_GRAYSCALE | IMREAD_ANYDEPTH)``: the codec's
    own grey (a colour JPEG's luma, a colour PNG's BGR -> grey as ``COLOR_BGR2GRAY``); a
    16-bit PNG is scaled to 8 bits by ``v >> 8`` as :func:`image_to_array` does. The
    ``format`` field ("bgr8; jpeg compressed bgr8", "mono8; png compressed", "jpeg") is
    not needed to decode: the data say their codec. A ``compressedDepth`` image (a depth
    map of compressed_depth_image_transport) is not a camera frame.

    Parameters
    ----------
    msg : sensor_msgs/CompressedImage
        The frame (format, data).

    Returns
    -------
    ndarray of uint8, shape (H, W)

    Raises
    ------
    ValueError
        On empty or undecodable data, or a compressedDepth image.

    References
    ----------
    OpenCV, ``cv::imdecode`` and ``ImreadModes``,
    https://docs.opencv.org/4.x/d4/da8/group__imgcodecs.html; ROS
    ``compressed_image_transport`` (the ``format`` field).
    """
    fmt = str(msg.format)
    if COMPRESSED_DEPTH in fmt.lower().replace(" ", ""):
        raise ValueError(f"a depth image ('{fmt}'), not a camera frame")
    data = np.asarray(msg.data, dtype=np.uint8)
    if not data.size:
        raise ValueError(f"empty CompressedImage ('{fmt}')")
    import cv2

    img = cv2.imdecode(data, cv2.IMREAD_GRAYSCALE | cv2.IMREAD_ANYDEPTH)
    if img is None or img.ndim != 2:
        raise ValueError(f"CompressedImage ('{fmt}') of {data.size} bytes cannot be decoded")
    if img.dtype == np.uint16:
        return (img >> 8).astype(np.uint8)
    if img.dtype != np.uint8:
        raise ValueError(f"CompressedImage ('{fmt}') decodes to {img.dtype}, not 8 or 16 bits")
    return img


def camera_info(
    t: float, frame_id: str, width: int, height: int, f: float, cx: float, cy: float
) -> Any:
    """sensor_msgs/CameraInfo of a distortion-free pinhole camera."""
    k = np.array([f, 0.0, cx, 0.0, f, cy, 0.0, 0.0, 1.0])
    p = np.array([f, 0.0, cx, 0.0, 0.0, f, cy, 0.0, 0.0, 0.0, 1.0, 0.0])
    roi = msgtype("sensor_msgs/msg/RegionOfInterest")(
        x_offset=0, y_offset=0, height=0, width=0, do_rectify=False
    )
    return msgtype(CAMERA_INFO)(
        header=header(t, frame_id),
        height=int(height),
        width=int(width),
        distortion_model="plumb_bob",
        d=np.zeros(5),
        k=k,
        r=np.eye(3).reshape(9),
        p=p,
        binning_x=0,
        binning_y=0,
        roi=roi,
    )


def joint_state(t: float, names: list[str], positions: np.ndarray) -> Any:
    return msgtype(JOINT_STATE)(
        header=header(t, ""),
        name=list(names),
        position=np.asarray(positions, dtype=float),
        velocity=np.zeros(0),
        effort=np.zeros(0),
    )


def odometry(
    t: float,
    frame_id: str,
    child_frame_id: str,
    pose: np.ndarray,
    cov3: np.ndarray | None = None,
    v: float = 0.0,
    w: float = 0.0,
) -> Any:
    """nav_msgs/Odometry with a planar pose and twist."""
    pwc = msgtype("geometry_msgs/msg/PoseWithCovariance")(
        pose=_pose_msg(*pose), covariance=cov3_to_cov6(cov3)
    )
    vec = msgtype("geometry_msgs/msg/Vector3")
    twist = msgtype("geometry_msgs/msg/Twist")(
        linear=vec(x=float(v), y=0.0, z=0.0), angular=vec(x=0.0, y=0.0, z=float(w))
    )
    twc = msgtype("geometry_msgs/msg/TwistWithCovariance")(twist=twist, covariance=np.zeros(36))
    return msgtype(ODOMETRY)(
        header=header(t, frame_id), child_frame_id=child_frame_id, pose=pwc, twist=twc
    )


def pose_with_covariance(t: float, frame_id: str, pose: np.ndarray, cov3: np.ndarray) -> Any:
    pwc = msgtype("geometry_msgs/msg/PoseWithCovariance")(
        pose=_pose_msg(*pose), covariance=cov3_to_cov6(cov3)
    )
    return msgtype(POSE_COV_STAMPED)(header=header(t, frame_id), pose=pwc)


def pose_array(t: float, frame_id: str, points: np.ndarray) -> Any:
    """geometry_msgs/PoseArray, one pose per (x, y) point (heading 0)."""
    poses = [
        _pose_msg(float(x), float(y), 0.0)
        for x, y in np.asarray(points, dtype=float).reshape(-1, 2)
    ]
    return msgtype(POSE_ARRAY)(header=header(t, frame_id), poses=poses)


def detection3d_array(
    t: float, frame_id: str, points: np.ndarray, covs: np.ndarray | None = None
) -> Any:
    """vision_msgs/Detection3DArray, one detection per (x, y) point with one hypothesis
    whose PoseWithCovariance carries the point and its (2, 2) covariance in the x, y
    block (zeros elsewhere; all zeros when ``covs`` is None: "unknown" in ROS)."""
    pts = np.asarray(points, dtype=float).reshape(-1, 2)
    cv = np.zeros((len(pts), 2, 2)) if covs is None else np.asarray(covs, float).reshape(-1, 2, 2)
    hyp = msgtype("vision_msgs/msg/ObjectHypothesis")
    hwp = msgtype("vision_msgs/msg/ObjectHypothesisWithPose")
    pwc = msgtype("geometry_msgs/msg/PoseWithCovariance")
    box = msgtype("vision_msgs/msg/BoundingBox3D")
    vec = msgtype("geometry_msgs/msg/Vector3")
    det = msgtype("vision_msgs/msg/Detection3D")
    dets = []
    for (x, y), c in zip(pts, cv, strict=True):
        c6 = np.zeros((6, 6))
        c6[:2, :2] = c
        pose = _pose_msg(float(x), float(y), 0.0)
        dets.append(
            det(
                header=header(t, frame_id),
                results=[hwp(hypothesis=hyp(class_id="landmark", score=1.0),
                             pose=pwc(pose=pose, covariance=c6.reshape(-1)))],
                bbox=box(center=pose, size=vec(x=0.0, y=0.0, z=0.0)),
                id="",
            )
        )  # fmt: skip
    return msgtype(DETECTION3D_ARRAY)(header=header(t, frame_id), detections=dets)


def _score(h: Any) -> float:
    """A detection hypothesis' score: vision_msgs 3 and later (Galactic, Humble, ...)
    hold it in ``hypothesis``, vision_msgs 2 (Foxy) on the hypothesis itself."""
    inner = getattr(h, "hypothesis", h)
    return float(inner.score)


def detections_of(msg: Any, dims: int = 2) -> tuple[np.ndarray, np.ndarray]:
    """Landmark detections of a PoseArray or a vision_msgs/Detection3DArray.

    Parameters
    ----------
    msg : geometry_msgs/PoseArray or vision_msgs/Detection3DArray
        The message.
    dims : {2, 3}
        The x, y (2) or x, y, z (3) of each detection and the block of its covariance.

    Returns
    -------
    points : ndarray, shape (N, dims)
        In the message's frame.
    covs : ndarray, shape (N, dims, dims)
        The x, y (, z) block of each detection's covariance; NaN where the message
        carries none (a PoseArray; a Detection3D whose covariance is all zeros, ROS's
        "unknown", or whose x, y block is not finite, symmetric and positive definite).
    """
    if not hasattr(msg, "detections"):
        poses = msg.poses
        pts = np.array([[p.position.x, p.position.y, p.position.z] for p in poses], dtype=float)
        pts = pts.reshape(-1, 3)[:, :dims]
        return pts, np.full((len(pts), dims, dims), np.nan)
    pts = np.full((len(msg.detections), dims), np.nan)
    covs = np.full((len(msg.detections), dims, dims), np.nan)
    for k, d in enumerate(msg.detections):
        if d.results:
            best = max(d.results, key=_score)
            p, c = best.pose.pose.position, np.asarray(best.pose.covariance, dtype=float)
            pts[k] = (p.x, p.y, p.z)[:dims]
            if c.size == 36:
                c2 = c.reshape(6, 6)[:2, :2]
                ok = np.all(np.isfinite(c2)) and c2[0, 1] == c2[1, 0]
                if ok and c2[0, 0] > 0 and np.linalg.det(c2) > 0:
                    covs[k] = c.reshape(6, 6)[:dims, :dims]
        else:
            center = d.bbox.center.position
            pts[k] = (center.x, center.y, center.z)[:dims]
    return pts, covs


def points_of_pose_array(msg: Any) -> np.ndarray:
    """(N, 2) positions of a PoseArray."""
    if not msg.poses:
        return np.zeros((0, 2))
    return np.array([[p.position.x, p.position.y] for p in msg.poses], dtype=float)


def transform_stamped(
    t: float, parent: str, child: str, x: float, y: float, z: float, yaw: float
) -> Any:
    q = yaw_to_quaternion(yaw)
    tr = msgtype("geometry_msgs/msg/Vector3")(x=float(x), y=float(y), z=float(z))
    rot = msgtype("geometry_msgs/msg/Quaternion")(
        x=float(q[0]), y=float(q[1]), z=float(q[2]), w=float(q[3])
    )
    tf = msgtype("geometry_msgs/msg/Transform")(translation=tr, rotation=rot)
    return msgtype("geometry_msgs/msg/TransformStamped")(
        header=header(t, parent), child_frame_id=child, transform=tf
    )


def tf_message(transforms: list[Any]) -> Any:
    return msgtype(TF_MESSAGE)(transforms=transforms)


def planar_transforms(msg: Any) -> dict[str, tuple[str, np.ndarray]]:
    """Each transform of a TFMessage as a planar pose in its immediate parent.

    For planar /tf such as odom -> base_link: the transform is neither composed with
    its parent's nor checked for roll and pitch. Sensor mounts from /tf_static, which
    may chain frames and turn a sensor upside down, are composed in 3D by
    :mod:`fuzzyslam.streams.tf`.

    Parameters
    ----------
    msg : TFMessage
        A tf2_msgs/TFMessage.

    Returns
    -------
    dict of str to (str, ndarray of shape (3,))
        Child frame -> (parent frame, (x, y, yaw)); yaw is the heading of the child's x
        axis in the parent's x-y plane; a repeated child keeps its last transform.
    """
    out = {}
    for ts in msg.transforms:
        tr, r = ts.transform.translation, ts.transform.rotation
        yaw = quaternion_to_yaw([r.x, r.y, r.z, r.w])
        out[ts.child_frame_id] = (ts.header.frame_id, np.array([tr.x, tr.y, yaw]))
    return out


def string_msg(text: str) -> Any:
    return msgtype(STRING)(data=text)


def json_msg(obj: Any) -> Any:
    """std_msgs/String holding JSON (used for scenario events)."""
    return string_msg(json.dumps(obj, sort_keys=True))


def color(r: float, g: float, b: float, a: float = 1.0) -> Any:
    return msgtype("std_msgs/msg/ColorRGBA")(r=float(r), g=float(g), b=float(b), a=float(a))


def marker(
    t: float,
    frame_id: str,
    ns: str,
    mid: int,
    mtype: int,
    pose: tuple[float, float, float] = (0.0, 0.0, 0.0),
    z: float = 0.0,
    scale: tuple[float, float, float] = (0.1, 0.1, 0.1),
    rgba: tuple[float, float, float, float] = (1.0, 1.0, 1.0, 1.0),
    points: np.ndarray | None = None,
    text: str = "",
    action: int = 0,
) -> Any:
    """visualization_msgs/Marker. mtype: 2 SPHERE, 3 CYLINDER, 4 LINE_STRIP, 5 LINE_LIST, 9 TEXT."""
    pt = msgtype("geometry_msgs/msg/Point")
    pts = [] if points is None else [pt(x=float(p[0]), y=float(p[1]), z=float(z)) for p in points]
    dur = msgtype("builtin_interfaces/msg/Duration")(sec=0, nanosec=0)
    vec = msgtype("geometry_msgs/msg/Vector3")
    return msgtype("visualization_msgs/msg/Marker")(
        header=header(t, frame_id),
        ns=ns,
        id=int(mid),
        type=int(mtype),
        action=int(action),
        pose=_pose_msg(pose[0], pose[1], pose[2], z),
        scale=vec(x=float(scale[0]), y=float(scale[1]), z=float(scale[2])),
        color=color(*rgba),
        lifetime=dur,
        frame_locked=False,
        points=pts,
        colors=[],
        texture_resource="",
        texture=msgtype("sensor_msgs/msg/CompressedImage")(
            header=header(t, ""), format="", data=np.zeros(0, dtype=np.uint8)
        ),
        uv_coordinates=[],
        text=text,
        mesh_resource="",
        mesh_file=msgtype("visualization_msgs/msg/MeshFile")(
            filename="", data=np.zeros(0, dtype=np.uint8)
        ),
        mesh_use_embedded_materials=False,
    )


def marker_array(markers: list[Any]) -> Any:
    return msgtype(MARKER_ARRAY)(markers=markers)


def occupancy_grid(
    t: float, frame_id: str, data: np.ndarray, resolution: float, origin: tuple[float, float]
) -> Any:
    """nav_msgs/OccupancyGrid from an (H, W) int8 array (row 0 at the origin's y)."""
    data = np.asarray(data, dtype=np.int8)
    h, w = data.shape
    info = msgtype("nav_msgs/msg/MapMetaData")(
        map_load_time=stamp(t),
        resolution=float(resolution),
        width=w,
        height=h,
        origin=_pose_msg(origin[0], origin[1], 0.0),
    )
    return msgtype(OCCUPANCY_GRID)(header=header(t, frame_id), info=info, data=data.reshape(-1))
