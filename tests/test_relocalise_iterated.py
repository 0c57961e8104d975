"""The iterated relocalisation (slam/iterated.py ``iterated_association``) and the lamp
model linearised at another pose (``EkfSlam.linearised_at``), on the real filter, in the
paper's setting: ceiling lamps 2.7 m apart along a corridor, detections of 0.7 mm, a
pose that a bump turned by 10 deg unseen."""

from __future__ import annotations

import copy

import numpy as np
import pytest

from fuzzyslam.se2 import inverse_transform_points, wrap_angle
from fuzzyslam.slam.association import jcbb, joint_nis
from fuzzyslam.slam.ekf import EkfSlam, lamp_measurement
from fuzzyslam.slam.iterated import converge, nearest_pairs
from fuzzyslam.slam.lamp_update import associate_update
from fuzzyslam.slam.params import SlamParams
from fuzzyslam.slam.relocalise import Relocaliser, relocalisation_test

NOISE = (2.5e-6, 1e-6, 1e-4, 1e-6)
GATE = 9.21
MARGIN = 4.0
SIGMA_Z = 7e-4  # the paper camera's detections (m)
CHI2_3 = 16.27  # chi-square, 3 dof, 99.9 %
# lamps along the corridor's centre line, 2.7 m apart
LAMPS = np.column_stack([np.arange(-2, 6) * 2.7, np.zeros(8)])
TRUE = np.array([1.2, 0.15, 0.02])
SEEN = [0, 1, 2]  # lamps 2, 3, 4 of LAMPS (x = 0, 2.7, 5.4): ranges 1.2, 1.5, 4.2 m
P_RR = np.diag([0.005**2, 0.005**2, np.radians(0.05) ** 2])
PARAMS = SlamParams(
    relocalise_sigma_m=0.1, relocalise_sigma_heading_deg=15.0, relocalise_min_pairs=2
)


def _filter(pose_est: np.ndarray) -> EkfSlam:
    """A filter whose map holds LAMPS to 0.1 mm (P_l = 1e-8 I, uncorrelated with the pose)
    and whose pose is ``pose_est`` with covariance P_RR."""
    ekf = EkfSlam(pose_est, np.zeros((3, 3)), NOISE, capacity=len(LAMPS))
    for lamp in LAMPS:
        ekf.add_lamp(inverse_transform_points(ekf.pose, lamp[None])[0], np.eye(2) * 1e-8)
    ekf.inflate_robot(P_RR)
    return ekf


def _frame(ids: list[int], seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Detections of lamps ``ids`` (indices into LAMPS[2:]) from TRUE, with their noise."""
    rng = np.random.default_rng(seed)
    z = inverse_transform_points(TRUE, LAMPS[2:][ids])
    z = z + rng.normal(size=z.shape) * SIGMA_Z
    return z, np.repeat(np.eye(2)[None] * SIGMA_Z**2, len(ids), axis=0)


def _nees(ekf: EkfSlam) -> float:
    e = ekf.pose - TRUE
    e[2] = wrap_angle(e[2])
    return float(e @ np.linalg.solve(ekf.pose_cov, e))


def _bumped() -> np.ndarray:
    """The estimate after an unseen 10-deg bump (and 3 mm of position error)."""
    return TRUE + np.array([0.003, -0.002, np.radians(10.0)])


def test_linearised_at_is_the_first_order_expansion_about_the_pose():
    ekf = _filter(_bumped())
    z, r = _frame(SEEN)
    ekf.inflate_robot(np.diag([0.01, 0.01, np.radians(15.0) ** 2]))
    h0, _, hc0 = ekf.predict_lamps([2, 3, 4])
    d0 = ekf.individual_compatibility(z, r)
    with ekf.linearised_at(ekf.pose):  # at the state's own pose: the plain EKF's model
        h1, _, hc1 = ekf.predict_lamps([2, 3, 4])
        assert np.allclose(h1, h0, atol=1e-15) and np.array_equal(hc1, hc0)
        assert np.allclose(ekf.individual_compatibility(z, r), d0, rtol=1e-12)
    lin = TRUE + np.array([0.01, -0.02, 0.05])
    x = ekf.pose
    with ekf.linearised_at(lin):
        assert np.array_equal(ekf.lin_pose, lin)
        h, _, hc = ekf.predict_lamps([2, 3, 4])
        d2 = ekf.individual_compatibility(z, r)
        # second implementation: h(x_i) + H_r(x_i) (x - x_i), lamp by lamp
        for a, i in enumerate([2, 3, 4]):
            hi, hri, hli = lamp_measurement(lin, LAMPS[i])
            dx = x - lin
            assert np.allclose(h[2 * a : 2 * a + 2], hi + hri @ dx, atol=1e-14)
            assert np.allclose(hc[2 * a : 2 * a + 2, :3], hri, atol=1e-15)
            assert np.allclose(hc[2 * a : 2 * a + 2, 3 + 2 * a : 5 + 2 * a], hli, atol=1e-15)
        # the vectorised distances against the stacked prediction's NIS, pair by pair
        for j in range(len(z)):
            for i in range(len(LAMPS)):
                assert d2[j, i] == pytest.approx(joint_nis(ekf, [(j, i)], z, r), rel=1e-9)
    assert ekf.lin_pose is None  # restored on leaving


def test_converge_finds_the_map_pose_of_a_hypothesis():
    """The iterate is the MAP pose: the gradient of (x - x0)^T P^-1 (x - x0) +
    sum |z - h(x)|^2_(R + P_l) vanishes there (the lamps, independent of the pose, enter
    with their covariance P_l = 1e-8 I)."""
    ekf = _filter(_bumped())
    ekf.inflate_robot(np.diag([0.01, 0.01, np.radians(15.0) ** 2]))
    z, r = _frame(SEEN)
    pairs = [(0, 2), (1, 3), (2, 4)]
    x0, pinv = ekf.pose.copy(), np.linalg.inv(ekf.pose_cov)

    def cost(x: np.ndarray) -> float:
        d = x - x0
        res = [z[j] - lamp_measurement(x, LAMPS[i])[0] for j, i in pairs]
        return float(d @ pinv @ d + sum(v @ v for v in res) / (SIGMA_Z**2 + 1e-8))

    xs = converge(ekf, z, r, pairs)
    assert abs(np.degrees(xs[2] - TRUE[2])) < 0.02  # the bump taken out
    eps = np.array([1e-7, 1e-7, 1e-8])
    grad = [(cost(xs + e) - cost(xs - e)) / (2 * e[k]) for k, e in enumerate(np.diag(eps))]
    scale = [abs(cost(x0 + e) - cost(x0 - e)) / (2 * e[k]) for k, e in enumerate(np.diag(eps))]
    assert np.all(np.abs(grad) < 1e-4 * np.array(scale))
    assert cost(xs) < 1e-3 * cost(x0)


@pytest.mark.parametrize("ids", [SEEN, [0, 1]])
def test_a_10_degree_bump_relocalises_on_the_first_frame_and_lands_within_the_noise(ids):
    ekf = _filter(_bumped())
    z, r = _frame(ids, seed=len(ids))
    d2 = ekf.individual_compatibility(z, r)
    assert np.all(d2.min(axis=1) > 100.0)  # every lamp far outside its gate
    rel = Relocaliser.from_params(PARAMS)
    # the single linearisation at the bumped pose: under the same inflation each pair
    # passes its gate, but no two pass the joint test (r dtheta^2 / 2 >> 0.7 mm)
    trial = copy.deepcopy(ekf)
    trial.inflate_robot(rel.q)
    dw = trial.individual_compatibility(z, r)
    assert np.all(dw.min(axis=1) <= GATE)
    assert len(jcbb(trial, z, r, dw, GATE, MARGIN).best) <= 1
    d2_new, known, lin = rel(ekf, z, r, d2, 0.0)
    assert rel.counts() == {"relocalisation_tests": 1, "relocalisations": 1}
    assert lin is not None and abs(np.degrees(wrap_angle(lin[2] - TRUE[2]))) < 0.1
    plain = copy.deepcopy(ekf)  # the same pairs updated at the bumped pose instead
    with ekf.linearised_at(lin):
        assoc, res = associate_update(ekf, z, r, d2_new, GATE, MARGIN, known)
    assert sorted(assoc.pairs) == [(j, j + 2) for j in range(len(ids))]
    assert res.accepted
    assert _nees(ekf) < CHI2_3  # the update of the iterated EKF lands within the noise
    assert abs(np.degrees(wrap_angle(ekf.pose[2] - TRUE[2]))) < 0.1
    det = [j for j, _ in assoc.pairs]
    plain.update_lamps(
        [i for _, i in assoc.pairs], z[det], np.kron(np.eye(len(det)), r[0])
    )  # one linearised step: the second-order error stays in the pose
    assert _nees(plain) > CHI2_3
    assert np.allclose(ekf.P, ekf.P.T) and np.linalg.eigvalsh(ekf.P).min() > 0


def test_two_detections_need_min_pairs_2():
    ekf = _filter(_bumped())
    z, r = _frame([0, 1])
    d2 = ekf.individual_compatibility(z, r)
    q = Relocaliser.from_params(PARAMS).q
    assert relocalisation_test(ekf, z, r, d2, GATE, MARGIN, q)[1] is None  # default 3
    p0 = ekf.P.copy()
    _, test = relocalisation_test(ekf, z, r, d2, GATE, MARGIN, q, min_pairs=2)
    assert test.accepted and test.pairs_after == 2 and np.allclose(ekf.P[:3, :3] - p0[:3, :3], q)


@pytest.mark.parametrize("ids", [SEEN, [0, 1]])
def test_no_relocalisation_when_the_heading_is_right(ids):
    """A pose within its covariance: the frame is explained, nothing is tested and the
    filter is left bit for bit as it was; the usual update follows."""
    est = TRUE + np.array([0.004, -0.003, np.radians(0.05)])
    ekf = _filter(est)
    rel = Relocaliser.from_params(PARAMS)
    for k in range(5):
        z, r = _frame(ids, seed=10 + k)
        x0, p0 = ekf.x.copy(), ekf.P.copy()
        d2 = ekf.individual_compatibility(z, r)
        out, known, lin = rel(ekf, z, r, d2, 0.2 * k)
        assert lin is None and out is d2
        assert np.array_equal(ekf.x, x0) and np.array_equal(ekf.P, p0)
        assoc, _ = associate_update(ekf, z, r, d2, GATE, MARGIN, known)
        assert assoc.pairs and all(i == j + 2 for j, i in assoc.pairs)
    assert rel.counts()["relocalisations"] == 0
    assert _nees(ekf) < CHI2_3


def test_no_relocalisation_beyond_the_disturbance_prior():
    """The pose 0.5 m off along the corridor (5 sigmas of the disturbance's 10 cm) and
    turned 10 deg: not a bump. Some detections pass their gates under the inflation, but
    the hypothesis' MAP cost (its prior term alone is 25) fails the joint test, so
    nothing is paired and the filter stays bit for bit as it was."""
    ekf = _filter(_bumped() + np.array([0.5, 0.0, 0.0]))
    z, r = _frame(SEEN)
    x0, p0 = ekf.x.copy(), ekf.P.copy()
    rel = Relocaliser.from_params(PARAMS)
    d2 = ekf.individual_compatibility(z, r)
    _, _, lin = rel(ekf, z, r, d2, 0.0)
    assert lin is None and rel.counts() == {"relocalisation_tests": 1, "relocalisations": 0}
    assert np.array_equal(ekf.x, x0) and np.array_equal(ekf.P, p0)
    # the same pose 5 cm off (half a sigma) is relocalised
    ekf = _filter(_bumped() + np.array([0.05, 0.0, 0.0]))
    assert rel(ekf, z, r, ekf.individual_compatibility(z, r), 0.0)[2] is not None


def test_nearest_pairs_takes_each_lamp_once_nearest_first():
    d2 = np.array([[0.5, 3.0, np.inf], [0.2, 8.0, 1.0], [20.0, 20.0, 20.0]])
    assert nearest_pairs(d2, GATE) == [(0, 1), (1, 0)]
    assert nearest_pairs(np.full((2, 3), 50.0), GATE) == []


@pytest.mark.parametrize(
    "est",
    [
        TRUE + np.array([0.004, -0.003, np.radians(0.05)]),  # within its covariance
        TRUE + np.array([0.004, -0.003, np.radians(0.3)]),  # a lamp or two out of gate
        _bumped(),  # every lamp out of gate: the test relocalises
    ],
)
def test_update_if_explained_is_the_test_and_association_it_spares(est):
    """Relocaliser.update_if_explained (the runner's first step) against the full path it
    stands for (the relocalisation test, then associate_update with the test's JCBB): on
    frames of 1-3 lamps, noisy, from a pose within and out of its covariance, either it
    declines and leaves the filter bit for bit as it was, or the full path left the
    frame untested and made the same update: the same pairs, state and covariance, bit
    for bit."""
    rel_a, rel_b = Relocaliser.from_params(PARAMS), Relocaliser.from_params(PARAMS)
    a, b = _filter(est), _filter(est)
    made = declined = 0
    for k, ids in enumerate([[0], [0, 1], SEEN, [1, 2], SEEN, [0, 2]] * 2):
        z, r = _frame(ids, seed=30 + k)
        x0, p0 = a.x.copy(), a.P.copy()
        done = rel_a.update_if_explained(a, z, r, a.individual_compatibility(z, r))
        d2 = b.individual_compatibility(z, r)
        tests = rel_b.tests
        d2, known, lin = rel_b(b, z, r, d2, 0.2 * k)
        with b.linearised_at(lin):
            assoc, _ = associate_update(b, z, r, d2, GATE, MARGIN, known)
        if done is None:
            declined += 1
            assert np.array_equal(a.x, x0) and np.array_equal(a.P, p0)
            d2a = a.individual_compatibility(z, r)
            d2a, known_a, lin_a = rel_a(a, z, r, d2a, 0.2 * k)
            with a.linearised_at(lin_a):
                associate_update(a, z, r, d2a, GATE, MARGIN, known_a)
        else:
            made += 1
            assert rel_b.tests == tests and lin is None  # untested on the full path
            assert done[0].pairs == assoc.pairs
        assert np.array_equal(a.x, b.x) and np.array_equal(a.P, b.P)
    assert made > 0 and declined > 0
