"""Odometry self-calibration (slam/calibration.py, docs/models.md sec. 4b) with the real
EkfSlam and SlamRunner: Jacobians against finite differences, the filter without
calibration reproduced when the factors are known, convergence to the true factors,
NEES of the augmented state over Monte Carlo runs, perfect odometry leaving the factors
at 1, and the observability freeze of heading-only fixes."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
import yaml
from click.testing import CliRunner
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.stats import chi2

from fuzzyslam.cli import _register, cli
from fuzzyslam.robot import integrate
from fuzzyslam.se2 import compose, wrap_angle
from fuzzyslam.slam import calibration as cal
from fuzzyslam.slam import calibration_files as calfiles
from fuzzyslam.slam.ekf import EkfSlam, Preintegrator, motion_noise
from fuzzyslam.slam.params import SlamParams
from fuzzyslam.slam.runner import Frame, Odom, SlamRunner

_register()

B = 0.40  # nominal wheel base (m), the simulator's
NOISE = (4e-6, 3e-6, 3e-5, 6e-5)


def _model(kind: str, sig, var: float = 0.0) -> cal.Calibration:
    k = len(sig)
    return cal.Calibration(kind, B, np.ones(k), np.diag(np.square(sig)), var, var)


def _nominal(kind: str, c, dt: float, dr: float) -> tuple[float, float]:
    """The odometry a robot with factors c reports for the true increment (dt, dr): the
    inverse of ``calibrated_increment`` (true arcs A = dt -+ b s_B dr / 2 = s a)."""
    if kind == "odom":
        return dt / c[0], dr / c[1]
    sl, sr, sb = c
    al = (dt - 0.5 * B * sb * dr) / sl
    ar = (dt + 0.5 * B * sb * dr) / sr
    return 0.5 * (al + ar), (ar - al) / B


# -- Jacobians -------------------------------------------------------------------------------


def test_true_factors_reproduce_the_simulators_kinematics():
    """The factor definitions are the simulator's: its true wheels (radii r left_scale,
    r right_scale, base b base_scale; sim/encoders.py) turned by a true motion, read back
    with the nominal r and b (robot.wheel_increments_to_odometry), give back the true
    increment through calibrated_increment at c = (left_scale, right_scale, base_scale),
    and not at the reciprocal base factor; also through simulate_encoders without noise
    (ticks fine enough that quantisation is below 1e-9 rad)."""
    from dataclasses import replace

    from fuzzyslam.robot import wheel_increments_to_odometry
    from fuzzyslam.sim.encoders import simulate_encoders, true_wheel_increments
    from fuzzyslam.sim.params import RobotParams

    rng = np.random.default_rng(11)
    robot = RobotParams(left_scale=1.003, right_scale=0.996, base_scale=1.01)
    dt = rng.uniform(0.0, 0.03, 200)
    dr = rng.uniform(-0.08, 0.08, 200)
    dl, dr_w = true_wheel_increments(dt, dr, robot)
    nt, nr = wheel_increments_to_odometry(dl, dr_w, robot.wheel_radius, robot.wheel_base)
    c = (robot.left_scale, robot.right_scale, robot.base_scale)
    got = np.array([cal.calibrated_increment("wheels", robot.wheel_base, c, a, b)[:2]
                    for a, b in zip(nt, nr, strict=True)])  # fmt: skip
    np.testing.assert_allclose(got[:, 0], dt, rtol=0, atol=1e-15)
    np.testing.assert_allclose(got[:, 1], dr, rtol=0, atol=1e-15)
    inv = (robot.left_scale, robot.right_scale, 1.0 / robot.base_scale)
    wrong = np.array([cal.calibrated_increment("wheels", robot.wheel_base, inv, a, b)[1]
                      for a, b in zip(nt, nr, strict=True)])  # fmt: skip
    assert np.max(np.abs(wrong - dr)) > 1e-3 * np.max(np.abs(dr))
    enc = simulate_encoders(dt, dr, replace(robot, wheel_noise=0.0, ticks_per_rev=2**40),
                            np.zeros(3), rng)  # fmt: skip
    got = np.array([cal.calibrated_increment("wheels", robot.wheel_base, c, a, b)[:2]
                    for a, b in zip(enc.d_trans, enc.d_rot, strict=True)])  # fmt: skip
    np.testing.assert_allclose(got, np.column_stack([dt, dr]), rtol=0, atol=1e-9)


@pytest.mark.parametrize("kind", ["wheels", "odom"])
def test_increment_jacobian_matches_finite_differences(kind):
    rng = np.random.default_rng(1)
    k = 3 if kind == "wheels" else 2
    for _ in range(20):
        c = 1.0 + 0.05 * rng.standard_normal(k)
        dtn, drn = rng.uniform(-0.05, 0.05), rng.uniform(-0.2, 0.2)
        _, _, f0, f1 = cal.calibrated_increment(kind, B, c, dtn, drn)
        f = np.array([f0, f1])
        num = np.empty((2, k))
        for j in range(k):
            e = np.zeros(k)
            e[j] = 1e-6
            hi = cal.calibrated_increment(kind, B, c + e, dtn, drn)[:2]
            lo = cal.calibrated_increment(kind, B, c - e, dtn, drn)[:2]
            num[:, j] = (np.array(hi) - np.array(lo)) / 2e-6
        np.testing.assert_allclose(f, num, atol=1e-9)


@pytest.mark.parametrize("kind", ["wheels", "odom"])
def test_preintegrated_jacobian_matches_finite_differences(kind):
    """D = d delta / dc accumulated through the composition, against re-preintegrating
    the same nominal increments with perturbed factors."""
    rng = np.random.default_rng(2)
    k = 3 if kind == "wheels" else 2
    incs = [(rng.uniform(0.0, 0.03), rng.uniform(-0.1, 0.1)) for _ in range(40)]
    c = 1.0 + 0.02 * rng.standard_normal(k)

    def delta(cc):
        m = _model(kind, [0.01] * k)
        m.factors = np.asarray(cc)
        pre = cal.CalibratedPreintegrator(NOISE, m)
        pre.instrumented = False  # the exact derivative (the instrument: the next test)
        for u in incs:
            pre.add(*u)
        return pre

    pre = delta(c)
    num = np.empty((3, k))
    for j in range(k):
        e = np.zeros(k)
        e[j] = 1e-6
        num[:, j] = (delta(c + e).delta - delta(c - e).delta) / 2e-6
    np.testing.assert_allclose(pre.d_calib, num, atol=1e-8)
    # the calibrated delta is the plain preintegration of the calibrated increments
    plain = Preintegrator(NOISE)
    for u in incs:
        plain.add(*cal.calibrated_increment(kind, B, c, *u)[:2])
    np.testing.assert_allclose(pre.delta, plain.delta, atol=1e-14)
    np.testing.assert_allclose(pre.q, plain.q, atol=1e-18)


def test_instrumented_jacobian_is_f_at_the_mean_step_between_updates():
    """With the instrument, D is the chain rule through the composition of F evaluated at
    the mean nominal step between the last two updates (``mark``), not at each increment
    (for up to twice as many steps): against a second implementation, the finite
    difference in c of a preintegration of the increments linearised in c with that F;
    and at a steady motion it is the exact D."""
    rng = np.random.default_rng(12)
    for kind, k in (("wheels", 3), ("odom", 2)):
        m = _model(kind, [0.01] * k)
        m.factors = 1.0 + 0.02 * rng.standard_normal(k)
        c0 = m.factors.copy()
        before = [(rng.uniform(0.0, 0.03), rng.uniform(-0.1, 0.1)) for _ in range(15)]
        incs = [(rng.uniform(0.0, 0.03), rng.uniform(-0.1, 0.1)) for _ in range(30)]
        pre = cal.CalibratedPreintegrator(NOISE, m)
        for u in before:
            pre.add(*u)
        pre.mark()
        pre.reset(c0)
        for u in incs:
            pre.add(*u)
        inst = np.mean(before, axis=0)
        np.testing.assert_allclose(pre.inst, inst, rtol=1e-12)
        f = np.array(cal.calibrated_increment(kind, B, c0, *inst)[2:])  # (2, k)

        def delta(cc, f=f, kind=kind, c0=c0, incs=incs):
            plain = Preintegrator(NOISE)
            for u in incs:
                plain.add(*(np.array(cal.calibrated_increment(kind, B, c0, *u)[:2])
                            + f @ (cc - c0)))  # fmt: skip
            return plain.delta

        num = np.empty((3, k))
        for j in range(k):
            e = np.zeros(k)
            e[j] = 1e-6
            num[:, j] = (delta(c0 + e) - delta(c0 - e)) / 2e-6
        np.testing.assert_allclose(pre.d_calib, num, atol=1e-8)
        # steady motion: the instrument is the increment itself, D the exact derivative
        u = (0.02, 0.05)
        pre.mark()
        for _ in range(6):
            pre.add(*u)
        pre.mark()
        pre.reset(c0)
        exact = cal.CalibratedPreintegrator(NOISE, m)
        exact.instrumented = False
        exact.reset(c0)
        for _ in range(12):
            pre.add(*u)
            exact.add(*u)
        np.testing.assert_allclose(pre.d_calib, exact.d_calib, rtol=1e-12, atol=1e-15)
        np.testing.assert_allclose(pre.delta, exact.delta, rtol=0, atol=0)


def _chain_reference(kind, c, inst, inst_steps, incs, n0=0):
    """A second implementation of CalibratedPreintegrator's D and E over one interval,
    as its docstring writes them: per step F (exact, or at the instrument while the
    interval has at most twice its steps), G = F_exact - F_inst, and D' = A D + B G_u F,
    E' = A E + B G_u G row by row (3 x k lists, the same float operations in the same
    order); the composition's own delta and Q come from the plain Preintegrator. ``n0``:
    the steps since the last update before this interval's."""
    k = len(c)
    d = [[0.0] * k for _ in range(3)]
    e = [[0.0] * k for _ in range(3)]
    plain = Preintegrator(NOISE)
    for n, (d_trans, d_rot) in enumerate(incs, n0 + 1):
        dt, dr, f0, f1 = cal.calibrated_increment(kind, B, c, d_trans, d_rot)
        g = None
        if n <= 2 * inst_steps:
            i0, i1 = cal.calibrated_increment(kind, B, c, *inst)[2:]
            g = (
                [x - y for x, y in zip(f0, i0, strict=True)],
                [x - y for x, y in zip(f1, i1, strict=True)],
            )
            f0, f1 = i0, i1
        h = 0.5 * dr
        mx, my = dt * math.cos(h), dt * math.sin(h)
        co, si = math.cos(plain.dth), math.sin(plain.dth)
        a, b = -si * mx - co * my, co * mx - si * my
        ch, sh, kk = math.cos(plain.dth + h), math.sin(plain.dth + h), 0.5 * dt
        for m, (u, v) in ((d, (f0, f1)), (e, g)) if g is not None else ((d, (f0, f1)),):
            m[0] = [m[0][j] + a * m[2][j] + ch * u[j] - kk * sh * v[j] for j in range(k)]
            m[1] = [m[1][j] + b * m[2][j] + sh * u[j] + kk * ch * v[j] for j in range(k)]
            m[2] = [m[2][j] + v[j] for j in range(k)]
        plain.add(dt, dr)
    return np.array(d), np.array(e), plain


@pytest.mark.parametrize("kind,k", [("wheels", 3), ("odom", 2)])
def test_preintegrated_jacobians_bit_for_bit_against_the_chain_rule_written_out(kind, k):
    """D, E, delta and Q of the preintegrator (columns, F at the instrument cached per
    instrument and factors, a reset with no step in between skipped) equal, bit for bit,
    the row-by-row chain rule of :func:`_chain_reference` over intervals of 1-12 random
    steps, updates (``mark``, after 80 % of the intervals) and new factors at random, the
    instrument standing for part of the steps and not for the rest; and q_calib is
    Q + E P_cc E^T of those E."""
    rng = np.random.default_rng(5)
    m = _model(kind, [0.01] * k)
    pre = cal.CalibratedPreintegrator(NOISE, m)
    c = tuple(m.factors.tolist())
    inst, inst_steps, since = (0.0, 0.0), 0, []  # since: the steps since the last mark
    p_cc = np.diag(rng.uniform(1e-6, 1e-4, k))
    for _ in range(60):
        if rng.random() < 0.5:
            c = tuple((1.0 + 0.01 * rng.standard_normal(k)).tolist())
        pre.reset(np.array(c))
        pre.reset(np.array(c))  # again, as the runner does: nothing to undo
        incs = [(rng.uniform(-0.01, 0.03), rng.uniform(-0.08, 0.08))
                for _ in range(int(rng.integers(1, 13)))]  # fmt: skip
        for u in incs:
            pre.add(*u)
        d, e, plain = _chain_reference(kind, c, inst, inst_steps, incs, len(since))
        since += incs
        assert np.array_equal(pre.d_calib, d) and np.array_equal(pre._matrices()[1], e)
        assert np.array_equal(pre.delta, plain.delta) and np.array_equal(pre.q, plain.q)
        assert np.array_equal(pre.q_calib(p_cc), plain.q + e @ p_cc @ e.T)
        if rng.random() < 0.8:  # an update: the next instrument
            pre.mark()
            inst_steps = len(since)
            inst = (sum(u[0] for u in since) / inst_steps, sum(u[1] for u in since) / inst_steps)
            since = []
    assert 0 < inst_steps


@pytest.mark.slow  # end to end, 1-3 s: the fast tier stays under a minute
def test_encoder_noise_does_not_bias_the_base_factor():
    """The errors-in-variables bias (CalibratedPreintegrator docstring): heading noise of
    3 cm/sqrt(m) on straight corridors and precise lamps at every step. With F at the
    measured increments the base factor comes out several sigma high (measured: +5.9
    sigma mean over 6 seeds, 2 laps); with the instrument it is within 2 sigma of the
    truth, the wheel factors too."""
    noise = (4e-6, 3e-6, 3e-5, 1e-3)
    c_true = np.array([1.0, 1.0, 1.01])
    z_inst, z_exact = [], []
    for seed in range(3):
        rng = np.random.default_rng(seed)
        ev, _ = _events(_loop(2, 0.5, 10.0), c_true, "wheels", rng, frame_every=1,
                        sigma=0.005, noise=noise)  # fmt: skip
        for inst, zs in ((True, z_inst), (False, z_exact)):
            _, runner = _run(ev, _model("wheels", [0.002, 0.002, 0.02]), noise=noise,
                             instrumented=inst)  # fmt: skip
            c, s = runner.ekf.calib, np.sqrt(np.diag(runner.ekf.calib_cov))
            zs.append((c - c_true) / s)
    z_inst, z_exact = np.array(z_inst), np.array(z_exact)
    assert np.all(np.abs(z_inst) <= 2.0), z_inst
    assert np.mean(z_exact[:, 2]) >= 3.0, z_exact  # the bias the instrument removes


def test_calibrated_prediction_is_the_dense_jacobian_form():
    """predict_calibrated's O(n) rows equal F P F^T + G Q G^T with the dense
    F = [[J_a, J_b D, 0], [0, I, 0], [0, 0, I]] over (pose, c, lamps)."""
    rng = np.random.default_rng(3)
    m = _model("wheels", [0.01, 0.01, 0.05])
    ekf = EkfSlam([1.0, 2.0, 0.3], np.diag([1e-4, 2e-4, 1e-3]), NOISE, calib=m.factors,
                  calib_cov=m.cov)  # fmt: skip
    for _ in range(3):
        ekf.add_lamp(rng.uniform(-2, 2, 2), np.eye(2) * 1e-3)
    ekf.update_lamps([0, 1], rng.uniform(-2, 2, (2, 2)), np.eye(4) * 1e-2)  # correlations
    p0 = ekf.P.copy()
    pre = cal.CalibratedPreintegrator(NOISE, m)
    pre.reset(ekf.calib)
    for _ in range(10):
        pre.add(0.02, 0.03)
    from fuzzyslam.se2 import jacobians_compose

    ja, jb = jacobians_compose(ekf.pose, pre.delta)
    n = ekf.dim
    f = np.eye(n)
    f[:3, :3] = ja
    f[:3, 3:6] = jb @ pre.d_calib
    g = np.zeros((n, 3))
    g[:3] = jb
    want = f @ p0 @ f.T + g @ pre.q @ g.T
    ekf.predict_relative(pre.delta, pre.q, pre.d_calib)
    np.testing.assert_allclose(ekf.P, want, atol=1e-15)


# -- a lamp world for the runner ----------------------------------------------------------------


def _loop(laps: int, v: float, rate: float) -> np.ndarray:
    """True increments (N, 2) of a rounded 10 x 7 m rectangle driven ``laps`` times."""
    ds = v / rate
    incs = []
    for _ in range(laps):
        for length in (10.0, 7.0, 10.0, 7.0):
            incs += [(ds, 0.0)] * int(length / ds)
            arc = 0.5 * math.pi * 0.6  # a 90-degree turn on a 0.6 m radius
            incs += [(ds, ds / 0.6)] * int(arc / ds)
    return np.array(incs)


LAMPS = np.array(
    [(x, y) for x in np.arange(0.0, 10.1, 2.0) for y in (0.3, 7.3)]
    + [(x, y) for x in (-0.3, 10.3) for y in np.arange(1.5, 6.0, 2.0)]
)


def _events(
    incs, c_true, kind, rng, rate=10.0, frame_every=5, odo_noise=True, sigma=0.02, noise=NOISE
):
    """Odometry of a robot with factors c_true (random walk ``noise`` in the true motion, as
    the filter models it), and lamp detections within 2 m every ``frame_every`` steps."""
    poses = integrate(np.zeros(3), incs[:, 0], incs[:, 1])
    ev = []
    for i, (dt, dr) in enumerate(incs):
        t = (i + 1) / rate
        m = motion_noise(dt, dr, noise)
        w = rng.standard_normal(2) * np.sqrt(np.diag(m)) if odo_noise else np.zeros(2)
        ev.append(Odom(t, *_nominal(kind, c_true, dt - w[0], dr - w[1])))
        if (i + 1) % frame_every == 0:
            p = poses[i + 1]
            cth, sth = math.cos(p[2]), math.sin(p[2])
            d = LAMPS - p[:2]
            near = np.hypot(d[:, 0], d[:, 1]) < 2.0
            z = d[near] @ np.array([[cth, -sth], [sth, cth]])  # R^T d
            z = z + sigma * rng.standard_normal(z.shape)
            ev.append(Frame(t, z, np.repeat(np.eye(2)[None] * sigma**2, len(z), axis=0)))
    return ev, poses


def _run(events, model, params=None, noise=NOISE, instrumented=True):
    p = params or SlamParams(
        trans_var_per_m=noise[0], trans_var_per_rad=noise[1], rot_var_per_rad=noise[2],
        rot_var_per_m=noise[3], start_sigma=[1e-6, 1e-6, 1e-6], record_period=0.0,
    )  # fmt: skip
    runner = SlamRunner(p, np.zeros(3), calibration=model)
    if model is not None:
        runner.preint.instrumented = instrumented
    return runner.run(events, t0=0.0), runner


def test_known_factors_reproduce_the_filter_without_calibration():
    """Factors fixed at 1 with zero covariance: the lamp indexing after the calibration
    block, the calibrated prediction and updates give the filter without calibration."""
    rng = np.random.default_rng(4)
    ev, _ = _events(_loop(1, 0.5, 10.0)[:300], (1.0, 1.0, 1.0), "wheels", rng)
    res0, _ = _run(ev, None)
    m = _model("wheels", [0.0, 0.0, 0.0])
    res1, runner = _run(ev, m)
    np.testing.assert_allclose(res1.poses, res0.poses, atol=1e-9)
    np.testing.assert_allclose(res1.cov, res0.cov, rtol=1e-6, atol=1e-12)
    assert len(res1.lamps) == len(res0.lamps) >= 8
    np.testing.assert_allclose(res1.ekf.lamps, res0.ekf.lamps, atol=1e-9)
    np.testing.assert_allclose(res1.ekf.lamp_covs(), res0.ekf.lamp_covs(), rtol=1e-6)
    np.testing.assert_allclose(runner.ekf.calib, [1.0, 1.0, 1.0], atol=1e-9)


@pytest.mark.parametrize("kind,c_true", [("wheels", (1.004, 0.996, 1.03)), ("odom", (0.97, 1.04))])
def test_factors_converge_to_the_truth_within_two_sigma(kind, c_true):
    rng = np.random.default_rng(5)
    sig = [0.01, 0.01, 0.05] if kind == "wheels" else [0.05, 0.05]
    ev, poses = _events(_loop(1, 0.5, 10.0), c_true, kind, rng)
    res, runner = _run(ev, _model(kind, sig))
    c, s = runner.ekf.calib, np.sqrt(np.diag(runner.ekf.calib_cov))
    assert np.all(np.abs(c - c_true) <= 2 * s), (c, s, c_true)
    assert np.all(s < 0.2 * np.array(sig))  # learnt: well inside the prior
    e = res.poses[-1] - poses[-1]
    assert np.all(np.abs(e) <= 3 * np.sqrt(np.diag(runner.ekf.pose_cov)))


@pytest.mark.slow
def test_nees_of_the_augmented_state_is_consistent():
    """Monte Carlo: true factors drawn from the prior, odometry noise as modelled; the
    mean NEES of (pose, c) after 22 m and two turns is within the two-sided 95 %
    chi-square interval of 6 dof over the runs (Bar-Shalom, Li, Kirubarajan 2001, sec.
    5.4). Measured: 7.2 (pose 3.6, factors 3.5): at the top of the band, EKF-SLAM's
    known overconfidence; with a 1 % prior on each wheel (a 35 mrad/m heading-drift
    prior) it is far outside it, hence the default 0.2 %."""
    rng = np.random.default_rng(6)
    sig = np.array([0.002, 0.002, 0.02])  # the config's default prior (slam/params.py)
    runs, nees = 24, []
    incs = _loop(1, 0.5, 10.0)[:450]  # 22 m, two turns: the factors all observed
    for _ in range(runs):
        c_true = 1.0 + sig * rng.standard_normal(3)
        ev, poses = _events(incs, c_true, "wheels", rng)
        _, runner = _run(ev, _model("wheels", sig))
        ekf = runner.ekf
        e = np.concatenate([ekf.pose - poses[-1], ekf.calib - c_true])
        e[2] = wrap_angle(e[2])
        p = ekf.P[:6, :6]
        nees.append(float(e @ np.linalg.solve(p, e)))
    lo, hi = chi2.ppf([0.025, 0.975], 6 * runs) / runs
    assert lo <= np.mean(nees) <= hi, (np.mean(nees), lo, hi)


@settings(max_examples=5, deadline=None)
@given(
    seed=st.integers(0, 2**31 - 1),
    v=st.floats(0.2, 0.8),
    kind=st.sampled_from(["wheels", "odom"]),
)
def test_perfect_odometry_keeps_the_factors_at_one(seed, v, kind):
    """Odometry without error: every factor stays at 1 within 2 prior sigmas, and its
    posterior sigma never exceeds the prior's (the issue's property; the posterior's own
    2-sigma coverage is the NEES test's)."""
    rng = np.random.default_rng(seed)
    k = 3 if kind == "wheels" else 2
    sig = np.array([0.01, 0.01, 0.05][:k] if kind == "wheels" else [0.05, 0.05])
    ev, _ = _events(_loop(1, v, 10.0)[:250], np.ones(k), kind, rng, odo_noise=False)
    _, runner = _run(ev, _model(kind, sig))
    c, s = runner.ekf.calib, np.sqrt(np.diag(runner.ekf.calib_cov))
    assert np.all(s <= sig * (1 + 1e-9))
    assert np.all(np.abs(c - 1.0) <= 2 * sig), (c, s)


# -- observability ------------------------------------------------------------------------------


@pytest.mark.parametrize("kind,c_true", [("wheels", (0.999, 1.001, 1.0)), ("odom", (1.03, 1.0))])
def test_heading_fixes_on_a_straight_line_freeze_the_translation_scale(kind, c_true):
    """Heading fixes alone on a straight corridor: the translation direction (s_L + s_R,
    or s_T) keeps its prior value and variance exactly; for wheels the wheel difference
    s_R - s_L (the heading drift per metre) converges to the truth."""
    rng = np.random.default_rng(7)
    k = len(c_true)
    sig = [0.01, 0.01, 0.05] if kind == "wheels" else [0.05, 0.05]
    m = _model(kind, sig)
    ekf = EkfSlam(np.zeros(3), np.diag([1e-6] * 3), NOISE, calib=m.factors, calib_cov=m.cov)
    ekf.heading_frozen = cal.HEADING_FROZEN[kind]
    pre = cal.CalibratedPreintegrator(NOISE, m)
    pose = np.zeros(3)
    sh = 2e-3  # heading fix sigma (rad)
    for _ in range(60):  # 30 m: a fix every 0.5 m
        pre.reset(ekf.calib)
        for _ in range(25):
            dt, dr = 0.02, 0.0
            pose = compose(pose, [dt, 0.0, dr])
            pre.add(*_nominal(kind, c_true, dt, dr))
        ekf.predict_relative(pre.delta, pre.q_calib(ekf.calib_cov), pre.d_calib)
        ekf.update_robot([pose[2] + sh * rng.standard_normal()], [[sh**2]], [2])
        pre.mark()  # an update (the runner's call): the next F's instrument
    u = cal.HEADING_FROZEN[kind][0] / np.linalg.norm(cal.HEADING_FROZEN[kind][0])
    c, p = ekf.calib, ekf.calib_cov
    assert u @ c == pytest.approx(u @ np.ones(k), abs=1e-12)
    assert u @ p @ u == pytest.approx(u @ m.cov @ u, rel=1e-9)
    if kind == "wheels":
        w = np.array([-1.0, 1.0, 0.0])
        sd = math.sqrt(w @ p @ w)
        assert sd < 0.05 * math.sqrt(w @ m.cov @ w)  # learnt
        assert abs(w @ c - (c_true[1] - c_true[0])) <= 2 * sd
    # without the freeze the same fixes move the translation direction (cross-covariance
    # through the pose): the freeze is what holds it
    ekf2 = EkfSlam(np.zeros(3), np.diag([1e-6] * 3), NOISE, calib=m.factors, calib_cov=m.cov)
    ekf2._p[2, 3 : 3 + k] = ekf2._p[3 : 3 + k, 2] = 0.3 * np.sqrt(1e-6) * np.array(sig)
    ekf2.update_robot([0.01], [[sh**2]], [2])
    assert abs(u @ ekf2.calib - u @ np.ones(k)) > 1e-6
    ekf2.heading_frozen = cal.HEADING_FROZEN[kind]
    before = u @ ekf2.calib
    ekf2.update_robot([0.02], [[sh**2]], [2])
    assert u @ ekf2.calib == pytest.approx(before, abs=1e-12)


def test_frozen_gain_update_is_the_joseph_form():
    """The projected gain's P is (I - KH) P (I - KH)^T + K R K^T (dense, second form)."""
    rng = np.random.default_rng(8)
    a = rng.standard_normal((6, 6))
    p0 = a @ a.T + np.eye(6)
    ekf = EkfSlam(np.zeros(3), p0[:3, :3], NOISE, calib=np.ones(3), calib_cov=p0[3:, 3:])
    ekf._p[:6, :6] = p0
    ekf.heading_frozen = cal.HEADING_FROZEN["wheels"]
    r = np.array([[0.3]])
    h = np.zeros((1, 6))
    h[0, 2] = 1.0
    k = p0 @ h.T / (h @ p0 @ h.T + r)
    k = cal.freeze_gain(k, ekf.heading_frozen, 3, 6)
    want = (np.eye(6) - k @ h) @ p0 @ (np.eye(6) - k @ h).T + k @ r @ k.T
    ekf.update_robot([0.5], r, [2])
    np.testing.assert_allclose(ekf.P, want, atol=1e-12)
    np.testing.assert_allclose(ekf.x, (k @ np.array([0.5])).ravel() + np.r_[0, 0, 0, 1, 1, 1])


# -- files ----------------------------------------------------------------------------------------


def test_calibration_at_time_reads_back_the_csv(tmp_path):
    m = _model("wheels", [0.01, 0.01, 0.05])
    cov = np.array([[4e-6, 1e-6, 2e-6], [1e-6, 5e-6, -1e-6], [2e-6, -1e-6, 9e-5]])
    rows = [
        calfiles.csv_row(t, np.array([1.0 + t * 1e-4, 1.0, 1.01]), cov * (1 + t)) for t in (0, 1, 2)
    ]
    calfiles.write_csv(tmp_path / "calibration.csv", m, rows)
    d = calfiles.at_time(tmp_path / "calibration.csv", 1.5)
    assert d["t"] == 1.0 and d["names"] == list(m.names)
    np.testing.assert_allclose(d["factors"], [1.0001, 1.0, 1.01], rtol=1e-8)
    np.testing.assert_allclose(d["covariance"], cov * 2, rtol=1e-7)
    calfiles.write_yaml(tmp_path / "c.yaml", d)
    back = calfiles.load(tmp_path / "c.yaml", m)
    np.testing.assert_allclose(back.cov, cov * 2, rtol=1e-7)
    with pytest.raises(Exception, match="model 'wheels'"):
        calfiles.load(tmp_path / "c.yaml", _model("odom", [0.05, 0.05]))
    assert calfiles.at_time(tmp_path / "calibration.csv", -1.0) is None


@pytest.mark.slow
def test_run_map_run_carry_the_calibration(tmp_path):
    """quick.yaml, calibrating, end to end: the run learns the wheel factors within 2 sigma of the
    simulator's (the base factor: comment below), the map keeps those of its freeze time,
    and run --map starts from them."""
    log = tmp_path / "q.mcap"
    conf = tmp_path / "quick_calibrated.yaml"  # the presets leave it off
    conf.write_text("extends: quick.yaml\nslam:\n  calibrate: true\n")
    inv = CliRunner().invoke
    assert inv(cli, ["simulate", "quick", "-o", str(log), "--seed", "1"]).exit_code == 0
    res = inv(cli, ["run", str(log), "-o", str(tmp_path / "AB"), "--config", str(conf)])
    assert res.exit_code == 0, res.output
    summary = json.loads(res.stdout)
    from fuzzyslam.config import load_config

    robot = load_config("quick").robot
    truth = np.array([robot.left_scale, robot.right_scale, robot.base_scale])
    c, s = np.array(summary["calibration"]["factors"]), np.array(summary["calibration"]["sigma"])
    assert np.all(np.abs(c[:2] - truth[:2]) <= 2 * s[:2]), (c, s, truth)
    # the base factor comes out 0.2-0.4 % high on the camera's lamps (2-3 sigma; with
    # detections made from the true poses on the same odometry it is within 1 sigma:
    # a bias of the lamp detections, not of the calibration): most of the 1 % is learnt
    assert abs(c[2] - truth[2]) < 0.5 * abs(1.0 - truth[2]), (c, s, truth)
    rows = np.loadtxt(tmp_path / "AB" / "calibration.csv", delimiter=",", skiprows=1)
    assert rows.shape[1] == 10 and np.all(np.diff(rows[:, 0]) > 0)
    res = inv(cli, ["map", str(log), "--trajectory", str(tmp_path / "AB" / "trajectory.tum"),
                    "-o", str(tmp_path / "fgm"), "--config", str(conf)])  # fmt: skip
    assert res.exit_code == 0, res.output
    fgm = yaml.safe_load((tmp_path / "fgm" / "calibration.yaml").read_text())
    assert fgm["t"] <= json.loads(res.stdout)["freeze_time"] < fgm["t"] + 1.0 + 1e-9
    res = inv(cli, ["run", str(log), "-o", str(tmp_path / "C"), "--config", str(conf),
                    "--map", str(tmp_path / "fgm"), "--fix", "heading"])  # fmt: skip
    assert res.exit_code == 0, res.output
    start = json.loads(res.stdout)["calibration"]
    assert Path(start["start"]) == tmp_path / "fgm" / "calibration.yaml"
    np.testing.assert_allclose(start["start_factors"], fgm["factors"])
