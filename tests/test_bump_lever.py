"""The bump recovery moves the position with the heading (fixes/heading.py, "Bumps";
fixes/bump_recovery.bump_position): an unseen heading step of beta at a point p_b leaves
the dead-reckoned position off by beta J (p - p_b), which the recovery's inflation
carries in its heading column, so the recovered fix takes it out. On the real EkfSlam
and heading aid, in an ideal corridor, against the simulated truth."""

from __future__ import annotations

import math

import numpy as np
import pytest
from test_fixes import DEG, MOUNTS, MP, SmallEkf, corridor_ref, corridor_walls, ideal_flm, ring

from fuzzyslam.fixes import heading as heading_mod
from fuzzyslam.fixes.bump_recovery import bump_position
from fuzzyslam.fixes.heading import HeadingDecision, HeadingFixAid
from fuzzyslam.fixes.params import FixParams
from fuzzyslam.maps.hough import flm_wall_direction
from fuzzyslam.se2 import compose, rot, wrap_angle

STEP = 0.075  # m per ring: 0.3 m/s at 4 Hz


def _drive_through_bump(bump_deg: float, bump_ring: int = 8, rings: int = 20):
    """Drive along a corridor; at ``bump_ring`` the true heading turns by ``bump_deg``
    unseen by the odometry. Returns the position errors (filter - truth, m) per ring
    before and after its fix, the aid, the ring of the recovery, the filter and the
    true pose."""
    angle = 0.3
    walls = corridor_walls(angle)
    true = np.array([*(rot(angle) @ [-6.0, -0.3]), angle])
    ekf = SmallEkf(true.copy(), np.diag([1e-6, 1e-6, (0.3 * DEG) ** 2]))
    src = {}
    aid = HeadingFixAid(
        [corridor_ref(angle)], FixParams(), lambda r, m: src["flm"],
        lambda f: flm_wall_direction(f, MP), 0.0,
    )  # fmt: skip
    errs, pre, rec = [], [], None
    for k in range(rings):
        if k == bump_ring:
            true[2] += bump_deg * DEG
        true = compose(true, [STEP, 0.0, 0.0])
        ekf.move(STEP, np.diag([1e-8, 1e-8, (0.05 * DEG) ** 2]))
        src["flm"] = ideal_flm(true, walls)
        pre.append(ekf.x[:2] - true[:2])  # before the ring's fix
        aid.on_ring(float(k), ring(float(k)), MOUNTS, ekf)
        if rec is None and aid.decisions[-1].reason == "recovered":
            rec = k
        errs.append(ekf.x[:2] - true[:2])
    return np.array(pre), np.array(errs), aid, rec, ekf, true


@pytest.mark.parametrize("bump_deg", [10.0, -10.0])
def test_recovery_removes_the_drift_since_the_bump(bump_deg):
    pre, errs, aid, rec, ekf, true = _drive_through_bump(bump_deg)
    assert rec is not None and aid.recoveries == 1
    before = float(np.hypot(*pre[rec]))
    # the drift the bump left: beta times the path since it (at least one ring's step)
    assert before > STEP * math.sin(10 * DEG)
    after = float(np.hypot(*errs[rec]))
    # the bump's place is known to half a ring: the residual is at most beta * STEP / 2
    # plus the second-order (1 - cos beta) of the lever, under a third of before
    assert after < 0.3 * before and after < 0.5 * STEP * math.sin(10 * DEG) + 0.003
    assert abs(wrap_angle(ekf.x[2] - true[2])) < 1.0 * DEG
    assert np.all(np.linalg.eigvalsh(ekf.P) > 0)


def test_without_the_lever_the_drift_stays(monkeypatch):
    """The same drive with the bump placed at the current pose (no lever: the diagonal
    inflation alone): the heading is recovered but the position keeps its drift."""
    # streak[0] is the current ring: its position is the pose the lever starts from
    monkeypatch.setattr(
        heading_mod, "bump_position", lambda streak, hist, ok: np.array([streak[0].x, streak[0].y])
    )
    pre, errs, aid, rec, _, _ = _drive_through_bump(10.0)
    assert rec is not None and aid.recoveries == 1
    assert float(np.hypot(*errs[rec])) > 0.8 * float(np.hypot(*pre[rec]))


def test_bump_position_between_the_last_agreeing_ring_and_the_streak():
    def dec(t, reason, x):
        return HeadingDecision(t, 0, 0.1, 0.0, False, reason, 1.0, x=x, y=2 * x)

    hist = [dec(0.0, "ok", 0.0), dec(1.0, "ok", 1.0), dec(2.0, "no_wall", 2.0),
            dec(3.0, "gated", 3.0), dec(4.0, "gated", 4.0)]  # fmt: skip
    streak = [dec(5.0, "gated", 5.0), hist[4], hist[3]]
    assert np.allclose(bump_position(streak, hist, None), [2.0, 4.0])  # (1 + 3) / 2
    # no agreeing ring in the history: the last accepted fix's position, else the first ring
    assert np.allclose(bump_position(streak, hist[2:], np.array([0.0, 1.0])), [1.5, 3.5])
    assert np.allclose(bump_position(streak, hist[2:], None), [3.0, 6.0])
