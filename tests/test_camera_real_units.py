"""Real cameras, unit level: frames of every common encoding to the detector's grey
image, CompressedImage decoding, and the lens models (undistort inverts OpenCV's own
forward model; a model the camera cannot undo is one line).

References: REP 104 and ``sensor_msgs/image_encodings.hpp`` (encoding names);
``sensor_msgs/distortion_models.hpp``; OpenCV's ``cvtColor``, ``imencode``/``imdecode``,
``projectPoints`` and ``fisheye::projectPoints``.
"""

from __future__ import annotations

from types import SimpleNamespace

import cv2
import numpy as np
import pytest

from fuzzyslam.camera import CeilingCamera, distortion_coefficients
from fuzzyslam.slam.log_setup import camera_info_problem
from fuzzyslam.streams import messages as M

W, H = 40, 30
F, CX, CY = 73.3, 79.5, 59.5  # the simulator's 160x120, 95-degree camera
PLUMB_BOB = [-0.3, 0.08, 0.001, -0.002, 0.0]  # a strong wide-angle barrel
RATIONAL = [-0.3, 0.08, 0.001, -0.002, 0.0, 0.05, 0.01, 0.0]
EQUIDISTANT = [-0.02, 0.01, -0.005, 0.001]


def image(encoding: str, arr: np.ndarray, big: bool = False, pad: int = 0):
    """A sensor_msgs/Image of ``arr`` (H, W[, C]) with ``pad`` bytes after each row."""
    a = np.ascontiguousarray(arr)
    if a.dtype == np.uint16:
        a = a.astype(">u2" if big else "<u2")
    rows = a.view(np.uint8).reshape(a.shape[0], -1)
    rows = np.hstack([rows, np.zeros((rows.shape[0], pad), np.uint8)])
    return SimpleNamespace(
        height=a.shape[0], width=a.shape[1], encoding=encoding, is_bigendian=int(big),
        step=rows.shape[1], data=rows.reshape(-1),
    )  # fmt: skip


def compressed(fmt: str, data: bytes):
    return SimpleNamespace(format=fmt, data=np.frombuffer(data, np.uint8))


@pytest.fixture
def frame() -> np.ndarray:
    """A grey frame: a dark noisy background and two bright discs."""
    rng = np.random.default_rng(3)
    img = rng.integers(20, 60, (H, W), dtype=np.uint8)
    cv2.circle(img, (10, 12), 4, 255, -1)
    cv2.circle(img, (28, 18), 3, 240, -1)
    return img


def test_mono8_is_the_data_itself(frame: np.ndarray) -> None:
    out = M.image_to_array(image("mono8", frame, pad=3))
    assert out.dtype == np.uint8 and np.array_equal(out, frame)


@pytest.mark.parametrize("enc", ["bgr8", "rgb8", "8UC3", "bgra8", "rgba8", "8UC4"])
def test_colour_frames_of_a_grey_scene_are_that_grey(frame: np.ndarray, enc: str) -> None:
    channels = 4 if enc[-1] == "4" or "a" in enc[3:] else 3
    arr = np.repeat(frame[:, :, None], channels, axis=2)
    assert np.array_equal(M.image_to_array(image(enc, arr, pad=5)), frame)


def test_colour_order_is_honoured(frame: np.ndarray) -> None:
    """A coloured frame: rgb8 and bgr8 give OpenCV's luma of their own channel order."""
    rgb = np.stack([frame, frame // 2, frame // 4], axis=2)
    want = cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY)
    assert np.array_equal(M.image_to_array(image("rgb8", rgb)), want)
    assert np.array_equal(M.image_to_array(image("bgr8", rgb[:, :, ::-1])), want)
    rgba = np.dstack([rgb, np.full_like(frame, 7)])
    assert np.array_equal(M.image_to_array(image("rgba8", rgba)), want)
    assert not np.array_equal(M.image_to_array(image("bgr8", rgb)), want)


@pytest.mark.parametrize("big", [False, True])
def test_16_bit_frames_keep_their_high_byte(frame: np.ndarray, big: bool) -> None:
    wide = frame.astype(np.uint16) * 256 + (frame ^ 0x5A)  # any low byte
    assert np.array_equal(M.image_to_array(image("mono16", wide, big=big, pad=2)), frame)
    assert np.array_equal(M.image_to_array(image("16UC1", wide, big=big)), frame)
    bgr = np.repeat(wide[:, :, None], 3, axis=2)
    assert np.array_equal(M.image_to_array(image("bgr16", bgr, big=big)), frame)


@pytest.mark.parametrize("pattern", ["rggb", "bggr", "gbrg", "grbg"])
def test_bayer_frames_are_demosaiced(frame: np.ndarray, pattern: str) -> None:
    """A flat grey scene through any Bayer pattern demosaics to itself; a frame to
    OpenCV's demosaicing of its pattern; the 16-bit mosaic to the same 8-bit image."""
    flat = np.full((H, W), 90, np.uint8)
    assert np.array_equal(M.image_to_array(image(f"bayer_{pattern}8", flat)), flat)
    got = M.image_to_array(image(f"bayer_{pattern}8", frame))
    code = getattr(cv2, f"COLOR_Bayer{pattern.upper()}2GRAY")
    assert np.array_equal(got, cv2.cvtColor(frame, code))
    wide = frame.astype(np.uint16) * 257
    wide_got = M.image_to_array(image(f"bayer_{pattern}16", wide)).astype(int)
    assert np.abs(wide_got - got).max() <= 1  # interpolated at 16 bits, then v >> 8


def test_yuv_frames_give_their_luma(frame: np.ndarray) -> None:
    chroma = np.full_like(frame, 128)
    uyvy = np.stack([chroma, frame], axis=2)  # U Y V Y ...: chroma first
    yuyv = np.stack([frame, chroma], axis=2)
    assert np.array_equal(M.image_to_array(image("yuv422", uyvy)), frame)
    assert np.array_equal(M.image_to_array(image("uyvy", uyvy)), frame)
    assert np.array_equal(M.image_to_array(image("yuyv", yuyv)), frame)
    assert np.array_equal(M.image_to_array(image("yuv422_yuy2", yuyv)), frame)
    nv12 = np.vstack([frame, np.full((H // 2, W), 128, np.uint8)])
    msg = image("nv12", nv12)
    msg.height = H
    assert np.array_equal(M.image_to_array(msg), frame)


@pytest.mark.parametrize("enc, size", [("32FC1", 4), ("16SC1", 2), ("bgr8", 1), ("weird", 1)])
def test_frames_it_cannot_decode_are_value_errors(frame: np.ndarray, enc: str, size: int) -> None:
    """Float and signed depth images, an unknown encoding, and data too short for the
    encoding (a bgr8 frame with mono8's bytes) are ValueError (one bad_frames each)."""
    msg = image("mono8", frame)
    msg.encoding = enc
    with pytest.raises(ValueError, match=enc if enc != "bgr8" else "does not match"):
        M.image_to_array(msg)


@pytest.mark.parametrize("ext, fmt", [(".png", "mono8; png compressed"), (".jpg", "jpeg")])
def test_compressed_frames_are_decoded(frame: np.ndarray, ext: str, fmt: str) -> None:
    ok, buf = cv2.imencode(ext, frame, [cv2.IMWRITE_JPEG_QUALITY, 98])
    assert ok
    got = M.compressed_to_array(compressed(fmt, buf.tobytes()))
    assert got.shape == frame.shape and got.dtype == np.uint8
    if ext == ".png":
        assert np.array_equal(got, frame)
    else:
        assert np.abs(got.astype(int) - frame).mean() < 2.0
    colour = np.repeat(frame[:, :, None], 3, axis=2)
    _, buf = cv2.imencode(".png", colour)
    assert np.array_equal(
        M.compressed_to_array(compressed("bgr8; png compressed bgr8", buf)), frame
    )
    _, buf = cv2.imencode(".png", frame.astype(np.uint16) * 257)
    assert np.array_equal(M.compressed_to_array(compressed("mono16; png compressed", buf)), frame)


def test_compressed_frames_it_cannot_decode_are_value_errors() -> None:
    with pytest.raises(ValueError, match="empty"):
        M.compressed_to_array(compressed("jpeg", b""))
    with pytest.raises(ValueError, match="cannot be decoded"):
        M.compressed_to_array(compressed("jpeg", b"\xff\xd8not a jpeg at all"))
    with pytest.raises(ValueError, match="depth"):
        M.compressed_to_array(compressed("16UC1; compressedDepth png", b"\x00" * 20))


# -- lens distortion -------------------------------------------------------------------


def info(model: str, d, fx: float = F, fy: float = F) -> SimpleNamespace:
    return SimpleNamespace(
        width=160, height=120, k=[fx, 0, CX, 0, fy, CY, 0, 0, 1], distortion_model=model, d=d
    )


def raw_pixels(model: str, d, ideal: np.ndarray, fx: float, fy: float) -> np.ndarray:
    """OpenCV's forward model of ideal pixels (P = K with fx = fy = f): the rays through
    cv2.projectPoints (cv2.fisheye.projectPoints for equidistant) with K and D."""
    f = 0.5 * (fx + fy)
    rays = np.column_stack([(ideal - [CX, CY]) / f, np.ones(len(ideal))])
    k = np.array([[fx, 0, CX], [0, fy, CY], [0, 0, 1.0]])
    if model == "equidistant":
        out, _ = cv2.fisheye.projectPoints(
            rays.reshape(-1, 1, 3), np.zeros(3), np.zeros(3), k, np.array(d, float)
        )
    else:
        out, _ = cv2.projectPoints(rays, np.zeros(3), np.zeros(3), k, np.array(d, float))
    return out.reshape(-1, 2)


@pytest.mark.parametrize(
    "model, d", [("plumb_bob", PLUMB_BOB), ("rational_polynomial", RATIONAL),
                 ("equidistant", EQUIDISTANT)],
)  # fmt: skip
def test_undistort_inverts_opencvs_forward_model(model: str, d) -> None:
    """undistort(distort(p)) = p to 1e-3 px over the whole raw image of a strongly
    distorting 95-degree lens, the forward model being OpenCV's projectPoints (fx and fy
    0.5 % apart); the camera's own distort is that model."""
    fx, fy = F, F * 1.005
    cam = CeilingCamera.from_camera_info(info(model, d, fx, fy), 1.7)
    assert cam.distorted
    u, v = np.meshgrid(np.linspace(-0.5, 159.5, 41), np.linspace(-0.5, 119.5, 31))
    raw = np.column_stack([u.ravel(), v.ravel()])
    ideal = cam.undistort(raw)
    assert np.all(np.isfinite(ideal))
    assert np.abs(raw_pixels(model, d, ideal, fx, fy) - raw).max() < 1e-3
    assert np.abs(cam.distort(ideal) - raw).max() < 1e-3
    assert np.abs(ideal - raw).max() > 20  # strong: the corners move tens of pixels
    pts = np.random.default_rng(1).uniform(-1.5, 1.5, (50, 2))
    assert np.abs(cam.unproject(cam.project(pts)) - pts).max() < 1e-6


def test_opencvs_default_undistortion_is_not_enough() -> None:
    """The reason for the Newton refinement: cv2.undistortPoints' 5 unchecked
    iterations are pixels off in this lens' corners."""
    cam = CeilingCamera.from_camera_info(info("plumb_bob", PLUMB_BOB), 1.7)
    corners = np.array([[-0.5, -0.5], [159.5, 119.5], [159.5, -0.5]])
    k = np.array([[F, 0, CX], [0, F, CY], [0, 0, 1.0]])
    quick = cv2.undistortPoints(corners.reshape(-1, 1, 2), k, np.array(PLUMB_BOB), P=k)
    assert np.abs(cam.distort(quick.reshape(-1, 2)) - corners).max() > 1.0
    assert np.abs(cam.distort(cam.undistort(corners)) - corners).max() < 1e-6


def test_the_noise_follows_the_undistortions_local_scale() -> None:
    """A raw pixel's sigma maps to the ceiling through the undistortion's Jacobian
    (checked against central differences of undistort itself): metric_sigma at the
    centre, another scale toward the rim; without D, metric_sigma everywhere."""
    cam = CeilingCamera.from_camera_info(info("plumb_bob", PLUMB_BOB), 1.7)
    plain = CeilingCamera.from_camera_info(info("plumb_bob", [0.0] * 5), 1.7)
    assert not plain.distorted and plain.dist == ()
    uv = np.array([[CX, CY], [150.0, 110.0], [20.0, 100.0]])
    cov = cam.ceiling_covariances(uv, 0.5)
    np.testing.assert_allclose(cov[0], plain.metric_sigma(0.5) ** 2 * np.eye(2), rtol=1e-6)
    e = 0.01
    for q, c in zip(uv[1:], cov[1:], strict=True):
        ex, ey = np.array([e, 0.0]), np.array([0.0, e])
        du = (cam.undistort([q + ex]) - cam.undistort([q - ex]))[0] / (2 * e)
        dv = (cam.undistort([q + ey]) - cam.undistort([q - ey]))[0] / (2 * e)
        j = np.column_stack([du, dv]) * 0.5 * 1.7 / F
        np.testing.assert_allclose(c, j @ j.T, rtol=1e-4)
        assert np.abs(np.linalg.eigvalsh(c) / plain.metric_sigma(0.5) ** 2 - 1).max() > 0.1
    np.testing.assert_allclose(
        plain.ceiling_covariances(uv, 0.5), np.repeat([np.eye(2)], 3, 0) * 0.5**2 * (1.7 / F) ** 2
    )


def test_points_the_model_cannot_undo_are_nan() -> None:
    """A plumb_bob whose polynomial turns back before the image's corners: those corners
    have no undistortion (NaN), the centre has."""
    cam = CeilingCamera.from_camera_info(info("plumb_bob", [-0.3, 0.08, 0, 0, -0.01]), 1.7)
    out = cam.undistort(np.array([[CX, CY], [-0.5, -0.5]]))
    assert np.all(np.isfinite(out[0])) and np.all(np.isnan(out[1]))


@pytest.mark.parametrize(
    "model, d, said",
    [
        ("double_sphere", [0.5, 0.6, 0, 0], "distortion model 'double_sphere'"),
        ("equidistant", [0.1, 0.2, 0.0, 0.0, 0.3], "takes 4 coefficients"),
        ("plumb_bob", [0.1, 0.2, 0.3], "with 3 coefficients"),
        ("plumb_bob", [np.nan, 0, 0, 0, 0], "not all finite"),
    ],
)
def test_a_distortion_it_cannot_undo_is_one_line(model: str, d, said: str) -> None:
    problem = camera_info_problem(info(model, d))
    assert problem is not None and said in problem and "\n" not in problem
    with pytest.raises(ValueError):
        distortion_coefficients(model, d)


def test_zero_distortion_of_a_radtan_or_unknown_model_is_none() -> None:
    for model in ("plumb_bob", "rational_polynomial", "", "anything"):
        assert camera_info_problem(info(model, [0.0] * 5)) is None
        assert distortion_coefficients(model, [0.0] * 5) == ()


def test_an_equidistant_lens_with_zero_coefficients_is_still_equidistant() -> None:
    """D = 0 of the equidistant model is the ideal fisheye, r = f theta, not a pinhole
    (r = f tan theta): a pixel 240 px off the centre of a 300-px lens is 2 m off on a
    ceiling 2 m up as a pinhole, 2 tan(0.8 rad) = 2.06 m as the fisheye it is; OpenCV's
    own undistortion agrees, and a tiny D does not jump away from it."""
    import cv2

    def cam(d):
        msg = SimpleNamespace(width=640, height=480, k=[300, 0, 320, 0, 300, 240, 0, 0, 1],
                              distortion_model="equidistant", d=d)  # fmt: skip
        return CeilingCamera.from_camera_info(msg, 2.0)

    zero, tiny = cam([0.0] * 4), cam([1e-9, 0.0, 0.0, 0.0])
    assert zero.distorted and distortion_coefficients("equidistant", [0.0] * 4) == (0.0,) * 4
    px = np.array([[560.0, 240.0]])
    x = zero.unproject(px)[0, 0]
    assert x == pytest.approx(2.0 * np.tan(0.8), rel=1e-9)
    assert tiny.unproject(px)[0, 0] == pytest.approx(x, rel=1e-6)
    k = np.array([[300.0, 0, 320], [0, 300, 240], [0, 0, 1]])
    ocv = cv2.fisheye.undistortPoints(px.reshape(1, 1, 2), k, np.zeros(4)).reshape(2)
    assert x == pytest.approx(2.0 * ocv[0], rel=1e-6)


def test_a_fisheye_pixel_past_its_rim_is_nan_and_the_others_are_kept() -> None:
    """A fisheye whose model stops growing before the image's edge (an Intel T265-like
    lens, 848x800, f = 285: its rim about 411 px from the centre): pixels past the rim
    come back NaN (the forward model is flat there: its Jacobian singular), those inside
    are undistorted, in the same batch (it once raised LinAlgError for the batch)."""
    msg = SimpleNamespace(width=848, height=800, k=[285, 0, 424, 0, 285, 400, 0, 0, 1],
                          distortion_model="equidistant",
                          d=[-0.0069, 0.0430, -0.0405, 0.0076])  # fmt: skip
    cam = CeilingCamera.from_camera_info(msg, 2.5)
    px = np.array([[424.0, 400.0], [0.0, 400.0], [847.0, 400.0], [600.0, 500.0], [0.0, 0.0]])
    out = cam.undistort(px)
    assert np.all(np.isfinite(out[[0, 3]])) and np.all(np.isnan(out[[1, 2, 4]]))
    np.testing.assert_allclose(cam.distort(out[[0, 3]]), px[[0, 3]], atol=1e-5)
    assert np.all(np.isnan(cam.ceiling_covariances(px, 0.5)[[1, 2, 4]]))


@pytest.mark.parametrize("model, d", [("plumb_bob", PLUMB_BOB), ("equidistant", EQUIDISTANT),
                                      ("plumb_bob", [0.0] * 5)])  # fmt: skip
def test_ceiling_measurements_are_unproject_and_ceiling_covariances(model: str, d) -> None:
    """A frame's lamps undistorted once (``ceiling_measurements``) give the points and
    covariances of ``unproject`` and ``ceiling_covariances``, which undistort apart."""
    cam = CeilingCamera.from_camera_info(info(model, d), 1.7)
    uv = np.array([[CX, CY], [10.0, 12.5], [150.0, 100.0], [80.0, 5.0]])
    z, cov = cam.ceiling_measurements(uv, 0.7)
    np.testing.assert_array_equal(z, cam.unproject(uv))
    np.testing.assert_array_equal(cov, cam.ceiling_covariances(uv, 0.7))
