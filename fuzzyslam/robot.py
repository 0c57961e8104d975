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
    """(N+1, 3) dead-reckoning poses from ``start`` and N increments (vectorised)."""
    d_trans = np.asarray(d_trans, dtype=float)
    d_rot = np.asarray(d_rot, dtype=float)
    theta = start[2] + np.concatenate([[0.0], np.cumsum(d_rot)])
    th_mid = theta[:-1] + 0.5 * d_rot
    x = start[0] + np.concatenate([[0.0], np.cumsum(d_trans * np.cos(th_mid))])
    y = start[1] + np.concatenate([[0.0], np.cumsum(d_trans * np.sin(th_mid))])
    return np.column_stack([x, y, wrap_angle(theta)])
