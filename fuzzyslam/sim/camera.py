"""Ceiling-camera frames: lamps as saturated anti-aliased discs, shading and noise (pure).

Projection is fuzzyslam.camera.CeilingCamera (the lamp detector un-projects with the
same class from CameraInfo). A lamp disc of radius R on the ceiling projects to a
disc of radius R f / h. Discs are drawn at sub-pixel positions on a canvas
supersampled k times (cv2.circle with fractional ``shift`` bits, anti-aliased) and
box-filtered back with cv2.resize(INTER_AREA), which averages each k x k block, so
a pixel's value is the disc's area coverage. Pixel centres are integers in both
images, so a final coordinate u maps to k (u + 1/2) - 1/2 on the canvas.

Frame = background (level minus a quadratic fall-off to the corners) blended with
the lamp level by coverage, plus Gaussian sensor noise, clipped and rounded to
mono8. A failed lamp is simply not drawn (dark).
"""

from __future__ import annotations

import cv2
import numpy as np

from fuzzyslam.camera import CeilingCamera
from fuzzyslam.sim.params import CameraParams

SHIFT = 4  # fractional bits of cv2.circle coordinates (1/16 canvas pixel)
# cv2.circle(LINE_AA, filled) paints a disc whose area-equivalent radius is 0.53-0.62
# canvas pixels larger than asked (measured for radii 1.5-10 px, k = 4 and 8); the
# radius is shrunk by the mean so the rendered area matches pi r^2 (tested to 2 %).
AA_RADIUS_EXCESS = 0.58


def make_camera(params: CameraParams) -> CeilingCamera:
    """The CeilingCamera of the config.

    Parameters
    ----------
    params : CameraParams
        The config's ``camera:`` section.

    Returns
    -------
    CeilingCamera
    """
    return CeilingCamera.from_fov(
        params.width,
        params.height,
        np.radians(params.hfov_deg),
        params.ceiling_height,
        (float(params.offset[0]), float(params.offset[1])),
    )


def background(cam: CeilingCamera, params: CameraParams) -> np.ndarray:
    """(H, W) float32 background: level minus vignetting * (r / r_corner)^2.

    Parameters
    ----------
    cam : CeilingCamera
        The camera (image size).
    params : CameraParams
        Background level and vignetting.

    Returns
    -------
    ndarray of float32, shape (H, W)
    """
    v, u = np.mgrid[0 : cam.height_px, 0 : cam.width].astype(np.float32)
    r2 = ((u - cam.cx) ** 2 + (v - cam.cy) ** 2) / (cam.cx**2 + cam.cy**2)
    return (params.background - params.vignetting * r2).astype(np.float32)


def visible(cam: CeilingCamera, uv: np.ndarray, radius_px: float) -> np.ndarray:
    """Mask of discs whose whole extent lies inside the image.

    Parameters
    ----------
    cam : CeilingCamera
        The camera (image size).
    uv : ndarray, shape (N, 2)
        Disc centres (pixels).
    radius_px : float
        Disc radius (pixels).

    Returns
    -------
    ndarray of bool, shape (N,)
    """
    return (
        (uv[:, 0] - radius_px >= -0.5)
        & (uv[:, 0] + radius_px <= cam.width - 0.5)
        & (uv[:, 1] - radius_px >= -0.5)
        & (uv[:, 1] + radius_px <= cam.height_px - 0.5)
    )


def coverage(cam: CeilingCamera, uv: np.ndarray, radius_px: float, k: int) -> np.ndarray:
    """(H, W) float32 area coverage in [0, 1] of discs centred at pixels ``uv`` (N, 2).

    Parameters
    ----------
    cam : CeilingCamera
        The camera (image size).
    uv : ndarray, shape (N, 2)
        Disc centres (pixels).
    radius_px : float
        Disc radius (pixels).
    k : int
        Supersampling factor.

    Returns
    -------
    ndarray of float32, shape (H, W)
    """
    w, h = cam.width, cam.height_px
    canvas = np.zeros((h * k, w * k), dtype=np.uint8)
    out = np.zeros((h, w), dtype=np.float32)
    scale = float(1 << SHIFT)
    r = max(round((k * radius_px - AA_RADIUS_EXCESS) * scale), 1)
    boxes = []
    for u, v in np.asarray(uv, dtype=float).reshape(-1, 2):
        if not (-radius_px - 1 < u < w + radius_px and -radius_px - 1 < v < h + radius_px):
            continue
        centre = (round((k * (u + 0.5) - 0.5) * scale), round((k * (v + 0.5) - 0.5) * scale))
        cv2.circle(canvas, centre, r, 255, thickness=-1, lineType=cv2.LINE_AA, shift=SHIFT)
        # the output pixels the disc (and its anti-aliased rim) can touch, 2 px to spare
        lo = [max(int((c - r) // scale) // k - 2, 0) for c in centre]
        hi = [int((c + r) // scale) // k + 3 for c in centre]
        boxes.append((slice(lo[1], min(hi[1], h)), slice(lo[0], min(hi[0], w))))
    # only the blocks under a disc: elsewhere the coverage is 0 (block sums of whole
    # numbers are exact in float32, so a block's mean is the same in a part or the whole)
    for by, bx in boxes:
        if by.start >= by.stop or bx.start >= bx.stop:
            continue
        part = canvas[by.start * k : by.stop * k, bx.start * k : bx.stop * k].astype(np.float32)
        if k > 1:
            part = cv2.resize(part, (bx.stop - bx.start, by.stop - by.start),
                              interpolation=cv2.INTER_AREA)  # fmt: skip
        out[by, bx] = part / 255.0
    return out


def render(
    cam: CeilingCamera,
    lamps_robot: np.ndarray,
    lamp_radius: float,
    params: CameraParams,
    bg: np.ndarray,
    rng: np.random.Generator,
) -> np.ndarray:
    """mono8 frame (H, W) of lit lamps at robot-frame ceiling positions ``lamps_robot``.

    Parameters
    ----------
    cam : CeilingCamera
        The camera.
    lamps_robot : ndarray, shape (N, 2)
        Lit lamps in the robot frame (m).
    lamp_radius : float
        Lamp radius (m).
    params : CameraParams
        Levels, supersampling, noise.
    bg : ndarray, shape (H, W)
        :func:`background`.
    rng : numpy.random.Generator
        The camera's random stream.

    Returns
    -------
    ndarray of uint8, shape (H, W)
    """
    uv = cam.project(lamps_robot)
    cov = coverage(cam, uv, cam.radius_px(lamp_radius), params.supersample)
    img = bg * (1.0 - cov) + np.float32(params.lamp_level) * cov
    noise = rng.standard_normal(img.shape, dtype=np.float32)
    noise *= np.float32(params.noise_sigma)
    img += noise
    # rint, then clip to [0, 255], in place (float32 throughout: the same values)
    np.rint(img, out=img)
    np.minimum(np.maximum(img, 0, out=img), 255, out=img)
    return img.astype(np.uint8)
