"""Times given on the command line (``--until``, ``--fix-from``): the log's own stamps or
``+S`` after its first message (fuzzyslam/stamps.py, the CLI's parameter type)."""

from __future__ import annotations

import click
import numpy as np
import pytest

from fuzzyslam.cli import LOG_TIME
from fuzzyslam.stamps import LogTime, log_time

START = 1_600_000_199.041407  # a CARMEN log's first stamp (Unix time)


@pytest.mark.parametrize(
    ("text", "seconds", "relative"),
    [("600", 600.0, False), ("+600", 600.0, True), (" +1e3 ", 1000.0, True), ("0", 0.0, False),
     ("1600000229.5", 1600000229.5, False), ("+0", 0.0, True)],
)  # fmt: skip
def test_log_time_parses_stamps_and_offsets(text: str, seconds: float, relative: bool) -> None:
    t = LOG_TIME.convert(text, None, None)
    assert t == LogTime(seconds, relative)
    assert log_time(t, START) == (START + seconds if relative else seconds)
    assert LOG_TIME.convert(str(t), None, None) == t  # its text reads back the same


@pytest.mark.parametrize("text", ["nan", "+inf", "-5", "+-5", "1e300", "", "+", "abc"])
def test_log_time_refuses_what_is_not_one(text: str) -> None:
    with pytest.raises(click.BadParameter):
        LOG_TIME.convert(text, None, None)


def test_plain_numbers_are_the_logs_own_stamps() -> None:
    """The stages' Python callers (reproduce's plan) give floats: stamps, as before."""
    assert log_time(0.0, START) == 0.0 and log_time(None, START) is None
    assert log_time(LogTime(30.0, True), START) == START + 30.0


def test_nanoseconds_are_the_floats_own_value_rounded() -> None:
    """to_ns: the float's exact value (a Fraction) rounded to the nanosecond, at simulated
    and Unix times alike, and the same digits as the TUM and CSV text (format_time);
    ``round(t * 1e9)`` missed it by up to 128 ns at Unix times (the /tf stamps then
    disagreed with trajectory.tum's)."""
    from fractions import Fraction

    from fuzzyslam.stamps import format_time, split_ns, to_ns

    rng = np.random.default_rng(7)
    edges = [0.0, 1e6, 1e6 - 1e-7, 1248444188.948999882, -2.5e-9, 0.5e-9]
    times = np.concatenate([rng.uniform(0, 4e4, 500), 1.2e9 + rng.uniform(0, 6e8, 2000), edges])
    off = 0
    for t in times.tolist():
        exact = round(Fraction(t) * 10**9)
        assert to_ns(t) == exact, t
        sec, nsec = split_ns(t)
        assert sec * 10**9 + nsec == exact and 0 <= nsec < 10**9
        assert t < 0 or f"{sec}.{nsec:09d}" == format_time(t)
        off = max(off, abs(round(t * 1e9) - exact))
    assert off > 16  # the old product's error at Unix times: the test can tell them apart
