"""Progress bars on stderr (stdout is kept for the machine-readable summary)."""

from __future__ import annotations

import os
import sys
from collections.abc import Iterable, Iterator
from typing import TypeVar

import click

T = TypeVar("T")


def enabled() -> bool:
    """Progress is shown unless FUZZYSLAM_NO_PROGRESS is set."""
    return not os.environ.get("FUZZYSLAM_NO_PROGRESS")


class Progress:
    """A stderr progress bar over a known amount of work (e.g. seconds of log)."""

    def __init__(self, total: float, label: str) -> None:
        self.total = max(float(total), 1e-9)
        self.label = label
        self._bar = None
        self._done = 0
        if enabled():
            self._bar = click.progressbar(
                length=1000, label=label, file=sys.stderr, show_eta=True, show_percent=True
            )
            self._bar.__enter__()

    def update_to(self, amount: float) -> None:
        """Advance the bar to ``amount`` out of ``total``."""
        if self._bar is None:
            return
        target = int(1000 * min(max(amount / self.total, 0.0), 1.0))
        if target > self._done:
            self._bar.update(target - self._done)
            self._done = target

    def close(self) -> None:
        if self._bar is not None:
            self.update_to(self.total)
            self._bar.__exit__(None, None, None)
            self._bar = None

    def __enter__(self) -> Progress:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def iterate(items: Iterable[T], length: int, label: str) -> Iterator[T]:
    """Iterate with a stderr progress bar of ``length`` steps."""
    with Progress(length, label) as bar:
        for i, item in enumerate(items):
            yield item
            bar.update_to(i + 1)


def note(text: str) -> None:
    """One line on stderr for the user (always shown: a warning is not progress)."""
    click.echo(f"fuzzyslam: note: {' '.join(text.split())}", err=True)
