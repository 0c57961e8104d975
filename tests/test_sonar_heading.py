"""Sonar heading fixes on real buildings (issue 13): windows in metres of travel
(``RecentRings(distance=)``, ``fixes.flm_window_m`` / ``flm_fix_travel``), the wall
fit's Birge ratio (``maps.tangent.fit_walls``) and R from a window's own fit
(``fixes.flm_fit_scatter``), against the real filter (EkfSlam), the maps stage's
multi-ring FLM and analytic sonar rings in a corridor (tests/maps_synth.py)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from maps_synth import cone_ranges

# the corridor, its reference and its analytic rings: the multi-ring window's own tests'
from test_multi_ring import ANGLE, DEG, FOV, MAXR, MOUNTS, MP, corridor_ref, ring_at

from fuzzyslam.fixes.heading_measure import HeadingDecision
from fuzzyslam.fixes.multi_ring import MultiRingWindow
from fuzzyslam.fixes.params import FixParams
from fuzzyslam.maps.flm import RecentRings
from fuzzyslam.maps.hough import flm_wall_direction
from fuzzyslam.maps.tangent import RingReadings, fit_walls
from fuzzyslam.se2 import compose, rot
from fuzzyslam.slam.ekf import EkfSlam


def test_recent_rings_keep_the_last_metres_of_travel():
    """With ``distance`` the window holds the rings within that much travel of the
    newest: poses 0.5 m apart, 2 m -> the newest 5 (span exactly 2 m); travel is the path
    through the poses, not the chord (a U-turn of 4 x 0.5 m spans 2 m, not 1 m)."""
    rr = RecentRings(count=100, window=1e9, distance=2.0)
    r = np.full(16, 1.0)
    for k in range(11):
        rr.push(float(k), np.array([0.5 * k, 0.0, 0.0]), r, MAXR, FOV)
    assert len(rr) == 5
    assert rr.span == pytest.approx(2.0)
    np.testing.assert_allclose(np.array(rr._poses)[:, 0], [3.0, 3.5, 4.0, 4.5, 5.0])
    u = RecentRings(count=100, window=1e9, distance=1.9)
    for k, xy in enumerate([(0, 0), (0.5, 0), (0.5, 0.5), (0, 0.5), (0, 1.0)]):
        u.push(float(k), np.array([*xy, 0.0]), r, MAXR, FOV)
    assert len(u) == 4  # 2 m of path > 1.9: the first dropped, though its chord is 1 m
    assert u.span == pytest.approx(1.5)
    # without a distance the count and the time bound as before
    c = RecentRings(count=3, window=1e9)
    for k in range(11):
        c.push(float(k), np.array([0.5 * k, 0.0, 0.0]), r, MAXR, FOV)
    assert len(c) == 3 and c.span == pytest.approx(1.0)


def walk(params: FixParams, steps: int, step: float = 0.1, heading_error_deg: float = 1.0):
    """The robot drives along the corridor (one ring per ``step`` m); the real EkfSlam
    starts ``heading_error_deg`` off, P_tt = (3 deg)^2, and predicts each step exactly;
    the window's decisions are applied with ``update_robot`` as the aid does."""
    true = np.array([*(rot(ANGLE) @ [-5.0, 0.1]), ANGLE])
    ekf = EkfSlam(
        true + np.array([0.0, 0.0, heading_error_deg * DEG]),
        np.diag([1e-4, 1e-4, (3 * DEG) ** 2]),
        (0.0, 0.0, 0.0, 0.0),
    )
    win = MultiRingWindow(
        params, lambda recent, mounts: recent.flm(mounts, MP), lambda f: flm_wall_direction(f, MP)
    )
    refs = [corridor_ref()]
    formed, spans = [], []
    q = np.diag([1e-8, 1e-8, 1e-8])
    none = HeadingDecision(0.0, -1, math.nan, 0.0, False, "no_wall", math.nan)
    for j in range(steps):
        true = compose(true, [step, 0.0, 0.0])
        ekf.predict_relative(np.array([step, 0.0, 0.0]), q)
        win.push(float(j), ring_at(true), ekf)
        before = win.formed
        d = win.decide(float(j), none, refs, MOUNTS, ekf)
        if win.formed > before:
            formed.append((j, d))
            spans.append(win.recent.span)
            if d.accepted:
                ekf.update_robot([d.measured], [[d.sigma**2]], [2], gate_chi2=params.gate_chi2)
    return ekf, formed, spans, true


def test_fixes_every_metre_of_travel_with_the_overlap_inflation():
    """``flm_fix_travel`` 0.45 m on rings 0.1 m apart: a fix every 5th ring (0.5 m of
    dead-reckoned travel) whatever ``flm_fix_every`` says, windows of at most
    ``flm_window_m`` 1 m, R = sigma_flm^2 * 1 / 0.45 (the overlap of 1 m windows formed
    every 0.45 m); the heading converges to the truth."""
    p = FixParams(
        flm_rings=64, flm_window_s=1e3, flm_window_m=1.0, flm_fix_travel=0.45,
        flm_fix_every=1, flm_fit_sigma=False, sigma_flm_deg=0.5,
    )  # fmt: skip
    ekf, formed, spans, true = walk(p, 41)
    assert [j for j, _ in formed] == [5, 10, 15, 20, 25, 30, 35, 40]
    assert max(spans) <= 1.0 + 1e-9 and min(spans[1:]) >= 0.9 - 1e-9
    want = math.radians(0.5 * math.sqrt(1.0 / 0.45))
    ok = [d for _, d in formed if d.reason == "ok"]
    assert len(ok) >= 6
    for d in ok:
        assert d.sigma == pytest.approx(want, rel=1e-12)
    assert abs(math.degrees(ekf.pose[2] - true[2])) < 0.3
    # flm_window_m 0: the ring-based rule (every flm_fix_every rings) as before
    p0 = FixParams(flm_rings=4, flm_window_s=1e3, flm_fix_travel=0.45, flm_fix_every=3)
    _, formed0, _, _ = walk(p0, 13)
    assert [j for j, _ in formed0] == [2, 5, 8, 11]


def _wall_readings(n: int, noise: float, rng: np.random.Generator) -> tuple[RingReadings, float]:
    """``n`` echoes of the wall y = 2 (normal +y) from sensors scattered along the x axis
    facing it within their cone, ranges with Gaussian noise of ``noise`` m."""
    x = rng.uniform(-3.0, 3.0, n)
    axis = np.pi / 2 + rng.uniform(-0.15, 0.15, n)
    sensors = np.column_stack([x, rng.uniform(-0.5, 0.5, n), axis])
    half = 12.5 * DEG
    r = cone_ranges(sensors, np.array([[0.0, 1.0, 2.0]]), half, 100.0)
    return RingReadings(sensors, r + rng.normal(0.0, noise, n), half), half


@pytest.mark.parametrize("factor", [1.0, 3.0])
def test_birge_ratio_measures_the_scatter_against_the_noise_model(factor):
    """The fit's Birge ratio sqrt(chi^2 / dof) is the ratio of the ranges' actual noise to
    the model's: 1 when the model is right, 3 when the wall scatters 3 times more
    (400 echoes: its standard error is about 1 / sqrt(2 * 400) = 3.5 %)."""
    model = 0.01  # m: the fit's sigma, as the quantum's q / sqrt(12)
    rd, _ = _wall_readings(400, factor * model, np.random.default_rng(7))
    fit = fit_walls(
        rd, np.pi / 2 + 0.01, sigma_frac=0.0, quantum=model * math.sqrt(12.0), tolerance=0.5,
        walls=(0.0,), iterations=6,
    )  # fmt: skip
    assert fit.ok and abs(fit.psi - np.pi / 2) < 3 * max(fit.sigma * factor, 1e-4)
    assert fit.birge == pytest.approx(factor, rel=0.12)


class _Wall:
    """A wall direction as the FLM's Hough + tangent fit gives it (angle in the robot
    frame, its fit's sigma and Birge ratio)."""

    def __init__(self, angle: float, sigma: float, birge: float) -> None:
        self.angle, self.sigma, self.birge = angle, sigma, birge
        self.strength, self.ambiguous = 5.0, False


@pytest.mark.parametrize(
    ("sigma_deg", "birge", "rings"), [(0.05, 2.0, 4), (0.02, 1.0, 9), (0.2, 1.5, 4), (0.3, 0.5, 9)]
)
def test_scatter_rule_weights_and_refuses_by_the_fit(sigma_deg, birge, rings):
    """``flm_fit_scatter``: q = sigma_fit max(1, Birge) sqrt(K); no fix (loose_fit) when
    q > ``flm_fit_max_deg``, else sigma = max(sigma_flm, scale q) times the overlap
    inflation sqrt(flm_window_m / flm_fix_travel), here 2."""
    p = FixParams(
        flm_rings=64, flm_window_s=1e3, flm_window_m=4.0, flm_fix_travel=1.0,
        flm_fit_scatter=True, flm_fit_scale=2.0, flm_fit_max_deg=1.0, sigma_flm_deg=0.3,
    )  # fmt: skip
    heading = ANGLE + 0.2 * DEG
    wall = _Wall(ANGLE - heading, math.radians(sigma_deg), birge)
    win = MultiRingWindow(p, lambda recent, mounts: None, lambda flm: wall)
    pose = np.array([*(rot(ANGLE) @ [0.0, 0.1]), heading])
    ekf = EkfSlam(pose, np.diag([1e-4, 1e-4, (2 * DEG) ** 2]), (0.0, 0.0, 0.0, 0.0))
    for k in range(rings):
        win.push(float(k), ring_at(pose), ekf)
        ekf.predict_relative(np.array([0.4, 0.0, 0.0]), np.zeros((3, 3)))
    single = HeadingDecision(float(rings), 0, heading, heading, True, "ok", 5.0)
    d = win.decide(float(rings), single, [corridor_ref()], MOUNTS, ekf)
    q = sigma_deg * max(1.0, birge) * math.sqrt(rings)
    if q > 1.0:
        assert (d.reason, d.accepted) == ("loose_fit", False)
        assert math.isnan(d.measured)
        return
    assert d.reason == "ok" and d.accepted
    assert d.sigma == pytest.approx(math.radians(2.0 * max(0.3, 2.0 * q)), rel=1e-12)
    assert d.measured == pytest.approx(heading, abs=1e-9)  # t_ref - t_local
