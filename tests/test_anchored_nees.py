"""NEES of a real run in the filter's own map frame (evaluation.core.anchored_nees)."""

from __future__ import annotations

import numpy as np

from fuzzyslam.evaluation.align import anchor
from fuzzyslam.evaluation.core import Estimate, Truth, anchored_nees, evaluate
from fuzzyslam.evaluation.params import EvalParams
from fuzzyslam.se2 import compose, inverse


def _path(n: int = 400) -> tuple[np.ndarray, np.ndarray]:
    t = 1.25e9 + 0.05 * np.arange(n)  # Unix-time stamps, as real logs have
    a = np.linspace(0.0, 3.0, n)
    poses = np.column_stack([2.0 * np.sin(a), 1.5 * (1 - np.cos(a)), a + 0.3])
    return t, poses


def test_anchor_maps_the_estimated_pose_onto_the_true_one():
    rng = np.random.default_rng(3)
    for _ in range(20):
        e, tr = rng.normal(size=3) * [5, 5, 3], rng.normal(size=3) * [5, 5, 3]
        s = anchor(e, tr)
        got = s.apply_poses(e)[0]
        assert np.allclose(got[:2], tr[:2]) and np.isclose(np.cos(got[2] - tr[2]), 1.0)
        # the same motion as the SE(2) product T_truth T_est^-1
        m = compose(tr, inverse(e))
        p = rng.normal(size=3)
        q = s.apply_poses(p)[0]
        r = compose(m, p)
        assert np.allclose(q[:2], r[:2]) and np.isclose(np.cos(q[2] - r[2]), 1.0)


def test_anchored_nees_is_the_error_in_the_filter_frame():
    """An estimate in its own frame (the truth moved by an arbitrary rigid motion, the
    first poses equal) with known errors: the NEES is e^T P^-1 e of those errors, while a
    whole-path alignment would report the first pose off by the spread of the late errors."""
    t, truth = _path()
    frame = np.array([-3.0, 7.0, 1.1])  # the run's map frame: the robot's start
    est = np.array([compose(inverse(compose(truth[0], inverse(frame))), p) for p in truth])
    # errors that grow with time in the filter's frame, and a covariance that grows too
    rng = np.random.default_rng(0)
    sig = np.column_stack(
        [0.001 + 0.01 * np.arange(len(t)) ** 0.5] * 2 + [0.001 + 0.002 * np.arange(len(t)) ** 0.5]
    )
    err = rng.normal(size=est.shape) * sig
    err[0] = 0.0
    cov = np.zeros((len(t), 3, 3))
    cov[:, [0, 1, 2], [0, 1, 2]] = sig**2
    est_noisy = est + err
    e = Estimate(t, est_noisy, cov=cov)
    tr = Truth(t, truth)
    got = anchored_nees(e, tr, EvalParams())
    want = np.sum(err**2 / sig**2, axis=1)
    assert np.allclose(got, want, rtol=1e-6, atol=1e-9)
    # through evaluate with alignment: the headline NEES is this one's mean
    ev = evaluate(tr, e, EvalParams(), align=True)
    assert np.isclose(ev.typed.headline.nees_mean, np.nanmean(want), rtol=1e-6)
    assert ev.typed.aligned_to_truth["nees_frame"] == "first pose"
