"""Time stamps in text outputs: one format for every CSV file (and TUM's time column).

Log times are seconds, often Unix time (about 1.7e9 s): a format with significant digits
("%.9g") would round them to ten seconds. Fixed point with nine decimals keeps every
digit a float64 holds (its resolution at 1.7e9 s is 0.24 us; simulated times keep
nanoseconds).
"""

from __future__ import annotations

import math

TIME_FORMAT = "%.9f"


def format_time(t: float) -> str:
    """Fixed-point text of a time in seconds; empty for NaN or infinity."""
    return TIME_FORMAT % t if math.isfinite(t) else ""
