"""Real cameras, end to end: the tiny simulated log (tests/test_robust_logs.py ``tiny``)
rewritten with its frames as a real ceiling camera records them, and ``run`` finds the
mono8 log's lamps.

- encodings: bgr8, rgb8 and mono16 Images and PNG CompressedImages on image_transport's
  ``.../compressed`` topic carry the same grey image, so the run's files are the mono8
  run's byte for byte; JPEG (quality 95) finds the same lamps within a few millimetres;
- lens distortion: every frame rendered through a known strong plumb_bob barrel lens
  (each raw pixel's ideal pixel by ``cv2.undistortPoints`` iterated to convergence,
  checked against ``cv2.projectPoints``, the ideal frame sampled there by ``cv2.remap``)
  with its CameraInfo's D: the lamps within a few centimetres of the undistorted log's,
  while the same frames with D ignored (zeros) put them decimetres off.

References: REP 104 / sensor_msgs (Image encodings, CompressedImage, CameraInfo's D);
OpenCV ``undistortPoints``, ``projectPoints``, ``remap``, ``imencode``.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import cv2
import numpy as np
import pytest
import test_robust_logs
import yaml
from test_robust_logs import IMAGE, Out, Tiny, cli, rewrite, run_json

from fuzzyslam.streams import messages as M
from fuzzyslam.streams.reader import LogMessage
from fuzzyslam.streams.typestore import msgtype

tiny = test_robust_logs.tiny  # the session fixture: a short simulated log and its run
INFO = "/ceiling_camera/camera_info"
COMPRESSED = IMAGE + "/compressed"
SAME_FILES = ("trajectory.tum", "landmarks.yaml", "updates.csv", "covariance.csv")
# a strong wide-angle barrel (k1, k2, p1, p2, k3), on a camera zoomed so that every raw
# pixel's ideal pixel falls inside the simulator's ideal frame
BARREL = (-0.25, 0.05, 0.001, -0.0015, 0.0)
ZOOM = 1.5


def ros_header(h):
    """A rosbags std_msgs/Header of a decoded header (the same stamp to the ns)."""
    t = msgtype("builtin_interfaces/msg/Time")(sec=h.stamp.sec, nanosec=h.stamp.nanosec)
    return msgtype("std_msgs/msg/Header")(stamp=t, frame_id=h.frame_id)


def grey(m: LogMessage) -> np.ndarray:
    return np.array(M.image_to_array(m.msg))


def as_image(encoding: str, arr: np.ndarray) -> Callable[[LogMessage], list[Out]]:
    """The frames re-encoded: ``arr(grey) -> (H, W, C)`` array of ``encoding``."""

    def fault(m: LogMessage) -> list[Out]:
        if m.topic != IMAGE:
            return [(m.topic, m.typename, m.msg, m.t)]
        a = np.ascontiguousarray(arr(grey(m)))
        raw = a.astype("<u2") if a.dtype == np.uint16 else a
        msg = msgtype(M.IMAGE)(
            header=ros_header(m.msg.header), height=a.shape[0], width=a.shape[1],
            encoding=encoding, is_bigendian=0, step=raw.nbytes // a.shape[0],
            data=raw.view(np.uint8).reshape(-1),
        )  # fmt: skip
        return [(m.topic, M.IMAGE, msg, m.t)]

    return fault


def as_compressed(ext: str, fmt: str) -> Callable[[LogMessage], list[Out]]:
    """The frames as CompressedImage on ``.../compressed`` (the raw topic dropped, as a
    robot recording only image_transport's compressed stream)."""

    def fault(m: LogMessage) -> list[Out]:
        if m.topic != IMAGE:
            return [(m.topic, m.typename, m.msg, m.t)]
        ok, buf = cv2.imencode(ext, grey(m), [cv2.IMWRITE_JPEG_QUALITY, 95])
        assert ok
        msg = msgtype(M.COMPRESSED_IMAGE)(header=ros_header(m.msg.header), format=fmt, data=buf)
        return [(COMPRESSED, M.COMPRESSED_IMAGE, msg, m.t)]

    return fault


def lamps(out: Path) -> np.ndarray:
    """The run's lamps (N, 2), sorted by x then y."""
    doc = yaml.safe_load((out / "landmarks.yaml").read_text(encoding="utf-8"))
    pts = np.array([[lm["x"], lm["y"]] for lm in doc["landmarks"]], dtype=float)
    return pts[np.lexsort((pts[:, 1], pts[:, 0]))]


def lamp_offsets(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Distance (m) from each lamp of ``a`` to the nearest of ``b``."""
    return np.min(np.linalg.norm(a[:, None] - b[None], axis=2), axis=1)


# -- encodings -------------------------------------------------------------------------

ENCODINGS = {
    "bgr8": as_image("bgr8", lambda g: np.repeat(g[:, :, None], 3, axis=2)),
    "rgb8": as_image("rgb8", lambda g: np.repeat(g[:, :, None], 3, axis=2)),
    "mono16": as_image("mono16", lambda g: g.astype(np.uint16) * 257),
    "png": as_compressed(".png", "mono8; png compressed"),
}


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(ENCODINGS))
def test_frames_of_any_encoding_give_the_mono8_run(tiny: Tiny, tmp_path: Path, name: str) -> None:
    """The same grey image in another encoding or as a PNG CompressedImage on the
    compressed topic: the mono8 run's files byte for byte, no bad frames."""
    log = rewrite(tiny.log, tmp_path / f"{name}.mcap", ENCODINGS[name])
    s = run_json(tiny, log, tmp_path / "est")
    assert "bad_frames" not in s["warnings"]
    assert s["counts"]["frames"] == tiny.run["counts"]["frames"]
    assert s["lamps"] == tiny.run["lamps"]
    topic = COMPRESSED if name == "png" else IMAGE
    assert s["lamp_source"] == f"frames ({topic})"
    for f in SAME_FILES:
        assert (tmp_path / "est" / f).read_bytes() == (tiny.est / f).read_bytes(), f


def test_jpeg_frames_find_the_same_lamps(tiny: Tiny, tmp_path: Path) -> None:
    """JPEG (quality 95, image_transport's "bgr8; jpeg compressed bgr8" format string):
    the same lamps within 5 mm of the mono8 run's (measured: at most 0.3 mm)."""
    fault = as_compressed(".jpg", "bgr8; jpeg compressed bgr8")
    log = rewrite(tiny.log, tmp_path / "jpeg.mcap", fault)
    s = run_json(tiny, log, tmp_path / "est")
    assert "bad_frames" not in s["warnings"]
    assert s["counts"]["frames"] == tiny.run["counts"]["frames"]
    assert s["lamps"] == tiny.run["lamps"]
    got, want = lamps(tmp_path / "est"), lamps(tiny.est)
    assert len(got) == len(want)
    off = lamp_offsets(got, want)
    print(f"JPEG lamp offsets: {np.round(off * 1000, 2)} mm")
    assert off.max() < 0.005


def test_a_frame_that_cannot_be_decoded_is_one_bad_frame(tiny: Tiny, tmp_path: Path) -> None:
    """Garbage bytes in a CompressedImage: each such frame one bad_frames, the first
    named, the run goes on."""
    jpeg = as_compressed(".jpg", "jpeg")
    n = [0]

    def fault(m: LogMessage) -> list[Out]:
        out = jpeg(m)
        if m.topic == IMAGE:
            n[0] += 1
            if n[0] % 10 == 0:
                out[0][2].data = np.frombuffer(b"\xff\xd8 not a jpeg", np.uint8)
        return out

    log = rewrite(tiny.log, tmp_path / "bad.mcap", fault)
    s = run_json(tiny, log, tmp_path / "est")
    assert s["warnings"]["bad_frames"] == n[0] // 10 >= 15
    assert s["lamps"] == tiny.run["lamps"]


def test_a_topic_of_another_type_is_one_line(tiny: Tiny, tmp_path: Path) -> None:
    """topics.image naming a topic that carries no frames: one line, exit 3."""

    def fault(m: LogMessage) -> list[Out]:
        if m.topic == IMAGE:
            return [(m.topic, M.STRING, M.string_msg("not a frame"), m.t)]
        return [(m.topic, m.typename, m.msg, m.t)]

    log = rewrite(tiny.log, tmp_path / "other.mcap", fault)
    code, _, err = cli("run", log, "-o", tmp_path / "est", "--config", tiny.config)
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert code == 3 and len(lines) == 1
    assert str(log) in lines[0] and "std_msgs/msg/String" in lines[0]


# -- lens distortion ---------------------------------------------------------------------


def distortion_maps(info, d: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The zoomed lens' K and, for each raw pixel, the ideal frame's pixel it sees
    (map_x, map_y for cv2.remap): cv2.undistortPoints with K, D and P = the simulator's
    camera matrix, iterated to convergence and checked with cv2.projectPoints."""
    k = np.asarray(info.k, dtype=float).reshape(3, 3)
    kd = k.copy()
    kd[0, 0] *= ZOOM
    kd[1, 1] *= ZOOM
    h, w = int(info.height), int(info.width)
    u, v = np.meshgrid(np.arange(w, dtype=float), np.arange(h, dtype=float))
    raw = np.column_stack([u.ravel(), v.ravel()])
    crit = (cv2.TERM_CRITERIA_COUNT + cv2.TERM_CRITERIA_EPS, 200, 1e-10)
    ideal = cv2.undistortPoints(raw.reshape(-1, 1, 2), kd, d, P=k, criteria=crit).reshape(-1, 2)
    rays = np.column_stack([(ideal - k[:2, 2]) / k[0, 0], np.ones(len(ideal))])
    back, _ = cv2.projectPoints(rays, np.zeros(3), np.zeros(3), kd, d)
    assert np.abs(back.reshape(-1, 2) - raw).max() < 1e-3  # the map is the lens' inverse
    assert ideal.min() > 0 and np.all(ideal.max(axis=0) < [w - 1, h - 1])  # in the frame
    mx = ideal[:, 0].reshape(h, w).astype(np.float32)
    my = ideal[:, 1].reshape(h, w).astype(np.float32)
    return kd, mx, my


def distorted(lens: bool, keep_d: bool) -> Callable[[LogMessage], list[Out]]:
    """Frames through the zoomed camera, with the barrel lens or without (``lens``),
    the CameraInfo the camera's (K zoomed, D = BARREL, or D zeros when not ``keep_d``:
    the old pinhole reading of the lens' frames)."""
    maps: list = []
    d = np.array(BARREL) if lens else np.zeros(5)

    def fault(m: LogMessage) -> list[Out]:
        if m.topic == INFO:
            if not maps:
                maps.extend(distortion_maps(m.msg, d))
            kd = maps[0]
            m.msg.k = kd.reshape(-1)
            p = np.zeros((3, 4))
            p[:, :3] = kd
            m.msg.p = p.reshape(-1)
            m.msg.distortion_model = "plumb_bob"
            m.msg.d = d if keep_d else np.zeros(5)
        elif m.topic == IMAGE:
            assert maps, "the CameraInfo comes before the first frame"
            img = cv2.remap(grey(m), maps[1], maps[2], cv2.INTER_LINEAR)
            m.msg.data = np.ascontiguousarray(img).reshape(-1)
        return [(m.topic, m.typename, m.msg, m.t)]

    return fault


@pytest.mark.slow
def test_a_distorting_lens_finds_the_undistorted_logs_lamps(tiny: Tiny, tmp_path: Path) -> None:
    """The frames of a zoomed camera through a strong barrel lens (its corners move 30
    px) with its D: the same lamps within 2 cm of the same camera's without the lens
    (measured: 0.8 cm at most); the lens' frames read as a pinhole (D zeros, the old
    code) put them 10-30 cm off."""
    ref = rewrite(tiny.log, tmp_path / "zoom.mcap", distorted(False, False))
    run_json(tiny, ref, tmp_path / "zoom")
    log = rewrite(tiny.log, tmp_path / "lens.mcap", distorted(True, True))
    s = run_json(tiny, log, tmp_path / "est")
    assert "bad_frames" not in s["warnings"]
    got, want = lamps(tmp_path / "est"), lamps(tmp_path / "zoom")
    assert len(got) == len(want) == s["lamps"]
    off = lamp_offsets(want, got)
    pinhole = rewrite(tiny.log, tmp_path / "pinhole.mcap", distorted(True, False))
    run_json(tiny, pinhole, tmp_path / "pinhole")
    old = lamp_offsets(want, lamps(tmp_path / "pinhole"))
    print(f"lamp offsets with D: {np.round(off * 100, 2)} cm; D ignored: {np.round(old * 100, 1)}")
    assert off.max() < 0.05
    assert old.max() > 0.1 and old.max() > 5 * off.max()
    # sighting by sighting (no filter between): the lens' blobs undistorted are the
    # zoomed camera's, to a few millimetres on the ceiling; read as a pinhole, not
    lens, plain = sightings(log, tiny), sightings(ref, tiny)
    ignored = sightings(pinhole, tiny)
    near, far = [], []
    for t, z in plain.items():
        if len(z) and t in lens and len(lens[t]) == len(z):
            near.append(lamp_offsets(z, lens[t]))
            far.append(lamp_offsets(z, ignored[t]))
    near_all, far_all = np.concatenate(near), np.concatenate(far)
    print(
        f"sightings: {len(near_all)}; with D median {np.median(near_all) * 1000:.2f} mm, "
        f"max {near_all.max() * 1000:.2f} mm; D ignored median "
        f"{np.median(far_all) * 1000:.1f} mm, max {far_all.max() * 1000:.1f} mm"
    )
    assert len(near_all) > 100
    assert np.median(near_all) < 0.003 and near_all.max() < 0.01
    assert np.median(far_all) > 5 * np.median(near_all) and far_all.max() > 0.1


def sightings(log: Path, small: Tiny) -> dict[int, np.ndarray]:
    """Each frame's lamps on the ceiling (base frame, m) by its stamp (ns): the run's
    detector (default gates) and the log's CameraInfo (CeilingCamera.unproject)."""
    from fuzzyslam.camera import CeilingCamera
    from fuzzyslam.config import load_config
    from fuzzyslam.slam.detect import detect_lamps
    from fuzzyslam.streams.reader import LogReader

    cfg = load_config(small.config)
    reader = LogReader(log)
    info = next(iter(reader.messages([INFO]))).msg
    cam = CeilingCamera.from_camera_info(info, cfg.camera.ceiling_height)
    p = cfg.slam
    out = {}
    for m in reader.messages([IMAGE]):
        blobs = detect_lamps(
            grey(m), p.threshold, p.min_area, p.max_area, p.min_fill, p.max_aspect, p.border
        )
        st = m.msg.header.stamp
        out[st.sec * 10**9 + st.nanosec] = cam.unproject(blobs.uv)
    return out


def test_a_lens_model_it_cannot_undo_is_one_line(tiny: Tiny, tmp_path: Path) -> None:
    """A CameraInfo whose distortion model the camera cannot undo (non-zero D): one line
    naming the log and the model, exit 3, nothing written."""

    def fault(m: LogMessage) -> list[Out]:
        if m.topic == INFO:
            m.msg.distortion_model = "double_sphere"
            m.msg.d = np.array([0.5, 0.6, 0.0, 0.0])
        return [(m.topic, m.typename, m.msg, m.t)]

    log = rewrite(tiny.log, tmp_path / "model.mcap", fault)
    code, _, err = cli("run", log, "-o", tmp_path / "est", "--config", tiny.config)
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert code == 3 and len(lines) == 1, err
    assert str(log) in lines[0] and "'double_sphere'" in lines[0]
    assert not (tmp_path / "est").exists()
