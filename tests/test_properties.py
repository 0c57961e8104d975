"""Property-based tests of the maths (issue 7), with hypothesis.

- SE(2): angle wrapping to (-pi, pi], compose/inverse group identities, the
  composition Jacobians against central finite differences;
- TBM (``maps.tbm``): masses stay non-negative and sum to 1 under random sequences of
  conjunctive combinations and discountings; commutativity, associativity, the
  vacuous function as neutral element, the grouped combination equal to a fold;
- EKF-SLAM (``slam.ekf.EkfSlam``): P stays symmetric positive definite across long
  random sequences of predictions, lamp additions and updates (including headings
  across +-pi), and no update ever increases P (Loewner order).
"""

from __future__ import annotations

import math

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from fuzzyslam.maps import tbm
from fuzzyslam.se2 import (
    between,
    compose,
    inverse,
    inverse_transform_points,
    jacobians_compose,
    transform_points,
    wrap_angle,
)
from fuzzyslam.slam.ekf import EkfSlam

FAST = settings(max_examples=200, deadline=None)
finite = st.floats(-1e3, 1e3, allow_nan=False)
angles = st.one_of(
    st.floats(-50.0, 50.0, allow_nan=False),
    st.sampled_from([math.pi, -math.pi, 3 * math.pi, -3 * math.pi, 0.0]),
    st.sampled_from([math.pi, -math.pi]).map(lambda a: float(np.nextafter(a, 0.0))),
    st.sampled_from([math.pi, -math.pi]).map(lambda a: float(np.nextafter(a, 10 * a))),
)
poses = st.tuples(finite, finite, angles).map(np.array)


def angle_diff(a, b):
    return np.asarray(wrap_angle(np.asarray(a) - np.asarray(b)))


def assert_pose_close(a, b, tol=1e-9) -> None:
    a, b = np.asarray(a), np.asarray(b)
    scale = 1.0 + np.abs(a[..., :2]).max() + np.abs(b[..., :2]).max()
    np.testing.assert_allclose(a[..., :2], b[..., :2], atol=tol * scale)
    np.testing.assert_allclose(angle_diff(a[..., 2], b[..., 2]), 0.0, atol=tol)


# -- angles -------------------------------------------------------------------------------


@FAST
@given(a=st.one_of(angles, st.floats(-1e6, 1e6, allow_nan=False)))
def test_wrap_angle_range_and_equivalence(a: float) -> None:
    w = wrap_angle(a)
    assert -math.pi < w <= math.pi
    k = (a - w) / (2 * math.pi)
    assert abs(k - round(k)) < 1e-9 * max(1.0, abs(a))
    assert wrap_angle(w) == w


def test_wrap_angle_at_pi() -> None:
    assert wrap_angle(math.pi) == math.pi
    assert wrap_angle(-math.pi) == math.pi
    arr = wrap_angle(np.array([math.pi, -math.pi, 3 * math.pi, np.nextafter(math.pi, 4.0)]))
    assert np.all((arr > -math.pi) & (arr <= math.pi))


# -- SE(2) --------------------------------------------------------------------------------


@FAST
@given(a=poses, b=poses, c=poses)
def test_se2_group_identities(a, b, c) -> None:
    zero = np.zeros(3)
    assert_pose_close(compose(a, inverse(a)), zero)
    assert_pose_close(compose(inverse(a), a), zero)
    assert_pose_close(inverse(inverse(a)), a)
    assert_pose_close(compose(compose(a, b), c), compose(a, compose(b, c)), 1e-8)
    assert_pose_close(between(a, compose(a, b)), b, 1e-8)
    assert_pose_close(inverse(compose(a, b)), compose(inverse(b), inverse(a)), 1e-8)
    assert -math.pi < compose(a, b)[2] <= math.pi


@FAST
@given(a=poses, pts=arrays(float, (5, 2), elements=st.floats(-100, 100)))
def test_points_round_trip_and_agree_with_compose(a, pts) -> None:
    back = inverse_transform_points(a, transform_points(a, pts))
    np.testing.assert_allclose(back, pts, atol=1e-9 * (1 + np.abs(a[:2]).max()))
    as_poses = np.column_stack([pts, np.zeros(len(pts))])
    np.testing.assert_allclose(transform_points(a, pts), compose(a, as_poses)[:, :2], atol=1e-9)


def numeric_jacobian(f, x, eps=1e-6):
    cols = []
    for i in range(3):
        d = np.zeros(3)
        d[i] = eps
        hi, lo = f(x + d), f(x - d)
        diff = hi - lo
        diff[2] = angle_diff(hi[2], lo[2])
        cols.append(diff / (2 * eps))
    return np.column_stack(cols)


@FAST
@given(
    a=st.tuples(st.floats(-50, 50), st.floats(-50, 50), angles).map(np.array),
    b=st.tuples(st.floats(-50, 50), st.floats(-50, 50), angles).map(np.array),
)
def test_compose_jacobians_match_finite_differences(a, b) -> None:
    ja, jb = jacobians_compose(a, b)
    np.testing.assert_allclose(ja, numeric_jacobian(lambda x: compose(x, b), a), atol=1e-5)
    np.testing.assert_allclose(jb, numeric_jacobian(lambda x: compose(a, x), b), atol=1e-5)


# -- TBM belief masses --------------------------------------------------------------------


def masses_strategy(n: int = 8):
    """n random mass functions (m_e, m_o, m_t, m_c), some with exact zeros."""
    raw = arrays(float, (4, n), elements=st.one_of(st.just(0.0), st.floats(0.0, 1.0)))
    return raw.filter(lambda r: np.all(r.sum(axis=0) > 1e-6)).map(
        lambda r: tuple(r / r.sum(axis=0))
    )


def assert_valid(m, tol=1e-12) -> None:
    stacked = np.stack(m)
    assert np.all(np.isfinite(stacked))
    assert np.all(stacked >= -tol)
    np.testing.assert_allclose(stacked.sum(axis=0), 1.0, atol=1e-9)


def assert_same(m1, m2, tol=1e-9) -> None:
    np.testing.assert_allclose(np.stack(m1), np.stack(m2), atol=tol)


@FAST
@given(m1=masses_strategy(), m2=masses_strategy(), m3=masses_strategy())
def test_conjunctive_rule_algebra(m1, m2, m3) -> None:
    assert_valid(tbm.conjunctive(m1, m2))
    assert_same(tbm.conjunctive(m1, m2), tbm.conjunctive(m2, m1))
    assert_same(
        tbm.conjunctive(tbm.conjunctive(m1, m2), m3), tbm.conjunctive(m1, tbm.conjunctive(m2, m3))
    )
    n = len(m1[0])
    vacuous = (np.zeros(n), np.zeros(n), np.ones(n), np.zeros(n))
    assert_same(tbm.conjunctive(m1, vacuous), m1)
    # combination never creates ignorance nor removes conflict
    m12 = tbm.conjunctive(m1, m2)
    assert np.all(m12[2] <= np.minimum(m1[2], m2[2]) + 1e-12)
    assert np.all(m12[3] >= np.maximum(m1[3], m2[3]) - 1e-12)


@settings(max_examples=60, deadline=None)
@given(
    seq=st.lists(
        st.tuples(masses_strategy(), st.floats(0.0, 1.0), st.floats(0.0, 1.0)),
        min_size=1,
        max_size=60,
    )
)
def test_random_update_sequences_keep_masses_valid(seq) -> None:
    """The FGM's cell update: forget by the conflict, then combine; over long random
    sequences the four masses stay in [0, 1] and sum to 1."""
    n = len(seq[0][0][0])
    m = (np.zeros(n), np.zeros(n), np.ones(n), np.zeros(n))
    for reading, gamma, alpha in seq:
        m = tbm.discount(m, tbm.forgetting_factor(m[3], gamma))
        assert_valid(m)
        m = tbm.conjunctive(m, tbm.discount(reading, alpha))
        assert_valid(m)
        m = tbm.clip_masses(m)
        assert_valid(m)


@settings(max_examples=80, deadline=None)
@given(ms=st.lists(masses_strategy(1), min_size=1, max_size=12), data=st.data())
def test_grouped_combination_equals_a_fold(ms, data) -> None:
    groups = np.array(data.draw(st.lists(st.integers(0, 2), min_size=len(ms), max_size=len(ms))))
    stacked = tuple(np.concatenate([m[k] for m in ms]) for k in range(4))
    got = tbm.conjunctive_grouped(stacked, groups, 3)
    assert_valid(got, tol=1e-9)
    for g in range(3):
        acc = (np.zeros(1), np.zeros(1), np.ones(1), np.zeros(1))
        for m, gi in zip(ms, groups, strict=True):
            if gi == g:
                acc = tbm.conjunctive(acc, m)
        assert_same(tuple(x[g : g + 1] for x in got), acc, tol=1e-9)


# -- EKF covariance -----------------------------------------------------------------------

ALPHA = (0.01, 0.001, 0.005, 0.001)  # k_tt, k_tr, k_rr, k_rt


def assert_spd(p: np.ndarray) -> None:
    assert np.all(np.isfinite(p))
    np.testing.assert_array_equal(p, p.T)  # exactly symmetric
    assert np.linalg.eigvalsh(p).min() > 0.0
    np.linalg.cholesky(p)


steps = st.lists(
    st.one_of(
        st.tuples(st.just("predict"), st.floats(-0.5, 0.5), st.floats(-1.0, 1.0)),
        st.tuples(st.just("lamp"), st.floats(-3.0, 3.0), st.floats(-3.0, 3.0)),
        st.tuples(st.just("see"), st.floats(0.0, 1.0), st.floats(1e-6, 0.3)),
        st.tuples(st.just("heading"), angles, st.floats(1e-6, 0.5)),
        st.tuples(st.just("pose"), st.floats(-1.0, 1.0), st.floats(1e-6, 1.0)),
    ),
    min_size=20,
    max_size=150,
)


@settings(max_examples=60, deadline=None)
@given(
    start=st.tuples(st.floats(-10, 10), st.floats(-10, 10), angles).map(np.array),
    sigma=st.floats(1e-6, 1.0),
    seq=steps,
    seed=st.integers(0, 2**16),
)
def test_covariance_stays_positive_definite(start, sigma, seq, seed) -> None:
    """Random predictions, lamp additions, (possibly gated-out) lamp updates with
    near-noiseless or noisy measurements, heading fixes at any angle (across +-pi) and
    full pose fixes: P symmetric positive definite after every step, an accepted
    update never increases P, the heading stays in (-pi, pi]."""
    rng = np.random.default_rng(seed)
    ekf = EkfSlam(start, np.eye(3) * sigma**2, ALPHA)
    for kind, a, b in seq:
        before = ekf.P.copy()
        if kind == "predict":
            ekf.predict(a, b)
        elif kind == "lamp":
            ekf.add_lamp(np.array([a, b]), np.eye(2) * 0.01)
        elif kind == "see" and ekf.n_lamps:
            i = min(int(a * ekf.n_lamps), ekf.n_lamps - 1)
            h, _, _ = ekf.predict_lamps([i])
            z = h + rng.normal(0.0, b, 2)
            res = ekf.update_lamp(i, z, np.eye(2) * b**2, gate_chi2=13.8)
            if res.accepted:
                gain = np.linalg.eigvalsh(before - ekf.P)
                assert gain.min() >= -1e-9 * max(1.0, np.abs(before).max())
        elif kind == "heading":
            ekf.update_robot([a], [[b**2]], [2])
        elif kind == "pose":
            z = ekf.pose + np.array([a, -a, a]) * 0.1
            ekf.update_robot(z, np.eye(3) * b**2, [0, 1, 2], gate_chi2=16.3)
        assert_spd(ekf.P)
        assert np.all(np.isfinite(ekf.x))
        assert -math.pi < ekf.x[2] <= math.pi
