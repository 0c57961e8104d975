"""Sonar Range messages into rings (streams/sonar.py ``group_rings``): rings stamped
alike (the simulator, CARMEN) and rings fired in sequence (a Pioneer: one sonar every
40 ms), with missing sonars, repeated messages and readings out of order."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from fuzzyslam.streams import messages as M
from fuzzyslam.streams.sonar import MAX_RING_SPAN_S, RingStats, group_rings

COUNT = 8
TOPICS = {f"/sonar/s{i:02d}": i for i in range(COUNT)}
FOV = math.radians(25.0)


def reading(t: float, i: int, r: float) -> SimpleNamespace:
    """A Range message of sonar ``i`` stamped ``t`` (s) reading ``r`` (m)."""
    return SimpleNamespace(topic=f"/sonar/s{i:02d}", msg=M.range_msg(t, f"s{i}", r, FOV, 0.1, 5.0))


def ranges_of(cycle: int, i: int) -> float:
    """A distinct range per cycle and sonar, to see which reading went where."""
    return 1.0 + 0.1 * cycle + 0.01 * i


def test_sequential_firing_makes_one_ring_per_cycle_at_its_mean_time() -> None:
    """Eight sonars fired one every 40 ms, cycle after cycle: one ring per cycle holding
    all eight readings, timed at the mean of their stamps (the old 50 ms window cut each
    cycle into four rings of two)."""
    dt, t0 = 0.04, 100.0
    msgs = [
        reading(t0 + (c * COUNT + i) * dt, i, ranges_of(c, i))
        for c in range(5)
        for i in range(COUNT)
    ]
    st = RingStats()
    rings = list(group_rings(msgs, TOPICS, COUNT, stats=st))
    assert len(rings) == 5 and st.rings == 5 and st.sequential == 5 and st.missing == 0
    for c, ring in enumerate(rings):
        stamps = t0 + (c * COUNT + np.arange(COUNT)) * dt
        assert ring.t == pytest.approx(stamps.mean(), abs=1e-9)
        np.testing.assert_allclose(ring.ranges, [ranges_of(c, i) for i in range(COUNT)])


def test_rings_stamped_alike_keep_their_stamp_exactly() -> None:
    """A whole ring at one stamp every 0.2 s (the simulator's): one ring per stamp at
    exactly that stamp; a sonar missing from a ring reads NaN and the next ring's reading
    of it does not join the earlier ring."""
    stamps = [1600000000.1 + 0.2 * k for k in range(4)]
    msgs = [reading(t, i, ranges_of(k, i)) for k, t in enumerate(stamps) for i in range(COUNT)]
    del msgs[COUNT + 0]  # ring 1 lacks sonar 0 (its first)
    st = RingStats()
    rings = list(group_rings(msgs, TOPICS, COUNT, stats=st))
    assert [r.t for r in rings] == stamps  # bit for bit
    assert st.sequential == 0 and st.missing == 1
    assert math.isnan(rings[1].ranges[0]) and rings[2].ranges[0] == ranges_of(2, 0)


def test_repeats_gaps_and_out_of_order_readings() -> None:
    """A sonar repeated at its own stamp is a duplicate; a sonar that reads again at a
    new stamp starts the next cycle; a pause longer than the gap starts a ring; a reading
    stamped more than the gap before the latest is dropped; a cycle is cut at
    MAX_RING_SPAN_S."""
    msgs = [reading(10.0, 0, 1.0), reading(10.04, 1, 1.1), reading(10.04, 1, 1.1)]  # duplicate
    msgs += [reading(10.08, 0, 1.2)]  # sonar 0 again: a new cycle
    msgs += [reading(9.9, 2, 1.3)]  # out of order
    msgs += [reading(10.5, 3, 1.4)]  # after a 0.42 s pause: a new ring
    st = RingStats()
    rings = list(group_rings(msgs, TOPICS, COUNT, stats=st))
    assert st.duplicates == 1 and st.out_of_order == 1
    assert [round(r.t, 6) for r in rings] == [10.02, 10.08, 10.5]
    # a slow sequence (one sonar every 40 ms over 40 sonars) is cut at the span limit
    many = {f"/sonar/s{i:02d}": i for i in range(40)}
    slow = [reading(20.0 + 0.04 * i, i, 1.0) for i in range(40)]
    cut = list(group_rings(slow, many, 40))
    spans = [int(np.count_nonzero(np.isfinite(r.ranges))) for r in cut]
    assert sum(spans) == 40 and len(cut) == 2
    assert (spans[0] - 1) * 0.04 <= MAX_RING_SPAN_S < spans[0] * 0.04
