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


def test_in_stamp_order_puts_back_what_lags_less_than_the_window() -> None:
    """Items logged with random lags below the window come out sorted by stamp (ties in
    read order) and complete; one that lags more is yielded at once, marked late."""
    import itertools

    import numpy as np

    from fuzzyslam.stamps import in_stamp_order

    rng = np.random.default_rng(5)
    stamps = np.round(np.sort(rng.uniform(0, 100, 2000)), 1)  # ties included
    logged = stamps + rng.uniform(0, 2.0, len(stamps))  # lags below the 2.5 s window
    order = np.argsort(logged, kind="stable")
    out = list(in_stamp_order(((float(stamps[k]), int(k)) for k in order), 2.5))
    assert [late for *_, late in out] == [False] * len(stamps)
    got = [(t, k) for t, k, _ in out]
    assert sorted(k for _, k in got) == list(range(len(stamps)))
    assert [t for t, _ in got] == sorted(stamps.tolist())
    # equal stamps keep their read order
    pos = {int(k): n for n, k in enumerate(order)}
    for (t1, k1), (t2, k2) in itertools.pairwise(got):
        assert t1 < t2 or pos[k1] < pos[k2]
    late = list(in_stamp_order([(10.0, "a"), (20.0, "b"), (12.0, "c"), (19.0, "d")], 5.0))
    assert late == [(10.0, "a", False), (12.0, "c", True), (19.0, "d", False), (20.0, "b", False)]
