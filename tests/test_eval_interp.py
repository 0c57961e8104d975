"""evaluate pairs a fast estimate with a slow truth by interpolating the truth at the
estimate's stamps (a 30 Hz run against a 4 Hz scan-matched truth), but not across a gap
in the truth longer than ``evaluation.max_gap_s``: known answers on hand-made paths."""

from __future__ import annotations

import numpy as np
import pytest

from fuzzyslam.evaluation import metrics as M
from fuzzyslam.evaluation.core import Estimate, Truth, evaluate
from fuzzyslam.evaluation.params import EvalParams
from fuzzyslam.se2 import wrap_angle

V = np.array([0.4, 0.3])  # m/s
W = 1.3  # rad/s: the heading crosses +-pi every 4.8 s


def _line(t: np.ndarray) -> np.ndarray:
    """Poses (N, 3) at t on a straight drive while spinning: linear in time in x, y and
    the unwrapped heading, so interpolation between any two samples is exact."""
    return np.column_stack([1.0 + V[0] * t, -2.0 + V[1] * t, wrap_angle(3.0 + W * t)])


def _arc(t: np.ndarray, r: float, w: float) -> np.ndarray:
    """Poses (N, 3) at t on a circle of radius r driven at turn rate w, heading tangent."""
    a = w * t
    return np.column_stack([r * np.sin(a), r * (1.0 - np.cos(a)), wrap_angle(a)])


def _times(hz: float, t1: float, t0: float = 0.0) -> np.ndarray:
    return t0 + np.arange(round((t1 - t0) * hz) + 1) / hz


def test_fast_estimate_on_slow_truth_is_covered_and_exact() -> None:
    tt = _times(4.0, 60.0)  # truth at 4 Hz: 0.25 s apart, more than 2 * max_dt_s
    te = _times(30.0, 60.0)
    truth = Truth(tt, _line(tt))
    ev = evaluate(truth, Estimate(te, _line(te)), EvalParams())
    m = ev.typed
    assert m.truth_coverage.fraction == 1.0 and m.samples == te.size
    assert not [w for w in m.warnings if "covers only" in w]
    ov = ev.typed.phases["overall"]
    assert ov.ape_m.raw.max < 1e-9
    assert ov.heading_deg.max < 1e-9
    # the old pairing (a truth sample within max_dt_s) compared only stamps near a sample
    near = M.nearest_gap(tt, te) <= EvalParams().max_dt_s
    assert near.mean() < 0.85


def test_constant_offset_is_the_error() -> None:
    tt = _times(4.0, 60.0)
    te = _times(30.0, 60.0) + 0.01  # stamps between the truth's, never on them
    te = te[te <= tt[-1]]
    off = np.array([0.3, -0.4, 0.2])
    est = _line(te) + off
    est[:, 2] = wrap_angle(est[:, 2])
    ev = evaluate(Truth(tt, _line(tt)), Estimate(te, est), EvalParams())
    assert ev.typed.truth_coverage.fraction == 1.0
    np.testing.assert_allclose(ev.errors, np.tile(off, (te.size, 1)), atol=1e-9)
    assert ev.typed.phases["overall"].ape_m.raw.mean == pytest.approx(0.5, abs=1e-9)


def test_curved_path_error_within_the_chord_bound() -> None:
    """On a circle the straight line between truth samples g apart departs from the arc by
    at most the sagitta r (1 - cos(w g / 2)); the heading (constant rate) is exact."""
    r, w, g = 2.0, 0.5, 0.25
    tt = _times(1.0 / g, 30.0)
    te = _times(30.0, 30.0)
    ev = evaluate(Truth(tt, _arc(tt, r, w)), Estimate(te, _arc(te, r, w)), EvalParams())
    sagitta = r * (1.0 - np.cos(w * g / 2.0))
    pos = np.hypot(ev.errors[:, 0], ev.errors[:, 1])
    assert ev.typed.truth_coverage.fraction == 1.0
    assert pos.max() <= sagitta + 1e-12
    assert pos.max() > 0.9 * sagitta  # a stamp near a segment's middle
    assert np.abs(ev.errors[:, 2]).max() < 1e-9


def test_gap_longer_than_the_bound_is_not_interpolated_across() -> None:
    p = EvalParams()
    tt = np.concatenate([_times(4.0, 20.0), _times(4.0, 40.0, 22.0)])  # a 2 s gap at 20 s
    te = _times(30.0, 40.0) + 0.005  # off the truth's stamps and the bounds' edges
    te = te[te <= tt[-1]]
    a = M.associate(te, _line(te), tt, _line(tt), p.max_dt_s, p.max_gap_s)
    kept = np.zeros(te.size, dtype=bool)
    kept[a.index] = True
    in_gap = (te > 20.0) & (te < 22.0)
    ends = in_gap & ((te < 20.0 + p.max_dt_s) | (te > 22.0 - p.max_dt_s))
    # everything outside the gap; in it only the stamps within max_dt_s of its ends
    np.testing.assert_array_equal(kept, ~in_gap | ends)
    assert in_gap.sum() == 60 and ends.sum() == 6
    # the coverage says so, and the warning names the bound
    ev = evaluate(Truth(tt, _line(tt)), Estimate(te, _line(te)), p)
    assert ev.typed.truth_coverage.fraction == pytest.approx(1.0 - 54 / te.size, abs=1e-6)
    assert any("covers only" in w and "max_gap_s" in w for w in ev.typed.warnings)
    assert ev.typed.phases["overall"].ape_m.raw.max < 1e-9
    # a bound above the gap interpolates across it
    wide = M.associate(te, _line(te), tt, _line(tt), p.max_dt_s, 2.5)
    assert len(wide) == te.size
    # outside the truth's span nothing is paired, however near
    out = M.associate([-0.01, 40.01], np.zeros((2, 3)), tt, _line(tt), p.max_dt_s, p.max_gap_s)
    assert len(out) == 0


def test_heading_interpolates_across_the_wrap() -> None:
    p = EvalParams()
    tt = np.array([0.0, 0.25, 0.5])
    pt = np.array([[0.0, 0.0, np.pi - 0.1], [0.0, 0.0, -np.pi + 0.1], [0.0, 0.0, -np.pi + 0.3]])
    te = np.array([0.125, 0.375])  # 0.125 s from both neighbours: more than max_dt_s
    a = M.associate(te, np.zeros((2, 3)), tt, pt, p.max_dt_s, p.max_gap_s)
    np.testing.assert_array_equal(a.index, [0, 1])
    assert abs(a.truth[0, 2]) == pytest.approx(np.pi, abs=1e-12)  # not 0: the short way
    assert a.truth[1, 2] == pytest.approx(-np.pi + 0.2, abs=1e-12)
    est = np.array([[0.0, 0.0, -np.pi + 0.05], [0.0, 0.0, -np.pi + 0.2]])
    assert M.pose_errors(est, a.truth)[:, 2] == pytest.approx([0.05, 0.0], abs=1e-12)


def test_bracket_gap() -> None:
    g = M.bracket_gap([0.0, 1.0, 3.0], [-1.0, 0.0, 0.5, 1.0, 2.0, 3.0, 4.0])
    np.testing.assert_array_equal(g, [np.inf, 1.0, 1.0, 2.0, 2.0, 2.0, np.inf])
    assert np.isinf(M.bracket_gap([1.0], [1.0])).all()


def test_heading_fixes_in_a_long_truth_gap_are_not_judged() -> None:
    """A heading fix is compared with the truth interpolated at its time by the same rule
    as the poses: one in the middle of a 2 s gap of the truth (beyond max_gap_s) is left
    out, ones beside truth samples are kept with their exact error (here 0.1 rad)."""
    from fuzzyslam.evaluation.core import HeadingFixes

    tt = np.concatenate([_times(4.0, 20.0), _times(4.0, 40.0, 22.0)])  # no truth in (20, 22)
    te = _times(30.0, 40.0)
    tf = np.array([5.05, 21.0, 30.05])
    measured = wrap_angle(_line(tf)[:, 2] + 0.1)
    fixes = HeadingFixes(tf, measured, np.ones(3, dtype=bool), np.array(["ok"] * 3))
    ev = evaluate(Truth(tt, _line(tt)), Estimate(te, _line(te), heading_fixes=fixes), EvalParams())
    np.testing.assert_allclose(ev.fix_err[[0, 2]], [0.1, 0.1], atol=1e-9)
    assert np.isnan(ev.fix_err[1])  # in the gap: not judged
    fm = ev.typed.phases["overall"].heading_fix
    assert fm.attempted == 3 and fm.error_deg.n == 2
