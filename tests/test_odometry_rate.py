"""Odometry at any rate: a gap is a silence long for the odometry's own rate, and slow
odometry gets a note saying what it costs (slam/inputs.py)."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from test_robust_logs import JOINTS, Out, Tiny, cli, keep, rewrite, tiny  # noqa: F401

from fuzzyslam.slam.log_setup import SLOW_ODOMETRY_S, odometry_clock, slow_odometry_note
from fuzzyslam.streams import messages as M
from fuzzyslam.streams.reader import LogMessage, LogReader


def every(n: int):
    """A fault keeping every n-th wheel-encoder message (the first kept)."""
    seen = [0]

    def fault(m: LogMessage) -> list[Out]:
        if m.topic != JOINTS:
            return keep(m)
        seen[0] += 1
        return keep(m) if seen[0] % n == 1 else []

    return fault


@pytest.mark.slow  # end to end, about 1 s: the fast tier stays under a minute
def test_slow_encoders_are_slow_not_silent(tiny: Tiny, tmp_path) -> None:  # noqa: F811
    """Encoders cut from 20 Hz to 1 Hz: no odometry gap is reported (each 1 s interval
    was one before: 'silent for 1.00 s'), the period is measured from the log, and stderr
    has one note naming the topic and the rate; at 20 Hz no note."""
    log = rewrite(tiny.log, tmp_path / "odo1.mcap", every(20))
    period = odometry_clock(LogReader(log), JOINTS)[0]
    assert 0.95 < period < 1.05
    assert odometry_clock(LogReader(tiny.log), JOINTS)[0] < 0.06
    code, out, err = cli("run", log, "-o", tmp_path / "est", "--config", tiny.config)
    assert code == 0, err
    s = json.loads(out)
    assert s["warnings"].get("odometry_gaps", 0) == 0
    assert s["filter_health"]["odometry_gap_s"] == 0
    lines = [ln for ln in err.splitlines() if "Hz" in ln]
    assert len(lines) == 1 and JOINTS in lines[0] and "1.0 Hz" in lines[0]
    # a real silence of 4 s in the 1 Hz odometry is still a gap (3 periods)
    kept = rewrite(
        log, tmp_path / "gap.mcap", lambda m: [] if m.topic == JOINTS and 10 < m.t < 14 else keep(m)
    )
    code, out, err = cli("run", kept, "-o", tmp_path / "est_gap", "--config", tiny.config)
    assert code == 0, err
    assert json.loads(out)["warnings"]["odometry_gaps"] == 1
    assert slow_odometry_note(JOINTS, SLOW_ODOMETRY_S) == ""
    assert "Hz" not in cli("run", tiny.log, "-o", tmp_path / "clean", "--config", tiny.config)[2]


def test_the_period_is_the_odometrys_own(tiny: Tiny, tmp_path) -> None:  # noqa: F811
    """The encoders stop after 10 s while the other streams go on (a driver that dies):
    the period is still the encoders' 0.05 s (the log's span over their count would say
    0.26 s), and no note is given."""

    def dies(m: LogMessage) -> list[Out]:
        return [] if m.topic == JOINTS and m.t > 10 else keep(m)

    stop = rewrite(tiny.log, tmp_path / "stop.mcap", dies)
    assert 0.049 < odometry_clock(LogReader(stop), JOINTS)[0] < 0.051
    code, out, err = cli("run", stop, "-o", tmp_path / "est", "--config", tiny.config)
    assert code == 0 and "Hz" not in err, err
    # the frames after it were compared with a stale pose and skipped: most of the run
    health = json.loads(out)["filter_health"]
    assert health["diverged"] and "events_lost" in health["reasons"]
    assert 10.0 < health["diverged_at"] < 12.0


def test_a_static_message_logged_at_time_0_does_not_start_the_run(tmp_path) -> None:
    """The Freiburg excerpt with its /tf_static logged at time 0 (as some converters do):
    the run starts at its first odometry message, not at 0, and its duration is the
    excerpt's minute."""
    src = Path(__file__).resolve().parents[1] / "data" / "carmen_fr079_excerpt" / "log.mcap"

    def at_zero(m: LogMessage) -> list[Out]:
        return [(m.topic, m.typename, m.msg, 0.0)] if m.topic == "/tf_static" else keep(m)

    log = rewrite(src, tmp_path / "tf0.mcap", at_zero)
    assert LogReader(log).start == 0.0
    code, out, err = cli(
        "run", log, "-o", tmp_path / "est", "--config", "real_building_scan", "--no-prefetch"
    )
    assert code == 0, err
    assert 55.0 < json.loads(out)["log_duration_s"] < 65.0
    first = np.loadtxt(tmp_path / "est" / "trajectory.tum", ndmin=2)[0, 0]
    assert first == pytest.approx(LogReader(src).start, abs=1.0)


def test_a_range_sensor_on_another_clock_is_lost_and_said(tmp_path) -> None:
    """The Freiburg excerpt's sonars stamped 20 s ahead of their log time (a sonar board
    with its own clock): their readings are not used, counted, the first described, and
    the run's health rule says a stream was lost; the untouched excerpt loses none."""
    from test_robust_logs import set_stamp

    from fuzzyslam.config import load_config
    from fuzzyslam.slam.inputs import open_inputs
    from fuzzyslam.slam.run_results import LateEvents, RunCounts, lost_events

    src = Path(__file__).resolve().parents[1] / "data" / "carmen_fr079_excerpt" / "log.mcap"

    def ahead(m: LogMessage) -> list[Out]:
        if m.topic.startswith("/sonar/"):
            set_stamp(m.msg, M.stamp_to_sec(m.msg.header.stamp) + 20.0)
        return keep(m)

    cfg = load_config("real_building_sonar")
    counts = RunCounts(**dict.fromkeys(RunCounts.__dataclass_fields__, 100))
    counts = replace(counts, frames_stale_odometry=0)
    for log, lost_all in ((src, False), (rewrite(src, tmp_path / "ahead.mcap", ahead), True)):
        inputs = open_inputs(log, cfg, need_rings=True)
        rings = [e for e in inputs.events(rings=True) if type(e).__name__ == "RingEvent"]
        found = lost_events(LateEvents(), counts, inputs.lost, inputs.ring_stats.readings)
        if lost_all:
            assert rings == [] and inputs.lost["readings"] == inputs.warnings["clock_mismatch"]
            assert inputs.lost["readings"] > 1000 and "/sonar/s" in inputs.first_problem
            assert found is not None and found[0] == "events_lost"
        else:
            assert len(rings) > 200 and inputs.lost["readings"] == 0 and found is None
