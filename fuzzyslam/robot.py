"""Robot geometry and odometry shared by the simulator and the filter.

- Sonar mounts: sensor i sits on the rim (radius r) at bearing i * 360/N deg,
  facing outward; frames ``sonar_00`` .. in ``base_link``.
- Wheel encoders: a differential pair of wheel angles (rad). Increments give the
  odometry increment (d_trans, d_rot) with the *nominal* wheel radius and base;
  the simulator's true wheels differ by the configured systematic scale errors.
- Dead reckoning integrates increments with the midpoint (second-order) rule.

Reference: Thrun, Burgard, Fox, Probabilistic Robotics (2005), sec. 5.4.
"""

from __future__ import annotations

import numpy as np

from fuzzyslam.se2 import wrap_angle

WHEEL_NAMES = ("wheel_left_joint", "wheel_right_joint")


def sonar_frame(i: int) -> str:
    return f"sonar_{i:02d}"


def sonar_mounts(count: int = 16, radius: float = 0.225) -> np.ndarray:
    """(count, 3) mount poses (x, y, yaw) of the sonar ring in base_link."""
    yaw = np.arange(count) * (2.0 * np.pi / count)
    return np.column_stack([radius * np.cos(yaw), radius * np.sin(yaw), wrap_angle(yaw)])


def wheel_increments_to_odometry(
    d_left: np.ndarray, d_right: np.ndarray, wheel_radius: float, wheel_base: float
) -> tuple[np.ndarray, np.ndarray]:
    """Odometry increments (d_trans, d_rot) of wheel angle increments (rad).

    d_trans = r (dL + dR) / 2,   d_rot = r (dR - dL) / b.
    """
    dl = np.asarray(d_left, dtype=float) * wheel_radius
    dr = np.asarray(d_right, dtype=float) * wheel_radius
    return 0.5 * (dl + dr), (dr - dl) / wheel_base


def odometry_to_wheel_increments(
    d_trans: np.ndarray, d_rot: np.ndarray, wheel_radius: float, wheel_base: float
) -> tuple[np.ndarray, np.ndarray]:
    """Inverse of wheel_increments_to_odometry: wheel angle increments (rad)."""
    dt = np.asarray(d_trans, dtype=float)
    dr = np.asarray(d_rot, dtype=float)
    half = 0.5 * wheel_base * dr
    return (dt - half) / wheel_radius, (dt + half) / wheel_radius


def motion_step(pose: np.ndarray, d_trans: float, d_rot: float) -> np.ndarray:
    """Pose after an odometry increment, midpoint rule:

    x' = x + d_trans cos(theta + d_rot/2), y' = y + d_trans sin(theta + d_rot/2),
    theta' = wrap(theta + d_rot).
    """
    th_mid = pose[2] + 0.5 * d_rot
    return np.array(
        [
            pose[0] + d_trans * np.cos(th_mid),
            pose[1] + d_trans * np.sin(th_mid),
            wrap_angle(pose[2] + d_rot),
        ]
    )


def integrate(start: np.ndarray, d_trans: np.ndarray, d_rot: np.ndarray) -> np.ndarray:
    """Dead-reckoning poses from ``start`` and N increments (vectorised midpoint rule).

    Parameters
    ----------
    start : ndarray, shape (3,)
        Start pose (x, y, theta).
    d_trans, d_rot : ndarray, shape (N,)
        Odometry increments (m, rad).

    Returns
    -------
    ndarray, shape (N + 1, 3)
        The start pose, then the pose after each increment.
    """
    return integrate_from(start, d_trans, d_rot)[0]


def integrate_from(
    start: np.ndarray,
    d_trans: np.ndarray,
    d_rot: np.ndarray,
    sums: tuple[float, float, float] = (0.0, 0.0, 0.0),
) -> tuple[np.ndarray, tuple[float, float, float]]:
    """:func:`integrate` continued from a previous block of increments, for a stream
    integrated block by block: the running sums of d_rot, dx and dy are carried over
    (cumulative sums are sequential, so the floats are those of one whole call).

    Parameters
    ----------
    start : ndarray, shape (3,)
        Start pose of the whole stream (x, y, theta).
    d_trans, d_rot : ndarray, shape (N,)
        This block's increments (m, rad).
    sums : tuple of float
        The running sums (d_rot, dx, dy) at the end of the previous block (zeros for
        the first block).

    Returns
    -------
    poses : ndarray, shape (N + 1, 3)
        The pose at the end of the previous block (the start pose for the first), then
        the pose after each increment.
    sums : tuple of float
        The running sums after this block (the next block's ``sums``).
    """
    d_trans = np.asarray(d_trans, dtype=float)
    d_rot = np.asarray(d_rot, dtype=float)
    rot = np.cumsum(np.concatenate([[sums[0]], d_rot]))
    theta = start[2] + rot
    th_mid = theta[:-1] + 0.5 * d_rot
    x = np.cumsum(np.concatenate([[sums[1]], d_trans * np.cos(th_mid)]))
    y = np.cumsum(np.concatenate([[sums[2]], d_trans * np.sin(th_mid)]))
    poses = np.column_stack([start[0] + x, start[1] + y, wrap_angle(theta)])
    return poses, (float(rot[-1]), float(x[-1]), float(y[-1]))
