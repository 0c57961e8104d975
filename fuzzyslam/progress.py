"""Progress bars on stderr (stdout is kept for the machine-readable summary).

Progress and notes are best effort: a write to stderr that fails (a full disk under
``2>FILE``, a reader gone) is dropped, never the command's error (:func:`say`)."""

from __future__ import annotations

import contextlib
import os
import sys
from collections.abc import Iterable, Iterator
from typing import TypeVar

import click

T = TypeVar("T")


def enabled() -> bool:
    """Progress is shown unless FUZZYSLAM_NO_PROGRESS is set."""
    return not os.environ.get("FUZZYSLAM_NO_PROGRESS")


def display_mode(stream, show: bool = True) -> str:
    """How progress is shown on ``stream``: "off" (not ``show``, or FUZZYSLAM_NO_PROGRESS
    set), "bar" (a terminal) or "lines" (a file or a pipe: CI, nohup).

    Parameters
    ----------
    stream : file-like
        Where progress goes.
    show : bool
        The caller shows progress at all.

    Returns
    -------
    str
    """
    if not (show and enabled()):
        return "off"
    return "bar" if getattr(stream, "isatty", lambda: False)() else "lines"


def say(text: str, stream=None) -> None:
    """``text`` and a newline on ``stream`` (default: sys.stderr), flushed; a write that
    fails (OSError: disk full, broken pipe) is dropped.

    Parameters
    ----------
    text : str
        One line.
    stream : file-like, optional
        Where to write.
    """
    with contextlib.suppress(OSError):
        stream = stream if stream is not None else sys.stderr
        click.echo(text, file=stream)
        stream.flush()


class Progress:
    """Progress over a known amount of work (e.g. seconds of log) on stderr.

    On a terminal: a bar. Anywhere else (stderr a file or a pipe: CI, nohup): the label when
    the work starts, a line ``LABEL: P % after S s`` at most every ``interval_s`` seconds,
    and ``LABEL: done in S s`` when the work ends without an error (an error is the
    command's own one line). Off when FUZZYSLAM_NO_PROGRESS is set or ``show`` is false.

    Parameters
    ----------
    total : float
        The amount of work (the unit of :meth:`update_to`).
    label : str
        The bar's label and every line's prefix.
    show : bool
        False: no display (a caller drawing beside another display).
    stream : file-like, optional
        Where to write (default: sys.stderr).
    clock : callable, optional
        Monotonic seconds (default: time.monotonic); tests pass their own.
    interval_s : float
        Longest silence between two lines (lines mode), seconds.
    """

    def __init__(
        self,
        total: float,
        label: str,
        show: bool = True,
        stream=None,
        clock=None,
        interval_s: float = 30.0,
    ) -> None:
        import time

        self.total = max(float(total), 1e-9)
        self.label = label
        self.stream = stream if stream is not None else sys.stderr
        self.clock = clock or time.monotonic
        self.interval_s = interval_s
        self._bar = None
        self._done = 0
        self.mode = display_mode(self.stream, show)
        if self.mode == "bar":
            self._bar = click.progressbar(
                length=1000, label=label, file=self.stream, show_eta=True, show_percent=True
            )
            self._bar.__enter__()
        elif self.mode == "lines":
            self.t0 = self.last = self.clock()
            self._line(label)

    def _line(self, text: str) -> None:
        say(text, self.stream)
        self.last = self.clock()

    def update_to(self, amount: float) -> None:
        """Advance to ``amount`` out of ``total``."""
        if self.mode == "off":
            return
        target = int(1000 * min(max(amount / self.total, 0.0), 1.0))
        if target <= self._done:
            return
        if self._bar is not None:
            self._bar.update(target - self._done)
        elif self.clock() - self.last >= self.interval_s:  # lines mode: at most one a period
            self._line(f"{self.label}: {target / 10:.0f} % after {self.clock() - self.t0:.0f} s")
        self._done = target

    def close(self, ok: bool = True) -> None:
        """End the display; ``ok``: the work ended without an error (lines mode says so)."""
        if self._bar is not None:
            self.update_to(self.total)
            self._bar.__exit__(None, None, None)
            self._bar = None
        elif self.mode == "lines" and ok:
            self._line(f"{self.label}: done in {self.clock() - self.t0:.1f} s")
        self.mode = "off"

    def __enter__(self) -> Progress:
        return self

    def __exit__(self, exc_type: object, *exc: object) -> None:
        self.close(ok=exc_type is None)


def iterate(items: Iterable[T], length: int, label: str) -> Iterator[T]:
    """Iterate with a stderr progress bar of ``length`` steps."""
    with Progress(length, label) as bar:
        for i, item in enumerate(items):
            yield item
            bar.update_to(i + 1)


def note(text: str) -> None:
    """One line on stderr for the user (always shown: a warning is not progress)."""
    say(f"fuzzyslam: note: {' '.join(text.split())}")


class PlanProgress:
    """Progress of a plan of steps on stderr, for a person at a terminal or a log file.

    On a terminal: the bar of :class:`Progress` (over the steps' expected cost). Anywhere
    else (stderr a file or a pipe: CI, nohup): one line per finished step (step, seed,
    seconds, steps done / total, where it ran) and a line at least every ``heartbeat_s``
    seconds naming the running steps. Off, like every progress display, when
    FUZZYSLAM_NO_PROGRESS is set.

    Parameters
    ----------
    total_cost : float
        Sum of the steps' expected costs (the bar's length).
    n_steps : int
        Number of steps.
    label : str
        Prefix of every line and the bar's label.
    heartbeat_s : float
        Longest silence between two lines (lines mode).
    stream : file-like, optional
        Where to write (default: sys.stderr).
    clock : callable, optional
        Monotonic seconds (default: time.monotonic); tests pass their own.
    """

    def __init__(
        self,
        total_cost: float,
        n_steps: int,
        label: str,
        heartbeat_s: float = 30.0,
        stream=None,
        clock=None,
    ) -> None:
        import time

        self.stream = stream if stream is not None else sys.stderr
        self.clock = clock or time.monotonic
        self.n_steps = n_steps
        self.label = label
        self.heartbeat_s = heartbeat_s
        self.t0 = self.last = self.clock()
        self.mode = display_mode(self.stream)
        self._total = total_cost
        self._bar: Progress | None = None

    def line(self, text: str) -> None:
        """One line now (before the bar starts, in bar mode)."""
        if self.mode == "off":
            return
        say(f"{self.label}: {text}", self.stream)
        self.last = self.clock()
        self._start_bar()

    def timeout(self) -> float | None:
        """Seconds until the next heartbeat is due (None: no heartbeat in this mode)."""
        if self.mode != "lines":
            return None
        return max(self.heartbeat_s - (self.clock() - self.last), 0.01)

    def _start_bar(self) -> None:
        if self.mode == "bar" and self._bar is None:
            self._bar = Progress(self._total, self.label, stream=self.stream)

    def step_done(self, key: str, seconds: float, n_done: int, where: str, cost_done: float):
        """A step finished: a line (lines mode) or the bar moved (bar mode)."""
        if self.mode == "bar":
            self._start_bar()
            assert self._bar is not None
            self._bar.update_to(cost_done)
            return
        parts = [x[4:] for x in key.split("/") if x.startswith("seed") and x[4:].isdigit()]
        seed = parts[0] if parts else "-"
        place = "" if where in ("", "local") else f" on {where}"
        self.line(
            f"[{n_done}/{self.n_steps}] {key} done in {seconds:.1f} s "
            f"(seed {seed}){place}; {self._clock_text()}"
        )

    def heartbeat(self, n_done: int, running: list[tuple[str, float]]) -> None:
        """A line if nothing was said for ``heartbeat_s`` seconds (lines mode)."""
        if self.mode != "lines" or self.clock() - self.last < self.heartbeat_s:
            return
        names = ", ".join(f"{k} {s:.0f} s" for k, s in sorted(running)) or "none"
        self.line(f"[{n_done}/{self.n_steps}] running: {names}; {self._clock_text()}")

    def _clock_text(self) -> str:
        return f"{self.clock() - self.t0:.0f} s elapsed"

    def __enter__(self) -> PlanProgress:
        return self

    def __exit__(self, *exc: object) -> None:
        if self._bar is not None:
            self._bar.close()
            self._bar = None
