"""Forked child processes: what the run's input process (:mod:`fuzzyslam.slam.prefetch`)
and its figure process (:class:`ChildCalls`) share, and the figure process itself.

A child is forked from the running process (Linux: ``fork``; no re-import, no pickling of
what it already holds) and ends with ``os._exit`` (nothing the parent buffered, in Python
or in a file it has open, is written twice). It ignores Ctrl-C (the parent's to handle),
dies with its parent (``prctl(PR_SET_PDEATHSIG)``) and is killed and reaped on every path
out of its parent's ``with`` block (:func:`reap`). Its exception reaches the parent
pickled (:func:`pickled_error`) and is raised there as the same type and message, its
traceback as the cause (:func:`raise_child_error`, :class:`ChildTraceback`: ``--debug``
shows it).

:class:`ChildCalls` is a child forked before the filter runs that imports the plotting
modules (matplotlib: 0.4-0.5 s) while the filter runs on the other core, then makes the
calls it is sent (module-level functions, pickled with their arguments) one at a time,
while the parent goes on (``submit``; ``Pending.result`` waits): a pose run's
``changes.png`` is drawn while the run's other outputs are written (``slam/stage.py``).
``fuzzyslam run --fix pose`` forks it first thing, before its own imports
(``cli/run.py``): its imports then take the second core while that one is idle (the
parent importing, loading the map, opening the log), not the time the filter and the
input process share it; the modules that draw, known once the aids are made, follow
(``ChildCalls.preload``).
"""

from __future__ import annotations

import contextlib
import gc
import importlib
import os
import pickle
import signal
import sys
import traceback
from collections.abc import Callable, Iterator, Sequence
from typing import TYPE_CHECKING, Any

from fuzzyslam.cpus import usable_cpus

if TYPE_CHECKING:  # multiprocessing loaded only for a child (16 ms of start-up)
    from multiprocessing.connection import Connection

_PR_SET_PDEATHSIG = 1  # linux/prctl.h
F_SETPIPE_SZ = 1031  # linux/fcntl.h (fcntl.F_SETPIPE_SZ from Python 3.10, Linux only)
# what a figure process imports while the filter runs (fuzzyslam/figsave.py's matplotlib)
FIGURE_MODULES = ("fuzzyslam.figsave",)
# the figure process's niceness: its imports use what the filter and the input process
# leave of the cores, and its calls come when the filter has finished
NICE = 10
ENV = "FUZZYSLAM_PREFETCH"  # "0" (or off, no, false): never an input or figure process
# Young-generation threshold of the cyclic garbage collector in a process that forks its
# workers (Python's default 700): a run or a step allocates millions of objects (decoded
# messages, the filter's small arrays, matplotlib's artists), so the default collects
# hundreds of times, each older collection rescanning its survivors (:func:`fewer_collections`)
GC_THRESHOLD = (10000, 10, 10)


def wanted(requested: bool = True) -> bool:
    """Whether a run forks its input process (slam/prefetch.py) and its figure process
    (:class:`ChildCalls`), onto a second CPU (slam/prefetch.py's docstring: when).

    Parameters
    ----------
    requested : bool
        The caller asks for it (``fuzzyslam run``'s ``--prefetch``, its default).

    Returns
    -------
    bool
        ``requested``, the environment does not turn it off, and the process may fork
        a child onto a second CPU.
    """
    if not requested or os.environ.get(ENV, "1").strip().lower() in ("0", "off", "no", "false"):
        return False
    if not sys.platform.startswith("linux") or usable_cpus() < 2:
        return False
    mp = sys.modules.get("multiprocessing.process")  # not loaded: no pool's worker
    if mp is not None and mp.current_process().daemon:
        return False
    dist = sys.modules.get("distributed")  # a Dask worker's tasks share its cores
    if dist is not None:
        try:
            dist.get_worker()
            return False
        except ValueError:
            pass
    return True


@contextlib.contextmanager
def fewer_collections() -> Iterator[None]:
    """Meanwhile, the cyclic garbage collector's young generation is collected every
    ``GC_THRESHOLD[0]`` allocations (children forked meanwhile keep it), then the
    thresholds are as before. The collector's timing changes nothing a stage computes.
    A pose run of the paper log: no full collection instead of one in each process (50-90
    ms each), about 70 young collections instead of 200."""
    before = gc.get_threshold()
    gc.set_threshold(*GC_THRESHOLD)
    try:
        yield
    finally:
        gc.set_threshold(*before)


def flush_std() -> None:
    """Flush stdout and stderr before a fork: nothing buffered is written twice."""
    for stream in (sys.stdout, sys.stderr):
        with contextlib.suppress(Exception):
            stream.flush()


def orphan_guard(parent: int) -> bool:
    """The child's set-up: Ctrl-C ignored, SIGTERM's default action (the CLI's handler
    would raise in the child), SIGKILL when the parent dies (Linux).

    Parameters
    ----------
    parent : int
        The parent's pid, read before the fork.

    Returns
    -------
    bool
        False when the parent died before the guard was set (the child should end).
    """
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    with contextlib.suppress(Exception):
        import ctypes

        ctypes.CDLL(None).prctl(_PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0)
    return os.getppid() == parent


def pickled_error(exc: BaseException) -> bytes:
    """``("error", ...)`` for the parent: ``exc`` pickled with its formatted traceback, or,
    for an exception that does not pickle and unpickle, its module, type name and message.

    Parameters
    ----------
    exc : BaseException
        The child's exception.

    Returns
    -------
    bytes
        The pickled message (:func:`raise_child_error` reads its payload).
    """
    tb = "".join(traceback.format_exception(exc))
    try:
        data = pickle.dumps(exc, pickle.HIGHEST_PROTOCOL)
        pickle.loads(data)  # an __init__ that the pickled args do not fit fails here
        return pickle.dumps(("error", (data, None, tb)), pickle.HIGHEST_PROTOCOL)
    except Exception:
        named = (type(exc).__module__, type(exc).__qualname__, str(exc))
        return pickle.dumps(("error", (None, named, tb)), pickle.HIGHEST_PROTOCOL)


class ChildTraceback(Exception):
    """The traceback of an exception raised in a child process (the cause of the
    exception raised again in the parent: ``--debug`` shows it)."""

    def __init__(self, text: str) -> None:
        super().__init__(text)
        self.text = text

    def __str__(self) -> str:
        return f'\n"""\n{self.text}"""'


def raise_child_error(payload: tuple) -> None:
    """Raise the child's exception of a :func:`pickled_error` message's payload.

    Parameters
    ----------
    payload : tuple
        (pickled exception or None, (module, name, message) or None, traceback text).

    Raises
    ------
    BaseException
        The child's exception (or a stand-in of the same module, name and message),
        from :class:`ChildTraceback`.
    """
    data, named, tb = payload
    if data is not None:
        exc = pickle.loads(data)
    else:
        module, name, message = named
        exc = type(name.rsplit(".", 1)[-1], (Exception,), {"__module__": module})(message)
    raise exc from ChildTraceback(tb)


def reap(pid: int) -> None:
    """Kill the child (it has done its work, or is no longer wanted) and wait for it; a
    second Ctrl-C while waiting kills it again and is raised once it is reaped.

    Parameters
    ----------
    pid : int
        The child.
    """
    interrupted: BaseException | None = None
    while True:
        with contextlib.suppress(ProcessLookupError):
            os.kill(pid, signal.SIGKILL)
        try:
            os.waitpid(pid, 0)
            break
        except ChildProcessError:
            break
        except KeyboardInterrupt as exc:
            interrupted = exc
    if interrupted is not None:
        raise interrupted


TO_CHILD, TO_PARENT = "to_child", "to_parent"  # a pipe's direction (fork_child)


def fork_child(
    target: Callable[[list[Connection]], None],
    directions: Sequence[str],
    pipe_bytes: int = 0,
) -> tuple[int, list[Connection]] | None:
    """Fork a child that runs ``target`` on its ends of new pipes, then ends (module
    docstring: ``os._exit``, Ctrl-C ignored, SIGKILL with its parent).

    Parameters
    ----------
    target : callable
        ``target(conns)`` in the child, ``conns`` its end of each pipe in the order of
        ``directions``; not run if the parent died before the orphan guard was set. An
        exception it lets through ends the child with code 1.
    directions : sequence of str
        Per pipe, ``TO_CHILD`` (the parent writes) or ``TO_PARENT`` (the child writes).
    pipe_bytes : int
        The pipes' buffer size (Linux ``F_SETPIPE_SZ``; 0: the system's, and a lower
        system limit keeps it).

    Returns
    -------
    (int, list of Connection) or None
        The child's pid and this process's end of each pipe; None when the system
        refuses a pipe or the fork (EMFILE, EAGAIN under a process limit, ENOMEM): the
        caller does the work itself.
    """
    from multiprocessing.connection import Connection

    flush_std()
    pipes: list[tuple[int, int]] = []
    try:
        for _ in directions:
            pipes.append(os.pipe())
        parent = os.getpid()
        pid = os.fork()
    except OSError:
        for fd in (fd for pipe in pipes for fd in pipe):
            os.close(fd)
        return None
    child = pid == 0
    ends = []
    for (r, w), way in zip(pipes, directions, strict=True):
        reads = (way == TO_CHILD) == child  # this process's end is the read end
        keep, drop = (r, w) if reads else (w, r)
        os.close(drop)
        if pipe_bytes and not reads:
            with contextlib.suppress(OSError, AttributeError):  # fcntl: Linux only
                import fcntl

                fcntl.fcntl(keep, F_SETPIPE_SZ, pipe_bytes)
        ends.append(Connection(keep, readable=reads, writable=not reads))
    if not child:
        return pid, ends
    code = 1  # the child: never returns
    try:
        if orphan_guard(parent):
            target(ends)
        code = 0
    finally:
        os._exit(code)


class ChildCalls:
    """Calls made in a child process, which imports ``warm`` first (module docstring); a
    context manager: the child is forked on entering and reaped on leaving.

    ``submit(fn, *args)`` sends the module-level function ``fn`` and its arguments, and
    its ``result()`` waits for the result or raises the exception as the child raised it.
    If there is no child (the system refused the fork or the
    pipes) or it is gone (killed), or ``fn`` or its arguments do not pickle, the call is
    made in this process instead: the result is the same, only later.

    Parameters
    ----------
    warm : sequence of str
        Modules the child imports before it waits for calls (an import that fails is
        left for the call to meet).
    """

    def __init__(self, warm: Sequence[str] = FIGURE_MODULES) -> None:
        self.warm = tuple(warm)
        self.pid: int | None = None
        self._send: Connection | None = None
        self._recv: Connection | None = None
        self._queue: list[Pending] = []  # sent, reply not yet read
        self._started = False  # forked (or refused) once: start() does nothing more

    def start(self) -> None:
        """Fork the child (``with`` does it, unless it was started before); none when the
        system refuses it."""
        if self._started:
            return
        self._started = True
        warm = self.warm
        forked = fork_child(lambda ends: _serve(*ends, warm), (TO_CHILD, TO_PARENT))
        if forked is not None:
            self.pid, (self._send, self._recv) = forked

    def submit(self, fn: Callable[..., Any], *args: Any) -> Pending:
        """Send ``fn(*args)`` to the child and return at once; the child makes the calls
        in the order sent, while this process goes on.

        Parameters
        ----------
        fn : callable
            A module-level function (pickled by name).
        *args
            Its arguments (pickled).

        Returns
        -------
        Pending
            Its ``result()`` waits for the call's result (or raises its exception).
        """
        job = Pending(self, fn, args)
        if self._send is None:
            return job
        try:
            request = pickle.dumps((fn, args), pickle.HIGHEST_PROTOCOL)
        except Exception:  # a closure, an open file: not for the child
            return job
        try:
            self._send.send_bytes(request)
        except OSError:  # the child is gone: made here
            self.close()
            return job
        job.sent = True
        self._queue.append(job)
        return job

    def preload(self, *names: str) -> None:
        """Have the child import ``names`` too before the calls to come (a child started
        before the caller knew what it would draw), while this process goes on; nothing
        without a child.

        Parameters
        ----------
        *names : str
            Modules (one that fails to import is left for a call to meet).
        """
        self.submit(import_modules, names)

    def _collect(self, job: Pending) -> None:
        """Read the child's replies, in the order of the calls, up to ``job``'s; a child
        that is gone leaves the calls still waiting to be made here."""
        while self._queue and not job.done:
            head = self._queue.pop(0)
            head.done = True
            if self._recv is None:  # closed: made here
                head.sent = False
                continue
            try:
                head.reply = pickle.loads(self._recv.recv_bytes())
            except (EOFError, OSError):  # the child is gone: made here
                head.sent = False
                self.close()

    def close(self) -> None:
        """Close the pipes, kill the child and reap it (idempotent)."""
        for conn in (self._send, self._recv):
            if conn is not None:
                conn.close()
        self._send = self._recv = None
        if self.pid is not None:
            pid, self.pid = self.pid, None
            reap(pid)

    def __enter__(self) -> ChildCalls:
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


class Pending:
    """A call sent to a :class:`ChildCalls` child (or to be made here: not sent)."""

    def __init__(self, calls: ChildCalls, fn: Callable[..., Any], args: tuple) -> None:
        self.calls, self.fn, self.args = calls, fn, args
        self.sent = False  # sent to the child
        self.done = False  # its reply read
        self.reply: tuple | None = None

    def result(self) -> Any:
        """Wait for the call's result: the child's, its exception raised here, or, when
        the call was not sent or the child is gone, ``fn(*args)`` made here (once: a
        second ``result()`` gives the same answer).

        Returns
        -------
        object
            ``fn``'s result.
        """
        if self.sent and not self.done:
            self.calls._collect(self)
        if self.reply is None:  # not sent, or the child gone: made here, once
            self.reply = ("ok", self.fn(*self.args))
        kind, payload = self.reply
        if kind == "error":
            raise_child_error(payload)
        return payload


def import_modules(names: Sequence[str]) -> None:
    """Import ``names`` (a figure process's modules: :class:`ChildCalls` ``warm`` and
    ``preload``); one that fails to import is left for a call to meet.

    Parameters
    ----------
    names : sequence of str
        Module names.
    """
    for name in names:
        with contextlib.suppress(Exception):
            importlib.import_module(name)


def _serve(calls: Connection, replies: Connection, warm: Sequence[str]) -> None:
    """The child of :class:`ChildCalls`: import ``warm``, then make each call received
    and send back ``("ok", result)`` or :func:`pickled_error`, until the parent closes
    its end."""
    with contextlib.suppress(OSError):  # the imports take the cores' idle time only
        os.nice(NICE)
    import_modules(warm)
    while True:
        try:
            data = calls.recv_bytes()
        except (EOFError, OSError):
            return
        try:
            fn, args = pickle.loads(data)
            reply = pickle.dumps(("ok", fn(*args)), pickle.HIGHEST_PROTOCOL)
        except BaseException as exc:
            reply = pickled_error(exc)
        try:
            replies.send_bytes(reply)
        except OSError:  # the parent stopped reading
            return
