"""Numerical guards of the filter (issue 7): near-singular innovation covariances,
covariance repair, the NIS divergence monitor, and their counts in ``run``'s summary."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from fuzzyslam.slam.ekf import EkfSlam
from fuzzyslam.slam.health import DivergenceMonitor, is_spd, repair_covariance, solve_spd

ALPHA = (0.01, 0.001, 0.005, 0.001)  # k_tt, k_tr, k_rr, k_rt


@settings(max_examples=100, deadline=None)
@given(
    a=arrays(float, (3, 3), elements=st.floats(-3, 3)),
    b=arrays(float, 3, elements=st.floats(-3, 3)),
)
def test_solve_spd_matches_solve_when_well_conditioned(a, b) -> None:
    s = a @ a.T + np.eye(3)
    x, reg = solve_spd(s, b)
    assert not reg
    np.testing.assert_allclose(x, np.linalg.solve(s, b), rtol=1e-9, atol=1e-12)


@pytest.mark.parametrize(
    "s",
    [
        np.zeros((2, 2)),  # a perfect measurement of a perfectly known state
        np.array([[1.0, 1.0], [1.0, 1.0]]),  # rank one
        np.array([[1.0, 0.0], [0.0, -1e-17]]),  # indefinite by rounding
        np.diag([1e8, 1e-30]),
    ],
)
def test_solve_spd_regularises_singular_matrices(s) -> None:
    b = np.array([0.3, -0.2])
    x, reg = solve_spd(s, b)
    assert reg and np.all(np.isfinite(x))
    # the regularised solve is the solve of S + eI for a small e: S x ~ b - e x
    r = s @ x - b
    e = -r / np.where(x == 0, 1.0, x)
    assert np.all(e >= -1e-6) and np.all(e <= 1e-3 * max(np.trace(np.abs(s)), 1.0) + 1e-9)


def test_solve_spd_refuses_nan() -> None:
    with pytest.raises(np.linalg.LinAlgError):
        solve_spd(np.full((2, 2), np.nan), np.ones(2))


@settings(max_examples=100, deadline=None)
@given(a=arrays(float, (4, 4), elements=st.floats(-3, 3)))
def test_repair_covariance_is_the_nearest_spd_matrix(a) -> None:
    p = 0.5 * (a + a.T)
    fixed, repaired = repair_covariance(p)
    assert is_spd(fixed)
    if is_spd(p):
        assert not repaired and fixed is p
        return
    assert repaired
    w, v = np.linalg.eigh(p)
    floor = 1e-12 * max(np.abs(w).max(), 1e-300)
    # Higham 1988: the Frobenius distance to the nearest matrix with eigenvalues >= floor
    np.testing.assert_allclose(
        np.linalg.norm(fixed - p), np.linalg.norm(np.maximum(w, floor) - w), atol=1e-9
    )
    np.testing.assert_allclose(fixed @ v, v * np.maximum(w, floor), atol=1e-9)


def test_repair_covariance_asymmetric_and_nan() -> None:
    p = np.array([[1.0, 0.5], [0.4, 1.0]])
    fixed, repaired = repair_covariance(p)
    assert repaired and is_spd(fixed)
    np.testing.assert_allclose(fixed, [[1.0, 0.45], [0.45, 1.0]])
    fixed, repaired = repair_covariance(np.array([[np.nan, 0.0], [0.0, 1.0]]))
    assert repaired and is_spd(fixed)


def test_divergence_monitor_consistent_and_overconfident() -> None:
    rng = np.random.default_rng(3)
    ok = DivergenceMonitor(window=50, alpha=1e-3, patience=3)
    for k, nis in enumerate(rng.chisquare(2, 20_000)):
        ok.observe(0.1 * k, float(nis), 2)
    assert ok.windows == 400 and ok.out_of_bounds <= 3 and not ok.diverged
    bad = DivergenceMonitor(window=50, alpha=1e-3, patience=3)
    for k, nis in enumerate(3.0 * rng.chisquare(2, 1000)):  # S three times too small
        bad.observe(0.1 * k, float(nis), 2)
    assert bad.diverged and bad.out_of_bounds >= 18
    assert bad.diverged_at == pytest.approx(0.1 * 149)  # the end of the third window
    s = bad.summary()
    assert s["diverged"] and s["nis_worst_window_ratio"] > 1.0


def test_divergence_needs_consecutive_windows() -> None:
    """Two bad windows, one good, ...: never three in a row, so the streak test (``nis``)
    does not fire; but 8 of 12 windows out of bounds is far more than a consistent
    filter's 0.1 % per window: the rate test (``nis_rate``) does, at the third bad one
    (tail 3e-7 after 4 windows)."""
    mon = DivergenceMonitor(window=10, alpha=1e-3, patience=3)
    for w in range(12):
        big = w % 3 != 2  # two bad windows, one good, ...
        for k in range(10):
            mon.observe(w * 10 + k, 40.0 if big else 2.0, 2)
    assert mon.out_of_bounds == 8 and mon.reasons == ["nis_rate"]
    assert mon.diverged_at == 39


# -- the filter's guards -------------------------------------------------------------------


def test_perfect_measurement_of_a_known_state_is_handled() -> None:
    """S = H P H^T + R = 0 (P_rr = 0, R = 0): no exception, the update is applied
    (counted once: the gate's NIS and the gain share one factorisation of S), P stays
    finite and symmetric positive semi-definite."""
    ekf = EkfSlam([1.0, 2.0, math.pi], np.zeros((3, 3)), ALPHA)
    ekf.add_lamp([1.0, 0.0], np.eye(2) * 0.01)
    res = ekf.update_robot([math.pi], [[0.0]], [2])
    assert res.accepted and np.isfinite(res.nis)
    assert ekf.guards["s_regularised"] == 1
    p = ekf.P
    assert np.all(np.isfinite(p)) and np.array_equal(p, p.T)
    assert np.linalg.eigvalsh(p).min() > -1e-12


def test_heading_innovation_wraps_at_pi() -> None:
    """A heading fix at -pi + 0.01 of a robot at pi - 0.01 is a 0.02 rad correction."""
    ekf = EkfSlam([0.0, 0.0, math.pi - 0.01], np.eye(3) * 0.01, ALPHA)
    res = ekf.update_robot([-math.pi + 0.01], [[0.01]], [2])
    assert res.innovation[0] == pytest.approx(0.02)
    assert res.nis == pytest.approx(0.02**2 / 0.02)
    assert ekf.x[2] == pytest.approx(math.pi, abs=1e-12) or ekf.x[2] == pytest.approx(
        -math.pi + 0.0, abs=1e-12
    )
    assert -math.pi < ekf.x[2] <= math.pi


def test_damaged_covariance_is_repaired_and_counted() -> None:
    ekf = EkfSlam([0.0, 0.0, 0.0], np.eye(3) * 0.01, ALPHA)
    ekf.add_lamp([2.0, 0.0], np.eye(2) * 0.01)
    ekf._p[3, 3] = -1.0  # as rounding over a very long run could leave it
    assert ekf.check_covariance() is True
    assert ekf.guards["p_repaired"] == 1 and is_spd(ekf.P)
    assert ekf.check_covariance() is False


def test_chi2_quantile_matches_scipy_stats() -> None:
    from scipy.stats import chi2

    from fuzzyslam.slam.health import chi2_quantile

    for dof in (1, 2, 3, 100, 1000):
        for p in (0.5, 0.95, 0.999):
            assert chi2_quantile(p, dof) == pytest.approx(chi2.ppf(p, dof), rel=1e-10)


def test_chi2_tables_are_scipy_bit_for_bit() -> None:
    """slam/chi2_values.py holds scipy.special's own floats (a regenerated table is the
    same text); points outside it are computed by scipy, also bit for bit."""
    from scipy.special import gammainc, gammaincinv

    from fuzzyslam.slam import chi2_values
    from fuzzyslam.slam.health import chi2_quantile, gate_level

    gates, quantiles = chi2_values.compute()
    assert (gates, quantiles) == (chi2_values.GATE_LEVELS, chi2_values.CHI2_QUANTILES)
    assert chi2_values.table_text() in open(chi2_values.__file__, encoding="utf-8").read()
    assert len(quantiles) == 190
    for (p, dof), v in quantiles.items():
        assert chi2_quantile(p, dof) == v == float(2.0 * gammaincinv(dof / 2.0, p))
    assert gate_level(9.21) == float(gammainc(1.0, 9.21 / 2.0))
    for p, dof in ((0.95, 7), (1.0 - 1e-3, 151), (0.5, 1000)):  # not in the table
        assert (p, dof) not in quantiles
        assert chi2_quantile(p, dof) == float(2.0 * gammaincinv(dof / 2.0, p))
    assert gate_level(5.99) == float(gammainc(1.0, 5.99 / 2.0))


@pytest.mark.slow
def test_run_imports_neither_scipy_nor_rosbags(tmp_path) -> None:
    """`run` on the sample log (lamps only) needs no scipy and no rosbags typestore: their
    imports would cost 0.27 s and 0.12 s of CPU, a seventh of a paper run together."""
    import os
    import subprocess
    import sys
    from pathlib import Path

    log = Path(__file__).resolve().parents[1] / "data" / "sample.mcap"
    code = (
        # the CLI's main, not its process entry: that leaves a run's process at once
        "import sys\nfrom fuzzyslam.cli import main\n"
        f"sys.argv = ['fuzzyslam', 'run', {str(log)!r}, '-o', {str(tmp_path / 'o')!r}]\n"
        "try:\n    main()\n"
        "except SystemExit as e:\n    assert not e.code, e.code\n"
        "print(sorted(m for m in sys.modules if m.split('.')[0] in ('scipy', 'rosbags')))\n"
    )
    env = {**os.environ, "FUZZYSLAM_NO_PROGRESS": "1"}
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                       cwd=tmp_path, env=env)  # fmt: skip
    assert p.returncode == 0, p.stderr[-2000:]
    assert p.stdout.strip().splitlines()[-1] == "[]"
    assert (tmp_path / "o" / "trajectory.tum").exists()
