"""Wheel encoders with systematic and random errors, and the odometry they give (pure).

The true wheels differ from the nominal ones the filter knows: true radii are
r_L = r * left_scale, r_R = r * right_scale and the true base b * base_scale. For a
true motion increment (d_trans, d_rot) the wheels turn by

    phi_L = (d_trans - b_true d_rot / 2) / r_L,   phi_R = (d_trans + b_true d_rot / 2) / r_R,

each read with random error  phi~ = phi + N(0, (sigma_w^2) |phi|)  (slip and
backlash grow with the angle turned: a random walk of sigma_w rad per sqrt(rad)),
accumulated and quantised to whole ticks of 2 pi / ticks_per_rev. Odometry is then
computed from the tick-quantised angles with the NOMINAL radius and base
(fuzzyslam.robot.wheel_increments_to_odometry), and dead reckoning integrates it
(fuzzyslam.robot.integrate) - the systematic errors make it drift, as in the
paper's Fig. 1a.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fuzzyslam.robot import integrate, odometry_to_wheel_increments, wheel_increments_to_odometry
from fuzzyslam.sim.params import RobotParams


@dataclass
class Encoders:
    """Encoder readings at every robot step and the dead reckoning they give.

    angles (N+1, 2): cumulative quantised wheel angles (left, right), rad, from 0;
    d_trans, d_rot (N,): nominal odometry increments; dead_reckoning (N+1, 3).
    """

    angles: np.ndarray
    d_trans: np.ndarray
    d_rot: np.ndarray
    dead_reckoning: np.ndarray


def true_wheel_increments(
    d_trans: np.ndarray, d_rot: np.ndarray, robot: RobotParams
) -> tuple[np.ndarray, np.ndarray]:
    """Wheel angle increments (rad) of the TRUE wheels for true motion increments.

    Parameters
    ----------
    d_trans : ndarray, shape (N,)
        True translation increments (m).
    d_rot : ndarray, shape (N,)
        True rotation increments (rad).
    robot : RobotParams
        The true wheel radii and base.

    Returns
    -------
    left, right : ndarray, shape (N,)
        Wheel angle increments (rad).
    """
    dl, dr = odometry_to_wheel_increments(
        d_trans, d_rot, wheel_radius=1.0, wheel_base=robot.wheel_base * robot.base_scale
    )
    return (
        dl / (robot.wheel_radius * robot.left_scale),
        dr / (robot.wheel_radius * robot.right_scale),
    )


def noisy_increments(phi: np.ndarray, sigma: float, rng: np.random.Generator) -> np.ndarray:
    """phi + N(0, sigma^2 |phi|): random encoder error growing with the angle turned.

    Parameters
    ----------
    phi : ndarray, shape (N,)
        Wheel angle increments (rad).
    sigma : float
        sigma_w (rad per sqrt(rad)).
    rng : numpy.random.Generator
        The encoders' random stream.

    Returns
    -------
    ndarray, shape (N,)
    """
    phi = np.asarray(phi, dtype=float)
    return phi + sigma * np.sqrt(np.abs(phi)) * rng.standard_normal(phi.shape)


def quantise(angles: np.ndarray, ticks_per_rev: int) -> np.ndarray:
    """Angles rounded to whole encoder ticks.

    Parameters
    ----------
    angles : ndarray, shape (...)
        Angles (rad).
    ticks_per_rev : int
        Encoder ticks per revolution.

    Returns
    -------
    ndarray, shape (...)
    """
    tick = 2.0 * np.pi / ticks_per_rev
    return np.round(np.asarray(angles) / tick) * tick


def simulate_encoders(
    d_trans: np.ndarray,
    d_rot: np.ndarray,
    robot: RobotParams,
    start: np.ndarray,
    rng: np.random.Generator,
) -> Encoders:
    """Encoder readings and dead reckoning for the true increments of a drive.

    Parameters
    ----------
    d_trans : ndarray, shape (N,)
        True translation increments (m).
    d_rot : ndarray, shape (N,)
        True rotation increments (rad).
    robot : RobotParams
        True and nominal wheels, noise, ticks.
    start : ndarray, shape (3,)
        The start pose (dead reckoning's origin).
    rng : numpy.random.Generator
        The encoders' random stream.

    Returns
    -------
    Encoders
        Angles (N+1, 2), nominal increments (N,), dead reckoning (N+1, 3).
    """
    phi_l, phi_r = true_wheel_increments(d_trans, d_rot, robot)
    noisy = noisy_increments(np.column_stack([phi_l, phi_r]), robot.wheel_noise, rng)
    angles = quantise(np.vstack([np.zeros((1, 2)), np.cumsum(noisy, axis=0)]), robot.ticks_per_rev)
    inc = np.diff(angles, axis=0)
    od_t, od_r = wheel_increments_to_odometry(
        inc[:, 0], inc[:, 1], robot.wheel_radius, robot.wheel_base
    )
    return Encoders(angles, od_t, od_r, integrate(np.asarray(start, float), od_t, od_r))
