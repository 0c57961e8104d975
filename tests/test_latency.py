"""Odometry latency (slam/latency.py): restamped odometry, the event stream in time order."""

from __future__ import annotations

import numpy as np
import pytest

from fuzzyslam.slam.events import Frame, Odom
from fuzzyslam.slam.latency import delay_odometry


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
