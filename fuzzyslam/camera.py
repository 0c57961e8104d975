"""The upward ceiling camera: pinhole projection of the ceiling plane (the one place for it).

Convention: the camera looks straight up; its optical frame has the same axes as
``base_link`` (x forward, y left, z up; right-handed, optical axis +z). So the
image column u grows toward the robot's front and the row v toward its left::

    u = cx + f * X / h,    v = cy + f * Y / h

where (X, Y) is a ceiling point relative to the lens, in the robot frame, and h
the height of the ceiling above the lens. Pixel centres are at integer
coordinates (OpenCV's convention). Distortion is not modelled (CameraInfo's D is
zero in simulation; a real camera's image should be rectified first).

``unproject`` returns points in ``base_link`` (the lens offset added back), so the
filter's measurement model is simply z = R(theta)^T (l - p) for a lamp at world l
seen from pose (p, theta) (docs/models.md sec. 3 with the offset folded in).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class CeilingCamera:
    """Pinhole camera looking at a ceiling plane ``height`` metres above the lens."""

    width: int
    height_px: int
    f: float
    cx: float
    cy: float
    height: float
    offset: tuple[float, float] = (0.0, 0.0)

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
    def from_camera_info(cls, msg, ceiling_height: float, offset=(0.0, 0.0)) -> CeilingCamera:
        """Camera from a sensor_msgs/CameraInfo (fx = fy assumed; their mean is used)."""
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
        )

    def project(self, pts_robot: np.ndarray) -> np.ndarray:
        """Pixels (N, 2) of ceiling points (N, 2) given in the robot frame (base_link)."""
        p = np.asarray(pts_robot, dtype=float).reshape(-1, 2)
        x = p[:, 0] - self.offset[0]
        y = p[:, 1] - self.offset[1]
        s = self.f / self.height
        return np.column_stack([self.cx + s * x, self.cy + s * y])

    def unproject(self, uv: np.ndarray) -> np.ndarray:
        """Robot-frame ceiling points (N, 2) of pixels (N, 2)."""
        q = np.asarray(uv, dtype=float).reshape(-1, 2)
        s = self.height / self.f
        # x = (u - cx) s + offset_x, y = (v - cy) s + offset_y, both columns at once
        return (q - np.array([self.cx, self.cy])) * s + np.array(self.offset, dtype=float)

    def metric_sigma(self, sigma_px: float) -> float:
        """Ceiling-plane standard deviation (m) of a pixel standard deviation."""
        return sigma_px * self.height / self.f

    def radius_px(self, radius_m: float) -> float:
        """Image radius (px) of a ceiling disc of radius ``radius_m``."""
        return radius_m * self.f / self.height
