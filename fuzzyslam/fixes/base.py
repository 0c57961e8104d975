"""What every fix plug-in of ``fuzzyslam run`` shares (the ``Aid`` protocol of
``slam/events.py``): its start time, the rings seen before it, its decisions (one
record per ring it acted on, each with a ``row()`` of its CSV) and the CSV file they
are written to (docs/contracts.md sec. 2). The heading aid (``fixes/heading.py``), the
pose aid (``fixes/pose_aid.py``) and the change detector (``fixes/changes.py``) derive
from :class:`FixAid` and add ``on_ring`` and ``summary``.
"""

from __future__ import annotations

import csv
from collections.abc import Callable, Iterable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, ClassVar, Protocol

from fuzzyslam.fileio import atomic_path
from fuzzyslam.fixes.params import FixParams

if TYPE_CHECKING:
    import numpy as np


class Row(Protocol):
    """A decision: one CSV row of text fields."""

    def row(self) -> list[str]: ...


def write_rows(path: Path, fields: Sequence[str], decisions: Iterable[Row]) -> None:
    """One CSV file of decisions, written whole or not at all (``fileio.atomic_path``).

    Parameters
    ----------
    path : Path
        The file.
    fields : sequence of str
        The header (the column names).
    decisions : iterable of Row
        One row each (``row()``, as many fields as ``fields``).
    """
    with atomic_path(path) as tmp, open(tmp, "w", newline="", encoding="utf-8") as fh:
        w = csv.writer(fh, lineterminator="\n")
        w.writerow(fields)
        w.writerows(d.row() for d in decisions)


class FlmAhead:
    """Mixin of the aids that read a ring's FLM through a shared ``flm_source``
    (``heading_measure.FlmSource``; the pose aid, the change detector): the FLM, built
    ahead in slam/prefetch.py's child process (where the heading aid's ``ahead`` has
    built it already: the same object, pickled once per batch), seeds the source, so
    that no aid builds it again (0.37 ms a ring; 6 KB through the pipe: ``LocalMap``
    pickles sparse)."""

    flm_source: Any

    def flm_every_ring(self) -> bool:
        """Whether the aid reads nearly every ring's FLM (default: yes). An aid that
        reads one ring in many (the building presets' pose fixes: every metre or 30 deg)
        says no: built ahead for every ring, the FLMs would cost the child more than the
        parent saves (Freiburg 079's laser, pose fixes: 4.7 -> 10.5 s of CPU, the wall
        time 1.7-2.2x longer).

        Returns
        -------
        bool
            True: the child process builds every ring's FLM ahead (:meth:`ahead`).
        """
        return True

    def ahead(self, ring: Any, mounts: np.ndarray) -> tuple | None:
        """The ring's FLM, in a 1-tuple (``FixAid.ahead``); None for a source that
        cannot be seeded (a test's function) or an aid that reads few rings' FLMs
        (:meth:`flm_every_ring`).

        Parameters
        ----------
        ring : Ring
            The sonar ring.
        mounts : ndarray, shape (M, 3)
            The sonars' poses in base_link.

        Returns
        -------
        (BeliefMap,) or None
        """
        if not hasattr(self.flm_source, "seed") or not self.flm_every_ring():
            return None
        return (self.flm_source(ring, mounts),)

    def take_ahead(self, ring: Any, value: tuple) -> None:
        """Seed the FLM source with :meth:`ahead`'s FLM of ``ring`` (``FixAid.take_ahead``).

        Parameters
        ----------
        ring : Ring
            The ring.
        value : (BeliefMap,)
            :meth:`ahead`'s answer.
        """
        self.flm_source.seed(ring, value[0])


class FixAid:
    """The base of the fix plug-ins: ``start_time``, ``before_start``, ``decisions``
    and ``write(outdir)`` (``csv_name`` with the header ``csv_fields``).

    A subclass sets ``kind``, ``csv_name`` and ``csv_fields``, calls
    ``FixAid.__init__`` and starts its ``on_ring`` with ``if not self.started(t): return``.

    Parameters
    ----------
    params : FixParams
        The ``fixes:`` section of the config.
    start_time : float
        Log time (s) from which the aid acts (the map's freeze time by default,
        fixes/aids.py); rings before it are only counted.
    """

    kind: ClassVar[str] = ""
    csv_name: ClassVar[str] = ""
    draws_figures: ClassVar[bool] = False  # :meth:`figures` has calls to make
    csv_fields: ClassVar[tuple[str, ...]] = ()
    viewer_map: Any = None  # (FGM, references) this aid shows in estimates.mcap (aids.py)

    def __init__(self, params: FixParams, start_time: float = 0.0) -> None:
        self.params = params
        self.start_time = float(start_time)
        self.decisions: list[Any] = []
        self.before_start = 0

    def ahead(self, ring: Any, mounts: np.ndarray) -> Any:
        """What the aid computes from a ring and the mounts alone (nothing of the filter),
        so that it can be computed before the filter reaches the ring: in the child
        process that makes the events (slam/prefetch.py), handed back through
        :meth:`take_ahead` just before :meth:`on_ring`. None: nothing (the default).

        Parameters
        ----------
        ring : Ring
            The range ring.
        mounts : ndarray, shape (M, 3)
            The sensors' poses in base_link.

        Returns
        -------
        object or None
            Picklable; None when the aid computes nothing ahead.
        """
        return None

    def take_ahead(self, ring: Any, value: Any) -> None:
        """Take :meth:`ahead`'s ``value`` for ``ring``, the next ring :meth:`on_ring` gets.

        Parameters
        ----------
        ring : Ring
            The ring (the object ``on_ring`` will be given).
        value : object
            :meth:`ahead`'s answer for it.
        """

    def started(self, t: float) -> bool:
        """Whether the aid acts on a ring at log time ``t`` (counted in ``before_start``
        when not).

        Parameters
        ----------
        t : float
            The ring's log time (s).

        Returns
        -------
        bool
            ``t >= start_time``.
        """
        if t < self.start_time:
            self.before_start += 1
            return False
        return True

    def figures(self, outdir: Path) -> list[tuple[Callable[..., None], tuple]]:
        """The aid's figures as calls ``fn(*args)`` that write them into ``outdir`` (none
        here): the run makes them before :meth:`write` (they must not read its files),
        in its figure process where it has one (``fuzzyslam.forked.ChildCalls``), while
        it writes the other outputs.

        Parameters
        ----------
        outdir : Path
            The run's (staging) output directory.

        Returns
        -------
        list of (callable, tuple)
            Module-level functions and their arguments (pickled for the figure process).
        """
        return []

    def write(self, outdir: Path) -> None:
        """The decisions as ``outdir/csv_name``.

        Parameters
        ----------
        outdir : Path
            The run's (staging) output directory.
        """
        write_rows(Path(outdir) / self.csv_name, self.csv_fields, self.decisions)
