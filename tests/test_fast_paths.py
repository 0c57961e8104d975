"""The speed paths give the same floats as the general ones (outputs stay byte-identical).

Each test compares a fast path with a second implementation, bit for bit:
``se2.compose`` / ``wrap_angle`` on one pose or float against the array path,
``hough_accumulator`` (cached angle table, shifted second bincount) against the plain
accumulator (np.average centroid, clipped bins), ``EkfSlam.lamp_covs`` (a block view)
against fancy indexing of P.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from fuzzyslam import se2
from fuzzyslam.maps.hough import hough_accumulator
from fuzzyslam.slam.ekf import EkfSlam


def test_compose_one_pose_equals_stacked():
    rng = np.random.default_rng(3)
    a = rng.normal(size=(500, 3)) * [5.0, 5.0, 4.0]
    b = rng.normal(size=(500, 3)) * [1.0, 1.0, 4.0]
    stacked = se2.compose(a, b)
    one = np.array([se2.compose(a[k], b[k]) for k in range(len(a))])
    assert np.array_equal(one, stacked)
    ja, jb = se2.jacobians_compose(a[0], b[0])
    c, s = np.cos(a[0, 2]), np.sin(a[0, 2])
    assert np.array_equal(ja[:2, 2], [-s * b[0, 0] - c * b[0, 1], c * b[0, 0] - s * b[0, 1]])
    assert np.array_equal(jb[:2, :2], [[c, -s], [s, c]])


def test_wrap_angle_float_equals_array():
    rng = np.random.default_rng(4)
    edges = [math.pi, -math.pi, 3 * math.pi, -3 * math.pi, 0.0, 2 * math.pi, 1e-300]
    edges += [np.nextafter(math.pi, 4.0), np.nextafter(-math.pi, -4.0)]
    x = np.concatenate([rng.uniform(-30.0, 30.0, 20000), edges])
    arr = se2.wrap_angle(x)
    one = np.array([se2.wrap_angle(float(v)) for v in x])
    assert np.array_equal(one, arr)
    assert np.array_equal([se2.wrap_angle(v) for v in x], arr)  # np.float64 items
    assert all(-math.pi < v <= math.pi for v in one)


def _plain_accumulator(x, y, w, theta_step, rho_step):
    """The accumulator written out plainly: np.average centroid, bins clipped to the
    plane, one bincount per tent side."""
    thetas = np.arange(0.0, np.pi, theta_step)
    if w.sum() > 0:
        centre = np.array([np.average(x, weights=w), np.average(y, weights=w)])
    else:
        centre = np.zeros(2)
    xc, yc = x - centre[0], y - centre[1]
    rmax = float(np.max(np.hypot(xc, yc))) + 2 * rho_step if len(x) else rho_step
    nr = int(np.ceil(2 * rmax / rho_step)) + 1
    r = xc[:, None] * np.cos(thetas)[None, :] + yc[:, None] * np.sin(thetas)[None, :] + rmax
    u = r / rho_step
    i0 = np.floor(u).astype(np.int64)
    f = u - i0
    nt = len(thetas)
    cols = np.broadcast_to(np.arange(nt), i0.shape)
    ww = np.broadcast_to(w[:, None], i0.shape)
    i0c, i1c = np.clip(i0, 0, nr - 1), np.clip(i0 + 1, 0, nr - 1)
    acc = np.bincount((i0c * nt + cols).ravel(), weights=(ww * (1 - f)).ravel(), minlength=nr * nt)
    acc += np.bincount((i1c * nt + cols).ravel(), weights=(ww * f).ravel(), minlength=nr * nt)
    return acc.reshape(nr, nt), centre


@pytest.mark.parametrize("n", [0, 1, 3, 40, 400])
def test_hough_accumulator_equals_plain(n):
    rng = np.random.default_rng(n)
    x, y = rng.normal(size=n) * 2.0, rng.normal(size=n) * 2.0
    for w in (rng.uniform(0.0, 1.0, n), np.zeros(n)):
        for theta_step, rho_step in ((np.deg2rad(0.5), 0.1), (np.deg2rad(2.0), 0.05)):
            plane = hough_accumulator(x, y, w, theta_step, rho_step)
            acc, centre = _plain_accumulator(x, y, w, theta_step, rho_step)
            assert np.array_equal(plane.acc, acc)
            assert np.array_equal(plane.centre, centre)


def test_lamp_covs_equals_fancy_indexing():
    rng = np.random.default_rng(5)
    ekf = EkfSlam([0.0, 0.0, 0.1], np.eye(3) * 1e-3, (1e-4, 1e-5, 1e-4, 1e-5), capacity=2)
    assert ekf.lamp_covs().shape == (0, 2, 2)
    for _ in range(9):  # grows past the capacity: P is a view of a larger array
        ekf.add_lamp(rng.normal(size=2), np.eye(2) * 1e-3)
        ekf.predict(0.2, 0.05)
    ekf.update_lamps([1, 4], ekf.predict_lamps([1, 4])[0] + 0.01, np.eye(4) * 1e-3)
    idx = ekf.m0 + 2 * np.arange(ekf.n_lamps)
    rows = idx[:, None, None] + np.array([0, 1])[None, :, None]
    cols = idx[:, None, None] + np.array([0, 1])[None, None, :]
    assert np.array_equal(ekf.lamp_covs(), ekf.P[rows, cols])
