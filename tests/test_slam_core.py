"""EKF-SLAM core: Jacobians, Joseph update, O(n) prediction, association, lamp detector."""

from __future__ import annotations

import numpy as np
import pytest

from fuzzyslam import se2
from fuzzyslam.robot import motion_step
from fuzzyslam.slam.association import TentativeLamps, block_diag_cov, jcbb, joint_threshold
from fuzzyslam.slam.detect import detect_lamps
from fuzzyslam.slam.ekf import (
    EkfSlam,
    Preintegrator,
    lamp_init,
    lamp_measurement,
    motion_jacobians,
    motion_noise,
)
from fuzzyslam.slam.params import SlamParams
from fuzzyslam.slam.runner import Frame, Odom, SlamRunner

ALPHA = SlamParams().odometry_noise


def numeric_jacobian(f, x, eps=1e-6, wrap=()):
    x = np.asarray(x, dtype=float)
    cols = []
    for k in range(len(x)):
        d = np.zeros_like(x)
        d[k] = eps
        diff = np.asarray(f(x + d)) - np.asarray(f(x - d))
        for w in wrap:
            diff[w] = se2.wrap_angle(diff[w])
        cols.append(diff / (2 * eps))
    return np.column_stack(cols)


@pytest.mark.parametrize("seed", range(5))
def test_motion_jacobians_numeric(seed):
    rng = np.random.default_rng(seed)
    pose = rng.uniform([-5, -5, -3], [5, 5, 3])
    u = rng.uniform([-0.5, -0.8], [0.5, 0.8])
    gx, gu = motion_jacobians(pose, *u)
    assert np.allclose(
        gx, numeric_jacobian(lambda p: motion_step(p, *u), pose, wrap=[2]), atol=1e-7
    )
    assert np.allclose(
        gu, numeric_jacobian(lambda q: motion_step(pose, *q), u, wrap=[2]), atol=1e-7
    )


@pytest.mark.parametrize("seed", range(5))
def test_measurement_and_init_jacobians_numeric(seed):
    rng = np.random.default_rng(seed)
    pose = rng.uniform([-5, -5, -3], [5, 5, 3])
    lamp = rng.uniform(-5, 5, 2)
    h, hr, hl = lamp_measurement(pose, lamp)
    assert np.allclose(h, se2.inverse_transform_points(pose, lamp))
    assert np.allclose(
        hr, numeric_jacobian(lambda p: lamp_measurement(p, lamp)[0], pose), atol=1e-7
    )
    assert np.allclose(
        hl, numeric_jacobian(lambda q: lamp_measurement(pose, q)[0], lamp), atol=1e-7
    )
    z = rng.uniform(-2, 2, 2)
    l0, jr, jz = lamp_init(pose, z)
    assert np.allclose(lamp_measurement(pose, l0)[0], z)
    assert np.allclose(jr, numeric_jacobian(lambda p: lamp_init(p, z)[0], pose), atol=1e-7)
    assert np.allclose(jz, numeric_jacobian(lambda q: lamp_init(pose, q)[0], z), atol=1e-7)


def make_filter(rng, n_lamps=4):
    ekf = EkfSlam([1.0, 2.0, 0.3], np.diag([0.01, 0.02, 0.003]), ALPHA)
    for _ in range(n_lamps):
        ekf.add_lamp(rng.uniform(-2, 2, 2), np.diag([0.01, 0.02]))
    for _ in range(5):
        ekf.predict(0.1, 0.05)
    return ekf


def test_prediction_matches_dense_formula_and_is_local():
    rng = np.random.default_rng(1)
    ekf = make_filter(rng)
    x0, p0 = ekf.x.copy(), ekf.P.copy()
    u = (0.2, -0.1)
    ekf.predict(*u)
    gx, gu = motion_jacobians(x0[:3], *u)
    g = np.eye(ekf.dim)
    g[:3, :3] = gx
    q = np.zeros((ekf.dim, ekf.dim))
    q[:3, :3] = gu @ motion_noise(*u, ALPHA) @ gu.T
    assert np.allclose(ekf.P, g @ p0 @ g.T + q)
    assert np.array_equal(ekf.P[3:, 3:], p0[3:, 3:])
    assert np.allclose(ekf.x[:3], motion_step(x0[:3], *u)) and np.array_equal(ekf.x[3:], x0[3:])


def test_joint_lamp_update_equals_dense_joseph_form():
    rng = np.random.default_rng(2)
    ekf = make_filter(rng)
    x0, p0 = ekf.x.copy(), ekf.P.copy()
    ids = [1, 3]
    z = np.array([[0.5, 0.2], [-0.4, 1.0]])
    r = block_diag_cov(np.array([np.diag([0.01, 0.015]), np.diag([0.02, 0.01])]))
    h, cols, hc = ekf.predict_lamps(ids)
    hfull = np.zeros((4, ekf.dim))
    hfull[:, cols] = hc
    v = z.reshape(-1) - h
    s = hfull @ p0 @ hfull.T + r
    k = p0 @ hfull.T @ np.linalg.inv(s)
    ikh = np.eye(ekf.dim) - k @ hfull
    res = ekf.update_lamps(ids, z, r)
    assert res.accepted and res.nis == pytest.approx(v @ np.linalg.solve(s, v))
    assert np.allclose(ekf.x[3:], x0[3:] + (k @ v)[3:])
    assert np.allclose(ekf.P, ikh @ p0 @ ikh.T + k @ r @ k.T)
    assert np.array_equal(ekf.P, ekf.P.T)
    assert np.all(np.linalg.eigvalsh(ekf.P) > 0)


def test_update_robot_wraps_heading_and_gates():
    ekf = EkfSlam([0.0, 0.0, np.pi - 0.01], np.diag([0.01, 0.01, 0.01]), ALPHA)
    res = ekf.update_robot([-np.pi + 0.01], [[0.01]], [2])
    assert res.accepted and res.innovation[0] == pytest.approx(0.02)
    assert abs(se2.wrap_angle(ekf.pose[2] - np.pi)) < 1e-9  # halfway between, wrapped
    assert ekf.pose_cov[2, 2] == pytest.approx(0.005)
    before = ekf.pose.copy()
    res = ekf.update_robot([5.0, 0.0, np.pi], np.eye(3) * 1e-4, [0, 1, 2], gate_chi2=9.0)
    assert not res.accepted and res.nis > 9.0 and np.array_equal(ekf.pose, before)


def test_individual_compatibility_matches_explicit_form():
    rng = np.random.default_rng(3)
    ekf = make_filter(rng, 6)
    z = rng.uniform(-2, 2, (3, 2))
    r = np.array([np.diag([0.01, 0.02]), np.diag([0.03, 0.01]), np.diag([0.02, 0.02])])
    d2 = ekf.individual_compatibility(z, r)
    for j in range(3):
        for i in range(6):
            h, cols, hc = ekf.predict_lamps([i])
            v = z[j] - h
            s = ekf.innovation_cov(cols, hc, r[j])
            assert d2[j, i] == pytest.approx(v @ np.linalg.solve(s, v))


def test_update_cost_structure_many_lamps():
    """add_lamp grows storage; P stays symmetric PD with hundreds of lamps."""
    rng = np.random.default_rng(4)
    ekf = EkfSlam([0.0, 0.0, 0.0], np.diag([1e-4, 1e-4, 1e-4]), ALPHA)
    for _ in range(200):
        ekf.add_lamp(rng.uniform(-3, 3, 2), np.eye(2) * 0.01)
        ekf.predict(0.05, 0.01)
    ekf.update_lamps([0, 150], ekf.predict_lamps([0, 150])[0].reshape(2, 2), np.eye(4) * 0.01)
    assert ekf.n_lamps == 200 and np.array_equal(ekf.P, ekf.P.T)
    np.linalg.cholesky(ekf.P)


def test_jcbb_keeps_two_close_lamps_apart():
    """Two lamps 10 cm apart, each detection gates with both; JCBB pairs each with its own."""
    ekf = EkfSlam([0.0, 0.0, 0.0], np.diag([0.02**2, 0.02**2, 0.01**2]), ALPHA)
    r = np.eye(2) * 0.02**2
    ekf.add_lamp([1.0, 0.0], r)
    ekf.add_lamp([1.0, 0.10], r)
    z = np.array([[1.0, 0.02], [1.0, 0.08]])  # lamp 0 read high, lamp 1 read low
    rr = np.array([r, r])
    d2 = ekf.individual_compatibility(z, rr)
    assert np.all(d2 <= 9.21), "both detections must gate with both lamps for this test"
    # nearest neighbour alone could pair detection 1 with lamp 0 after moving; here
    # each detection is nearest to its own lamp but both are individually compatible
    pairs = jcbb(ekf, z, rr, d2, 9.21).pairs
    assert sorted(pairs) == [(0, 0), (1, 1)]
    # swapped order in the frame: still each to its own lamp
    pairs = jcbb(ekf, z[::-1].copy(), rr, ekf.individual_compatibility(z[::-1], rr), 9.21).pairs
    assert sorted(pairs) == [(0, 1), (1, 0)]


def test_jcbb_rejects_jointly_incompatible_pair():
    """Two detections each compatible alone, but their relative offset contradicts the map."""
    ekf = EkfSlam([0.0, 0.0, 0.0], np.diag([1e-6, 1e-6, 1e-6]), ALPHA)
    r = np.eye(2) * 0.01**2
    ekf.add_lamp([1.0, 0.0], r)
    ekf.add_lamp([1.0, 1.0], r)
    ekf.P[:2, :2] += np.eye(2) * 0.3**2  # the robot is lost relative to a good map
    # both shifted the same way is fine (robot offset); opposite shifts are not
    z = np.array([[1.3, 0.0], [0.7, 1.0]])
    rr = np.array([r, r])
    d2 = ekf.individual_compatibility(z, rr)
    assert np.all(np.diag(d2) <= 9.21)
    pairs = jcbb(ekf, z, rr, d2, 9.21).pairs
    assert len(pairs) == 1
    assert joint_threshold(9.21, 2) == pytest.approx(9.21, rel=1e-3)


def test_tentative_lamps_promote_after_hits_and_expire():
    tl = TentativeLamps(hits=3, radius=0.2, timeout=1.0)
    assert not tl.observe(0.0, np.array([1.0, 1.0]), set())
    assert not tl.observe(0.2, np.array([1.05, 1.0]), set())
    assert not tl.observe(0.4, np.array([3.0, 1.0]), set())  # another candidate
    assert tl.observe(0.6, np.array([1.0, 1.05]), set())
    assert len(tl.items) == 1
    tl.expire(2.0)
    assert tl.items == [] and tl.expired == 1


# -- a small synthetic SLAM run (measurement generator only; no robot simulator) -------------


def synthetic_run(seed, lamps, laps=2, sigma=0.01, noise=ALPHA):
    """Robot on a circle of radius 2 m; odometry noise drawn from the filter's own model."""
    rng = np.random.default_rng(seed)
    p = SlamParams(tentative_hits=3)
    p.trans_var_per_m, p.trans_var_per_rad, p.rot_var_per_rad, p.rot_var_per_m = noise
    runner = SlamRunner(p, np.array([2.0, 0.0, np.pi / 2]))
    truth = np.array([2.0, 0.0, np.pi / 2])
    steps = int(laps * 2 * np.pi * 2.0 / 0.015)
    nees, poses = [], []
    r = np.eye(2) * sigma**2
    for k in range(steps):
        dt, dr = 0.015, 0.015 / 2.0
        truth = motion_step(truth, dt, dr)
        m = motion_noise(dt, dr, noise)
        noisy = rng.multivariate_normal([dt, dr], m)
        t = 0.05 * (k + 1)
        runner.odometry(Odom(t, *noisy))
        if k % 4 == 3:
            zt = se2.inverse_transform_points(truth, lamps)
            vis = np.all(np.abs(zt) < [2.7, 2.0], axis=1)
            z = zt[vis] + rng.normal(0, sigma, (int(vis.sum()), 2))
            runner.frame(Frame(t, z, np.repeat(r[None], len(z), axis=0)))
            e = runner.ekf.pose - truth
            e[2] = se2.wrap_angle(e[2])
            nees.append(e @ np.linalg.solve(runner.ekf.pose_cov, e))
            poses.append(np.hypot(*e[:2]))
            if k % 40 == 3:
                np.linalg.cholesky(runner.ekf.P)
                assert np.array_equal(runner.ekf.P, runner.ekf.P.T)
    return runner, np.array(nees), np.array(poses)


def test_synthetic_slam_is_accurate_consistent_without_duplicates():
    ang = np.linspace(0, 2 * np.pi, 9)[:-1]
    lamps = np.column_stack([2.0 * np.cos(ang), 2.0 * np.sin(ang)]) * 1.1
    runner, nees, err = synthetic_run(0, lamps)
    res = runner.result()
    assert runner.ekf.n_lamps == len(lamps) and res.counts.lamps_created == len(lamps)
    # each true lamp has exactly one estimate within 5 cm
    d = np.hypot(*(runner.ekf.lamps[:, None, :] - lamps[None, :, :]).transpose(2, 0, 1))
    assert np.all(d.min(axis=0) < 0.05) and np.all(d.min(axis=1) < 0.05)
    # relative error (map frame is anchored at the start pose, so errors are small)
    assert err.mean() < 0.03
    # average NEES of the 3-dof pose near 3 (loose band: one seed, correlated samples)
    assert 1.0 < nees[len(nees) // 4 :].mean() < 6.0
    assert abs(res.mean_nis() - 2.0) < 0.6


def test_duplicate_guard_counts_near_misses():
    """A detection outside the association gate but near a mapped lamp creates no lamp."""
    p = SlamParams(tentative_hits=1, gate_chi2=9.21, new_lamp_chi2=100.0)
    runner = SlamRunner(p, np.zeros(3))
    r = np.eye(2) * 0.01**2
    runner.frame(Frame(0.0, np.array([[1.0, 0.0]]), r[None]))
    assert runner.ekf.n_lamps == 1
    runner.frame(Frame(0.1, np.array([[1.06, 0.0]]), r[None]))  # D2 ~ 18: gated, guarded
    assert runner.ekf.n_lamps == 1 and runner.counts["duplicates_guarded"] == 1
    runner.frame(Frame(0.2, np.array([[2.0, 0.0]]), r[None]))  # far: a new lamp
    assert runner.ekf.n_lamps == 2


# -- lamp detector ----------------------------------------------------------------------------


def render(centres, radius, shape=(120, 160), bg=40.0, noise=3.0, seed=0, ss=8):
    """Anti-aliased discs (area coverage by ss x ss supersampling) plus Gaussian noise."""
    h, w = shape
    off = (np.arange(ss) + 0.5) / ss - 0.5
    v = (np.arange(h)[:, None] + off[None, :]).reshape(-1)
    u = (np.arange(w)[:, None] + off[None, :]).reshape(-1)
    cover = np.zeros((h * ss, w * ss))
    for cu, cv in centres:
        cover = np.maximum(cover, ((u[None, :] - cu) ** 2 + (v[:, None] - cv) ** 2) <= radius**2)
    frac = cover.reshape(h, ss, w, ss).mean(axis=(1, 3))
    rng = np.random.default_rng(seed)
    img = bg + (255.0 - bg) * frac + rng.normal(0, noise, shape)
    return np.clip(np.rint(img), 0, 255).astype(np.uint8)


@pytest.mark.parametrize("seed", range(4))
def test_detector_subpixel(seed):
    rng = np.random.default_rng(seed)
    centres = np.column_stack([rng.uniform(15, 145, 3), rng.uniform(15, 105, 3)])
    centres[1] = centres[0] + [40.3, 0.0] if centres[0, 0] < 100 else centres[0] - [40.3, 0.0]
    centres[2] = [rng.uniform(20, 140), 110.0 - centres[0, 1] / 2]
    radius = rng.uniform(2.5, 5.0)
    img = render(centres, radius, seed=seed)
    blobs = detect_lamps(img)
    assert len(blobs) == 3
    d = np.hypot(*(blobs.uv[:, None, :] - centres[None, :, :]).transpose(2, 0, 1))
    assert np.all(d.min(axis=1) < 0.5) and np.all(d.min(axis=0) < 0.5)
    assert np.allclose(blobs.area, np.pi * radius**2, rtol=0.35)


def test_detector_dark_noisy_frame_and_gates():
    dark = render([], 3.0, noise=12.0, seed=5)
    assert len(detect_lamps(dark)) == 0
    img = render([(80.0, 60.0)], 4.0)
    img[10:12, 20:60] = 255  # a long thin glint: fails the aspect gate
    img[0:6, 100:106] = 255  # a lamp cut by the border
    blobs = detect_lamps(img)
    assert len(blobs) == 1 and blobs.rejected == 2
    assert np.hypot(*(blobs.uv[0] - [80.0, 60.0])) < 0.5


def test_preintegrated_prediction_equals_sequential_predictions():
    rng = np.random.default_rng(7)
    a = make_filter(rng, 3)
    b = EkfSlam(a.pose, a.pose_cov, ALPHA)
    b._x, b._p, b.dim = a._x.copy(), a._p.copy(), a.dim
    pre = Preintegrator(ALPHA)
    for _ in range(12):
        u = rng.uniform([0.0, -0.1], [0.05, 0.1])
        a.predict(*u)
        pre.add(*u)
    b.predict_relative(pre.delta, pre.q)
    assert np.allclose(a.x, b.x, atol=1e-12) and np.allclose(a.P, b.P, atol=1e-12)


def test_runner_two_close_lamps_keep_their_own_detections():
    """Lamps 15 cm apart, gate ~3 sigma = 30 cm wide: each detection updates its own lamp."""
    runner = SlamRunner(SlamParams(tentative_hits=1), np.zeros(3))
    r = np.eye(2) * 0.01**2
    runner.frame(Frame(0.0, np.array([[1.0, 0.0], [1.0, 0.15]]), np.array([r, r])))
    assert runner.ekf.n_lamps == 2
    runner.ekf.P[:2, :2] += np.eye(2) * 0.1**2  # the robot gets lost by 10 cm (1 sigma)
    z = np.array([[1.05, 0.21], [1.05, 0.06]])  # shifted by the pose error (5, 6 cm)
    rr = np.array([r, r])
    assert np.all(runner.ekf.individual_compatibility(z, rr) < 9.21)
    runner.frame(Frame(0.1, z, rr))
    last = runner.updates[-2:]
    assert sorted((u.id, u.accepted) for u in last) == [(0, True), (1, True)]
    assert runner._obs == [2, 2] and runner.counts["duplicates_guarded"] == 0
    # the pose moved by the common shift, the lamps stayed 15 cm apart
    assert np.allclose(runner.ekf.pose[:2], [-0.05, -0.06], atol=0.01)
    assert np.hypot(*(runner.ekf.lamps[1] - runner.ekf.lamps[0])) == pytest.approx(0.15, abs=0.01)


def test_predict_lamps_blocks_equal_single_lamp_model():
    rng = np.random.default_rng(8)
    ekf = make_filter(rng, 5)
    h, cols, hc = ekf.predict_lamps([3, 1])
    for a, i in enumerate([3, 1]):
        hi, hr, hl = lamp_measurement(ekf.pose, ekf.lamps[i])
        assert np.allclose(h[2 * a : 2 * a + 2], hi)
        assert np.allclose(hc[2 * a : 2 * a + 2, :3], hr)
        assert np.allclose(hc[2 * a : 2 * a + 2, 3 + 2 * a : 5 + 2 * a], hl)
        assert list(cols[3 + 2 * a : 5 + 2 * a]) == [3 + 2 * i, 4 + 2 * i]
    assert np.count_nonzero(hc[0:2, 5:7]) == 0 and np.count_nonzero(hc[2:4, 3:5]) == 0


def test_inline_wheel_odometry_equals_robot_model():
    from types import SimpleNamespace

    from fuzzyslam.config import load_config
    from fuzzyslam.robot import wheel_increments_to_odometry
    from fuzzyslam.slam.inputs import LogInputs

    cfg = load_config("quick")
    inputs = SimpleNamespace(cfg=cfg)
    rng = np.random.default_rng(9)
    for dl, dr in rng.normal(0, 0.3, (20, 2)):
        ours = LogInputs._wheel_odometry(inputs, dl, dr)
        ref = wheel_increments_to_odometry(dl, dr, cfg.robot.wheel_radius, cfg.robot.wheel_base)
        assert np.allclose(ours, ref, rtol=1e-14, atol=0)


def test_joint_table_equals_joint_nis():
    """The JCBB table's sliced joint NIS equals the direct stacked computation."""
    from fuzzyslam.slam.association import JointTable, candidates, joint_nis

    rng = np.random.default_rng(11)
    ekf = make_filter(rng, 6)
    z = ekf.predict_lamps([0, 1, 2, 4])[0].reshape(4, 2) + rng.normal(0, 0.05, (4, 2))
    r = np.repeat((np.eye(2) * 0.05**2)[None], 4, axis=0)
    cands = candidates(ekf.individual_compatibility(z, r), 1e6)  # every pair
    table = JointTable(ekf, z, r, cands)
    for pairs in ([(0, 0)], [(0, 0), (1, 1)], [(0, 2), (2, 0), (3, 4)], [(1, 5), (3, 3)]):
        assert table.nis(pairs) == pytest.approx(joint_nis(ekf, pairs, z, r), rel=1e-9)


def test_integrate_in_blocks_equals_one_call():
    """The streamed dead reckoning (``robot.integrate_from`` block by block, the running
    sums carried over) gives the floats of one ``robot.integrate`` call, which agrees with
    ``motion_step`` applied one increment at a time."""
    from fuzzyslam.robot import integrate, integrate_from, motion_step

    rng = np.random.default_rng(4)
    start = np.array([1.5, -2.0, 3.0])
    d_trans, d_rot = rng.normal(0.05, 0.02, 200), rng.normal(0.0, 0.05, 200)
    whole = integrate(start, d_trans, d_rot)
    blocks, sums, first = [], (0.0, 0.0, 0.0), True
    for a, b in ((0, 7), (7, 8), (8, 120), (120, 200)):
        poses, sums = integrate_from(start, d_trans[a:b], d_rot[a:b], sums)
        blocks.append(poses if first else poses[1:])
        first = False
    assert np.array_equal(np.concatenate(blocks), whole)
    pose = start
    for dt, dr in zip(d_trans, d_rot, strict=True):
        pose = motion_step(pose, dt, dr)
    assert np.allclose(pose, whole[-1], atol=1e-12)


def test_odometry_speed_bound():
    """odom_gate.within_speed: SPEED_MARGIN times the top speed over dt + SLACK_S."""
    from fuzzyslam.slam.odom_gate import SLACK_S, SPEED_MARGIN, within_speed

    span = SPEED_MARGIN * (0.1 + SLACK_S)
    assert within_speed(0.1, 0.5 * span, 0.0, 0.5, 1.0)
    assert not within_speed(0.1, 0.5 * span * 1.001, 0.0, 0.5, 1.0)
    assert not within_speed(0.1, 0.0, -1.0 * span * 1.001, 0.5, 1.0)
    assert within_speed(-1.0, 0.5 * SPEED_MARGIN * SLACK_S, 0.0, 0.5, 1.0)  # dt < 0: slack only


def test_nis_windows_out_of_bounds_too_often_mean_divergence() -> None:
    """Windows out of the chi-square band now and then, never three in a row: a rate
    a consistent filter (alpha = 1e-3 per window) gives with probability below 1e-6 is
    divergence (``nis_rate``); one window out of 36, as a real MRCLAM run has, is not.
    The binomial tail is checked against its closed form for k = 1 and k = n."""
    from fuzzyslam.slam.health import DivergenceMonitor, binomial_tail

    assert binomial_tail(1, 36, 1e-3) == pytest.approx(1 - (1 - 1e-3) ** 36, rel=1e-12)
    assert binomial_tail(5, 5, 0.1) == pytest.approx(1e-5, rel=1e-12)

    def run(bad_windows: set[int], windows: int = 36) -> DivergenceMonitor:
        mon = DivergenceMonitor(window=10)
        for w in range(windows):
            nis = 20.0 if w in bad_windows else 2.0  # 10 updates of 2 dof: chi2(20)
            for k in range(10):
                mon.observe(w + 0.1 * k, nis, 2)
        return mon

    assert not run({7}).diverged
    alternate = run({3, 6, 9, 12, 15, 18, 21})  # 7 out of bounds, never two in a row
    assert alternate.diverged and alternate.reasons == ["nis_rate"]
    assert alternate.diverged_at == pytest.approx(9.9)  # the third of 10: tail 1.2e-7


def test_binomial_tail_of_a_long_run_neither_overflows_nor_drifts() -> None:
    """A run of 50 000 NIS windows (2.5 million updates): the tail is finite (the sum of
    binomial coefficients overflowed a float from n = 1030) and equals the complement of
    the lower sum computed by the pmf's recurrence (a second implementation); k > n gives
    0, k = 0 gives 1."""
    import math

    from fuzzyslam.slam.health import binomial_tail

    n, p = 50_000, 1e-3
    pmf = [(1.0 - p) ** n]  # the pmf by its recurrence: pmf(i + 1) = pmf(i) (n - i) p / ((i + 1) q)
    for i in range(59):
        pmf.append(pmf[-1] * (n - i) / (i + 1) * p / (1.0 - p))
    lower = math.fsum(pmf)
    assert binomial_tail(60, n, p) == pytest.approx(1.0 - lower, rel=1e-6)
    assert 0.0 < binomial_tail(200, n, p) < 1e-40
    assert binomial_tail(n + 1, n, p) == 0.0 and binomial_tail(0, n, p) == 1.0
