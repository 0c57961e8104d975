"""The test session's environment (no progress bars, Agg), :func:`shared_dir`, for
fixtures built once per test run rather than once per xdist worker, and :func:`run_cli`,
the in-process ``fuzzyslam`` the end-to-end tests share."""

from __future__ import annotations

import fcntl
import json
import os
import shutil
from pathlib import Path

import pytest
from rosbags.interfaces import QosDurability, QosReliability

from fuzzyslam.streams.topics import Topics

os.environ.setdefault("FUZZYSLAM_NO_PROGRESS", "1")
os.environ.setdefault("MPLBACKEND", "Agg")


def shared_dir(factory: pytest.TempPathFactory, name: str, build) -> Path:
    """A directory of this test run built once by ``build(path)``, whichever xdist worker
    asks first; the others wait for it (an exclusive lock) and reuse it. A module- or
    session-scoped fixture is otherwise built once per worker that runs one of its tests
    (twice under ``-n 2``). ``build`` must leave complete files; the tests only read them.

    Parameters
    ----------
    factory : TempPathFactory
        pytest's (its base temporary directory is the worker's, under the run's).
    name : str
        The directory's name, unique in the test run.
    build : callable
        ``build(path)`` writes into the new directory ``path``.

    Returns
    -------
    Path
        The built directory.
    """
    base = factory.getbasetemp()
    if os.environ.get("PYTEST_XDIST_WORKER"):
        base = base.parent  # the run's base directory, shared by its workers
    root = base / f"shared-{name}"
    with open(base / f"shared-{name}.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)  # released when the file is closed
        if not (root / ".built").is_file():
            shutil.rmtree(root, ignore_errors=True)  # a failed build's remains
            root.mkdir()
            build(root)
            (root / ".built").write_text("")
    return root


def run_cli(args: list[str], capsys: pytest.CaptureFixture) -> tuple[int, dict, str]:
    """``fuzzyslam ARGS`` in this process.

    Parameters
    ----------
    args : list of str
        The command line after ``fuzzyslam``.
    capsys : CaptureFixture
        pytest's, whose captured output is read (and reset).

    Returns
    -------
    code : int
        The exit code (0 unless ``SystemExit`` said otherwise).
    summary : dict
        The JSON summary on stdout; {} when the code is not 0.
    err : str
        The stderr.
    """
    from fuzzyslam.cli import main

    try:
        main(args)
        code = 0
    except SystemExit as exc:
        code = int(exc.code or 0)
    out = capsys.readouterr()
    return code, (json.loads(out.out) if code == 0 else {}), out.err


# The modules whose tests run whole ``reproduce`` or ``sweep`` plans (each step a process
# of its own, two at a time) go first: under ``pytest -n 2`` the longest chains start at
# once, and the many short tests fill the cores around them instead of leaving one long
# plan running alone at the end (the tier's wall time is at least its longest chain).
FIRST = ("test_reproduce_dask.py", "test_reproduce.py")


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """Run the tests of :data:`FIRST` first, in that order; the rest keep theirs."""
    rank = {name: k for k, name in enumerate(FIRST)}
    items.sort(key=lambda item: rank.get(item.path.name, len(FIRST)))  # a stable sort


def assert_offered_qos(connections) -> None:
    """Every channel carries the QoS its publisher offered, as rosbag2 records it (the
    MCAP ros2 profile's ``offered_qos_profiles``, parsed here by rosbags): the latched
    topics (/tf_static, the map layers, the simulated world) transient local, so that
    ``ros2 bag play`` offers them to tf2's static listener and RViz's map display, which
    ask for it; every other topic volatile. Both reliable."""
    latched = Topics().latched()
    seen = set()
    for conn in connections:
        (qos,) = conn.ext.offered_qos_profiles
        want = QosDurability.TRANSIENT_LOCAL if conn.topic in latched else QosDurability.VOLATILE
        assert qos.durability == want, conn.topic
        assert qos.reliability == QosReliability.RELIABLE, conn.topic
        seen.add(conn.topic in latched)
    assert seen, "no channel"
