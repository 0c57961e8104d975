"""Sonar Range messages into rings (streams/sonar.py ``group_rings``): rings stamped
alike (the simulator, CARMEN) and rings fired in sequence (a Pioneer: one sonar every
40 ms), with missing sonars, repeated messages and readings out of order; the ring gap
measured from the log (``firing_gap``, streams/ranges.py); readings without a valid field
of view read with the configured cone, and a map whose evidence touched no cell refused."""

from __future__ import annotations

import json
import math
from dataclasses import replace
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from test_robust_logs import cli, rewrite

from fuzzyslam.config import load_config
from fuzzyslam.streams import messages as M
from fuzzyslam.streams.ranges import open_ranges
from fuzzyslam.streams.reader import LogReader
from fuzzyslam.streams.sonar import MAX_RING_SPAN_S, RingStats, firing_gap, group_rings
from fuzzyslam.streams.writer import LogWriter

COUNT = 8
TOPICS = {f"/sonar/s{i:02d}": i for i in range(COUNT)}
FOV = math.radians(25.0)


def reading(t: float, i: int, r: float) -> SimpleNamespace:
    """A Range message of sonar ``i`` stamped ``t`` (s) reading ``r`` (m)."""
    return SimpleNamespace(topic=f"/sonar/s{i:02d}", msg=M.range_msg(t, f"s{i}", r, FOV, 0.1, 5.0))


def ranges_of(cycle: int, i: int) -> float:
    """A distinct range per cycle and sonar, to see which reading went where."""
    return 1.0 + 0.1 * cycle + 0.01 * i


def test_sequential_firing_makes_one_ring_per_cycle_at_its_last_stamp() -> None:
    """Eight sonars fired one every 40 ms, cycle after cycle: one ring per cycle holding
    all eight readings (the old 50 ms window cut each cycle into four rings of two),
    timed at its last reading's stamp, with each reading's stamp as an offset from it."""
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
        assert ring.t == pytest.approx(stamps[-1], abs=1e-9)
        np.testing.assert_allclose(ring.t + ring.offsets, stamps, rtol=0, atol=1e-9)
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
    assert all(r.offsets is None for r in rings)  # nothing to deskew
    assert st.sequential == 0 and st.missing == 1
    assert math.isnan(rings[1].ranges[0]) and rings[2].ranges[0] == ranges_of(2, 0)


def test_repeats_gaps_and_out_of_order_readings() -> None:
    """A sonar repeated at its own stamp is a duplicate; a sonar that reads again at a
    new stamp starts the next cycle; a pause longer than the gap starts a ring; a reading
    stamped more than MAX_RING_SPAN_S before the latest (too late to be put back in
    order) is dropped; a cycle is cut at MAX_RING_SPAN_S."""
    msgs = [reading(10.0, 0, 1.0), reading(10.04, 1, 1.1), reading(10.04, 1, 1.1)]  # duplicate
    msgs += [reading(10.08, 0, 1.2)]  # sonar 0 again: a new cycle
    msgs += [reading(10.08 - MAX_RING_SPAN_S - 0.01, 2, 1.3)]  # out of order
    msgs += [reading(10.5, 3, 1.4)]  # after a 0.42 s pause: a new ring
    st = RingStats()
    rings = list(group_rings(msgs, TOPICS, COUNT, stats=st))
    assert st.duplicates == 1 and st.out_of_order == 1
    assert [round(r.t, 6) for r in rings] == [10.04, 10.08, 10.5]  # each at its last stamp
    # a slow sequence (one sonar every 40 ms over 40 sonars) is cut at the span limit
    many = {f"/sonar/s{i:02d}": i for i in range(40)}
    slow = [reading(20.0 + 0.04 * i, i, 1.0) for i in range(40)]
    cut = list(group_rings(slow, many, 40))
    spans = [int(np.count_nonzero(np.isfinite(r.ranges))) for r in cut]
    assert sum(spans) == 40 and len(cut) == 2
    assert (spans[0] - 1) * 0.04 <= MAX_RING_SPAN_S < spans[0] * 0.04


# --- the ring gap measured from the log ---------------------------------------------------

RING16 = {f"/sonar/s{i:02d}": i for i in range(16)}


def firing(period: float, jitter: float = 0.0, dead: tuple[int, ...] = ()) -> list:
    """Five cycles of 16 sonars fired in sequence, one every ``period`` s (+- ``jitter``,
    uniform), the ``dead`` sonars never reading (a double step where each should be)."""
    rng = np.random.default_rng(0)
    t, out = 100.0, []
    for c in range(5):
        for i in range(16):
            t += period + rng.uniform(-jitter, jitter)
            if i not in dead:
                out.append(reading(t, i, ranges_of(c, i)))
    return out


def measured_rings(msgs: list) -> tuple[str, float, list, RingStats]:
    stamps = [M.stamp_to_sec(m.msg.header.stamp) for m in msgs]
    kind, gap = firing_gap(stamps, 16)
    st = RingStats()
    return kind, gap, list(group_rings(msgs, RING16, 16, gap, st)), st


@pytest.mark.parametrize(
    ("period", "jitter", "dead", "size"),
    [(0.0625, 0.0, (), 16), (0.04, 0.015, (), 16), (0.04, 0.0, (3, 9), 14)],
    ids=["62.5ms", "jitter", "dead_sonars"],
)
def test_measured_gap_keeps_each_sequential_cycle_whole(period, jitter, dead, size) -> None:
    """16 sonars over 1 s (62.5 ms each), 40 +- 15 ms, or two dead sonars (double steps):
    the gap measured from the stamps (2.5 x the median step) gives one ring per cycle
    holding every reading (the fixed 50 ms gap cut these into rings of one to ten)."""
    kind, gap, rings, st = measured_rings(firing(period, jitter, dead))
    assert kind == "sequential" and gap < MAX_RING_SPAN_S
    assert gap == pytest.approx(2.5 * period, rel=0.15)
    assert len(rings) == 5 and st.sequential == 5 and st.out_of_order == 0
    assert [int(np.count_nonzero(np.isfinite(r.ranges))) for r in rings] == [size] * 5
    for c, ring in enumerate(rings):
        want = [np.nan if i in dead else ranges_of(c, i) for i in range(16)]
        np.testing.assert_allclose(ring.ranges, want)


def test_two_banks_logged_late_are_put_back_in_stamp_order() -> None:
    """Two drivers fire banks s0-s7 and s8-s15 together every 40 ms; bank B is logged
    100 ms after its stamp. The reorder buffer puts it back: all 80 readings in 5 rings,
    none dropped as out of order (the old code dropped 38 of bank B)."""
    ev = []
    for c in range(5):
        for k in range(8):
            ts = 100.0 + (c * 8 + k) * 0.04
            ev.append((ts, reading(ts, k, ranges_of(c, k))))
            ev.append((ts + 0.1, reading(ts, k + 8, ranges_of(c, k + 8))))
    msgs = [m for _, m in sorted(ev, key=lambda e: e[0])]
    for gap in (0.05, measured_rings(msgs)[1]):
        st = RingStats()
        rings = list(group_rings(msgs, RING16, 16, gap, st))
        assert st.out_of_order == 0 and st.readings == 80 and st.missing == 0
        assert len(rings) == 5
        for c, ring in enumerate(rings):
            np.testing.assert_allclose(ring.ranges, [ranges_of(c, i) for i in range(16)])
            assert ring.t == pytest.approx(100.0 + (c * 8 + 7) * 0.04)  # the last stamp


def test_firing_gap_of_rings_stamped_alike_is_a_small_tolerance() -> None:
    """Whole rings at one stamp (0.2 s apart, or 0.06 s): simultaneous, gap 50 ms or half
    the ring period; a single stamp: 50 ms."""
    assert firing_gap([1.0 + 0.2 * (k // 16) for k in range(300)], 16) == ("simultaneous", 0.05)
    kind, gap = firing_gap([1.0 + 0.06 * (k // 9) for k in range(300)], 9)
    assert kind == "simultaneous" and gap == pytest.approx(0.03)
    assert firing_gap([5.0] * 16, 16) == ("simultaneous", 0.05)


def _sonar_log(path, stamps: list[tuple[float, int]]) -> None:
    """A log of 16 sonars under base_link, readings (stamp, sonar) in log order."""
    links = [
        M.transform_stamped(0.0, "base_link", f"sonar_{i:02d}", 0.2, 0.0, 0.1, i * math.pi / 8)
        for i in range(16)
    ]
    with LogWriter(path) as w:
        w.write("/tf_static", M.TF_MESSAGE, M.tf_message(links), 0.0)
        for t, i in stamps:
            msg = M.range_msg(t, f"sonar_{i:02d}", 1.0 + 0.01 * i, FOV, 0.1, 5.0)
            w.write(f"/sonar/s{i:02d}", M.RANGE, msg, t)


def test_open_ranges_measures_simultaneous_or_sequential_firing(tmp_path) -> None:
    """open_ranges reads the sonars' first stamps: rings stamped alike every 0.2 s are
    simultaneous (gap 50 ms, rings as before); one sonar every 62.5 ms is sequential (gap
    156 ms) and its RangeSensor groups whole cycles; both in the summary."""
    cfg = load_config("quick.yaml")
    alike, seq = tmp_path / "alike.mcap", tmp_path / "seq.mcap"
    _sonar_log(alike, [(1.0 + 0.2 * c, i) for c in range(5) for i in range(16)])
    _sonar_log(seq, [(1.0 + 0.0625 * (c * 16 + i), i) for c in range(5) for i in range(16)])
    for log, kind, gap in ((alike, "simultaneous", 0.05), (seq, "sequential", 0.15625)):
        sensor = open_ranges(LogReader(log), cfg, "sonar")
        d = sensor.describe()
        assert sensor.firing == d["firing"] == kind
        assert sensor.ring_gap == pytest.approx(gap) and d["ring_gap_s"] == pytest.approx(gap)
        rings = list(sensor.rings(LogReader(log).messages(sensor.topics), RingStats()))
        assert len(rings) == 5
        assert all(np.count_nonzero(np.isfinite(r.ranges)) == 16 for r in rings)


def test_sonars_published_in_a_loop_are_one_firing() -> None:
    """A driver publishing its 16 readings one by one in a loop, 50 us apart with
    scheduling hiccups of 1-3 ms, every 0.1 s: one ring per firing (the measured gap is
    never below SIMULTANEOUS_GAP_S)."""
    from fuzzyslam.streams.sonar import SIMULTANEOUS_GAP_S, firing_gap

    rng = np.random.default_rng(2)
    count = 16
    topics = {f"/sonar/s{i:02d}": i for i in range(count)}
    msgs, stamps = [], []
    for c in range(40):
        t = 10.0 + 0.1 * c
        for i in range(count):
            t += 50e-6 + (rng.uniform(1e-3, 3e-3) if rng.random() < 0.1 else 0.0)
            msgs.append(reading(t, i, 1.0 + 0.01 * i))
            stamps.append(t)
    kind, gap = firing_gap(stamps[:300], count)
    assert gap >= SIMULTANEOUS_GAP_S
    st = RingStats()
    rings = list(group_rings(msgs, topics, count, gap, st))
    assert len(rings) == 40 and st.missing == 0, (kind, gap, len(rings))


# --- an invalid field of view: the configured cone ----------------------------------------


def test_rings_before_a_valid_field_of_view_take_the_configured_cone() -> None:
    """Range messages saying ``field_of_view: 0`` (or NaN): their rings take the cone
    given (the config's ``sonar.fov_deg``; DEFAULT_CONE when none), each reading counted
    ``bad_fov``; once a valid one is read, the last valid one."""
    from fuzzyslam.streams.sonar import DEFAULT_CONE

    cone = math.radians(30.0)

    def ring(c: int, fov: float) -> list:
        msgs = [reading(1.0 + c, i, ranges_of(c, i)) for i in range(COUNT)]
        for m in msgs:
            m.msg.field_of_view = fov
        return msgs

    zero = [m for c in range(3) for m in ring(c, 0.0 if c % 2 else math.nan)]
    st = RingStats()
    rings = list(group_rings(zero, TOPICS, COUNT, stats=st, cone=cone))
    assert [r.fov for r in rings] == [cone] * 3 and st.bad_fov == st.readings == 3 * COUNT
    assert [r.fov for r in group_rings(zero, TOPICS, COUNT)] == [DEFAULT_CONE] * 3
    later = zero + ring(3, math.radians(20.0)) + ring(4, 0.0)
    fovs = [r.fov for r in group_rings(later, TOPICS, COUNT, cone=cone)]
    assert fovs[:3] == [cone] * 3
    assert fovs[3:] == pytest.approx([math.radians(20.0)] * 2)  # float32 in the message


EXCERPT = Path(__file__).resolve().parents[1] / "data" / "carmen_fr079_excerpt"


def _excerpt_with(dst: Path, change) -> Path:
    """The real excerpt (9 sonars cut from its scans) with ``change(msg)`` applied to
    every Range message."""

    def fault(m):
        if m.typename == M.RANGE:
            change(m.msg)
        return [(m.topic, m.typename, m.msg, m.t)]

    return rewrite(EXCERPT / "log.mcap", dst, fault)


def _sonar_map(log: Path, out: Path) -> tuple[int, str, str]:
    return cli(
        "map", log, "--trajectory", EXCERPT / "truth.tum", "--config", "real_building_sonar",
        "--ranges", "sonar", "--no-figures", "-o", out,
    )  # fmt: skip


def test_open_ranges_takes_the_sonar_cone_from_the_config() -> None:
    """RangeSensor.cone is the config's ``sonar.fov_deg``."""
    cfg = load_config("real_building_sonar")
    cfg = replace(cfg, sonar=replace(cfg.sonar, fov_deg=33.0))
    sensor = open_ranges(LogReader(EXCERPT / "log.mcap"), cfg, "sonar")
    assert sensor.cone == pytest.approx(math.radians(33.0))


def test_sonars_without_a_field_of_view_map_with_the_configured_cone(tmp_path: Path) -> None:
    """Every Range message with ``field_of_view: 0``: the map stage reads them with the
    config's 25-degree cone (the excerpt's own), so it builds the clean log's map (to the
    float32 rounding of the cone), every reading counted ``bad_fov`` and the references finite."""
    zero = _excerpt_with(tmp_path / "fov0.mcap", lambda msg: setattr(msg, "field_of_view", 0.0))
    code, out, err = _sonar_map(zero, tmp_path / "fgm0")
    assert code == 0, err
    s = json.loads(out)
    assert s["sonar_stats"]["bad_fov"] == s["sonar_stats"]["readings"] > 0
    assert s["cells_touched"] > 0 and s["references"]
    assert all(math.isfinite(r["angle_deg"]) for r in s["references"])
    code, _, err = _sonar_map(EXCERPT / "log.mcap", tmp_path / "fgm")
    assert code == 0, err
    for k in ("m_e", "m_o", "m_t", "m_c"):
        with (
            np.load(tmp_path / "fgm0" / "fgm.npz") as a,
            np.load(tmp_path / "fgm" / "fgm.npz") as b,
        ):
            # the message's float32 cone against the config's float64 one
            np.testing.assert_allclose(a[k], b[k], atol=1e-5)


def test_a_map_whose_evidence_touched_no_cell_is_refused(tmp_path: Path) -> None:
    """Every sonar reading invalid (NaN): the map stage writes nothing and exits 3 with
    one line naming the log and why."""
    bad = _excerpt_with(tmp_path / "nan.mcap", lambda msg: setattr(msg, "range", math.nan))
    code, out, err = _sonar_map(bad, tmp_path / "fgm")
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert code == 3 and out == "" and len(lines) == 1, err
    assert str(bad) in lines[0] and "no map written" in lines[0] and "no map cell" in lines[0]
    assert not (tmp_path / "fgm").exists()


# --- REP 117: +inf nothing detected, -inf closer than min_range ------------------------------


def test_rep117_infinities_read_as_no_echo_and_invalid() -> None:
    """+inf (REP 117: nothing detected) is no echo, read as max_range like a range at or
    beyond it; -inf (an object closer than min_range) is invalid, as NaN is."""
    msgs = [reading(1.0, i, ranges_of(0, i)) for i in range(COUNT)]
    msgs[1].msg.range, msgs[2].msg.range, msgs[3].msg.range = math.inf, -math.inf, math.nan
    st = RingStats()
    (ring,) = group_rings(msgs, TOPICS, COUNT, stats=st, cone=FOV)
    assert st.no_echo == 1 and st.invalid == 2
    assert ring.ranges[1] == ring.max_range[1] == pytest.approx(5.0)
    assert np.isnan(ring.ranges[2]) and np.isnan(ring.ranges[3])
