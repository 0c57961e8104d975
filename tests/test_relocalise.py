"""The relocalisation test (slam/relocalise.py) on the real filter."""

from __future__ import annotations

import copy

import numpy as np

from fuzzyslam.se2 import inverse_transform_points
from fuzzyslam.slam.association import jcbb
from fuzzyslam.slam.ekf import EkfSlam
from fuzzyslam.slam.relocalise import Relocaliser, relocalisation_test

NOISE = (0.01, 0.005, 0.01, 0.02)
GATE = 9.21
# two groups that look alike (a pair 0.2 m apart, 2.5 m from a third landmark), as the
# landmarks of the MRCLAM arena stand; the robot sees them from about 3 m
LAMPS = np.array([[3.0, 0.0], [3.0, 0.2], [3.2, 2.5], [0.0, 3.0], [0.2, 3.0], [2.5, 3.2]])
Q = np.diag([0.5**2, 0.5**2, np.radians(30.0) ** 2])


def _filter(pose_est: np.ndarray, sigma_deg: float = 2.0) -> EkfSlam:
    """A filter whose map holds LAMPS exactly (tiny lamp covariance) and whose pose is
    ``pose_est`` with a heading sigma of ``sigma_deg``."""
    ekf = EkfSlam(pose_est, np.diag([1e-4, 1e-4, np.radians(sigma_deg) ** 2]), NOISE, capacity=8)
    for lamp in LAMPS:
        z = inverse_transform_points(ekf.pose, lamp[None])[0]
        ekf.add_lamp(z, np.eye(2) * 1e-8)
    return ekf


def _detections(pose_true: np.ndarray, ids: list[int], rng=None) -> tuple[np.ndarray, np.ndarray]:
    z = inverse_transform_points(pose_true, LAMPS[ids])
    r = np.repeat(np.diag([0.1**2, 0.05**2])[None], len(ids), axis=0)
    if rng is not None:
        z = z + rng.normal(size=z.shape) * [0.1, 0.05]
    return z, r


def test_a_pose_off_by_15_deg_is_relocalised_and_then_pairs_every_detection():
    true = np.array([0.5, 0.5, 0.3])
    est = true + np.array([0.0, 0.0, np.radians(15.0)])  # a turn the wheels did not make: 7.5 sigma
    ekf = _filter(est)
    z, r = _detections(true, [0, 1, 2, 3, 4, 5], np.random.default_rng(1))
    d2 = ekf.individual_compatibility(z, r)
    before = jcbb(ekf, z, r, d2, GATE, 4.0)
    assert len(before.best) <= 2  # the wrong pose explains at most a pair
    p_before = ekf.P.copy()
    d2_new, test = relocalisation_test(ekf, z, r, d2, GATE, 4.0, Q)
    assert test is not None and test.accepted
    assert test.pairs_after >= 5 and test.pairs_before == len(before.best)
    # 10-cm detections: linearised at the turned pose the joint test already passes, so
    # it is not iterated (slam/iterated.py) and the update is the plain EKF's
    assert test.lin is None and test.iterations == 0
    # the robot block got exactly Q, nothing else changed; P stays symmetric PD
    dp = ekf.P - p_before
    assert np.allclose(dp[:3, :3], Q) and np.allclose(dp[3:], 0) and np.allclose(dp[:, 3:], 0)
    assert np.allclose(ekf.P, ekf.P.T) and np.linalg.eigvalsh(ekf.P).min() > 0
    with ekf.linearised_at(test.lin):  # the iterated test's pose (slam/iterated.py)
        after = jcbb(ekf, z, r, d2_new, GATE, 4.0)
        assert sorted(after.pairs) == [(j, j) for j in range(6)]  # each with its own lamp
        det = [j for j, _ in after.pairs]
        res = ekf.update_lamps([i for _, i in after.pairs], z[det], np.kron(np.eye(6), r[0]))
    assert res.accepted
    e = ekf.pose - true
    assert abs(np.degrees(e[2])) < 1.0
    assert e @ np.linalg.solve(ekf.pose_cov, e) < 16.27  # chi2(3) 99.9 %: consistent again


def test_no_test_when_the_frame_is_explained_and_no_change_when_refused():
    true = np.array([0.5, 0.5, 0.3])
    ekf = _filter(true)
    z, r = _detections(true, [0, 1, 2])
    d2 = ekf.individual_compatibility(z, r)
    out, test = relocalisation_test(ekf, z, r, d2, GATE, 4.0, Q)
    assert out is d2 and not test.tested and not test.accepted
    assert sorted(test.before.pairs) == [(0, 0), (1, 1), (2, 2)]
    # three detections of landmarks not in the map (20 m away): the test runs, explains
    # nothing more, is refused and leaves the filter bit for bit as it was
    p0, x0 = ekf.P.copy(), ekf.x.copy()
    far = np.array([[20.0, 0.0], [20.0, 1.0], [21.0, 3.0]])
    d2f = ekf.individual_compatibility(far, r)
    out, test = relocalisation_test(ekf, far, r, d2f, GATE, 4.0, Q)
    assert test is not None and not test.accepted and test.pairs_after == 0
    assert out is d2f and np.array_equal(ekf.P, p0) and np.array_equal(ekf.x, x0)


def test_relocaliser_counts_and_is_off_by_default():
    from fuzzyslam.slam.params import SlamParams

    assert Relocaliser.from_params(SlamParams()) is None
    p = SlamParams(relocalise_sigma_m=0.5, relocalise_sigma_heading_deg=30.0)
    rel = Relocaliser.from_params(p)
    assert np.allclose(rel.q, Q)
    true = np.array([0.5, 0.5, 0.3])
    ekf = _filter(true + np.array([0.0, 0.0, np.radians(15.0)]))
    z, r = _detections(true, [0, 1, 2, 3, 4, 5])
    _, known, _ = rel(ekf, z, r, ekf.individual_compatibility(z, r), 0.0)
    assert known is None  # accepted: the association must be made again on the new d2
    assert rel.counts() == {"relocalisation_tests": 1, "relocalisations": 1}


def test_pool_window_moves_earlier_detections_by_the_odometry_and_drops_repeats():
    from fuzzyslam import se2
    from fuzzyslam.slam.relocalise import _Sighting, pool_window

    # the robot drove 1 m forward and turned 90 deg left since the earlier frame
    odo_then, odo_now = np.array([0.0, 0.0, 0.0]), np.array([1.0, 0.0, np.pi / 2])
    r = np.repeat(np.diag([0.1**2, 0.05**2])[None], 2, axis=0)
    world = np.array([[3.0, 0.0], [1.0, 2.0]])  # two landmarks
    then = _Sighting(0.0, odo_then, se2.inverse_transform_points(odo_then, world), r)
    # now the frame sees the second landmark only
    z_now = se2.inverse_transform_points(odo_now, world[1:])
    zw, rw = pool_window(z_now, r[:1], odo_now, [then], GATE)
    assert zw.shape == (2, 2)  # the repeat of landmark 2 dropped, landmark 1 added
    assert np.allclose(zw[0], z_now[0])
    assert np.allclose(zw[1], se2.inverse_transform_points(odo_now, world[:1])[0])  # (0, -2)
    # its covariance turned with it: range along the robot's new -y axis
    assert np.allclose(rw[1], np.diag([0.05**2, 0.1**2]))


def test_window_relocalises_a_pose_seen_one_or_two_landmarks_at_a_time():
    """Frames of 1-2 detections cannot call for the test; pooled over 2 s they do: the
    disturbance is accepted (P_rr + Q exactly), and the frames that follow pair each
    detection with its own landmark until the pose is consistent again. Without the window
    the filter never pairs again."""
    from fuzzyslam.slam.lamp_update import associate_update
    from fuzzyslam.slam.params import SlamParams

    # groups of different shapes, as a real arena's (a pair, a single, a wider pair)
    lamps = np.array([[3.0, 0.0], [3.0, 0.2], [3.2, 2.5], [0.0, 3.0], [0.3, 3.1], [-1.5, 2.0]])
    true = np.array([0.5, 0.5, 0.3])
    est = true + np.array([0.0, 0.0, np.radians(20.0)])  # 10 sigma off
    frames = [[0, 3], [2], [1, 5], [4], [0, 3], [2, 5], [1, 4]]  # still, 0.25 s apart
    results = {}
    for window in (0.0, 2.0):
        p = SlamParams(
            relocalise_sigma_m=0.5, relocalise_sigma_heading_deg=30.0, relocalise_window_s=window
        )
        rel = Relocaliser.from_params(p)
        ekf = EkfSlam(est, np.diag([1e-4, 1e-4, np.radians(2.0) ** 2]), NOISE, capacity=8)
        for lamp in lamps:
            ekf.add_lamp(inverse_transform_points(ekf.pose, lamp[None])[0], np.eye(2) * 1e-8)
        paired, grew = [], []
        for k, ids in enumerate(frames):
            rng = np.random.default_rng(k)
            z = inverse_transform_points(true, lamps[ids]) + rng.normal(size=(len(ids), 2)) * 0.03
            r = np.repeat(np.diag([0.1**2, 0.05**2])[None], len(ids), axis=0)
            rel.moved(np.zeros(3))
            p_before = ekf.P.copy()
            d2, known, lin = rel(ekf, z, r, ekf.individual_compatibility(z, r), 0.25 * k)
            grew.append(ekf.P[:3, :3] - p_before[:3, :3])
            with ekf.linearised_at(lin):
                assoc, _ = associate_update(ekf, z, r, d2, GATE, 4.0, known)
            rel.unexplained(0.25 * k, z, r, assoc)
            paired.append([(ids[j], i) for j, i in assoc.pairs])
        results[window] = (paired, grew, rel.counts(), ekf)
    paired, grew, counts, _ = results[0.0]
    assert counts["relocalisations"] == 0 and all(not pr for pr in paired)
    paired, grew, counts, ekf = results[2.0]
    assert counts["relocalisations"] == 1
    k = next(k for k, g in enumerate(grew) if np.any(g))
    assert k == 1 and np.allclose(grew[k], Q)  # frame 1 pooled with frame 0: P_rr + Q
    assert all(lid == i for pr in paired for lid, i in pr)  # never a wrong pairing
    assert sum(len(pr) for pr in paired[k:]) >= 4
    e = ekf.pose - true
    assert abs(np.degrees(e[2])) < 2.0
    assert e @ np.linalg.solve(ekf.pose_cov, e) < 16.27  # consistent again


def test_a_young_map_of_min_pairs_lamps_is_not_relocalised_on_landmarks_not_yet_mapped():
    # the map holds three lamps; the robot, where the filter says it is, sees three
    # landmarks not yet mapped that stand like them, 0.8 m and 40 deg off (a disturbance
    # of 1.6 and 1.3 sigma of Q): the test pairs the whole map with them and turns the
    # filter 40 deg. With min_lamps = 4 it waits for a map with a lamp more than the
    # pairings it needs; the detections stay unexplained (new landmarks)
    true = np.array([0.5, 0.5, 0.3])
    ekf = EkfSlam(true, np.diag([1e-4, 1e-4, np.radians(2.0) ** 2]), NOISE, capacity=8)
    for lamp in LAMPS[:3]:
        ekf.add_lamp(inverse_transform_points(true, lamp[None])[0], np.eye(2) * 1e-8)
    z = inverse_transform_points(true, LAMPS[:3])
    c, s = np.cos(np.radians(40.0)), np.sin(np.radians(40.0))
    z = z @ np.array([[c, s], [-s, c]]) + [0.8, 0.0]  # the look-alikes, in the robot frame
    r = np.repeat(np.diag([0.1**2, 0.05**2])[None], 3, axis=0)
    d2 = ekf.individual_compatibility(z, r)
    _, test = relocalisation_test(copy.deepcopy(ekf), z, r, d2, GATE, 4.0, Q)
    assert test is not None and test.accepted and test.pairs_before == 0  # without min_lamps
    p0, x0 = ekf.P.copy(), ekf.x.copy()
    out, test = relocalisation_test(ekf, z, r, d2, GATE, 4.0, Q, min_lamps=4)
    assert test is None and out is d2
    assert np.array_equal(ekf.P, p0) and np.array_equal(ekf.x, x0)
    rel = Relocaliser(Q, GATE, 4.0, window_s=2.0, min_lamps=4)
    assert rel.update_if_explained(ekf, z, r, d2) is None
    out, known, lin = rel(ekf, z, r, d2, 0.0)
    assert out is d2 and known is None and lin is None
    assert rel.counts() == {"relocalisation_tests": 0, "relocalisations": 0}
    assert np.array_equal(ekf.x, x0)
