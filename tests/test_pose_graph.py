"""The pose graph of the live map's loop closure (fixes/pose_graph.py), and the path
moved with its keyframes (fixes/live_map.corrected_path).

The analytic Jacobians against central differences of the errors; consistent edges
leave the poses where they are; a square loop driven with a biased odometry is pulled
back onto the truth by one loop edge, and a false loop edge is turned down by the
robust weights.
"""

from __future__ import annotations

import itertools
import math

import numpy as np

from fuzzyslam.fixes.live_map import corrected_path
from fuzzyslam.fixes.pose_graph import edge_errors, edge_jacobians, optimise
from fuzzyslam.se2 import between, compose, wrap_angle


def square_loop(n_side: int = 10, step: float = 1.0) -> np.ndarray:
    """Poses around a square, n_side steps a side, turning 90 deg at each corner."""
    poses, p = [], np.zeros(3)
    for k in range(4 * n_side):
        poses.append(p.copy())
        turn = math.pi / 2 if (k + 1) % n_side == 0 else 0.0
        p = compose(p, np.array([step, 0.0, turn]))
    return np.array(poses)


def test_jacobians_are_the_derivatives_of_the_errors():
    rng = np.random.default_rng(1)
    poses = rng.normal(0.0, 2.0, (6, 3))
    i, j = np.array([0, 1, 2, 4, 5]), np.array([1, 3, 4, 0, 2])
    z = rng.normal(0.0, 1.0, (5, 3))
    a, b = edge_jacobians(poses, i, j)
    h = 1e-6
    for node, jac in ((i, a), (j, b)):
        for c in range(3):
            num = np.zeros((len(i), 3))
            for e in range(len(i)):
                up, down = poses.copy(), poses.copy()
                up[node[e], c] += h
                down[node[e], c] -= h
                d = edge_errors(up, i[e : e + 1], j[e : e + 1], z[e : e + 1])
                d -= edge_errors(down, i[e : e + 1], j[e : e + 1], z[e : e + 1])
                d[:, 2] = wrap_angle(d[:, 2])
                num[e] = d[0] / (2 * h)
            np.testing.assert_allclose(jac[:, :, c], num, atol=1e-6)


def test_consistent_edges_leave_the_poses_alone():
    truth = square_loop()
    n = len(truth)
    i, j = np.arange(n - 1), np.arange(1, n)
    z = np.array([between(truth[a], truth[b]) for a, b in zip(i, j, strict=True)])
    w = np.repeat(np.eye(3)[None] * 10.0, len(i), axis=0)
    out, info = optimise(truth, i, j, z, w)
    np.testing.assert_allclose(out, truth, atol=1e-9)
    assert info["cost"] < 1e-12


def test_a_loop_edge_pulls_a_biased_path_back_and_a_false_one_is_turned_down():
    truth = square_loop()
    n = len(truth)
    # the odometry turns 1 deg too far at every step: dead reckoning drifts around the loop
    odo = [truth[0]]
    for a, b in itertools.pairwise(truth):
        z = between(a, b)
        odo.append(compose(odo[-1], z + np.array([0.0, 0.0, math.radians(1.0)])))
    odo = np.array(odo)
    i, j = np.arange(n - 1), np.arange(1, n)
    z = np.array([between(odo[a], odo[b]) for a, b in zip(i, j, strict=True)])
    w_odo = np.diag([1 / 0.05, 1 / 0.05, 1 / math.radians(1.5)])
    loop = between(truth[0], truth[n - 1])  # the last pose seen from the first: a loop
    w_loop = np.diag([1 / 0.02, 1 / 0.02, 1 / math.radians(0.5)])
    ii, jj = np.append(i, 0), np.append(j, n - 1)
    zz = np.vstack([z, loop])
    ww = np.concatenate([np.repeat(w_odo[None], len(i), axis=0), w_loop[None]])
    out, info = optimise(odo, ii, jj, zz, ww)
    before = np.hypot(*(odo[:, :2] - truth[:, :2]).T).mean()
    after = np.hypot(*(out[:, :2] - truth[:, :2]).T).mean()
    assert after < 0.25 * before, (before, after)
    assert info["cost"] < info["cost_start"]
    # a false loop edge (the last pose 3 m off) besides the true one: down-weighted
    wrong = compose(loop, np.array([3.0, 0.0, 0.0]))
    out2, info2 = optimise(
        odo, np.append(ii, 0), np.append(jj, n - 1), np.vstack([zz, wrong]),
        np.concatenate([ww, w_loop[None]]),
    )  # fmt: skip
    assert info2["downweighted"] >= 1
    assert np.hypot(*(out2[:, :2] - truth[:, :2]).T).mean() < 0.6 * before


def test_corrected_path_moves_each_pose_with_its_keyframes():
    t = np.linspace(0.0, 10.0, 11)
    path = np.column_stack([t, np.zeros(11), np.zeros(11)])
    t_key = np.array([0.0, 10.0])
    before = path[[0, 10]]
    after = np.array([[0.0, 0.0, 0.0], [10.0, 1.0, 0.0]])  # the end moved 1 m sideways
    out = corrected_path(t, path, t_key, before, after)
    np.testing.assert_allclose(out[:, 0], t, atol=1e-12)
    np.testing.assert_allclose(out[:, 1], t / 10.0, atol=1e-12)  # the correction grows linearly
    # keyframes land where the graph put them
    np.testing.assert_allclose(out[[0, 10]], after, atol=1e-12)


def _two_laps(stretch: float) -> dict:
    """A square driven twice with exact odometry, each second-lap pose tied by a loop
    edge to the first lap's (sigma 2 cm): ``stretch`` of the second lap's distance from
    the square's first corner is what its scan matches say it is beyond the odometry's (a
    map drifted along its corridors); returns ``optimise``'s figures with the graph's
    counts, as KeyframeGraph.solve gives them."""
    lap = square_loop()
    n = len(lap)
    truth = np.vstack([lap, lap])
    i, j = np.arange(2 * n - 1), np.arange(1, 2 * n)
    z = np.array([between(truth[a], truth[b]) for a, b in zip(i, j, strict=True)])
    w = np.repeat(np.diag([1 / 0.05, 1 / 0.05, 1 / math.radians(1.5)])[None], len(i), axis=0)
    li, lj = np.arange(n), np.arange(n, 2 * n)
    seen = lap.copy()
    seen[:, :2] = lap[:, :2] * (1.0 + stretch)  # lap 2 where the drifted map puts it
    lz = np.array([between(lap[a], seen[a]) for a in range(n)])
    lw = np.repeat(np.diag([1 / 0.02, 1 / 0.02, 1 / math.radians(0.5)])[None], n, axis=0)
    _, info = optimise(
        truth, np.append(i, li), np.append(j, lj), np.vstack([z, lz]), np.concatenate([w, lw])
    )
    return {**info, "loops": n, "loop_candidates": n}


def test_a_graph_that_contradicts_itself_is_found_inconsistent():
    """A live map's loops that agree with its odometry leave no edge beyond the robust
    kernel's threshold: consistent. Loops that say the second lap is 30 % longer than
    the odometry (0.3 m a step, 6 sigmas) bend the chain: its edges down-weighted, more
    than half the loop edges' count: inconsistent. And loop candidates of which
    more than 40 % found no match: inconsistent too (at least 10 either way)."""
    from fuzzyslam.fixes.live_map import inconsistent

    good, bent = _two_laps(0.0), _two_laps(0.3)
    assert good["downweighted"] == 0 and not inconsistent(good)
    assert bent["downweighted"] > 0.5 * bent["loops"] and inconsistent(bent)
    assert not inconsistent({"loops": 30, "loop_candidates": 50})  # 20 of 50 unmatched
    assert inconsistent({"loops": 29, "loop_candidates": 50})  # 21 of 50
    assert not inconsistent({"loops": 1, "loop_candidates": 10})  # 9: too few to tell
