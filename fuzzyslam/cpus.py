"""How many CPUs this process may use: one home for the local pool's size (``reproduce``,
``sweep``) and for whether ``run`` reads its log in a second process (slam/prefetch.py).

A machine's core count (``os.cpu_count``) is not what a process may use: its CPU
affinity (``taskset``, a batch scheduler's cpuset) and its cgroup's CPU quota (a
container started with ``--cpus=1``) may allow fewer. Processes beyond that only take
turns on the same CPUs (measured for the input process: 3-7 % more CPU, no wall time
gained).
"""

from __future__ import annotations

import math
import os
from pathlib import Path


def cgroup_quota(root: str = "/sys/fs/cgroup") -> float:
    """The CPUs this process's cgroup may use per second (inf: no limit or unknown).

    cgroup v2: ``cpu.max`` ("QUOTA PERIOD" or "max PERIOD"); v1: ``cpu/cpu.cfs_quota_us``
    over ``cpu/cpu.cfs_period_us`` (a quota of -1: no limit).

    Parameters
    ----------
    root : str
        The cgroup filesystem's mount point (tests pass their own).

    Returns
    -------
    float
        quota / period, or inf.
    """
    base = Path(root)
    try:
        quota, period = (base / "cpu.max").read_text().split()[:2]
        return math.inf if quota == "max" else int(quota) / int(period)
    except (OSError, ValueError):
        pass
    try:
        quota_us = int((base / "cpu" / "cpu.cfs_quota_us").read_text())
        period_us = int((base / "cpu" / "cpu.cfs_period_us").read_text())
        return math.inf if quota_us <= 0 or period_us <= 0 else quota_us / period_us
    except (OSError, ValueError):
        return math.inf


def usable_cpus() -> int:
    """The CPUs this process may keep busy at once: its affinity set's size (the
    machine's count where the platform has none), at most the cgroup's quota rounded
    down, at least 1.

    Returns
    -------
    int
    """
    if hasattr(os, "sched_getaffinity"):
        n = len(os.sched_getaffinity(0))
    else:
        n = os.cpu_count() or 1
    quota = cgroup_quota()
    if math.isfinite(quota):
        n = min(n, math.floor(quota))
    return max(n, 1)
