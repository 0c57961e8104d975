"""The sequential test of a heading jump (fixes/bump_recovery.py: jump_log_odds,
ring_evidence, sequential_streak): its Bayes factor against closed forms, and on the real
heading aid and EkfSlam: an unseen bump recovered as soon as the rings' evidence
suffices (one ring whose wall fit is tight; two loose ones; one loose ring after two
ambiguous_wall rings that lean the same way), no recovery from rings the no-jump
hypothesis explains."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest
from test_fixes import DEG, MOUNTS, OdoEkf, corridor_ref, sonar_ring

from fuzzyslam.fixes.bump_recovery import jump_log_odds
from fuzzyslam.fixes.heading import HeadingFixAid
from fuzzyslam.fixes.params import FixParams
from fuzzyslam.se2 import wrap_angle

T = math.pi  # the comb's period without right angles


def _normal(x: float, var: float) -> float:
    return math.exp(-0.5 * x * x / var) / math.sqrt(2.0 * math.pi * var)


def _closed_form(v, s, eps, p_tt):
    """log B for one or two rings, integrated analytically: with a_i = 1 - eps_i and
    b_i = eps_i / T, (1/T) int (a N(v; d, s^2) + b) dd = (a + b T) / T, and for two rings
    (1/T) [a1 a2 N(v1 - v2; 0, s1^2 + s2^2) + a1 b2 + a2 b1 + b1 b2 T] (the Gaussians'
    mass outside the period is negligible here)."""
    a = [1.0 - e for e in eps]
    b = [e / T for e in eps]
    terms = zip(a, b, v, s, strict=True)
    den = math.prod(ai * _normal(vi, si * si + p_tt) + bi for ai, bi, vi, si in terms)
    if len(v) == 1:
        num = (a[0] + b[0] * T) / T
    else:
        g = _normal(v[0] - v[1], s[0] ** 2 + s[1] ** 2)
        num = (a[0] * a[1] * g + a[0] * b[1] + a[1] * b[0] + b[0] * b[1] * T) / T
    return math.log(num / den)


@pytest.mark.parametrize(
    "v_deg, s_deg, eps",
    [
        ([10.0], [1.5], [4.3e-4]),
        ([3.0], [1.5], [4.3e-4]),
        ([-25.0], [4.0], [3.9e-3]),
        ([0.2], [2.0], [0.059]),
        ([10.0, 9.0], [1.5, 2.5], [4.3e-4, 7.7e-3]),
        ([10.0, -9.0], [1.5, 1.5], [4.3e-4, 4.3e-4]),
        ([1.0, 0.5], [1.5, 5.0], [4.3e-4, 3.9e-3]),
    ],
)
def test_jump_log_odds_matches_the_closed_form(v_deg, s_deg, eps):
    v, s = np.radians(v_deg), np.radians(s_deg)
    p_tt = (0.5 * DEG) ** 2
    got = jump_log_odds(v, s, np.array(eps), p_tt, T)
    assert got == pytest.approx(_closed_form(list(v), list(s), eps, p_tt), abs=1e-3)


def test_one_ring_says_at_most_one_over_its_gross_error_rate():
    """However far a ring is from the prediction, the no-jump hypothesis explains it as a
    gross error with density eps / T: B -> 1 / eps (so a ring decides alone only where
    its gross errors are rarer than recover_alpha)."""
    eps = 4.3e-4
    logs = [jump_log_odds([x * DEG], [1.5 * DEG], [eps], 0.0, T) for x in (5, 10, 20, 40, 80)]
    assert np.all(np.diff(logs) >= -1e-9) and logs[0] < math.log(1e3)
    assert max(logs) <= -math.log(eps) + 1e-6
    assert logs[-1] == pytest.approx(-math.log(eps), abs=0.01)


def _walk(rings, params=None, bump_deg=10.0):
    """A robot in a corridor whose true heading was turned ``bump_deg`` (unseen: the
    filter and the dead reckoning keep 0.05 rad). ``rings``: per ring (error of the
    wall's heading (deg), fit sigma (deg), ambiguous) or None (no wall); the real
    HeadingFixAid and EkfSlam, single-ring fixes, rings at 4 Hz."""
    true_heading = 0.05 + bump_deg * DEG
    ref = corridor_ref(0.0)
    ekf = OdoEkf([0.0, 0.0, 0.05], np.diag([1e-4, 1e-4, (0.5 * DEG) ** 2]))
    state = {}
    aid = HeadingFixAid(
        [ref], params or FixParams(flm_rings=1), lambda r, m: None, lambda f: state["wall"], 0.0
    )
    for j, spec in enumerate(rings):
        state["wall"] = None
        if spec is not None:
            err, fit, amb = spec
            angle = ref.angle - (true_heading + err * DEG)
            state["wall"] = SimpleNamespace(
                angle=angle, strength=3.0, ambiguous=amb, sigma=fit * DEG
            )
        aid.on_ring(0.25 * j, sonar_ring(0.25 * j), MOUNTS, ekf)
    return aid, ekf, true_heading


def test_no_ring_decides_alone_a_second_does():
    """A wall fit within sigma_heading_deg may still be a gross error (at most
    recover_outlier_fit), so one gated ring 10 deg off is not enough (1 / eps_fit <
    1 / alpha); the second that agrees decides."""
    aid, ekf, true_heading = _walk([(0.5, 1.0, False), (-0.5, 1.0, False), (0.0, 1.0, False)])
    assert [d.reason for d in aid.decisions] == ["gated", "recovered", "ok"]
    assert abs(np.degrees(wrap_angle(ekf.x[2] - true_heading))) < 1.0
    # the streak rule alone waits for three agreeing rings
    aid, _, _ = _walk([(0.5, 1.0, False)] * 3, FixParams(flm_rings=1, recover_alpha=0.0))
    assert [d.reason for d in aid.decisions] == ["gated", "gated", "recovered"]


def test_loose_rings_need_two():
    """A loose fit (2.5 deg) may be a gross error one time in 130: one ring is not
    enough, the second that agrees is."""
    aid, ekf, true_heading = _walk([(1.0, 2.5, False), (-1.0, 2.5, False), (0.0, 1.0, False)])
    assert [d.reason for d in aid.decisions] == ["gated", "recovered", "ok"]
    assert abs(np.degrees(wrap_angle(ekf.x[2] - true_heading))) < 1.0


def test_ambiguous_rings_that_lean_toward_the_jump_add_their_evidence():
    """Two ambiguous_wall rings (loose, 5 deg) whose dominant walls say the heading
    jumped, then one tight formed ring: together they decide at that ring; the same
    ring after rings without a wall does not (B <= 1 / eps_fit < 1 / alpha)."""
    amb = [(1.0, 5.0, True), (-2.0, 5.0, True)]
    aid, _, _ = _walk([*amb, (1.0, 1.0, False)])
    assert [d.reason for d in aid.decisions] == ["ambiguous_wall"] * 2 + ["recovered"]
    aid, _, _ = _walk([None, None, (1.0, 1.0, False)])
    assert [d.reason for d in aid.decisions] == ["no_wall", "no_wall", "gated"]
    # ambiguous rings that agree with the prediction weigh against the jump
    aid, _, _ = _walk([(-10.0, 5.0, True), (-9.0, 5.0, True), (1.0, 1.0, False)])
    assert aid.decisions[-1].reason == "gated"


def test_no_recovery_without_a_jump():
    """Rings the no-jump hypothesis explains: a tight ring 4 sigma off (6 deg; gated)
    among agreeing ones, loose rings that disagree with each other (+8, -8 deg), and
    scattered ambiguous rings: gated or refused, never recovered."""
    p = FixParams(flm_rings=1)
    aid, _, _ = _walk([(-10.0, 1.0, False), (-4.0, 1.0, False), (-10.0, 1.0, False)], p)
    assert [d.reason for d in aid.decisions] == ["ok", "gated", "ok"]
    aid, _, _ = _walk([(-2.0, 2.5, False), (-18.0, 2.5, False), (-2.0, 2.5, False)], p)
    assert aid.recoveries == 0
    aid, _, _ = _walk([(-14.0, 6.0, True), (-6.0, 4.0, True), (-4.0, 1.0, False)], p)
    assert aid.recoveries == 0 and aid.decisions[-1].reason == "gated"
