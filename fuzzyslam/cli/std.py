"""The standard streams of a command: closed descriptors and readers that go away.

A command started with stdout or stderr closed (``>&-``, ``2>&-``) gets them on the null
device, so that its outputs, which it opens later, never take descriptor 1 or 2 (a
stray print would land in them) and its progress and summary go nowhere instead of
failing. A reader that goes away (``| head -c 10``, ``| true``) closes the pipe: the
next write raises BrokenPipeError (Python ignores SIGPIPE). The summary and the progress
are for the reader only, so the command goes on, its files are written, and it exits
as it would have: :class:`QuietPipe` turns the stream into the null device at the first
broken write, once, and remembers it. stderr carries only progress, notes and the error
line, all best effort: any failed write to it (a full disk under ``2>FILE`` too) silences
it the same way, and is never the command's failure nor blamed on an output file.
Text written through it that holds a path the locale could not decode (lone surrogates)
is written as :func:`fuzzyslam.summary.valid_text` has it (the path's bytes read as UTF-8).
"""

from __future__ import annotations

import contextlib
import os
import sys
from typing import Any, TextIO

from fuzzyslam.summary import valid_text


def open_closed_descriptors() -> None:
    """Put the null device on descriptors 0, 1 and 2 where they are closed, and give
    Python a stream for each one it started without (``sys.stdout`` is None then)."""
    for fd in (0, 1, 2):
        try:
            os.fstat(fd)
        except OSError:
            null = os.open(os.devnull, os.O_RDWR)  # the lowest free descriptor: fd
            if null != fd:
                os.dup2(null, fd)
                os.close(null)
    for name, fd, mode in (("stdin", 0, "r"), ("stdout", 1, "w"), ("stderr", 2, "w")):
        if getattr(sys, name) is None:
            setattr(sys, name, open(fd, mode, closefd=False, encoding="utf-8"))


class QuietPipe:
    """A text stream that becomes the null device when its reader has gone away.

    Parameters
    ----------
    stream : TextIO
        ``sys.stdout`` or ``sys.stderr``.
    best_effort : bool
        Any OSError of a write or flush silences the stream, not only a broken pipe
        (stderr: a full disk must not fail the command; stdout's summary is an output,
        whose write failure is the command's error).
    """

    def __init__(self, stream: TextIO, best_effort: bool = False) -> None:
        self._stream = stream
        self.broken = False
        self._quiet: type[OSError] = OSError if best_effort else BrokenPipeError

    def _silence(self) -> None:
        """The reader is gone: the descriptor goes to the null device (what is still
        buffered is dropped with it)."""
        self.broken = True
        with contextlib.suppress(OSError, ValueError):
            null = os.open(os.devnull, os.O_WRONLY)
            os.dup2(null, self._stream.fileno())
            os.close(null)

    def write(self, text: str) -> int:
        """Write ``text`` (a path in it that the locale could not decode as
        :func:`fuzzyslam.summary.valid_text` has it); nothing when the reader is gone.

        Parameters
        ----------
        text : str
            The text.

        Returns
        -------
        int
            The characters taken (all of them).
        """
        if not self.broken:
            try:
                self._stream.write(valid_text(text))
                return len(text)
            except self._quiet:
                self._silence()
        return len(text)

    def flush(self) -> None:
        """Flush; nothing when the reader is gone."""
        if not self.broken:
            try:
                self._stream.flush()
            except self._quiet:
                self._silence()
                with contextlib.suppress(OSError, ValueError):
                    self._stream.flush()  # what was buffered now goes to the null device

    def __getattr__(self, name: str) -> Any:
        return getattr(self._stream, name)


def guard_streams() -> None:
    """:func:`open_closed_descriptors`, then stdout and stderr wrapped in
    :class:`QuietPipe` (once; stderr best effort)."""
    open_closed_descriptors()
    for name in ("stdout", "stderr"):
        stream = getattr(sys, name)
        if not isinstance(stream, QuietPipe):
            setattr(sys, name, QuietPipe(stream, best_effort=name == "stderr"))
