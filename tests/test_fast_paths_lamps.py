"""The lamps-only run's speed paths give the same floats as the general ones (issue 16).

Each test compares a fast path with a second implementation, bit for bit (the run's
outputs stay byte-identical): ``solve_spd`` (LAPACK gufuncs without numpy.linalg's
wrappers) against ``np.linalg.solve``, and its regularisation of a singular or indefinite
S; ``DetectionNoiseEstimator.add`` (floats) against the matrix formula;
``EkfSlam.individual_compatibility`` against the per-pair S = H P H^T + R of
``predict_lamps``; ``se2.compose_with_jacobians`` against ``compose`` and
``jacobians_compose``; the batched landmark ellipses against one ``eigh`` per lamp;
``CeilingCamera.unproject`` against ``project``; updates.csv lines against ``csv.writer``;
``cli._register`` importing only the invoked command.
"""

from __future__ import annotations

import csv
import io
import math
import subprocess
import sys

import numpy as np
import pytest

from fuzzyslam import se2
from fuzzyslam.camera import CeilingCamera
from fuzzyslam.slam.association import block_diag_cov
from fuzzyslam.slam.ekf import EkfSlam
from fuzzyslam.slam.events import UpdateRow
from fuzzyslam.slam.health import solve_spd
from fuzzyslam.slam.markers import _ellipses
from fuzzyslam.slam.noise import DetectionNoiseEstimator
from fuzzyslam.slam.outputs import _num, _update_line
from fuzzyslam.stamps import format_time


@pytest.mark.parametrize("k", [1, 2, 4, 6])
def test_solve_spd_equals_numpy_solve(k):
    rng = np.random.default_rng(k)
    for _ in range(200):
        a = rng.normal(size=(k, k))
        s = a @ a.T + np.eye(k) * rng.uniform(1e-6, 1.0)
        s = 0.5 * (s + s.T)
        b = rng.normal(size=(k, 7))
        x, reg = solve_spd(s, b)
        assert not reg and np.array_equal(x, np.linalg.solve(s, b))
        x1, _ = solve_spd(s, b[:, 0])
        assert np.array_equal(x1, np.linalg.solve(s, b[:, 0]))


def test_solve_spd_regularises_singular_and_indefinite():
    b = np.array([1.0, 2.0])
    for s in (np.array([[1.0, 1.0], [1.0, 1.0]]), np.array([[-1.0, 0.0], [0.0, 1.0]])):
        x, reg = solve_spd(s, b)
        assert reg and np.all(np.isfinite(x))
        # the smallest load e tried tenfold from rel_eps trace / k that makes S + e I PD
        eps = max(1e-12 * abs(np.trace(s)) / 2, 1e-15)
        while np.linalg.eigvalsh(s + eps * np.eye(2)).min() <= 0:
            eps *= 10.0
        assert np.allclose((s + eps * np.eye(2)) @ x, b)
    with pytest.raises(np.linalg.LinAlgError):
        solve_spd(np.array([[1.0, 0.0], [0.0, np.inf]]), b)
    with pytest.raises(np.linalg.LinAlgError):
        solve_spd(np.eye(2), np.array([np.nan, 0.0]))


def test_noise_add_equals_matrix_formula():
    rng = np.random.default_rng(7)
    est = DetectionNoiseEstimator()
    for _ in range(2000):
        z = rng.normal(size=2) * 3.0
        v = rng.normal(size=2) * 1e-2
        a = rng.normal(size=(2, 2)) * 1e-2
        s = a @ a.T + np.eye(2) * 1e-4
        r = np.eye(2) * rng.uniform(1e-5, 1e-4)
        est.add(z, v, s, r)
        rng_ = math.hypot(z[0], z[1])
        u = z / rng_
        n = np.array([-u[1], u[0]])
        hph = s - r
        vr, vt = float(u @ v), float(n @ v)
        uhu, nhn = float(u @ hph @ u), float(n @ hph @ n)
        got = est._rows[-1]
        assert got[0] == rng_
        # numpy's matmul may sum the 2x2 products in another order (or fused) from one
        # release to the next: equal to a few ulps of the terms, not bit for bit
        for g, sq, q in ((got[1], vr * vr, uhu), (got[2], vt * vt, nhn)):
            assert abs(g - (sq - q)) <= 1e-14 * (sq + abs(q))


def test_noise_add_joint_equals_add_per_detection():
    """add_joint on a real joint update (the runner's call) gives add's rows, bit for bit."""
    rng = np.random.default_rng(5)
    ekf = EkfSlam([0.3, -0.2, 0.7], np.diag([1e-3, 2e-3, 1e-3]), [0.01, 0.001, 0.01, 0.001])
    for _ in range(6):
        ekf.add_lamp(rng.uniform(-3, 3, 2), np.eye(2) * rng.uniform(1e-4, 1e-3))
        ekf.predict(rng.uniform(0.0, 0.2), rng.uniform(-0.2, 0.2))
    ids = [4, 1, 3]
    z = np.array([ekf.predict_lamps([i])[0] for i in ids]) + rng.normal(size=(3, 2)) * 1e-2
    r = np.array([np.eye(2) * rng.uniform(1e-4, 1e-3) for _ in ids])
    res = ekf.update_lamps(ids, z, block_diag_cov(r))
    joint, single = DetectionNoiseEstimator(), DetectionNoiseEstimator()
    joint.add_joint(z, res.innovation, res.s, r)
    for a in range(3):
        b = slice(2 * a, 2 * a + 2)
        single.add(z[a], res.innovation[b], res.s[b, b], r[a])
    assert len(joint) == 3
    assert joint._rows == single._rows


def test_individual_compatibility_equals_joint_innovation():
    rng = np.random.default_rng(11)
    ekf = EkfSlam([0.3, -0.2, 0.7], np.diag([1e-3, 2e-3, 1e-3]), [0.01, 0.001, 0.01, 0.001])
    for _ in range(12):
        ekf.add_lamp(rng.uniform(-3, 3, 2), np.eye(2) * rng.uniform(1e-4, 1e-3))
        ekf.predict(rng.uniform(0.0, 0.2), rng.uniform(-0.2, 0.2))
    z = rng.uniform(-2, 2, (3, 2))
    r = np.array([np.eye(2) * rng.uniform(1e-4, 1e-3) for _ in range(3)])
    d2 = ekf.individual_compatibility(z, r)
    one_r = ekf.individual_compatibility(z, r[0])
    for j in range(3):
        for i in range(ekf.n_lamps):
            h, cols, hc = ekf.predict_lamps([i])
            s = ekf.innovation_cov(cols, hc, r[j])
            v = z[j] - h
            assert d2[j, i] == pytest.approx(float(v @ np.linalg.solve(s, v)), rel=1e-9)
            s0 = ekf.innovation_cov(cols, hc, r[0])
            assert one_r[j, i] == pytest.approx(float(v @ np.linalg.solve(s0, v)), rel=1e-9)


def test_compose_with_jacobians_equals_both():
    rng = np.random.default_rng(5)
    for _ in range(500):
        a = rng.normal(size=3) * [5.0, 5.0, 4.0]
        b = rng.normal(size=3) * [1.0, 1.0, 4.0]
        pose, ja, jb = se2.compose_with_jacobians(a, b)
        ja2, jb2 = se2.jacobians_compose(a, b)
        assert np.array_equal(pose, se2.compose(a, b))
        assert np.array_equal(pose, se2.compose(a[None], b[None])[0])
        assert np.array_equal(ja, ja2) and np.array_equal(jb, jb2)


def test_landmark_ellipses_equal_one_eigh_per_lamp():
    rng = np.random.default_rng(9)
    lamps = rng.uniform(-5, 5, (40, 2))
    covs = []
    for _ in range(40):
        a = rng.normal(size=(2, 2)) * 1e-2
        covs.append(a @ a.T + np.eye(2) * 1e-6)
    covs.append(np.zeros((2, 2)))  # a degenerate one: the 5 cm floor
    lamps = np.vstack([lamps, [0.0, 0.0]])
    poses, scales = _ellipses(lamps, np.array(covs))
    for k, (xy, c) in enumerate(zip(lamps, covs, strict=True)):
        w, v = np.linalg.eigh(c)
        assert poses[k].tolist() == [xy[0], xy[1], float(np.arctan2(v[1, 1], v[0, 1]))]
        want = [max(6.0 * float(np.sqrt(max(e, 0.0))), 0.05) for e in (w[1], w[0])]
        assert scales[k].tolist() == want


def test_unproject_inverts_project():
    cam = CeilingCamera(160, 120, 100.3, 80.1, 60.7, 2.5, (0.11, -0.03))
    pts = np.random.default_rng(2).uniform(-1, 1, (300, 2))
    assert np.allclose(cam.unproject(cam.project(pts)), pts, atol=1e-12)
    q = np.random.default_rng(3).uniform(0, 160, (300, 2))
    s = cam.height / cam.f
    want = np.column_stack(
        [(q[:, 0] - cam.cx) * s + cam.offset[0], (q[:, 1] - cam.cy) * s + cam.offset[1]]
    )
    assert np.array_equal(cam.unproject(q), want)
    assert cam.unproject(np.zeros((0, 2))).shape == (0, 2)


@pytest.mark.parametrize(
    "row",
    [
        UpdateRow(12.5, "lamp", 3, 2, 1.25, True, np.array([1e-3, -2e-4])),
        UpdateRow(1.7e9, "lamp", 0, 2, 40.0, False, np.full(2, np.nan)),
        UpdateRow(3.0, "heading", -1, 1, 0.5, True, np.array([0.01])),
        UpdateRow(3.0, "pose", -1, 3, math.inf, False, np.array([1.0, 2.0, -3.0])),
    ],
)
def test_update_line_equals_csv_writer(row):
    buf = io.StringIO()
    v = (*row.v, np.nan, np.nan, np.nan)[:3]
    fields = [format_time(row.t), row.kind, row.id, row.dof, _num(row.nis), int(row.accepted)]
    csv.writer(buf, lineterminator="\n").writerow(fields + [_num(x) for x in v])
    assert _update_line(row) == buf.getvalue()


def test_register_imports_only_the_command():
    code = (
        "import sys; from fuzzyslam.cli import _register, cli; _register(['--debug', 'run', 'x']);"
        "print(sorted(cli.commands), 'fuzzyslam.cli.map' in sys.modules);"
        "_register(['--help']); print(sorted(cli.commands))"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True
    ).stdout.splitlines()
    assert out[0] == "['run'] False"
    assert out[1] == str(sorted(["evaluate", "map", "reproduce", "run", "simulate", "sweep"]))


def test_last_stamp_equals_per_message_bookkeeping():
    """reader._last_stamp once per batch against the per-message bookkeeping it replaced
    (the last log time given and the (channel, sequence) given at it)."""
    from fuzzyslam.streams.reader import _last_stamp

    rng = np.random.default_rng(13)
    for _ in range(300):
        times = np.sort(rng.integers(0, 6, rng.integers(0, 12))).tolist()
        cut = sorted(rng.integers(0, len(times) + 1, 3).tolist())
        batches = [times[a:b] for a, b in zip([0, *cut], [*cut, len(times)], strict=True)]
        last_ns, seen, ref_ns, ref_seen, k = -1, set(), -1, set(), 0
        for b in batches:
            batch = []
            for t in b:
                batch.append((t, k % 3, k, b""))
                if t != ref_ns:
                    ref_ns, ref_seen = t, set()
                ref_seen.add((k % 3, k))
                k += 1
            last_ns, seen = _last_stamp(batch, last_ns, seen)
            assert (last_ns, seen) == (ref_ns, ref_seen)


def test_solve_spd_without_the_private_gufuncs(monkeypatch):
    """numpy without ``numpy.linalg._umath_linalg``: the public calls, the same floats."""
    from fuzzyslam.slam import health

    rng = np.random.default_rng(4)
    cases = []
    for k in (2, 4):
        a = rng.normal(size=(k, k))
        cases.append((a @ a.T + np.eye(k) * 1e-3, rng.normal(size=k)))
    cases.append((np.array([[1.0, 1.0], [1.0, 1.0]]), np.array([1.0, 2.0])))  # singular
    want = [solve_spd(s, b) for s, b in cases]
    monkeypatch.setattr(health, "_umath_linalg", None)
    for (s, b), (x, reg) in zip(cases, want, strict=True):
        x2, reg2 = solve_spd(s, b)
        assert reg2 == reg and np.array_equal(x2, x)
