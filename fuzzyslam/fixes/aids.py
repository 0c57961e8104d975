"""The thin edge of the fixes stage: load a frozen map directory and make ``run``'s aids.

``make_aids(fgm_dir, mode, cfg, start_time)`` is all ``fuzzyslam run --map`` needs:
it loads ``fgm.npz`` and ``references.yaml`` (docs/contracts.md sec. 3) with the maps stage's
``mapio``, refuses a map that
is missing, malformed or was never frozen (one-line :class:`InputError`), and returns
the plug-ins for the chosen mode, sharing one FLM per ring:

- ``none``: no aids;
- ``heading``: :class:`HeadingFixAid` (the paper; with ``fixes.flm_rings`` > 1 on FLMs
  of the last few rings, see fixes.heading);
- ``pose``: :class:`PoseFixAid` (with ``fixes.pose_with_heading`` also the
  :class:`HeadingFixAid`, which measures the heading the match leaves free) and, with
  ``fixes.detect_changes``, :class:`ChangeDetector`.

Each aid (a :class:`fuzzyslam.fixes.base.FixAid`) has ``start_time``, ``on_ring(t, ring,
mounts, ekf)``, ``summary()`` and
``write(outdir)``. ``start_time`` defaults to the map's freeze time.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from fuzzyslam.errors import InputError, UsageError
from fuzzyslam.references import Reference, read_references
from fuzzyslam.stamps import LogTime, format_seconds, log_time
from fuzzyslam.summary import log_name

if TYPE_CHECKING:  # the plug-ins and the maps stage load with a map only (lazy below):
    from fuzzyslam.maps.grid import BeliefMap  # a run without --map does not import them

MODES = ("none", "heading", "pose")


@dataclass
class FrozenMap:
    """A frozen FGM with its corridor references, as ``run`` needs it."""

    fgm: BeliefMap
    freeze_time: float
    log_id: str
    references: list[Reference]


def load_frozen_map(
    fgm_dir: Path,
    expect_log_id: str | None = None,
    need_references: bool = True,
    other_recording: bool = False,
) -> FrozenMap:
    """Load and check a map directory written by ``fuzzyslam map`` (through maps.mapio).

    Refused (InputError naming the file): a missing directory or file, a malformed map,
    masses that are not finite or do not sum to 1, a map never frozen, a map built from
    another log or world (``log_id`` differs from ``expect_log_id`` when given), a
    malformed references.yaml (or a missing one when ``need_references``: heading fixes).
    A map of another real recording (both identities ``log-``: no world record tells
    whether the building is the same) is taken when ``other_recording`` (the user gave
    ``--fix-from``: the fixes then start at a time of this log, not at the other log's
    freeze time), with a note on stderr.

    Parameters
    ----------
    fgm_dir : Path
        The map directory.
    expect_log_id : str or None
        The log's identity the map must have (None: any).
    need_references : bool
        references.yaml is required (heading fixes).
    other_recording : bool
        Take a map of another real recording.

    Returns
    -------
    FrozenMap
    """
    from fuzzyslam.maps.mapio import load_fgm

    fgm_dir = Path(fgm_dir)
    if not fgm_dir.is_dir():
        what = "is not a directory (--map takes the map directory 'map' wrote)"
        raise InputError(fgm_dir, what if fgm_dir.exists() else "map directory does not exist")
    npz = fgm_dir / "fgm.npz"
    f = load_fgm(npz)
    m = f.map
    masses = (m.m_e, m.m_o, m.m_t, m.m_c)
    if not all(np.all(np.isfinite(a)) for a in masses):
        raise InputError(npz, "mass arrays hold NaN or infinite values")
    if not np.allclose(sum(masses), 1.0, atol=1e-3):
        raise InputError(npz, "masses do not sum to 1 per cell")
    if not f.frozen:
        raise InputError(npz, "the map was never frozen; fixes need a frozen map")
    if not np.isfinite(f.freeze_time):
        raise InputError(npz, "the frozen map has no freeze_time")
    if expect_log_id is not None and f.log_id != expect_log_id:
        real = f.log_id.startswith("log-") and expect_log_id.startswith("log-")
        if not real:
            raise InputError(
                npz, f"map was built in another world ({f.log_id!r}, not {expect_log_id!r})"
            )
        if not other_recording:
            raise InputError(
                npz,
                f"map was built from another recording ({f.log_id!r}, not this log's "
                f"{expect_log_id!r}); to use it as a map of this log's building, give "
                "--fix-from SECONDS (this log's time from which its fixes apply); a map "
                "made by fuzzyslam before maps knew their recording: run 'fuzzyslam map' again",
            )
        from fuzzyslam.progress import note

        note(f"{npz}: a map of another recording, used as a map of this log's building")
    refs_path = fgm_dir / "references.yaml"
    refs: list[Reference] = []
    if need_references or refs_path.exists():
        refs = read_references(refs_path)
    if need_references and not refs:
        raise InputError(refs_path, "no corridor references: heading fixes need some")
    return FrozenMap(m, f.freeze_time, f.log_id, refs)


def make_aids(
    fgm_dir: Path,
    mode: str,
    cfg: Any,
    start_time: float | None = None,
    expect_log_id: str | None = None,
) -> list[Any]:
    """The plug-ins of ``run`` for ``mode`` in none|heading|pose (module docstring).

    ``expect_log_id``: the log's identity (``maps.mapio.log_identity``); a map built in
    another world is refused, and one of another real recording unless ``start_time`` is
    given (:func:`load_frozen_map`).

    Parameters
    ----------
    fgm_dir : Path
        The map directory.
    mode : str
        none, heading or pose.
    cfg : Config
        The run's config (its ``fixes:`` and ``fgm:`` sections).
    start_time : float or None
        Log time (s) from which the aids act (None: the map's freeze time).
    expect_log_id : str or None
        The log's identity.

    Returns
    -------
    list of FixAid
    """
    if mode not in MODES:
        raise ValueError(f"mode must be one of {', '.join(MODES)}, got {mode!r}")
    if mode == "none":
        return []
    fm = load_frozen_map(
        Path(fgm_dir), expect_log_id, mode == "heading", other_recording=start_time is not None
    )
    return aids_for_map(fm, mode, cfg, start_time)


def aids_for_map(fm: FrozenMap, mode: str, cfg: Any, start_time: float | None = None) -> list:
    """The plug-ins for an already loaded map (pure: no I/O).

    Parameters
    ----------
    fm : FrozenMap
        The loaded map.
    mode : str
        none, heading or pose.
    cfg : Config
        The run's config.
    start_time : float or None
        Log time (s) from which the aids act (None: the map's freeze time).

    Returns
    -------
    list of FixAid
    """
    from fuzzyslam.fixes.heading import FlmSource, HeadingFixAid
    from fuzzyslam.maps.flm import build_flm
    from fuzzyslam.maps.hough import flm_wall_direction

    t0 = fm.freeze_time if start_time is None else float(start_time)
    mp = cfg.fgm
    source = FlmSource(
        lambda ring, mounts: build_flm(ring.ranges, ring.max_range, ring.fov, mounts, mp)
    )

    def heading_aid() -> HeadingFixAid:
        if cfg.fixes.heading_source == "scan_lines":
            from fuzzyslam.fixes.scan_heading import ScanLineHeadingAid

            return ScanLineHeadingAid(fm.references, cfg.fixes, t0)
        return HeadingFixAid(
            fm.references,
            cfg.fixes,
            source,
            lambda flm: flm_wall_direction(flm, mp),
            t0,
            rings_flm=lambda recent, mounts: recent.flm(mounts, mp),
        )

    refs = [(r.id, r.name, r.angle, r.polygon) for r in fm.references]
    if mode == "heading":
        if not fm.references:
            raise InputError("references.yaml", "no corridor references: heading fixes need some")
        from fuzzyslam.fixes.off_map import OffMapWatch

        aid = heading_aid()
        aid.viewer_map = (fm.fgm, refs)  # the map used, in estimates.mcap (one aid shows it)
        aid.off_map = OffMapWatch(fm.fgm)  # heading fixes alone: is the position lost?
        return [aid]
    # the pose match and change detection (their kernels, the figure) load for pose fixes only
    from fuzzyslam.fixes.changes import ChangeDetector
    from fuzzyslam.fixes.pose_aid import PoseFixAid

    pose = PoseFixAid(fm.fgm, cfg.fixes, source, t0)
    pose.viewer_map = (fm.fgm, refs)
    aids: list[Any] = [pose]
    if cfg.fixes.pose_with_heading and fm.references:
        # sonar echo arcs are centred on the robot, so the correlative match rarely pins
        # the heading (measured: free in > 98 % of the rings); the Hough heading fix does
        aids.insert(0, heading_aid())
    if cfg.fixes.detect_changes:
        aids.append(ChangeDetector(fm.fgm, cfg.fixes, source, t0))
    return aids


def aids_for_live_map(cfg: Any) -> list[Any]:
    """The plug-ins of ``run --live-map`` (pure: no I/O): :class:`LiveMapPoseAid`, and
    with ``fixes.live_right_angles`` first :class:`LiveRightAngleHeading`
    (fixes/live_map.py).

    Parameters
    ----------
    cfg : Config
        The run's config (its ``fixes:`` and ``fgm:`` sections).

    Returns
    -------
    list of FixAid
    """
    from fuzzyslam.fixes.heading import FlmSource
    from fuzzyslam.fixes.live_map import LiveMapPoseAid, LiveRightAngleHeading
    from fuzzyslam.maps.flm import build_flm

    mp = cfg.fgm
    source = FlmSource(
        lambda ring, mounts: build_flm(ring.ranges, ring.max_range, ring.fov, mounts, mp)
    )
    pose = LiveMapPoseAid(cfg.fixes, mp, source)
    aids: list[Any] = [pose]
    if cfg.fixes.live_right_angles:
        heading = LiveRightAngleHeading(cfg.fixes)
        pose.heading_aid = heading  # the loop closure holds the headings it fixed
        aids.insert(0, heading)
    return aids


def aids_for_log(
    map_dir: Path | None,
    fix: str | None,
    cfg: Any,
    log: str | os.PathLike,
    fix_from: float | None = None,
    live_map: bool = False,
) -> list[Any]:
    """The aids of ``run LOG [--map map_dir] [--fix fix] [--fix-from fix_from]``: the mode
    ``fix``, else the config's ``fixes.mode`` when a map is given, else none; the map must
    be of the log's world (its identity, maps.mapio.log_identity). UsageError for a fix
    without a map.

    Parameters
    ----------
    map_dir : Path or None
        ``--map``.
    fix : str or None
        ``--fix`` (None: the config's ``fixes.mode`` with a map).
    cfg : Config
        The run's config.
    log : path
        The log (its world's identity).
    fix_from : float, LogTime or None
        ``--fix-from`` (a plain number: the log's own stamp).

    live_map : bool
        ``--live-map``: the map built while localising (:func:`aids_for_live_map`);
        UsageError with ``--map`` or a fix other than pose (``--fix-from`` without
        ``--map`` is refused by the run stage before).

    Returns
    -------
    list of FixAid
        Empty for no fixes.
    """
    if live_map:
        if map_dir is not None:
            raise UsageError("--live-map builds its own map: it takes no --map")
        if fix not in (None, "pose"):
            raise UsageError(f"--live-map makes pose fixes; --fix {fix} needs --map FGMDIR")
        return aids_for_live_map(cfg)
    mode = fix if fix is not None else ("none" if map_dir is None else cfg.fixes.mode)
    if mode == "none":
        return []
    if map_dir is None:
        raise UsageError(f"--fix {mode} needs --map FGMDIR (a frozen map from 'map')")
    from fuzzyslam.maps.mapio import log_identity
    from fuzzyslam.streams.logmeta import read_world
    from fuzzyslam.streams.reader import LogReader

    reader = LogReader(log)
    world = read_world(reader)  # the identity the map stage recorded (maps/build.py)
    world_dict = world.to_dict() if world is not None else None
    start = log_time(fix_from, reader.start)
    aids = make_aids(
        map_dir, mode, cfg, start, expect_log_id=log_identity(world_dict, reader.fingerprint())
    )
    for aid in aids:  # the log named in the figures' titles (changes.png)
        if hasattr(aid, "log"):
            aid.log = log_name(log)
    when = min((a.start_time for a in aids), default=None)
    if when is not None:
        _tell_fix_start(when, fix_from, reader.start, reader.end)
    return aids


def _tell_fix_start(when: float, given: Any, first: float, last: float) -> None:
    """A note when the fixes would start where the user probably did not mean them to:
    after the log's last message (no fix at all; e.g. the freeze time of a map built on
    the whole log), or at a stamp before its first message other than 0 (``600`` on a
    log stamped in Unix time: from its start, not 600 s into it)."""
    from fuzzyslam.progress import note

    if given is None:
        text, how = "", "the map's freeze time"
    else:
        text = str(given) if isinstance(given, LogTime) else format_seconds(given)
        how = f"--fix-from {text}"
    if when >= last:
        note(
            f"fixes start at {when:.3f} s ({how}), at or after the log's last message at "
            f"{last:.3f} s: no fix will be applied (--fix-from +0 applies them from the start)"
        )
    elif given is not None and 0.0 < when < first:
        note(
            f"--fix-from {text} s is before the log's first message at {first:.3f} s: the "
            f"fixes apply from its start (+{text} is {text} s after the start)"
        )
