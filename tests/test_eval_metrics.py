"""Evaluation metrics on hand-made trajectories with known answers."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import least_squares
from scipy.stats import chi2

from fuzzyslam.evaluation import metrics as M
from fuzzyslam.evaluation.align import umeyama
from fuzzyslam.evaluation.consistency import consistency, nees
from fuzzyslam.evaluation.lamps import match_lamps
from fuzzyslam.se2 import compose, rot, wrap_angle


def _loop(n: int = 400, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """A smooth closed-ish path (times, poses) that is not symmetric."""
    t = np.linspace(0.0, 100.0, n)
    x = 5.0 * np.cos(0.05 * t) + 0.3 * t / 10.0
    y = 3.0 * np.sin(0.07 * t)
    th = np.arctan2(np.gradient(y), np.gradient(x))
    return t, np.column_stack([x, y, th])


def test_stats_known_values() -> None:
    s = M.stats([3.0, -4.0])
    assert s.mean == pytest.approx(3.5)
    assert s.rmse == pytest.approx(np.sqrt(12.5))
    assert s.max == pytest.approx(4.0)
    assert s.bias == pytest.approx(-0.5)
    assert s.std == pytest.approx(3.5)
    assert M.stats([]).n == 0


def test_constant_offset_unaligned_equals_offset_aligned_zero() -> None:
    _, truth = _loop()
    off = np.array([0.3, -0.4, 0.0])
    res = M.ape(truth[:, :2] + off[:2], truth[:, :2])
    assert res.raw.mean == pytest.approx(0.5)
    assert res.raw.rmse == pytest.approx(0.5)
    assert res.raw.max == pytest.approx(0.5)
    assert res.aligned.rmse < 1e-9
    assert res.alignment["tx"] == pytest.approx(-0.3)
    assert res.alignment["ty"] == pytest.approx(0.4)


def test_pure_rotation_about_origin() -> None:
    _, truth = _loop()
    a = 0.2
    est = compose(np.array([0.0, 0.0, a]), truth)
    res = M.ape(est[:, :2], truth[:, :2])
    # unaligned error of a point at radius r rotated by a is 2 r sin(a/2)
    r = np.hypot(truth[:, 0], truth[:, 1])
    assert res.raw.mean == pytest.approx(np.mean(2 * r * np.sin(a / 2)))
    assert res.aligned.rmse < 1e-9
    assert res.alignment["theta_deg"] == pytest.approx(-np.degrees(a))
    err = M.pose_errors(est, truth)
    np.testing.assert_allclose(err[:, 2], a, atol=1e-12)


def test_heading_error_wraps_across_pi() -> None:
    est = np.array([[0.0, 0.0, np.pi - 0.01]])
    truth = np.array([[0.0, 0.0, -np.pi + 0.01]])
    assert M.pose_errors(est, truth)[0, 2] == pytest.approx(-0.02)


def test_aligned_ape_matches_brute_force_least_squares() -> None:
    rng = np.random.default_rng(3)
    _, truth = _loop()
    est = compose(np.array([1.0, -2.0, 0.4]), truth)
    est[:, :2] += rng.normal(0.0, 0.05, size=(truth.shape[0], 2))

    def resid(p: np.ndarray) -> np.ndarray:
        q = est[:, :2] @ rot(p[2]).T + p[:2]
        return (q - truth[:, :2]).ravel()

    fit = least_squares(resid, x0=np.zeros(3))
    brute = np.sqrt(np.mean(np.sum(fit.fun.reshape(-1, 2) ** 2, axis=1)))
    res = M.ape(est[:, :2], truth[:, :2])
    assert res.aligned.rmse == pytest.approx(brute, rel=1e-6)
    sim = umeyama(est[:, :2], truth[:, :2])
    assert sim.angle == pytest.approx(fit.x[2], abs=1e-6)


def test_umeyama_scale_recovered() -> None:
    rng = np.random.default_rng(1)
    p = rng.normal(size=(50, 2))
    q = 1.7 * p @ rot(0.9).T + np.array([2.0, 3.0])
    s = umeyama(p, q, with_scale=True)
    assert s.scale == pytest.approx(1.7)
    np.testing.assert_allclose(s.apply(p), q, atol=1e-9)


def test_interpolation_heading_short_way_and_association_gap() -> None:
    tt = np.array([0.0, 1.0, 2.0, 10.0])
    pt = np.array([[0, 0, np.pi - 0.1], [1, 0, -np.pi + 0.1], [2, 0, 0.0], [3, 0, 0.0]])
    q = M.interpolate_poses(tt, pt, [0.5])
    assert abs(q[0, 2]) == pytest.approx(np.pi)
    a = M.associate([0.5, 1.5, 6.0, 11.0], np.zeros((4, 3)), tt, pt, max_dt=0.6, max_gap=0.5)
    # 6.0 is 4 s from any truth sample; 11.0 is outside the span
    np.testing.assert_array_equal(a.index, [0, 1])
    # between samples 1 s apart, 0.5 s from each: interpolated when the bound allows it
    a = M.associate([0.5, 1.5, 6.0], np.zeros((3, 3)), tt, pt, max_dt=0.1, max_gap=1.0)
    np.testing.assert_array_equal(a.index, [0, 1])


def test_rpe_zero_for_rigidly_moved_estimate_and_known_drift() -> None:
    _, truth = _loop()
    moved = compose(np.array([3.0, 1.0, 1.0]), truth)
    r = M.rpe_per_metre(moved, truth, 1.0)
    assert r.trans_per_m.max < 1e-9
    assert r.rot_deg_per_m.max < 1e-9
    # straight line, estimate scaled by 1.1: 0.1 m error per metre travelled
    t = np.linspace(0, 10, 1001)
    line = np.column_stack([t, np.zeros_like(t), np.zeros_like(t)])
    est = line.copy()
    est[:, 0] *= 1.1
    r = M.rpe_per_metre(est, line, 1.0)
    assert r.trans_per_m.mean == pytest.approx(0.1, rel=1e-6)


def test_nees_of_consistent_filter_in_band_and_overconfident_out() -> None:
    rng = np.random.default_rng(7)
    n = 2000
    a = rng.normal(size=(n, 3, 3)) * 0.1
    cov = a @ np.swapaxes(a, 1, 2) + 1e-3 * np.eye(3)
    err = np.einsum("nij,nj->ni", np.linalg.cholesky(cov), rng.normal(size=(n, 3)))
    v = nees(err, cov)
    c = consistency(v, 3)
    assert c.band_lo < 3.0 < c.band_hi
    assert c.in_band
    lo, hi = chi2.ppf([0.025, 0.975], 3 * n) / n
    assert (c.band_lo, c.band_hi) == pytest.approx((lo, hi))
    assert not consistency(nees(err, cov / 4.0), 3).in_band
    # singular covariance gives NaN, not a crash
    assert np.isnan(nees(err[:1], np.zeros((1, 3, 3)))[0])


LAMPS = np.array([[0.0, 0.0], [2.5, 0.0], [5.0, 0.0], [7.5, 1.0]])


def test_lamp_known_displacement() -> None:
    est = LAMPS + np.array([[0.03, 0.04], [0, 0], [0, 0], [0, 0]])
    m = match_lamps(est[::-1], LAMPS, 0.5)
    assert m.per_true[0] == pytest.approx(0.05)
    np.testing.assert_allclose(m.per_true[1:], 0.0, atol=1e-12)
    assert not m.duplicates and not m.missed and not m.spurious


def test_lamp_duplicate_counted_once_and_missed() -> None:
    est = np.vstack([LAMPS[:3], LAMPS[1] + [0.2, 0.0], [[20.0, 20.0]]])
    m = match_lamps(est, LAMPS, 0.5)
    assert m.duplicates == [3]
    assert m.spurious == [4]
    assert m.missed == [3]
    np.testing.assert_allclose(m.errors, 0.0, atol=1e-12)
    s = m.summary()
    assert (s["duplicates"], s["missed"], s["matched"]) == (1, 1, 3)


def test_lamp_assignment_is_one_to_one_and_optimal() -> None:
    # a greedy nearest match would pair e0 with t1 (0.1) and leave t0 to e1 (0.45)
    truth = np.array([[0.0, 0.0], [0.3, 0.0]])
    est = np.array([[0.2, 0.0], [0.4, 0.0]])
    m = match_lamps(est, truth, 0.5)
    assert m.errors.sum() == pytest.approx(0.2 + 0.1)
    assert sorted(m.pairs[:, 1].tolist()) == [0, 1]


def test_phases_from_runs() -> None:
    iv = [(1, 0.0, 10.0), (2, 10.0, 20.0), (3, 20.0, 30.0)]
    ph = {p.name: p for p in M.phases_from_runs(iv, 2, (0.0, 30.0))}
    assert (ph["A"].t0, ph["A"].t1, ph["A"].runs) == (0.0, 20.0, (1, 2))
    assert (ph["after"].t0, ph["after"].t1) == (20.0, 30.0)
    assert set(ph) == {"overall", "run1", "run2", "run3", "A", "after"}


def test_wrap_consistency_with_se2() -> None:
    a = np.linspace(-10, 10, 101)
    err = M.pose_errors(np.column_stack([a * 0, a * 0, a]), np.zeros((101, 3)))
    np.testing.assert_allclose(err[:, 2], wrap_angle(a))


def test_aligned_ape_matches_evo_when_available() -> None:
    evo_traj = pytest.importorskip("evo.core.trajectory")
    evo_metrics = pytest.importorskip("evo.core.metrics")
    rng = np.random.default_rng(5)
    t, truth = _loop()
    est = compose(np.array([0.5, -0.2, 0.3]), truth)
    est[:, :2] += rng.normal(0.0, 0.05, size=(truth.shape[0], 2))

    def traj(p: np.ndarray) -> object:
        xyz = np.column_stack([p[:, :2], np.zeros(len(p))])
        q = np.column_stack([np.cos(p[:, 2] / 2), 0 * p[:, 2], 0 * p[:, 2], np.sin(p[:, 2] / 2)])
        return evo_traj.PoseTrajectory3D(xyz, q, t)  # evo's quaternions are w x y z

    ref, e = traj(truth), traj(est)
    e.align(ref, correct_scale=False)
    ape = evo_metrics.APE(evo_metrics.PoseRelation.translation_part)
    ape.process_data((ref, e))
    ours = M.ape(est[:, :2], truth[:, :2])
    assert ours.aligned.rmse == pytest.approx(ape.get_statistic(evo_metrics.StatisticsType.rmse))
    assert ours.aligned.mean == pytest.approx(ape.get_statistic(evo_metrics.StatisticsType.mean))
