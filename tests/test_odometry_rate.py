"""Odometry at any rate: a gap is a silence long for the odometry's own rate, and slow
odometry gets a note saying what it costs (slam/inputs.py)."""

from __future__ import annotations

from test_robust_logs import JOINTS, Out, Tiny, cli, keep, rewrite, tiny  # noqa: F401

from fuzzyslam.slam.inputs import SLOW_ODOMETRY_S, odometry_period, slow_odometry_note
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


def test_slow_encoders_are_slow_not_silent(tiny: Tiny, tmp_path) -> None:  # noqa: F811
    """Encoders cut from 20 Hz to 1 Hz: no odometry gap is reported (each 1 s interval
    was one before: 'silent for 1.00 s'), the period is measured from the log, and stderr
    has one note naming the topic and the rate; at 20 Hz no note."""
    log = rewrite(tiny.log, tmp_path / "odo1.mcap", every(20))
    period = odometry_period(LogReader(log), JOINTS)
    assert 0.95 < period < 1.05
    assert odometry_period(LogReader(tiny.log), JOINTS) < 0.06
    code, out, err = cli("run", log, "-o", tmp_path / "est", "--config", tiny.config)
    assert code == 0, err
    import json

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
