"""The upward ceiling camera: pinhole projection of the ceiling plane (the one place for it).

Convention: the camera looks straight up; its optical frame has the same axes as
``base_link`` (x forward, y left, z up; right-handed, optical axis +z). So the
image column u grows toward the robot's front and the row v toward its left::

    u = cx + f * X / h,    v = cy + f * Y / h

where (X, Y) is a ceiling point relative to the lens, in the robot frame, and h
the height of the ceiling above the lens. Pixel centres are at integer
coordinates (OpenCV's convention).

Lens distortion (a real wide-angle lens; CameraInfo's ``distortion_model`` and ``d``, REP
104 and image_pipeline's conventions): the pixels of the raw image are undistorted to the
ideal pinhole pixels above (the new camera matrix P = K, so u, v keep K's scale) before
``unproject``, and ``project`` distorts its ideal pixels, both with OpenCV's models:
``plumb_bob`` and ``rational_polynomial`` (Brown-Conrady radial and tangential,
``cv2.undistortPoints`` / ``cv2.projectPoints``) and ``equidistant`` (the fisheye model,
``cv2.fisheye.undistortPoints`` / ``cv2.fisheye.distortPoints``). A D of zeros (the
simulator's) is no distortion: the pinhole formulas alone, bit for bit.

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

import functools
import math
from dataclasses import dataclass

import numpy as np

from fuzzyslam.streams.tf import Rigid, TfProblem, planar_mount

IDENTITY_AXES = (1.0, 0.0, 0.0, 1.0)  # image x, y along base x, y (a mount of yaw 0)
# the largest angle (deg) between the optical axis and the vertical: the model takes the
# image plane parallel to the ceiling (a tilt of t shifts points by h tan t)
MAX_TILT_DEG = 15.0
# CameraInfo distortion models (sensor_msgs/distortion_models.hpp) -> OpenCV's model:
# "radtan" (cv2.undistortPoints: 4, 5, 8, 12 or 14 coefficients), "fisheye" (4)
DISTORTION_MODELS = {
    "plumb_bob": "radtan",
    "rational_polynomial": "radtan",
    "equidistant": "fisheye",
    "fisheye": "fisheye",  # the names some drivers and calibrators give the same model
    "kannala_brandt": "fisheye",
}
RADTAN_LENGTHS = (4, 5, 8, 12, 14)
# OpenCV's undistortion iterations: to a reprojection error of 1e-9 px (radtan; its
# default is 5 iterations unchecked) or an angle of 1e-12 rad (fisheye, Newton's method)
_RADTAN_CRITERIA = (3, 100, 1e-9)  # cv2.TERM_CRITERIA_COUNT + EPS, count, eps
_FISHEYE_CRITERIA = (3, 50, 1e-12)
# Newton's method after OpenCV's start (CeilingCamera.undistort): at most this many steps,
# to this residual (px) of the forward model; a point left further off has no undistortion
NEWTON_STEPS = 20
UNDISTORT_TOL_PX = 1e-6
JACOBIAN_STEP_PX = 1e-3  # the central difference of the forward model's derivative


def distortion_coefficients(model: str, d) -> tuple[float, ...]:
    """The distortion coefficients of a CameraInfo as the camera uses them: () for none
    (every coefficient zero of a model other than the equidistant one, whatever its
    name: the simulator's logs), else ``d`` (equidistant: its four k1-k4, trailing zeros
    dropped; all four zero is still the equidistant lens, r = f theta, not a pinhole).

    Parameters
    ----------
    model : str
        ``distortion_model`` (plumb_bob, rational_polynomial, equidistant).
    d : sequence of float
        ``d``.

    Returns
    -------
    tuple of float

    Raises
    ------
    ValueError
        One line naming the model: a model the camera cannot undistort with non-zero
        coefficients, a count of them the model does not have, or one not finite.

    References
    ----------
    ``sensor_msgs/distortion_models.hpp`` and REP 104 (the names); OpenCV's camera
    model, https://docs.opencv.org/4.x/d9/d0c/group__calib3d.html (the coefficients).
    """
    c = np.asarray(d, dtype=float).ravel()
    if not np.all(np.isfinite(c)):
        raise ValueError(f"distortion coefficients D = {c.tolist()} are not all finite")
    kind = DISTORTION_MODELS.get(str(model).strip().lower())
    if not np.any(c):  # a pinhole, but for a fisheye: r = f theta is its lens, not r = f tan
        return (0.0, 0.0, 0.0, 0.0) if kind == "fisheye" else ()
    known = ", ".join(k for k in DISTORTION_MODELS if k != "fisheye")
    if kind is None:
        raise ValueError(
            f"distortion model '{model}' (D = {c.tolist()}) cannot be undistorted: "
            f"{known} can (or rectify the frames and record D as zeros)"
        )
    if kind == "fisheye":
        if len(c) < 4 or np.any(c[4:]):
            raise ValueError(f"distortion model '{model}' takes 4 coefficients, D has {len(c)}")
        c = c[:4]
    elif len(c) not in RADTAN_LENGTHS:
        raise ValueError(
            f"distortion model '{model}' with {len(c)} coefficients (OpenCV takes "
            f"{', '.join(map(str, RADTAN_LENGTHS))})"
        )
    return tuple(float(v) for v in c)


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
    lens at ``offset`` in base_link, its image axes along ``axes``, its lens' distortion
    ``dist`` of ``distortion_model`` with focal lengths ``fxy`` (K's fx, fy; empty
    ``dist``: none; module docstring)."""

    width: int
    height_px: int
    f: float
    cx: float
    cy: float
    height: float
    offset: tuple[float, float] = (0.0, 0.0)
    axes: tuple[float, float, float, float] = IDENTITY_AXES
    distortion_model: str = ""
    dist: tuple[float, ...] = ()
    fxy: tuple[float, float] = (0.0, 0.0)

    @property
    def distorted(self) -> bool:
        """Whether the lens has distortion to undo (``dist`` not empty)."""
        return bool(self.dist)

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
        """Camera from a sensor_msgs/CameraInfo (fx = fy assumed; their mean is the
        ideal pinhole's f) and its lens distortion (``distortion_model``, ``d``:
        :func:`distortion_coefficients`; undone with K's own fx, fy).

        Parameters
        ----------
        msg : sensor_msgs/CameraInfo
            Size, camera matrix K, distortion model and coefficients D.
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

        Raises
        ------
        ValueError
            A distortion it cannot undo (:func:`distortion_coefficients`).
        """
        k = np.asarray(msg.k, dtype=float).reshape(3, 3)
        f = 0.5 * (k[0, 0] + k[1, 1])
        model = str(getattr(msg, "distortion_model", ""))
        dist = distortion_coefficients(model, getattr(msg, "d", ()))
        return cls(
            int(msg.width),
            int(msg.height),
            float(f),
            float(k[0, 2]),
            float(k[1, 2]),
            float(ceiling_height),
            (float(offset[0]), float(offset[1])),
            tuple(float(a) for a in axes),
            DISTORTION_MODELS.get(model.strip().lower(), "") if dist else "",
            dist,
            (float(k[0, 0]), float(k[1, 1])) if dist else (0.0, 0.0),
        )

    # -- lens distortion ------------------------------------------------------------------

    def _matrices(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """K (the lens' own fx, fy), the ideal pinhole's P (f, f) and D."""
        fx, fy = self.fxy
        k = np.array([[fx, 0.0, self.cx], [0.0, fy, self.cy], [0.0, 0.0, 1.0]])
        p = np.array([[self.f, 0.0, self.cx], [0.0, self.f, self.cy], [0.0, 0.0, 1.0]])
        return k, p, np.array(self.dist, dtype=float)

    def undistort(self, uv: np.ndarray) -> np.ndarray:
        """Ideal pinhole pixels (N, 2) of raw image pixels (N, 2): the lens' distortion
        undone, reprojected with P = K (fx = fy = f); the pixels themselves without
        distortion.

        OpenCV's inverse (``cv2.undistortPoints``; ``cv2.fisheye.undistortPoints`` for
        the equidistant model) is the start; Newton's method on the forward model
        (:meth:`distort`) then solves distort(x) = uv to ``UNDISTORT_TOL_PX``: OpenCV's
        fixed-point iteration for plumb_bob does not converge in a strongly distorting
        lens' corners (off by tens of pixels with k1 = -0.3 on a 95-degree lens). A point
        the model cannot undo (beyond where its polynomial turns back, a fisheye's 90
        degrees) comes back NaN.

        Parameters
        ----------
        uv : ndarray, shape (N, 2)
            Pixels of the raw (distorted) image, OpenCV's convention.

        Returns
        -------
        ndarray, shape (N, 2)

        References
        ----------
        OpenCV, ``cv::undistortPoints`` and ``cv::fisheye::undistortPoints``,
        https://docs.opencv.org/4.x/d9/d0c/group__calib3d.html and
        https://docs.opencv.org/4.x/db/d58/group__calib3d__fisheye.html
        """
        q = np.asarray(uv, dtype=float).reshape(-1, 2)
        if not self.dist or not len(q):
            return q
        import cv2

        k, p, d = self._matrices()
        src = q.reshape(-1, 1, 2)
        if self.distortion_model == "fisheye":
            out = cv2.fisheye.undistortPoints(
                src, k, d, R=np.eye(3), P=p, criteria=_FISHEYE_CRITERIA
            )
        else:
            out = cv2.undistortPoints(src, k, d, R=None, P=p, criteria=_RADTAN_CRITERIA)
        x = np.asarray(out, dtype=float).reshape(-1, 2)
        bad = ~np.all(np.isfinite(x), axis=1)
        x[bad] = q[bad]  # no start from OpenCV: from the raw pixel
        for _ in range(NEWTON_STEPS):
            live = np.flatnonzero(np.all(np.isfinite(x), axis=1))
            res = self.distort(x[live]) - q[live]
            todo = live[np.any(np.abs(res) > UNDISTORT_TOL_PX, axis=1)]
            if not len(todo):
                break
            res = res[np.any(np.abs(res) > UNDISTORT_TOL_PX, axis=1)]
            j = self.distort_jacobians(x[todo])
            with np.errstate(all="ignore"):
                det = j[:, 0, 0] * j[:, 1, 1] - j[:, 0, 1] * j[:, 1, 0]
            # a flat model (past a fisheye's rim the raw pixel stops moving) has no step
            step = np.isfinite(det) & (np.abs(det) > 1e-12)
            x[todo[~step]] = np.nan
            x[todo[step]] -= np.linalg.solve(j[step], res[step][:, :, None])[:, :, 0]
        live = np.all(np.isfinite(x), axis=1)
        ok = np.zeros(len(q), dtype=bool)
        ok[live] = np.max(np.abs(self.distort(x[live]) - q[live]), axis=1) <= UNDISTORT_TOL_PX
        # the root on the lens' side of where its model turns back, not a far one
        ok &= np.hypot(*((x - [self.cx, self.cy]) / self.f).T) < self._valid_radius
        x[~ok] = np.nan
        return x

    @functools.cached_property
    def _valid_radius(self) -> float:
        """The largest radius of the ideal image (normalised, r = tan of the ray's angle)
        the lens model maps one to one: where its radial distortion first stops growing
        outward (a polynomial that turns back; a fisheye's 90 degrees). A root of
        distort(x) = uv beyond it is not the lens' (:meth:`undistort`)."""
        d = np.zeros(8)
        if self.distortion_model == "fisheye":
            theta = np.linspace(0.0, np.pi / 2, 20001)[:-1]
            k1, k2, k3, k4 = self.dist
            t2 = theta * theta
            rd = theta * (1 + t2 * (k1 + t2 * (k2 + t2 * (k3 + t2 * k4))))
            radius = np.tan(theta)
        else:
            c = np.array(self.dist, dtype=float)
            d[: min(len(c), 8)] = c[:8]
            k1, k2, _, _, k3, k4, k5, k6 = d
            radius = np.linspace(0.0, 50.0, 200001)
            r2 = radius * radius
            num = 1 + r2 * (k1 + r2 * (k2 + r2 * k3))
            den = 1 + r2 * (k4 + r2 * (k5 + r2 * k6))
            with np.errstate(all="ignore"):
                rd = np.where(den > 0, radius * num / den, -np.inf)
        stops = np.flatnonzero(np.diff(rd) <= 0)
        return float(radius[stops[0]]) if len(stops) else np.inf

    def distort(self, uv: np.ndarray) -> np.ndarray:
        """Raw image pixels (N, 2) of ideal pinhole pixels (N, 2): the forward lens model
        (``cv2.projectPoints`` of the ray, ``cv2.fisheye.distortPoints``), the inverse of
        :meth:`undistort`; the pixels themselves without distortion.

        Parameters
        ----------
        uv : ndarray, shape (N, 2)
            Ideal pixels (P = K, fx = fy = f).

        Returns
        -------
        ndarray, shape (N, 2)

        References
        ----------
        OpenCV, ``cv::projectPoints`` and ``cv::fisheye::distortPoints``,
        https://docs.opencv.org/4.x/d9/d0c/group__calib3d.html
        """
        q = np.asarray(uv, dtype=float).reshape(-1, 2)
        if not self.dist or not len(q):
            return q
        import cv2

        k, _, d = self._matrices()
        xy = (q - np.array([self.cx, self.cy])) / self.f  # the ray (x, y, 1)
        if self.distortion_model == "fisheye":
            out = cv2.fisheye.distortPoints(xy.reshape(-1, 1, 2), k, d)
        else:
            rays = np.column_stack([xy, np.ones(len(xy))])
            out, _ = cv2.projectPoints(rays, np.zeros(3), np.zeros(3), k, d)
        return np.asarray(out, dtype=float).reshape(-1, 2)

    def distort_jacobians(self, uv: np.ndarray) -> np.ndarray:
        """d(raw pixel) / d(ideal pixel) (N, 2, 2) of :meth:`distort` at ideal pixels
        (N, 2), by central differences over ``JACOBIAN_STEP_PX`` (one call for all).

        Parameters
        ----------
        uv : ndarray, shape (N, 2)
            Ideal pixels.

        Returns
        -------
        ndarray, shape (N, 2, 2)
            Row i: raw coordinate i; column j: ideal coordinate j.
        """
        q = np.asarray(uv, dtype=float).reshape(-1, 2)
        e = JACOBIAN_STEP_PX
        steps = np.array([[e, 0.0], [-e, 0.0], [0.0, e], [0.0, -e]])
        raw = self.distort((q[:, None, :] + steps[None]).reshape(-1, 2)).reshape(-1, 4, 2)
        return np.stack([raw[:, 0] - raw[:, 1], raw[:, 2] - raw[:, 3]], axis=2) / (2 * e)

    def undistort_jacobians(self, uv: np.ndarray) -> np.ndarray:
        """The local scale of the undistortion: d(ideal pixel) / d(raw pixel) (N, 2, 2)
        at raw pixels (N, 2), the inverse of :meth:`distort_jacobians` at their ideal
        pixels; the identity without distortion.

        Parameters
        ----------
        uv : ndarray, shape (N, 2)
            Raw pixels.

        Returns
        -------
        ndarray, shape (N, 2, 2)
            Row i: ideal coordinate i; column j: raw coordinate j (NaN where
            :meth:`undistort` is).
        """
        q = np.asarray(uv, dtype=float).reshape(-1, 2)
        if not self.dist:
            return np.repeat(np.eye(2)[None], len(q), axis=0)
        return self._undistortion_scale(self.undistort(q))

    def _undistortion_scale(self, x: np.ndarray) -> np.ndarray:
        """:meth:`undistort_jacobians` at the ideal pixels ``x`` (N, 2) already found."""
        out = np.full((len(x), 2, 2), np.nan)
        ok = np.all(np.isfinite(x), axis=1)
        j = self.distort_jacobians(x[ok])
        good = np.abs(np.linalg.det(j)) > 1e-12  # the model not folded over here
        out[np.flatnonzero(ok)[good]] = np.linalg.inv(j[good])
        return out

    def ceiling_covariances(self, uv: np.ndarray, sigma_px: float) -> np.ndarray:
        """Base-frame covariances (N, 2, 2) of the ceiling points of raw pixels (N, 2)
        measured with ``sigma_px`` in each raw image coordinate: sigma_px^2 J J^T in
        ideal pixels (J: :meth:`undistort_jacobians`, the undistortion's local scale: a
        pixel near the rim of a wide-angle lens covers more of the ceiling), then (h /
        f)^2 A (...) A^T on the ceiling. Without distortion every one is
        ``metric_sigma(sigma_px)^2 I``.

        Parameters
        ----------
        uv : ndarray, shape (N, 2)
            Raw pixels.
        sigma_px : float
            The detector's standard deviation (px) in the raw image.

        Returns
        -------
        ndarray, shape (N, 2, 2)
        """
        return self._covariances(self.undistort_jacobians(uv), sigma_px)

    def _covariances(self, j: np.ndarray, sigma_px: float) -> np.ndarray:
        """:meth:`ceiling_covariances` of the undistortion's local scales ``j`` (N, 2, 2)."""
        a = np.array(self.axes, dtype=float).reshape(2, 2)
        m = a @ j * (sigma_px * self.height / self.f)
        return m @ np.swapaxes(m, 1, 2)

    def ceiling_measurements(
        self, uv: np.ndarray, sigma_px: float
    ) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`unproject` and :meth:`ceiling_covariances` of raw pixels with the lens'
        distortion undone once for both (a frame's lamps).

        Parameters
        ----------
        uv : ndarray, shape (N, 2)
            Raw pixels.
        sigma_px : float
            The detector's standard deviation (px) in the raw image.

        Returns
        -------
        points : ndarray, shape (N, 2)
            Base-frame ceiling points (NaN where the lens model cannot undo a pixel).
        covs : ndarray, shape (N, 2, 2)
        """
        q = np.asarray(uv, dtype=float).reshape(-1, 2)
        if not self.dist:
            eye = np.repeat(np.eye(2)[None], len(q), axis=0)
            return self._ceiling(q), self._covariances(eye, sigma_px)
        x = self.undistort(q)
        return self._ceiling(x), self._covariances(self._undistortion_scale(x), sigma_px)

    def project(self, pts_robot: np.ndarray) -> np.ndarray:
        """Pixels (N, 2) of ceiling points (N, 2) given in the robot frame (base_link);
        with lens distortion, the raw image's (:meth:`distort`)."""
        p = np.asarray(pts_robot, dtype=float).reshape(-1, 2)
        x = p[:, 0] - self.offset[0]
        y = p[:, 1] - self.offset[1]
        if self.axes != IDENTITY_AXES:  # into the image axes: A^T (A orthogonal)
            a, b, c, d = self.axes
            x, y = a * x + c * y, b * x + d * y
        s = self.f / self.height
        uv = np.column_stack([self.cx + s * x, self.cy + s * y])
        return self.distort(uv) if self.dist else uv

    def unproject(self, uv: np.ndarray) -> np.ndarray:
        """Robot-frame ceiling points (N, 2) of pixels (N, 2); with lens distortion, of
        the raw image's pixels, undistorted first (:meth:`undistort`)."""
        q = np.asarray(uv, dtype=float).reshape(-1, 2)
        return self._ceiling(self.undistort(q) if self.dist else q)

    def _ceiling(self, q: np.ndarray) -> np.ndarray:
        """Robot-frame ceiling points (N, 2) of ideal pinhole pixels ``q`` (N, 2)."""
        s = self.height / self.f
        if self.axes != IDENTITY_AXES:  # the image plane's point, through A
            return (q - np.array([self.cx, self.cy])) * s @ np.array(self.axes).reshape(
                2, 2
            ).T + np.array(self.offset, dtype=float)
        # x = (u - cx) s + offset_x, y = (v - cy) s + offset_y, both columns at once
        return (q - np.array([self.cx, self.cy])) * s + np.array(self.offset, dtype=float)

    def metric_sigma(self, sigma_px: float) -> float:
        """Ceiling-plane standard deviation (m) of a pixel standard deviation (in ideal
        pixels; :meth:`ceiling_covariances` for the raw pixels of a distorting lens)."""
        return sigma_px * self.height / self.f

    def radius_px(self, radius_m: float) -> float:
        """Image radius (px) of a ceiling disc of radius ``radius_m`` (ideal pixels)."""
        return radius_m * self.f / self.height
