"""The tangent-line refinement of the FLM's wall direction (fuzzyslam.maps.tangent)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from maps_synth import cone_ranges, corridor_lines, ring_in_lines, room_lines

from fuzzyslam.maps.flm import RecentRings, build_flm, build_flm_rings
from fuzzyslam.maps.hough import flm_wall_direction
from fuzzyslam.maps.params import MapParams
from fuzzyslam.maps.tangent import fit_walls, predict_ranges, readings_in_frame
from fuzzyslam.robot import sonar_mounts
from fuzzyslam.se2 import between, compose, wrap_angle_period

FOV = np.deg2rad(25.0)
RMAX = 6.5
MOUNTS = sonar_mounts()


def err_deg(a: float, b: float) -> float:
    return float(np.rad2deg(abs(wrap_angle_period(a - b, np.pi))))


def test_model_is_the_nearest_point_of_the_line_in_the_cone():
    """predict_ranges against maps_synth.cone_ranges (a second implementation), and its
    derivative against finite differences."""
    rng = np.random.default_rng(1)
    sensors = np.column_stack(
        [rng.uniform(-0.5, 0.5, 200), rng.uniform(-0.5, 0.5, 200), rng.uniform(-np.pi, np.pi, 200)]
    )
    psi, c = 0.7, 1.3
    line = np.array([[np.cos(psi), np.sin(psi), c]])
    r, dpsi, dc, delta, _p = predict_ranges(psi, c, sensors, FOV / 2)
    ok = delta < np.deg2rad(60)
    want = cone_ranges(sensors, line, FOV / 2, 1e9)
    np.testing.assert_allclose(r[ok], want[ok], rtol=1e-9)
    h = 1e-6
    r2 = predict_ranges(psi + h, c, sensors, FOV / 2)[0]
    r3 = predict_ranges(psi, c + h, sensors, FOV / 2)[0]
    inner = ok & (np.abs(delta - 0.0) > 1e-4)  # away from the kink at the cone's edge
    np.testing.assert_allclose(dpsi[inner], ((r2 - r) / h)[inner], atol=1e-4)
    np.testing.assert_allclose(dc[ok], ((r3 - r) / h)[ok], atol=1e-4)


@pytest.mark.parametrize("heading_deg", [-30.0, -7.0, 0.0, 5.0, 19.0])
def test_noise_free_corridor_ring_gives_the_exact_direction(heading_deg):
    h = np.deg2rad(heading_deg)
    pose = np.array([0.0, 0.15, h])
    lines = corridor_lines(0.0, 1.0)
    r = ring_in_lines(pose, MOUNTS, lines, FOV, RMAX)
    rd = readings_in_frame(np.zeros((1, 3)), r[None], RMAX, FOV, MOUNTS)
    psi_true = np.pi / 2 - h  # the left wall's normal in the robot frame
    fit = fit_walls(rd, psi_true + np.deg2rad(3.0), delta_max=np.pi / 2 - 0.1)
    assert fit.ok
    assert err_deg(fit.psi, psi_true) < 1e-3
    np.testing.assert_allclose(np.sort(fit.offsets), np.sort([0.85, 1.15]), atol=1e-4)


def test_sigma_is_honest_and_outliers_are_rejected():
    """With 1 % noise and 1-inch quantisation (the simulator's), the normalised errors
    (psi - truth) / sigma have unit spread; long 'bounced' readings are left out."""
    rng = np.random.default_rng(7)
    lines = corridor_lines(0.0, 1.0)
    z, rejected = [], 0
    for _ in range(300):
        h = rng.uniform(-0.35, 0.35)
        pose = np.array([0.0, rng.uniform(-0.3, 0.3), h])
        r = ring_in_lines(pose, MOUNTS, lines, FOV, RMAX)
        r = r * (1 + 0.01 * rng.standard_normal(r.size))
        r = np.round(r / 0.0254) * 0.0254
        bounce = rng.integers(0, 16)
        r[bounce] = min(r[bounce] + rng.uniform(0.5, 2.0), RMAX - 0.1)
        rd = readings_in_frame(np.zeros((1, 3)), r[None], RMAX, FOV, MOUNTS)
        truth = np.pi / 2 - h
        fit = fit_walls(rd, truth + rng.normal(0, np.deg2rad(2.0)), delta_max=np.deg2rad(40.0))
        if not fit.ok:
            continue
        z.append(wrap_angle_period(fit.psi - truth, np.pi) / fit.sigma)
        idx = np.flatnonzero(np.isfinite(r) & (r < RMAX - 1e-6)).tolist().index(bounce)
        rejected += not fit.inliers[idx]
    z = np.array(z)
    assert len(z) > 250
    assert 0.75 < np.std(z) < 1.3, np.std(z)
    assert abs(np.mean(z)) < 0.2
    assert rejected >= 0.95 * len(z)


def test_tangent_refinement_beats_the_hough_peak():
    """FLM of noisy analytic rings in a 2 m corridor: the refined direction is closer to
    the truth than the Hough peak alone (the paper's method), and reports a sigma."""
    rng = np.random.default_rng(3)
    hough = dataclasses.replace(MapParams(), flm_refine="hough")
    tang = MapParams(tangent_max_incidence_deg=80.0)  # analytic walls: no critical angle
    eh, et = [], []
    for _ in range(40):
        h = rng.uniform(-0.3, 0.3)
        r = ring_in_lines(
            np.array([0.0, rng.uniform(-0.3, 0.3), h]), MOUNTS, corridor_lines(0.0, 1.0), FOV, RMAX
        )
        r = np.round(r * (1 + 0.01 * rng.standard_normal(r.size)) / 0.0254) * 0.0254
        flm = build_flm(r, RMAX, FOV, MOUNTS, tang)
        a = flm_wall_direction(flm, hough)
        b = flm_wall_direction(flm, tang)
        assert a.method == "hough" and np.isnan(a.sigma)
        if b.method == "tangent":
            assert np.isfinite(b.sigma) and b.inliers >= 3
        eh.append(err_deg(a.angle, -h))
        et.append(err_deg(b.angle, -h))
    assert np.mean(et) < 0.7 * np.mean(eh), (np.mean(et), np.mean(eh))


def test_several_rings_are_fitted_jointly():
    """build_flm_rings keeps every ring's echoes (placed by the relative poses); the joint
    fit of 8 noisy rings is better than one ring's on average."""
    rng = np.random.default_rng(11)
    params = MapParams()
    lines = corridor_lines(0.0, 1.0)
    e1, e8 = [], []
    for _ in range(15):
        h0 = rng.uniform(-0.2, 0.2)
        path = np.array(
            [[0.1 * k, 0.1 * np.sin(0.4 * k), h0 + 0.02 * np.sin(0.5 * k)] for k in range(8)]
        )
        rings = np.array([ring_in_lines(p, MOUNTS, lines, FOV, RMAX) for p in path])
        rings = np.round(rings * (1 + 0.01 * rng.standard_normal(rings.shape)) / 0.0254) * 0.0254
        rel = between(path[-1], path)
        flm8 = build_flm_rings(rel, rings, RMAX, FOV, MOUNTS, params)
        n_echo = int((rings < RMAX - 1e-6).sum())
        assert len(flm8.readings) == n_echo
        np.testing.assert_allclose(
            flm8.readings.sensors[:16],
            compose(np.repeat(rel[:1], 16, 0), MOUNTS)[rings[0] < RMAX - 1e-6][:16],
            atol=1e-12,
        )
        w8 = flm_wall_direction(flm8, params)
        w1 = flm_wall_direction(build_flm(rings[-1], RMAX, FOV, MOUNTS, params), params)
        e8.append(err_deg(w8.angle, -path[-1, 2]))
        e1.append(err_deg(w1.angle, -path[-1, 2]))
    assert np.mean(e8) < 0.6 * np.mean(e1), (np.mean(e8), np.mean(e1))
    assert np.mean(e8) < 0.5


def test_corner_is_ambiguous_and_corridor_is_not():
    """In a room's corner (two perpendicular walls at equal distances) the ring is flagged
    ambiguous; in the middle of a straight corridor it is not."""
    params = MapParams()
    corner = ring_in_lines(
        np.array([0.9, 0.9, np.deg2rad(-135.0)]), MOUNTS, room_lines(0.0, 0.0, 6.0, 4.0), FOV, RMAX
    )
    wc = flm_wall_direction(build_flm(corner, RMAX, FOV, MOUNTS, params), params)
    assert wc.ambiguous
    straight = ring_in_lines(np.array([0.0, 0.1, 0.1]), MOUNTS, corridor_lines(0.0, 1.0), FOV, RMAX)
    ws = flm_wall_direction(build_flm(straight, RMAX, FOV, MOUNTS, params), params)
    assert not ws.ambiguous and ws.method == "tangent"


def test_recent_rings_window():
    """RecentRings keeps the last `count` rings within `window` s and builds the same FLM
    as build_flm_rings with the relative poses; time going back starts afresh."""
    params = MapParams()
    lines = corridor_lines(0.0, 1.0)
    path = np.array([[0.08 * k, 0.05, 0.1 + 0.01 * k] for k in range(10)])
    rings = np.array([ring_in_lines(p, MOUNTS, lines, FOV, RMAX) for p in path])
    rr = RecentRings(count=8, window=10.0)
    for k in range(10):
        rr.push(0.25 * k, path[k], rings[k], RMAX, FOV)
    assert len(rr) == 8
    want = build_flm_rings(between(path[-1], path[2:]), rings[2:], RMAX, FOV, MOUNTS, params)
    got = rr.flm(MOUNTS, params)
    np.testing.assert_array_equal(got.m_o, want.m_o)
    np.testing.assert_allclose(got.readings.sensors, want.readings.sensors, atol=1e-12)
    short = RecentRings(count=8, window=0.6)
    for k in range(10):
        short.push(0.25 * k, path[k], rings[k], RMAX, FOV)
    assert len(short) == 3  # 1.75, 2.0, 2.25 s
    short.push(0.0, path[0], rings[0], RMAX, FOV)
    assert len(short) == 1


def test_multi_ring_flm_at_a_corridor_end_is_ambiguous():
    """8 rings approaching the end wall of a 2 m corridor (to 0.5 m from it): the end
    wall's echoes (the other direction) flag the FLM ambiguous; mid-corridor they do not."""
    params = MapParams()
    lines = room_lines(-10.0, 0.0, 6.0, 2.0)  # a 2 m wide corridor closed at x = 6
    h = np.deg2rad(3.0)

    def flm_at(x_end: float):
        path = np.array([[x_end - 0.6 + 0.075 * k, 1.05, h] for k in range(9)])
        rings = np.array([ring_in_lines(p, MOUNTS, lines, FOV, RMAX) for p in path])
        return flm_wall_direction(
            build_flm_rings(between(path[-1], path), rings, RMAX, FOV, MOUNTS, params), params
        )

    end = flm_at(5.5)
    assert end.ambiguous
    mid = flm_at(0.0)
    assert not mid.ambiguous and mid.method == "tangent"
    assert err_deg(mid.angle, -h) < 0.05  # noise-free rings: the exact direction
