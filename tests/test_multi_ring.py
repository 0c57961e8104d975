"""The heading aid's multi-ring window (fuzzyslam/fixes/multi_ring.py) against the real
filter (EkfSlam), the maps stage's multi-ring FLM (RecentRings.flm) and its Hough/tangent
wall direction, on analytic sonar rings in a corridor (tests/maps_synth.py)."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest
from maps_synth import corridor_lines, ring_in_lines

from fuzzyslam.fixes.heading_measure import decide_heading_fix
from fuzzyslam.fixes.multi_ring import MultiRingWindow
from fuzzyslam.fixes.params import FixParams
from fuzzyslam.fixes.references import Reference
from fuzzyslam.maps.flm import build_flm
from fuzzyslam.maps.hough import flm_wall_direction
from fuzzyslam.maps.params import MapParams
from fuzzyslam.robot import sonar_mounts
from fuzzyslam.se2 import compose, rot, wrap_angle
from fuzzyslam.slam.ekf import EkfSlam

DEG = math.pi / 180.0
FOV, MAXR = 25 * DEG, 6.5
MOUNTS = sonar_mounts(16, 0.225)
MP = MapParams()
ANGLE = 0.3  # the corridor's direction (rad)
LINES = corridor_lines(ANGLE, 1.0)
STEP = np.array([0.1, 0.0, 0.0])  # one ring per 0.1 m straight ahead


def corridor_ref() -> Reference:
    box = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]]) * [20.0, 1.0]
    return Reference(0, "c0", ANGLE, 1.0, box @ rot(ANGLE).T)


def ring_at(pose) -> SimpleNamespace:
    ranges = ring_in_lines(np.asarray(pose, float), MOUNTS, LINES, FOV, MAXR)
    return SimpleNamespace(ranges=ranges, max_range=np.full(16, MAXR), fov=FOV)


def walk(params: FixParams, rings: int, wall_direction=None, heading_error_deg=2.0):
    """The robot drives along the corridor; the filter (real EkfSlam, no lamps) starts
    ``heading_error_deg`` off with P_tt = (3 deg)^2 and predicts each step exactly (the
    dead reckoning is exact up to the start error); every ring's single-ring decision is
    remembered, the window's decision applied with ``update_robot`` as the aid does.
    Returns the window, the filter, the decisions, the window's poses at each formed fix
    and the poses the dead reckoning should give (composed here)."""
    true = np.array([*(rot(ANGLE) @ [-5.0, 0.1]), ANGLE])
    start = true + np.array([0.0, 0.0, heading_error_deg * DEG])
    ekf = EkfSlam(start, np.diag([1e-4, 1e-4, (3 * DEG) ** 2]), (0.0, 0.0, 0.0, 0.0))
    wall_direction = wall_direction or (lambda flm: flm_wall_direction(flm, MP))
    win = MultiRingWindow(params, lambda recent, mounts: recent.flm(mounts, MP), wall_direction)
    refs = [corridor_ref()]
    decisions, at_fix, odo = [], [], [start]
    q = np.diag([1e-8, 1e-8, 1e-8])
    for j in range(rings):
        true = compose(true, STEP)
        ekf.predict_relative(STEP, q)
        odo.append(compose(odo[-1], STEP))
        ring = ring_at(true)
        win.push(float(j), ring, ekf)
        flm = build_flm(ring.ranges, ring.max_range, FOV, MOUNTS, MP)
        single = decide_heading_fix(
            float(j), wall_direction(flm), refs, ekf.pose, ekf.pose_cov, params
        )
        win.remember(float(j), single)
        formed_before = win.formed
        d = win.decide(float(j), single, refs, MOUNTS, ekf)
        if win.formed > formed_before:
            at_fix.append(np.array(win.recent._poses))
        if d.accepted:
            res = ekf.update_robot([d.measured], [[d.sigma**2]], [2], gate_chi2=params.gate_chi2)
            assert res.accepted
        decisions.append(d)
    return win, ekf, decisions, at_fix, np.array(odo[1:]), true


@pytest.mark.parametrize("every", [0, 2])
def test_window_forms_fixes_at_its_rate_with_the_inflated_noise(every):
    """One multi-ring fix every ``flm_fix_every`` rings (0: every flm_rings) once the
    window is half full, R = sigma_flm^2 max(1, flm_rings / every); rows in between are
    not applied; the fixes bring the filter's 2-degree heading error under 0.3 deg."""
    k = 4
    p = FixParams(flm_rings=k, flm_fix_every=every, flm_window_s=100.0, flm_fit_sigma=False)
    win, ekf, decisions, _, _, true = walk(p, 12)
    step = every or k
    formed = [j for j, d in enumerate(decisions) if d.reason == "ok"]
    assert formed == [j for j in range(12) if (j + 1) % step == 0 and 2 * min(j + 1, k) >= k]
    assert win.formed == len(formed) and win.fix_every == step
    want = p.sigma_flm_deg * math.sqrt(max(1.0, k / step)) * DEG
    assert all(decisions[j].sigma == pytest.approx(want) for j in formed)
    others = [d for j, d in enumerate(decisions) if j not in formed]
    assert all(d.reason == "between_fixes" and not d.accepted for d in others)
    assert all(math.isnan(d.measured) for d in others)
    assert abs(float(wrap_angle(ekf.pose[2] - true[2]))) < 0.3 * DEG


def test_window_places_rings_by_dead_reckoning_not_by_the_filter():
    """The window's poses are the filter's dead reckoning (``EkfSlam.odometry_pose``):
    the composed odometry steps from the start pose, 2 deg off, although the heading
    fixes pulled the filter's own heading to the truth."""
    p = FixParams(flm_rings=4, flm_fix_every=0, flm_window_s=100.0)
    _, ekf, _, at_fix, odo, true = walk(p, 12)
    assert len(at_fix) == 3
    for n, poses in enumerate(at_fix):
        last = 4 * (n + 1)
        np.testing.assert_allclose(poses, odo[last - 4 : last], atol=1e-12)
    assert abs(float(wrap_angle(odo[-1][2] - true[2]))) == pytest.approx(2 * DEG, abs=1e-9)
    assert abs(float(wrap_angle(ekf.pose[2] - true[2]))) < 0.3 * DEG


def test_window_noise_follows_a_loose_wall_fit():
    """A wall whose tangent fit reports sigma above sigma_flm_deg gets that sigma times
    the window's inflation; with ``flm_fit_sigma`` off, the floor."""

    def loose(flm):
        w = flm_wall_direction(flm, MP)
        return SimpleNamespace(angle=w.angle, strength=w.strength, ambiguous=False, sigma=1.2 * DEG)

    for fit, want in ((True, 1.2 * math.sqrt(2.0)), (False, 0.5 * math.sqrt(2.0))):
        p = FixParams(flm_rings=4, flm_fix_every=2, flm_window_s=100.0, flm_fit_sigma=fit)
        _, _, decisions, _, _, _ = walk(p, 4, wall_direction=loose)
        formed = [d for d in decisions if d.reason == "ok"]
        assert len(formed) == 2
        assert all(d.sigma == pytest.approx(want * DEG) for d in formed)


def test_watchdog_memory_and_restart():
    """``remember`` keeps the single-ring decisions of the last ``recover_window_s``
    seconds; ``restart`` keeps only the current ring, and the next fix comes
    ``fix_every`` rings later; a gated single-ring decision between fixes is kept as
    it is (it drives the bump recovery)."""
    p = FixParams(flm_rings=4, flm_fix_every=0, flm_window_s=100.0, recover_window_s=2.0)
    ekf = EkfSlam(np.zeros(3), np.diag([1e-4, 1e-4, (1 * DEG) ** 2]), (0.0, 0.0, 0.0, 0.0))
    win = MultiRingWindow(p, lambda r, m: pytest.fail("no fix is due"), lambda f: None)
    gated = SimpleNamespace(t=0.0, reason="gated", accepted=False)
    for j in range(5):
        win.remember(0.5 * j, SimpleNamespace(t=0.5 * j))
    assert [d.t for d in win.single] == [0.0, 0.5, 1.0, 1.5, 2.0]
    win.remember(2.6, gated)
    assert [d.t for d in win.single] == [1.0, 1.5, 2.0, 0.0]  # 0.0: the gated one's stamp
    true = np.array([*(rot(ANGLE) @ [-5.0, 0.1]), ANGLE])
    for j in range(3):
        win.push(float(j), ring_at(true), ekf)
    win.restart(3.0, ring_at(true), ekf)
    assert len(win.recent) == 1 and win.since_fix == 0
    assert win.decide(3.0, gated, [corridor_ref()], MOUNTS, ekf) is gated
    for j in range(4, 7):
        win.push(float(j), ring_at(true), ekf)
        row = decide_heading_fix(float(j), None, [corridor_ref()], ekf.pose, ekf.pose_cov, p)
        assert win.decide(float(j), row, [corridor_ref()], MOUNTS, ekf).reason == "between_fixes"
    assert win.formed == 0 and win.since_fix == 3


def test_multi_ring_flm_is_the_fgm_steps_bit_for_bit():
    """build_flm_rings fuses its rings with its own vectorised steps (flm._fuse_rings):
    the same floats as FgmBuilder.add_rings on the FLM grid (fgm._step), on rings along a
    noisy path (cells seen by several rings, forgetting at work); and the grouped
    combination of the readings (tbm.conjunctive_grouped, whose zero-commonality count is
    made only when one is there) with a zero commonality, against folding the mass-form
    rule group by group."""
    from fuzzyslam.maps.fgm import FgmBuilder
    from fuzzyslam.maps.flm import build_flm_rings, flm_grid
    from fuzzyslam.maps.tbm import conjunctive, conjunctive_grouped
    from fuzzyslam.se2 import between

    rng = np.random.default_rng(3)
    path = [np.zeros(3)]
    for _ in range(11):
        path.append(compose(path[-1], STEP + rng.normal(0.0, [0.02, 0.02, 0.03])))
    path = np.array(path)
    rings = np.array([ring_at(p).ranges for p in path])
    rings[rng.random(rings.shape) < 0.1] = np.nan
    rel = between(path[-1], path)
    got = build_flm_rings(rel, rings, MAXR, FOV, MOUNTS, MP)
    assert got.m_c.max() > 0.01  # conflicting rings: the forgetting acts
    b = FgmBuilder(flm_grid(MP), MP)
    b.add_rings(rel, rings, MAXR, FOV, MOUNTS)
    for a, w in zip(
        (got.m_e, got.m_o, got.m_t, got.m_c),
        (b.map.m_e, b.map.m_o, b.map.m_t, b.map.m_c),
        strict=True,
    ):
        assert a.dtype == w.dtype and a.tobytes() == w.tobytes()
    # the grouped combination, with groups of several functions and a zero commonality
    m_e = rng.random(40) * 0.5
    m_o = rng.random(40) * 0.5
    m_e[3], m_o[3] = 0.5, 0.5  # m(Theta) = 0: q(Theta) = 0
    groups = rng.integers(0, 12, 40)
    m = (m_e, m_o, 1.0 - m_e - m_o, np.zeros(40))
    got = conjunctive_grouped(m, groups, 12)
    for k in range(12):
        acc = (np.zeros(1), np.zeros(1), np.ones(1), np.zeros(1))
        for i in np.flatnonzero(groups == k):
            acc = conjunctive(acc, tuple(x[i : i + 1] for x in m))
        np.testing.assert_allclose([x[k] for x in got], [x[0] for x in acc], atol=1e-12)
    assert got[2][groups[3]] == 0.0  # the zero commonality's group: m(Theta) = 0
