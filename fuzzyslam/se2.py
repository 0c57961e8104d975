"""SE(2) toolkit: the one place for planar pose maths and angle wrapping.

A pose is ``(x, y, theta)``: the transform from a child frame to its parent,
``p_parent = R(theta) p_child + t``. Every function accepts a single pose of
shape ``(3,)`` or a stack of shape ``(N, 3)``.

References: J.-L. Blanco, "A tutorial on SE(3) transformation parameterizations
and on-manifold optimization", 2010, sec. 2 (the planar case).
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

Array = NDArray[np.float64]
_TAU = 2.0 * math.pi  # the period of wrap_angle, the same float as 2.0 * np.pi


def wrap_angle(a: ArrayLike) -> Array | float:
    """Wrap angles to the half-open interval (-pi, pi].

    Parameters
    ----------
    a : array_like, shape (...)
        Angles (rad).

    Returns
    -------
    float or ndarray, shape (...)
        The wrapped angles (a float for a scalar).
    """
    if isinstance(a, float):  # one float (np.float64 too): the same floats without numpy
        w = math.pi - (math.pi - float(a)) % _TAU
        return w + _TAU if w <= -math.pi else w
    arr = np.asarray(a, dtype=float)
    w = np.pi - np.mod(np.pi - arr, 2.0 * np.pi)
    # np.mod may round up to the period itself (a just above pi): -pi belongs to pi
    w = np.where(w <= -np.pi, w + 2.0 * np.pi, w)
    if w.ndim == 0:
        return float(w)
    return w


def wrap_angle_period(a: ArrayLike, period: float) -> Array | float:
    """Wrap angles to (-period/2, period/2]; period pi for undirected lines.

    Parameters
    ----------
    a : array_like, shape (...)
        Angles (rad).
    period : float
        The period (rad), e.g. pi or pi/2.

    Returns
    -------
    float or ndarray, shape (...)
        The wrapped angles (a float for a scalar).
    """
    arr = np.asarray(a, dtype=float)
    half = period / 2.0
    w = half - np.mod(half - arr, period)
    w = np.where(w <= -half, w + period, w)  # as in wrap_angle
    if w.ndim == 0:
        return float(w)
    return w


def wrap_angle_scalar(a: float) -> float:
    """:func:`wrap_angle` of one float (the hot loops of the simulator: no array).

    Parameters
    ----------
    a : float
        An angle (rad).

    Returns
    -------
    float
        The angle in (-pi, pi].
    """
    return math.pi - (math.pi - a) % (2.0 * math.pi)


def direction_mod_pi(a: ArrayLike) -> Array | float:
    """The direction of an undirected line, angles taken mod pi into [0, pi).

    Parameters
    ----------
    a : array_like, shape (...)
        Angles (rad).

    Returns
    -------
    float or ndarray, shape (...)
        The directions in [0, pi).
    """
    w = np.mod(a, np.pi)
    return float(w) if np.ndim(w) == 0 else w


def rot(theta: float) -> Array:
    """2x2 rotation matrix R(theta).

    Parameters
    ----------
    theta : float
        The angle (rad).

    Returns
    -------
    ndarray, shape (2, 2)
        [[cos, -sin], [sin, cos]].
    """
    c, s = np.cos(theta), np.sin(theta)
    return np.array([[c, -s], [s, c]])


def compose(a: ArrayLike, b: ArrayLike) -> Array:
    """Pose composition a (+) b: b expressed in a's parent frame.

    Parameters
    ----------
    a, b : array_like, shape (3,) or (N, 3)
        Poses (x, y, theta); stacks compose row by row (or broadcast).

    Returns
    -------
    ndarray, shape (3,) or (N, 3)
        a (+) b, heading wrapped to (-pi, pi].
    """
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
    if a.shape == b.shape == (3,):  # two poses: the same arithmetic on floats (per step)
        return np.array(_compose_floats(a.tolist(), b.tolist()))
    c, s = np.cos(a[..., 2]), np.sin(a[..., 2])
    x = a[..., 0] + c * b[..., 0] - s * b[..., 1]
    y = a[..., 1] + s * b[..., 0] + c * b[..., 1]
    th = wrap_angle(a[..., 2] + b[..., 2])
    return np.stack([x, y, np.asarray(th)], axis=-1)


def inverse(a: ArrayLike) -> Array:
    """Pose inverse (-)a, so that compose(a, inverse(a)) is the identity.

    Parameters
    ----------
    a : array_like, shape (3,) or (N, 3)
        Poses (x, y, theta).

    Returns
    -------
    ndarray, shape (3,) or (N, 3)
        The inverse poses.
    """
    a = np.asarray(a, dtype=float)
    c, s = np.cos(a[..., 2]), np.sin(a[..., 2])
    x = -c * a[..., 0] - s * a[..., 1]
    y = s * a[..., 0] - c * a[..., 1]
    return np.stack([x, y, np.asarray(wrap_angle(-a[..., 2]))], axis=-1)


def between(a: ArrayLike, b: ArrayLike) -> Array:
    """Relative pose (-)a (+) b: b expressed in a's frame.

    Parameters
    ----------
    a, b : array_like, shape (3,) or (N, 3)
        Poses (x, y, theta) in the same parent frame.

    Returns
    -------
    ndarray, shape (3,) or (N, 3)
        b seen from a.
    """
    return compose(inverse(a), b)


def transform_points(pose: ArrayLike, pts: ArrayLike) -> Array:
    """Map points from the pose's child frame into its parent frame: R p + t.

    Parameters
    ----------
    pose : array_like, shape (3,)
        The pose (x, y, theta).
    pts : array_like, shape (N, 2) or (2,)
        Points in the child frame.

    Returns
    -------
    ndarray, shape of ``pts``
        The points in the parent frame.
    """
    pose = np.asarray(pose, dtype=float)
    pts = np.asarray(pts, dtype=float)
    c, s = np.cos(pose[2]), np.sin(pose[2])
    out = np.empty_like(pts)
    out[..., 0] = pose[0] + c * pts[..., 0] - s * pts[..., 1]
    out[..., 1] = pose[1] + s * pts[..., 0] + c * pts[..., 1]
    return out


def inverse_transform_points(pose: ArrayLike, pts: ArrayLike) -> Array:
    """Map points from the parent frame into the pose's child frame: R^T (p - t).

    Parameters
    ----------
    pose : array_like, shape (3,)
        The pose (x, y, theta).
    pts : array_like, shape (N, 2) or (2,)
        Points in the parent frame.

    Returns
    -------
    ndarray, shape of ``pts``
        The points in the child frame.
    """
    pose = np.asarray(pose, dtype=float)
    pts = np.asarray(pts, dtype=float)
    c, s = np.cos(pose[2]), np.sin(pose[2])
    dx = pts[..., 0] - pose[0]
    dy = pts[..., 1] - pose[1]
    out = np.empty_like(pts)
    out[..., 0] = c * dx + s * dy
    out[..., 1] = -s * dx + c * dy
    return out


def _compose_floats(a: list[float], b: list[float]) -> list[float]:
    """a (+) b of two poses given as 3 floats each (:func:`compose`'s arithmetic)."""
    (ax, ay, at), (bx, by, bt) = a, b
    c, s = math.cos(at), math.sin(at)
    return [ax + c * bx - s * by, ay + s * bx + c * by, wrap_angle(at + bt)]


def compose_with_jacobians(a: ArrayLike, b: ArrayLike) -> tuple[Array, Array, Array]:
    """compose(a, b) and jacobians_compose(a, b) of two poses in one call (a prediction
    step needs both: the same floats, half the calls).

    Parameters
    ----------
    a, b : array_like, shape (3,)
        Poses (x, y, theta).

    Returns
    -------
    pose : ndarray, shape (3,)
        a (+) b, heading wrapped to (-pi, pi].
    ja, jb : ndarray, shape (3, 3)
        d(a (+) b)/da and d(a (+) b)/db.
    """
    a = np.asarray(a, dtype=float).tolist()
    b = np.asarray(b, dtype=float).tolist()
    return (np.array(_compose_floats(a, b)), *jacobians_compose(a, b))


def jacobians_compose(a: ArrayLike, b: ArrayLike) -> tuple[Array, Array]:
    """Jacobians of compose(a, b) with respect to a and to b (Blanco 2010, sec. 2).

    Parameters
    ----------
    a, b : array_like, shape (3,)
        Poses (x, y, theta).

    Returns
    -------
    ja, jb : ndarray, shape (3, 3)
        d(a (+) b)/da and d(a (+) b)/db.
    """
    bx, by = float(b[0]), float(b[1])
    at = float(a[2])
    c, s = math.cos(at), math.sin(at)
    ja = np.array(
        [
            [1.0, 0.0, -s * bx - c * by],
            [0.0, 1.0, c * bx - s * by],
            [0.0, 0.0, 1.0],
        ]
    )
    jb = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    return ja, jb


def yaw_to_quaternion(theta: ArrayLike) -> Array:
    """Yaw-only quaternion (qx, qy, qz, qw) for heading theta.

    Parameters
    ----------
    theta : array_like, shape (...)
        Headings (rad).

    Returns
    -------
    ndarray, shape (..., 4)
        (0, 0, sin(theta/2), cos(theta/2)).
    """
    th = np.asarray(theta, dtype=float)
    z = np.zeros_like(th)
    return np.stack([z, z, np.sin(th / 2.0), np.cos(th / 2.0)], axis=-1)


def quaternion_to_yaw(q: ArrayLike) -> Array | float:
    """Yaw (rotation about z) of quaternion(s) (qx, qy, qz, qw).

    Parameters
    ----------
    q : array_like, shape (4,) or (N, 4)
        Quaternions (qx, qy, qz, qw).

    Returns
    -------
    float or ndarray, shape (N,)
        Yaw in (-pi, pi].
    """
    q = np.asarray(q, dtype=float)
    x, y, z, w = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    yaw = np.arctan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))
    return wrap_angle(yaw)


def interpolate_poses(
    t: ArrayLike, poses: ArrayLike, tq: ArrayLike, outside: str = "nan"
) -> Array:
    """Poses at the query times: x, y linear in time, the heading linear on the unwrapped
    heading (the shorter way round the circle between samples), wrapped to (-pi, pi].

    Parameters
    ----------
    t : array_like, shape (N,)
        Increasing sample times.
    poses : array_like, shape (N, 3)
        The poses at ``t``.
    tq : array_like, shape (M,)
        Query times.
    outside : {"nan", "hold"}
        Queries outside [t[0], t[-1]]: NaN rows, or the first / last pose.

    Returns
    -------
    ndarray, shape (M, 3)
        The interpolated poses.
    """
    t = np.asarray(t, dtype=float)
    p = np.asarray(poses, dtype=float).reshape(-1, 3)
    tq = np.asarray(tq, dtype=float).reshape(-1)
    if outside == "hold":
        inside = np.ones(tq.shape, dtype=bool)
    elif outside == "nan":
        inside = (tq >= t[0]) & (tq <= t[-1])
    else:
        raise ValueError(f"outside must be 'nan' or 'hold', not {outside!r}")
    out = np.full((tq.size, 3), np.nan)
    if not inside.any():
        return out
    q = tq[inside]
    out[inside, 0] = np.interp(q, t, p[:, 0])
    out[inside, 1] = np.interp(q, t, p[:, 1])
    out[inside, 2] = np.asarray(wrap_angle(np.interp(q, t, np.unwrap(p[:, 2])))).reshape(-1)
    return out


def interpolate_pose(t: np.ndarray, poses: np.ndarray, tq: float) -> Array:
    """The pose at one time ``tq``, linear between the samples around it (the heading
    difference wrapped); beyond the ends, the end segments continued. The simulator's
    form (one time at a time, each sensor sample; its floats are those its logs were
    recorded with), :func:`interpolate_poses` for arrays of times.

    Parameters
    ----------
    t : ndarray, shape (N,)
        Increasing sample times, N >= 2.
    poses : ndarray, shape (N, 3)
        The poses at ``t``.
    tq : float
        Query time.

    Returns
    -------
    ndarray, shape (3,)
        The interpolated pose.
    """
    i = int(np.clip(np.searchsorted(t, tq, side="right") - 1, 0, len(t) - 2))
    a = (tq - t[i]) / (t[i + 1] - t[i])
    p0, p1 = poses[i], poses[i + 1]
    d = p1 - p0
    d[2] = wrap_angle(d[2])
    out = p0 + a * d
    out[2] = wrap_angle(out[2])
    return out
