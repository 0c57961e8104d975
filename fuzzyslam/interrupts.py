"""Interruptions: Ctrl-C and SIGTERM raised as exceptions, only where that is safe.

Python runs a signal's handler between two bytecodes of the main thread, wherever it
is. An exception raised there can land inside a library's critical section: between a
lock's acquisition and the ``with`` that would release it. ``concurrent.futures.wait``
holds every future's lock while it installs its waiter; a SIGTERM raised there left one
held by the main thread, and the pool's manager thread then waited on it for ever while
the sweep shut its pool down (one killed sweep in about twenty hung so).

So the parent of a process pool holds the signals (:func:`deferred`) and raises them at
points of its own (:meth:`Held.deliver`), and the pool's workers (:func:`worker_init`)
raise SIGTERM only inside a step (:func:`in_step`), never in the pool's queue.
"""

from __future__ import annotations

import contextlib
import os
import signal
import threading
from collections.abc import Iterator
from dataclasses import dataclass, field
from types import FrameType
from typing import Any

SIGNALS = (signal.SIGINT, signal.SIGTERM)


class Terminated(KeyboardInterrupt):
    """SIGTERM, raised like Ctrl-C so that temporary outputs are removed on the way out."""


_terminating = False  # this command raised Terminated already


def raise_terminated(signum: int, frame: FrameType | None) -> None:
    """SIGTERM's handler in a command: raise :class:`Terminated`, once. A second SIGTERM
    (a supervisor's, or one sent to the whole process group and again by a parent to its
    workers) is not raised: it would cut the first one's clean-up short and leave a
    temporary output behind. SIGKILL is the way to stop a command at once."""
    global _terminating
    if _terminating:
        return
    _terminating = True
    raise Terminated()


def install() -> None:
    """Handle SIGTERM like Ctrl-C (:func:`raise_terminated`) unless the process was
    given another handler (an embedding program's, or SIG_IGN); a new command."""
    global _terminating
    _terminating = False
    if signal.getsignal(signal.SIGTERM) is signal.SIG_DFL:
        signal.signal(signal.SIGTERM, raise_terminated)


@dataclass
class Held:
    """The signals caught while held, and the handlers they would have met."""

    old: dict[int, Any] = field(default_factory=dict)
    caught: list[tuple[int, FrameType | None]] = field(default_factory=list)

    def deliver(self) -> None:
        """Give the first signal caught so far to its own handler, here and now (which
        raises KeyboardInterrupt or :class:`Terminated` for the CLI's handlers); later
        ones are dropped, as a second Ctrl-C during the first one's handling is."""
        if not self.caught:
            return
        signum, frame = self.caught[0]
        self.caught.clear()
        handler = self.old.get(signum)
        if callable(handler):
            handler(signum, frame)
        elif handler == signal.SIG_DFL:  # the default action: the process ends
            signal.signal(signum, signal.SIG_DFL)
            os.kill(os.getpid(), signum)


@contextlib.contextmanager
def deferred() -> Iterator[Held]:
    """Hold SIGINT and SIGTERM in the block; they are delivered by :meth:`Held.deliver`
    inside it, or when it ends. In another thread than the main one (where no signal
    handler runs) the block runs as it is.

    Yields
    ------
    Held
        Its ``deliver()`` raises a held signal at a point the caller chose.
    """
    held = Held()
    if threading.current_thread() is not threading.main_thread():
        yield held
        return
    for sig in SIGNALS:
        held.old[sig] = signal.getsignal(sig)
        signal.signal(sig, lambda signum, frame: held.caught.append((signum, frame)))
    try:
        yield held
    finally:
        for sig, handler in held.old.items():
            signal.signal(sig, handler)
        held.deliver()


_stepping = False  # a step runs (in_step)
_terminated = False  # this worker was sent SIGTERM


def worker_init() -> None:
    """A pool worker's signal set-up (the pool's ``initializer``): Ctrl-C ignored (the
    parent stops its workers with SIGTERM, :meth:`Engine.close`), and SIGTERM raises
    :class:`Terminated` inside a step, so that the step removes its temporary outputs
    (once: a second SIGTERM, the parent's after the process group's, lets it finish).
    Outside a step it raises nothing: an exception there would land in the pool's
    queue read, and a read cut between a message's length and its body leaves the rest
    in the pipe that the other workers share (the next reader unpickled garbage: a
    traceback on stderr, one killed sweep in ~270). The worker leaves when the pool
    shuts down, and a step it takes from its queue after SIGTERM does not start
    (:func:`in_step`)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, _worker_sigterm)


def _worker_sigterm(signum: int, frame: FrameType | None) -> None:
    global _terminated
    first, _terminated = not _terminated, True
    if _stepping and first:  # a second SIGTERM: the step's clean-up goes on
        raise Terminated()


@contextlib.contextmanager
def in_step() -> Iterator[None]:
    """Mark the block as a step's work: a pool worker's SIGTERM raises there, and a
    worker already sent SIGTERM raises at once (a step queued for it before it was
    stopped does not run)."""
    global _stepping
    if _terminated:
        raise Terminated()
    before, _stepping = _stepping, True
    try:
        yield
    finally:
        _stepping = before
