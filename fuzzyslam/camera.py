"""The upward ceiling camera: pinhole projection of the ceiling plane (the one place for it).

Convention: the camera looks straight up; its optical frame has the same axes as
``base_link`` (x forward, y left, z up; right-handed, optical axis +z). So the
image column u grows toward the robot's front and the row v toward its left::

    u = cx + f * X / h,    v = cy + f * Y / h

where (X, Y) is a ceiling point relative to the lens, in the robot frame, and h
the height of the ceiling above the lens. Pixel centres are at integer
coordinates (OpenCV's convention). Distortion is not modelled (CameraInfo's D is
zero in simulation; a real camera's image should be rectified first).

That is the camera mounted with the identity rotation. A camera mounted otherwise
(/tf_static: ``ceiling_camera`` in the base frame, a 3D :class:`~fuzzyslam.streams.tf.Rigid`)
maps its image axes into the base plane through its rotation: ``axes`` (a 2x2 matrix A,
row by row) takes a point (X, Y) of the image plane (camera x, y, metres at the ceiling)
to ``A (X, Y) + offset`` in ``base_link``; A is the camera's x and y axes projected onto
the floor (:func:`floor_mount`): a rotation by the mount's yaw (an image rotated 180 deg:
yaw pi, A = -I), or a reflection for a camera frame whose z axis points down (a mirrored
image), both from the rotation, with no special case.

``unproject`` returns points in ``base_link`` (the lens offset added back), so the
filter's measurement model is simply z = R(theta)^T (l - p) for a lamp at world l
seen from pose (p, theta) (docs/models.md sec. 3 with the offset folded in).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from fuzzyslam.streams.tf import Rigid, TfProblem, planar_mount

IDENTITY_AXES = (1.0, 0.0, 0.0, 1.0)  # image x, y along base x, y (a mount of yaw 0)
# the largest angle (deg) between the optical axis and the vertical: the model takes the
# image plane parallel to the ceiling (a tilt of t shifts points by h tan t)
MAX_TILT_DEG = 15.0


def floor_mount(mount: Rigid) -> tuple[tuple[float, float], tuple[float, float, float, float]]:
    """The planar mount of the ceiling camera: its lens' x, y in the base frame and the
    matrix A of its image axes in the base plane (:class:`CeilingCamera` ``axes``).

    A is orthogonal: the rotation by the yaw of the camera's x axis
    (``streams.tf.planar_mount``), its second column negated when the optical axis (the
    camera's z) points down in the base frame, i.e. the image mirrored. The optical axis
    must be within :data:`MAX_TILT_DEG` of the vertical.

    Parameters
    ----------
    mount : Rigid
        The camera frame's composed mount in the base frame (``streams.tf.compose_to_base``).

    Returns
    -------
    offset : (float, float)
        The lens' x, y (m).
    axes : (float, float, float, float)
        A row by row.

    Raises
    ------
    TfProblem
        When the optical axis is tilted more than :data:`MAX_TILT_DEG` from the vertical.
    """
    r = mount.rotation
    tilt = math.degrees(math.acos(min(abs(float(r[2, 2])), 1.0)))
    if tilt > MAX_TILT_DEG:
        raise TfProblem(
            f"the camera's optical axis is {tilt:.0f} deg from the vertical (more than "
            f"{MAX_TILT_DEG:.0f}): not a ceiling camera"
        )
    x, y, yaw = planar_mount(mount).tolist()
    c, s = math.cos(yaw), math.sin(yaw)
    m = -1.0 if r[2, 2] < 0.0 else 1.0  # mirrored: the image's y axis the other way
    return (x, y), (c, -s * m, s, c * m)


@dataclass(frozen=True)
class CeilingCamera:
    """Pinhole camera looking at a ceiling plane ``height`` metres above the lens, its
    lens at ``offset`` in base_link, its image axes along ``axes`` (module docstring)."""

    width: int
    height_px: int
    f: float
    cx: float
    cy: float
    height: float
    offset: tuple[float, float] = (0.0, 0.0)
    axes: tuple[float, float, float, float] = IDENTITY_AXES

    @classmethod
    def from_fov(
        cls, width: int, height_px: int, hfov_rad: float, ceiling_height: float, offset=(0.0, 0.0)
    ) -> CeilingCamera:
        """Camera whose horizontal field of view (across ``width``) is ``hfov_rad``."""
        f = (width / 2.0) / np.tan(hfov_rad / 2.0)
        return cls(
            width,
            height_px,
            float(f),
            (width - 1) / 2.0,
            (height_px - 1) / 2.0,
            float(ceiling_height),
            (float(offset[0]), float(offset[1])),
        )

    @classmethod
    def from_camera_info(
        cls, msg, ceiling_height: float, offset=(0.0, 0.0), axes=IDENTITY_AXES
    ) -> CeilingCamera:
        """Camera from a sensor_msgs/CameraInfo (fx = fy assumed; their mean is used).

        Parameters
        ----------
        msg : sensor_msgs/CameraInfo
            Size and camera matrix K.
        ceiling_height : float
            Height of the ceiling above the lens (m).
        offset : (float, float)
            The lens' x, y in base_link (m).
        axes : (float, float, float, float)
            The image axes in the base plane, row by row (:func:`floor_mount`; default:
            along base_link's).

        Returns
        -------
        CeilingCamera
        """
        k = np.asarray(msg.k, dtype=float).reshape(3, 3)
        f = 0.5 * (k[0, 0] + k[1, 1])
        return cls(
            int(msg.width),
            int(msg.height),
            float(f),
            float(k[0, 2]),
            float(k[1, 2]),
            float(ceiling_height),
            (float(offset[0]), float(offset[1])),
            tuple(float(a) for a in axes),
        )

    def project(self, pts_robot: np.ndarray) -> np.ndarray:
        """Pixels (N, 2) of ceiling points (N, 2) given in the robot frame (base_link)."""
        p = np.asarray(pts_robot, dtype=float).reshape(-1, 2)
        x = p[:, 0] - self.offset[0]
        y = p[:, 1] - self.offset[1]
        if self.axes != IDENTITY_AXES:  # into the image axes: A^T (A orthogonal)
            a, b, c, d = self.axes
            x, y = a * x + c * y, b * x + d * y
        s = self.f / self.height
        return np.column_stack([self.cx + s * x, self.cy + s * y])

    def unproject(self, uv: np.ndarray) -> np.ndarray:
        """Robot-frame ceiling points (N, 2) of pixels (N, 2)."""
        q = np.asarray(uv, dtype=float).reshape(-1, 2)
        s = self.height / self.f
        if self.axes != IDENTITY_AXES:  # the image plane's point, through A
            return (q - np.array([self.cx, self.cy])) * s @ np.array(self.axes).reshape(
                2, 2
            ).T + np.array(self.offset, dtype=float)
        # x = (u - cx) s + offset_x, y = (v - cy) s + offset_y, both columns at once
        return (q - np.array([self.cx, self.cy])) * s + np.array(self.offset, dtype=float)

    def metric_sigma(self, sigma_px: float) -> float:
        """Ceiling-plane standard deviation (m) of a pixel standard deviation."""
        return sigma_px * self.height / self.f

    def radius_px(self, radius_m: float) -> float:
        """Image radius (px) of a ceiling disc of radius ``radius_m``."""
        return radius_m * self.f / self.height
