"""The run's input events made in a forked child process, on a second core (issue 16).

``LogInputs.events`` (chunk decompression, CDR decoding, lamp detection, the sonar
rings: pure per message, in order) costs about a third of a lamps-only run. A forked
child makes them and sends them to the filter in the parent as pickled batches
(``FIRST_BATCH`` events, then twice as many each time up to ``BATCH``) through a pipe;
the two run at once on two cores (a thread could not: both sides are short Python steps
under one GIL; ``benchmarks/bench_prefetch.py``).

With aids, the child also computes what each aid can compute from a ring alone
(``FixAid.ahead``: the heading aid's single-ring FLM and wall direction, a fifth of a
heading run) and sends it with the ring (``RingEvent.ahead``); the aid takes it instead of
computing it (``take_ahead``). An exception there is left for the aid to raise itself,
where the one-process run would. The child does this only while the parent has a
backlog (:func:`ahead_wanted`: it counts the events the parent has handled in a shared
mapping, :class:`Taken`); when the parent is about to wait, the ring goes without and
the aid computes it in the parent. With fixes the child's work is nearly the filter's,
so the two share it by need rather than by a fixed split; the results are the same
either way.

The child's own reading state comes back with its last batch
(``LogInputs.read_state``: glitch counts, first problem, gaps, ring statistics, the
reader's damage), so that every output, summary.json included, is the one-process
run's, byte for byte. An exception of the child is raised in the parent as the same
type and message (its traceback as the cause, for ``--debug``), after the events made
before it, as the one-process run would.

Memory: the pipe's buffer (``PIPE_BYTES``, 1 MiB) and one batch on each side; the child
blocks while the parent lags. The child is reaped on every path out of
:func:`input_events` (the end of the events, the parent's exception, Ctrl-C, SIGTERM
raised as KeyboardInterrupt by the CLI): SIGKILL, then ``waitpid``. If the parent dies
without that (SIGKILL), the child gets SIGKILL too (``prctl(PR_SET_PDEATHSIG)`` on
Linux), and a write to the pipe without a reader ends it elsewhere. (These fork helpers
are :mod:`fuzzyslam.forked`'s, shared with the run's figure process.)

A system that refuses the child (no process, pipe or memory to spare: ``fork`` or
``pipe`` failing with EAGAIN, EMFILE, ENOMEM) gets the one-process run, the same
outputs.

When: :func:`wanted` (``fuzzyslam.forked.wanted``, which decides the figure process
too; ``fuzzyslam run``'s default, ``--no-prefetch`` or ``FUZZYSLAM_PREFETCH=0`` to turn
it off): a platform with ``fork`` (Linux), at least two CPUs usable by this process (its
affinity and its cgroup's CPU quota, ``fuzzyslam.cpus.usable_cpus``: a container limited
to one CPU gains nothing), not a daemonic process nor a Dask worker. ``reproduce`` and
``sweep`` steps never ask for it: their pool already keeps every core busy.
"""

from __future__ import annotations

import contextlib
import pickle
from collections.abc import Iterator, Sequence
from typing import TYPE_CHECKING, Any

from fuzzyslam.forked import ENV as ENV  # FUZZYSLAM_PREFETCH=0: no input process
from fuzzyslam.forked import TO_PARENT, fork_child, pickled_error, raise_child_error, reap
from fuzzyslam.forked import wanted as wanted  # whether to fork (it lives with the forks)
from fuzzyslam.slam.events import Event, RingEvent
from fuzzyslam.streams.sonar import ring_mounts

if TYPE_CHECKING:  # multiprocessing loaded only for a child (16 ms of start-up)
    from multiprocessing.connection import Connection

BATCH = 256  # events per pickled batch (bench_prefetch.py: 64 and 256 alike, 1 slower)
# the first batch is small and the next ones double up to BATCH: the parent waits for the
# first batch with nothing to do (256 events of the paper log: 40-60 ms, 2 % of a run)
FIRST_BATCH = 16
# the parent's backlog (events sent, not yet handled) from which the child does the aids'
# ring work (ahead_wanted): more than the batch the parent is handling (two batches and
# one alike on the paper log; four: the parent then does nearly all of it, 1.25x slower).
# Side by side with the child doing all of it (two free cores, whole command, medians of
# 5): paper log heading fixes 2.06 -> 2.04 s, pose 2.64 -> 2.60 s; Freiburg 079 sonar
# heading fixes (4791 rings) 6.61 -> 6.44 s (3 runs each); outputs byte-identical
AHEAD_BACKLOG = 2 * BATCH
# the pipe's buffer (Linux's default 64 KiB): 1 MiB lets the child run further ahead of a
# parent whose steps come in bursts (a multi-ring fix, a relocalisation); paper log, in one
# warm process, two cores: heading fixes 3.12 s wall with 64 KiB, 2.29 s with 1 MiB
PIPE_BYTES = 1 << 20


@contextlib.contextmanager
def input_events(
    inputs,
    rings: bool = False,
    ring_start: float | None = None,
    child: bool = False,
    aids: Sequence = (),
) -> Iterator[Iterator[Event]]:
    """``inputs.events(rings, ring_start)``, made in this process or (``child``) in a
    forked child process; on leaving, the child is killed if still running and reaped.

    Parameters
    ----------
    inputs : slam.inputs.LogInputs
        The opened log; with ``child``, its reading state is the child's once the
        events are all read (``LogInputs.restore_read_state``).
    rings : bool
        Merge in the range sensor's rings (``LogInputs.events``).
    ring_start : float or None
        Rings from this log time (s) on.
    child : bool
        Make the events in a child process (:func:`wanted` decides).
    aids : sequence of Aid
        The run's aids, in the runner's order: with ``child``, each ring carries what
        they compute ahead (``RingEvent.ahead``).

    Yields
    ------
    iterator of Odom, Frame or RingEvent
        The events, in time order.
    """
    if not child:
        yield inputs.events(rings, ring_start)
        return
    import mmap

    try:
        taken = Taken(mmap.mmap(-1, Taken.SIZE))  # shared with the child (MAP_SHARED)
    except OSError:  # no memory to spare: made here
        taken = None
    forked = None
    if taken is not None:
        forked = fork_child(
            lambda ends: _child(ends[0], inputs, rings, ring_start, aids, taken),
            (TO_PARENT,),
            PIPE_BYTES,
        )
    if forked is None:  # the system refused the child (module docstring): made here
        yield inputs.events(rings, ring_start)
        return
    pid, (conn,) = forked
    try:
        yield _received(conn, inputs, pid, taken)
    finally:
        conn.close()
        reap(pid)


class Taken:
    """The count of events the parent has taken from the pipe and handled, in a shared
    anonymous mapping (written by the parent after each batch, read by the child):
    what the child has sent minus this is the parent's backlog (:func:`ahead_wanted`).
    Eight bytes written and read without a lock: a stale (or torn) value only moves work
    between the two processes, never changes a result."""

    SIZE = 8

    def __init__(self, buf) -> None:
        self.buf = buf

    def add(self, n: int) -> None:
        """Count ``n`` more events handled by the parent.

        Parameters
        ----------
        n : int
            Events handled since the last call.
        """
        self.buf[:8] = (int.from_bytes(self.buf[:8], "little") + n).to_bytes(8, "little")

    @property
    def count(self) -> int:
        """Events handled by the parent so far."""
        return int.from_bytes(self.buf[:8], "little")


def ahead_wanted(sent: int, taken: int) -> bool:
    """Whether the child computes a ring's ``ahead`` (the aids' work on the ring alone):
    only while the parent has at least ``AHEAD_BACKLOG`` events sent and not yet handled.
    With less, the parent is about to wait for the child (with fixes the two are nearly
    balanced: on the paper log a pose run's child spends 1.9 s of CPU on the events and
    the rings' FLMs, Hough and tangent fits, the parent 2.1 s on the filter): the ring goes
    without, and the aid computes it in the parent, which would otherwise be idle. The
    work is the same function either way, so the outputs are too; only its place depends
    on timing.

    Parameters
    ----------
    sent : int
        Events the child has sent.
    taken : int
        Events the parent has handled (:class:`Taken`).

    Returns
    -------
    bool
    """
    return sent - taken >= AHEAD_BACKLOG


def _child(conn: Connection, inputs, rings: bool, ring_start, aids, taken: Taken) -> None:
    """The child's work: the events in batches of ``FIRST_BATCH``, twice that, ... up to
    ``BATCH``, then the last batch with the reading state; or an exception, pickled
    (``fuzzyslam.forked.pickled_error``). Its own exceptions, and a parent gone (a
    broken pipe), end it quietly."""
    buf: list[Event] = []
    limit = FIRST_BATCH
    sent = 0
    try:
        try:
            ahead = [(getattr(a, "ahead", None), float(a.start_time)) for a in aids]
            mounts = inputs.mounts
            for ev in inputs.events(rings, ring_start):
                if ahead and type(ev) is RingEvent and ahead_wanted(sent, taken.count):
                    ev.ahead = _ahead(ahead, ev, mounts)
                buf.append(ev)
                if len(buf) >= limit:
                    batch, buf = buf, []
                    conn.send_bytes(pickle.dumps(("events", batch), pickle.HIGHEST_PROTOCOL))
                    sent += len(batch)
                    limit = min(2 * limit, BATCH)
            last = ("end", (buf, inputs.read_state()))
            conn.send_bytes(pickle.dumps(last, pickle.HIGHEST_PROTOCOL))
        except BrokenPipeError:  # the parent stopped reading
            return
        except BaseException as exc:
            with contextlib.suppress(Exception):  # the events made before it, first
                conn.send_bytes(pickle.dumps(("events", buf), pickle.HIGHEST_PROTOCOL))
            conn.send_bytes(pickled_error(exc))
        conn.close()
    except OSError:  # the parent stopped reading
        return


def _ahead(ahead: list, ev: RingEvent, mounts) -> tuple | None:
    """Per aid (``ahead``: its ``ahead`` method or None, its start time), what it computes
    from the ring ahead, or None; None for all: nothing. An aid's exception gives None:
    the aid then computes it itself and raises it where the one-process run would."""
    out: list[Any] = []
    for fn, start in ahead:
        value = None
        if fn is not None and ev.t >= start:
            try:
                value = fn(ev.ring, ring_mounts(ev.ring, mounts))
            except Exception:
                value = None
        out.append(value)
    return tuple(out) if any(v is not None for v in out) else None


def _received(conn: Connection, inputs, pid: int, taken: Taken) -> Iterator[Event]:
    """The child's events, in order (each batch counted in ``taken`` once handled); then
    its reading state into ``inputs``."""
    while True:
        try:
            data = conn.recv_bytes()
        except EOFError:
            raise RuntimeError(
                f"the process reading {inputs.reader.path} (pid {pid}) ended without its "
                "events (killed?)"
            ) from None
        kind, payload = pickle.loads(data)
        if kind == "events":
            yield from payload
            taken.add(len(payload))
        elif kind == "end":
            events, state = payload
            inputs.restore_read_state(state)
            yield from events
            return
        else:
            raise_child_error(payload)
