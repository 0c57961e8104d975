"""Odometry latency (slam/latency.py): restamped odometry, the event stream in time order,
the latency estimated from the bearings."""

from __future__ import annotations

import numpy as np
import pytest

from fuzzyslam.slam.events import Frame, Odom
from fuzzyslam.slam.latency import MIN_PAIRS, MotionTap, delay_note, delay_odometry


def _stream(rng: np.random.Generator, n: int = 300):
    """Odometry at ~50 Hz and frames at ~7 Hz, each in stamp order, merged by stamp."""
    t_odo = np.cumsum(rng.uniform(0.005, 0.035, n))
    t_frm = np.sort(rng.uniform(0.0, t_odo[-1], n // 7))
    evs = [
        Odom(float(t), float(a), float(b))
        for t, a, b in zip(t_odo, *rng.normal(size=(2, n)), strict=True)
    ]
    evs += [Frame(float(t), np.zeros((1, 2)), np.eye(2)[None]) for t in t_frm]
    evs.sort(key=lambda e: e.t)
    return evs


@pytest.mark.parametrize("seed", range(5))
@pytest.mark.parametrize("delay", [0.0, 0.013, 0.2, 1.5])
def test_delayed_stream_equals_a_stable_sort_of_the_restamped_events(seed, delay):
    evs = _stream(np.random.default_rng(seed))
    out = list(delay_odometry(evs, delay))
    # second implementation: restamp all, then a stable sort by time
    restamped = [Odom(e.t + delay, e.d_trans, e.d_rot) if isinstance(e, Odom) else e for e in evs]
    expect = sorted(restamped, key=lambda e: e.t)
    assert [type(e) for e in out] == [type(e) for e in expect]
    assert [e.t for e in out] == [e.t for e in expect]
    assert all(np.diff([e.t for e in out]) >= 0)
    odo_in = [(e.t + delay, e.d_trans, e.d_rot) for e in evs if isinstance(e, Odom)]
    assert [(e.t, e.d_trans, e.d_rot) for e in out if isinstance(e, Odom)] == odo_in
    assert [e for e in out if isinstance(e, Frame)] == [e for e in evs if isinstance(e, Frame)]


def test_no_delay_keeps_the_stream_as_it_is():
    evs = _stream(np.random.default_rng(7))
    assert list(delay_odometry(evs, 0.0)) == evs


def test_a_negative_delay_is_refused():
    with pytest.raises(ValueError, match="delay"):
        list(delay_odometry([], -0.1))


def test_a_frame_sees_only_the_motion_that_has_happened_by_its_stamp():
    """Odometry stamped 0.1 s before a frame describes motion 0.1 s after it with a
    0.2 s latency: the frame comes first."""
    evs = [Odom(1.0, 0.1, 0.0), Frame(1.1, np.zeros((0, 2)), np.zeros((0, 2, 2))),
           Odom(1.2, 0.1, 0.0)]  # fmt: skip
    out = list(delay_odometry(evs, 0.2))
    assert [type(e).__name__ for e in out] == ["Frame", "Odom", "Odom"]
    assert [e.t for e in out] == [1.1, pytest.approx(1.2), pytest.approx(1.4)]


def _drive(delay: float, seed: int, bearing_sigma_deg: float = 0.5):
    """A robot weaving among 30 landmarks for 120 s: odometry at 50 Hz whose increments
    happen ``delay`` s after their stamps, frames at 7 Hz with the landmarks within 5 m
    and 35 deg, stamped when taken. Returns the events in stamp order."""
    rng = np.random.default_rng(seed)
    marks = rng.uniform(-6.0, 6.0, (30, 2))
    dt = 0.02
    t = np.arange(0.0, 120.0, dt)
    v = 0.25 + 0.1 * np.sin(0.31 * t)
    w = 0.6 * np.sin(0.23 * t) + 0.3 * np.sin(1.1 * t + 1.0)
    th = np.concatenate([[0.0], np.cumsum(w[:-1] * dt)])
    xy = np.column_stack([np.cumsum(v * np.cos(th) * dt), np.cumsum(v * np.sin(th) * dt)])
    xy -= xy.mean(axis=0)
    evs = []
    for k in range(1, len(t)):  # increment k-1 -> k happens at t[k]; stamped t[k] - delay
        evs.append(Odom(float(t[k] - delay), float(v[k - 1] * dt), float(w[k - 1] * dt)))
    sig = np.radians(bearing_sigma_deg)
    for k in range(0, len(t), 7):
        d = marks - xy[k]
        rng_ = np.hypot(d[:, 0], d[:, 1])
        b = np.arctan2(d[:, 1], d[:, 0]) - th[k]
        b = np.angle(np.exp(1j * b)) + rng.normal(0.0, sig, len(b))
        seen = (rng_ < 5.0) & (np.abs(b) < np.radians(35))
        z = np.column_stack([rng_ * np.cos(b), rng_ * np.sin(b)])[seen]
        evs.append(Frame(float(t[k]), z, np.tile(np.eye(2) * 1e-4, (len(z), 1, 1))))
    evs.sort(key=lambda e: e.t)
    return evs


@pytest.mark.parametrize("delay", [0.0, 0.1, 0.25])
def test_the_bearings_recover_a_known_odometry_delay(delay):
    """Synthetic drive with a known latency: the estimate is within 0.01 s of it, and the
    residual scale at the estimate is no larger than at the stamps as given."""
    tap = MotionTap(_drive(delay, seed=3))
    for _ in tap:
        pass
    est = tap.estimate(0.0)
    assert est is not None and est.pairs >= MIN_PAIRS
    assert abs(est.delay_s - delay) <= 0.01, est
    assert est.residual_deg <= est.residual_at_configured_deg * 1.001


def test_the_estimate_does_not_depend_on_the_configured_delay():
    """Restamping by the configured delay first, then estimating the rest, gives the same
    total: the estimator reads the stamps as the filter sees them."""
    evs = _drive(0.2, seed=5)
    totals = []
    for configured in (0.0, 0.1, 0.2):
        tap = MotionTap(delay_odometry(evs, configured))
        for _ in tap:
            pass
        totals.append(tap.estimate(configured).delay_s)
    assert np.ptp(totals) <= 0.01, totals
    assert abs(totals[0] - 0.2) <= 0.02


def test_too_few_sightings_give_no_estimate():
    evs = [e for e in _drive(0.1, seed=1) if e.t < 3.0]
    tap = MotionTap(evs)
    assert list(tap) == evs  # passes every event through, unchanged and in order
    assert tap.estimate(0.0) is None


def test_the_advice_names_the_key_only_when_the_estimate_is_far_off():
    assert delay_note(0.21, 0.2) == ""
    line = delay_note(0.3, 0.0)
    assert "slam.odometry_delay_s: 0.3" in line and "\n" not in line
