"""The range sensor of a log, as the log has it: a sonar ring or a laser scanner.

:func:`open_ranges` decides which sensor feeds the maps and the fixes and where its
sensors sit (one home for ``map`` and ``run``):

- ``sonar``: the topics ``topics.sonar_prefix``NN present in the log (any number and
  placement: a 9-sonar front ring reads as 9 sensors), each placed by the /tf_static mount
  of its Range messages' ``header.frame_id`` (or, where /tf_static does not place it, by
  /tf's constant transforms: :mod:`fuzzyslam.streams.static_tf`). A present topic whose
  frame has no mount, or whose mount cannot be composed (two parents, a cycle, a zero
  quaternion, a cone axis near vertical), is an error naming it. Only a log without any
  /tf_static (nor /tf mounts; older simulated logs) falls back to the nominal
  ``sonar.count`` ring of ``robot.radius``, and says so in ``mounts_source``. The firing
  pattern (simultaneous or sequential) and the stamp gap that groups readings into rings
  are measured on the first ``FIRING_SAMPLE`` readings
  (:func:`fuzzyslam.streams.sonar.firing_gap`). Rings read before any Range message with a
  valid field of view take the config's sonar cone ``sonar.fov_deg``
  (``RangeSensor.cone``).
- ``scan``: ``topics.scan`` (sensor_msgs/LaserScan) as a ring of narrow sensors, one per
  kept beam (:mod:`fuzzyslam.streams.scan`), at the laser's /tf_static (or /tf constant)
  mount (frame of the first message) composed with each beam angle; cone width
  ``ranges.beam_width_deg``, every ``ranges.scan_step``-th beam kept, or fewer: the kept
  beams at least a cone apart (:func:`fuzzyslam.streams.scan.kept_step`). A scan of
  another beam count or angles is read onto the first scan's kept beams, placed by the
  same laser mount (``RangeSensor.laser``; :func:`fuzzyslam.streams.scan.scan_rings`).

A mount is the sensor frame's transform in the robot's base frame (``base``: the
odometry's child frame), composed down the whole /tf_static chain with full 3D
rotations and projected onto the base plane (:mod:`fuzzyslam.streams.tf`). A sensor not
connected to the base is an error; only in a /tf_static that does not name the base at
all does the root of the sensors' chains stand in for it, said in ``mounts_source``.

``ranges.source`` (or ``--ranges``): ``auto`` takes the sonar ring when the log has one,
else the scan.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from fuzzyslam.errors import InputError
from fuzzyslam.robot import sonar_mounts
from fuzzyslam.streams.messages import stamp_to_sec
from fuzzyslam.streams.reader import LogMessage, LogReader
from fuzzyslam.streams.scan import ZERO_READS, ScanGeometry, scan_geometry, scan_rings
from fuzzyslam.streams.sonar import (
    FIRING_SAMPLE,
    SIMULTANEOUS_GAP_S,
    Ring,
    RingStats,
    firing_gap,
    group_rings,
    mounts_of_frames,
    present_sonar_topics,
)
from fuzzyslam.streams.static_tf import static_messages
from fuzzyslam.streams.tf import Rigid, TfProblem, frame_mounts

SOURCES = ("auto", "sonar", "scan")


@dataclass
class RangeParams:
    """Which range sensor feeds the maps and fixes, and how a laser scan is read.

    ``beam_width_deg``: the cone of one laser beam in the evidence model. A laser's beam
    diverges by well under a degree; the cone also stands for the angular share of the
    beams left out by ``scan_step``, so the preset sets it to about the kept beams'
    spacing (cones that tile the field of view, no cell between two beams skipped). A
    laser whose beams are finer than that keeps fewer, one every cone
    (:func:`fuzzyslam.streams.scan.kept_step`): ``scan_step`` is the least step.

    ``scan_zero``: how a LaserScan's exact 0.0 below its (positive) range_min is read:
    ``no_echo`` (no return within range_max: weak empty evidence, as +inf) or
    ``invalid`` (skipped). REP 117 writes +inf for no return, but common drivers (a
    TurtleBot3's LDS-01, others) write 0.0, and an exact 0.0 from a laser is practically
    never an object nearer than range_min. Read as invalid, an LDS-01's no returns leave
    the maps without their empty space: the ACES building re-recorded as one (67 % of
    the beams 0.0) had its pose fixes lost (2.09 m mean error; 0.11 m read as no echo).
    So ``no_echo`` is the default, but only on a beam that has echoed in an earlier scan:
    a beam blocked by the robot's own body, or outside the laser's real view, reads 0.0
    in every scan and is no open space (that recording's rear half, never seen by the
    180-deg source laser: read as open too, its pose fixes erred 0.15 m and its closed
    live map 1.26 m, against 0.11 and 0.65 m left invalid). No CARMEN log, nor the
    simulator (sonars only, no echo at max_range), writes an exact 0.0: their outputs
    are unchanged.

    ``min_range_m``: the least range of an echo used (m), scans and sonar Range messages
    alike; nearer echoes are invalid (``too_near`` in the ring counts), not walls. 0 (the
    default) leaves the message's own range_min the only limit; a robot whose body or
    struts stand in the sensor's view (echoes at 0.15-0.2 m off them) sets it beyond
    them, as slam_toolbox's ``min_laser_range``.
    """

    source: str = field(default="auto", metadata={"choices": list(SOURCES)})
    beam_width_deg: float = field(default=1.0, metadata={"min": 0.01, "max": 45.0})
    scan_step: int = field(default=1, metadata={"min": 1, "max": 100})
    scan_zero: str = field(default="no_echo", metadata={"choices": list(ZERO_READS)})
    min_range_m: float = field(default=0.0, metadata={"min": 0.0, "max": 10.0})


@dataclass
class RangeSensor:
    """The chosen range sensor: its topics, the (M, 3) mounts (x, y, yaw) of its M
    sensors in the robot's base frame, and how its messages become :class:`Ring` s
    (a sonar ring: ``firing`` simultaneous or sequential, ``ring_gap`` the largest
    stamp step within a ring, s, :func:`fuzzyslam.streams.sonar.firing_gap`, and
    ``cone`` the field of view (rad) until a Range message gives a valid one; a laser:
    ``laser`` its mount, which places the beams of a scan of another geometry;
    ``zero`` and ``min_range``: ``ranges.scan_zero`` and ``ranges.min_range_m``)."""

    kind: str
    topics: list[str]
    mounts: np.ndarray
    mounts_source: str
    geometry: ScanGeometry | None = None
    beam_width: float = 0.0
    ring_gap: float = SIMULTANEOUS_GAP_S
    firing: str = ""
    cone: float | None = None
    laser: Rigid | None = None
    zero: str = "no_echo"  # ranges.scan_zero
    min_range: float = 0.0  # ranges.min_range_m

    @property
    def stamped_apart(self) -> bool:
        """Whether its readings are taken at different times (sonars fired in sequence, a
        laser's beams ``time_increment`` apart): a run deskews its rings by the odometry
        (:mod:`fuzzyslam.slam.deskew`)."""
        if self.kind == "scan":
            return self.geometry is not None and self.geometry.time_increment > 0
        return self.firing == "sequential"

    def rings(self, messages: Iterable[LogMessage], stats: RingStats) -> Iterator[Ring]:
        """Rings (or scans) of the log's messages on :attr:`topics`, in log order."""
        if self.kind == "scan":
            assert self.geometry is not None
            return scan_rings(
                messages,
                self.geometry,
                self.beam_width,
                stats,
                self.laser,
                self.zero,
                self.min_range,
            )
        index = {tp: i for i, tp in enumerate(self.topics)}
        return group_rings(
            messages, index, len(self.topics), self.ring_gap, stats, self.cone, self.min_range
        )

    def describe(self) -> dict[str, Any]:
        """For a stage's JSON summary."""
        out: dict[str, Any] = {
            "kind": self.kind,
            "topics": self.topics if len(self.topics) <= 16 else self.topics[:1],
            "sensors": len(self.mounts),
            "mounts_source": self.mounts_source,
        }
        if self.kind == "sonar":
            out["firing"] = self.firing
            out["ring_gap_s"] = round(self.ring_gap, 6)
        if self.geometry is not None:
            out["beams"] = self.geometry.beams
            out["time_increment_s"] = self.geometry.time_increment
            out["scan_step"] = self.geometry.step
            out["beam_width_deg"] = float(np.rad2deg(self.beam_width))
            out["scan_zero"] = self.zero
        if self.min_range > 0:
            out["min_range_m"] = self.min_range
        return out


def _first_frames(reader: LogReader, topics: list[str]) -> dict[str, str]:
    """topic -> header.frame_id of its first message (topics without messages left out)."""
    frames: dict[str, str] = {}
    for m in reader.messages(topics):
        frames.setdefault(m.topic, str(m.msg.header.frame_id))
        if len(frames) == len(topics):
            break
    return {tp: frames[tp] for tp in topics if tp in frames}


def _firing(reader: LogReader, topics: list[str]) -> tuple[str, float]:
    """The sonars' firing pattern and ring gap, from the stamps of their first
    ``FIRING_SAMPLE`` readings in the log."""
    stamps = []
    for m in reader.messages(topics):
        stamps.append(stamp_to_sec(m.msg.header.stamp))
        if len(stamps) >= FIRING_SAMPLE:
            break
    return firing_gap(stamps, len(topics))


def _mounts_source(reader: LogReader, tf_topic: str, stand_ins: dict[str, str], base) -> str:
    """``tf_topic``, and the root taken as the base frame when /tf_static does not name
    it (:func:`fuzzyslam.streams.tf.locate`); sensors under different such roots are an
    InputError (they cannot all be the base)."""
    roots = sorted(set(stand_ins.values()))
    if not roots:
        return tf_topic
    if len(roots) > 1:
        raise InputError(
            reader.path,
            f"{tf_topic} places the sensors under different roots "
            f"{', '.join(map(repr, roots))}, none of them the base frame {base!r}",
        )
    return f"{tf_topic} (root {roots[0]!r} taken as the base frame {base!r})"


def _tf_problem(reader: LogReader, tf_topic: str, problems: dict[str, str], frames) -> None:
    """InputError naming each topic whose /tf_static mount cannot be composed."""
    if problems:
        why = "; ".join(f"{tp} (frame {frames[tp]!r}): {p}" for tp, p in problems.items())
        raise InputError(reader.path, f"{tf_topic} cannot place {why}")


def _nor_tf(reader: LogReader, cfg: Any) -> str:
    """The end of a missing mount's line: whether /tf was looked at too."""
    return f", nor a constant transform on {cfg.topics.tf}" if reader.has(cfg.topics.tf) else ""


def _sonar(reader: LogReader, cfg: Any, topics: list[str], base: str) -> RangeSensor:
    frames = _first_frames(reader, topics)
    tf, source = static_messages(reader, cfg.topics, frames.values(), base)
    if not tf:  # no /tf_static (nor /tf mounts), or none readable (a damaged log)
        count = cfg.sonar.count
        nominal = [cfg.topics.sonar(i) for i in range(count)]
        if topics != nominal:
            raise InputError(
                reader.path,
                f"no {cfg.topics.tf_static} to place the sonars {', '.join(topics)} "
                f"(the nominal ring needs exactly {nominal[0]}..{nominal[-1]})",
            )
        firing, gap = _firing(reader, topics)
        return RangeSensor(
            "sonar",
            topics,
            sonar_mounts(count, cfg.robot.radius),
            f"nominal {count}-sonar ring (no {cfg.topics.tf_static}"
            + (" message: the log is damaged)" if reader.has(cfg.topics.tf_static) else ")"),
            ring_gap=gap,
            firing=firing,
            cone=_cone(cfg),
            min_range=cfg.ranges.min_range_m,
        )
    topics = [tp for tp in topics if tp in frames]
    if not topics:
        raise InputError(reader.path, f"no message on the sonar topics {cfg.topics.sonar_prefix}NN")
    stand_ins: dict[str, str] = {}
    mounts, missing, problems = mounts_of_frames(tf, frames, base, stand_ins)
    _tf_problem(reader, source, problems, frames)
    if missing:
        names = ", ".join(f"{tp} (frame {frames[tp]!r})" for tp in missing)
        raise InputError(
            reader.path, f"no {cfg.topics.tf_static} mount for {names}" + _nor_tf(reader, cfg)
        )
    source = _mounts_source(reader, source, stand_ins, base)
    firing, gap = _firing(reader, topics)
    return RangeSensor(
        "sonar",
        topics,
        mounts,
        source,
        ring_gap=gap,
        firing=firing,
        cone=_cone(cfg),
        min_range=cfg.ranges.min_range_m,
    )


def _cone(cfg: Any) -> float:
    """The configured sonar cone (rad): ``sonar.fov_deg``."""
    return float(np.deg2rad(cfg.sonar.fov_deg))


def _scan(reader: LogReader, cfg: Any, base: str) -> RangeSensor:
    tp = cfg.topics.scan
    first = next(iter(reader.messages([tp])), None)
    if first is None:
        raise InputError(reader.path, f"no message on {tp}")
    rp: RangeParams = cfg.ranges
    geom = scan_geometry(first.msg, rp.scan_step, float(np.deg2rad(rp.beam_width_deg)))
    if geom.beams == 0 or not (np.isfinite(geom.angle_increment) and geom.angle_increment != 0):
        raise InputError(reader.path, f"{tp}: a scan with no beams or a zero angle increment")
    tf, source = static_messages(reader, cfg.topics, [geom.frame], base)
    frames = {tp: geom.frame}
    stand_ins: dict[str, str] = {}
    found, missing, problems = frame_mounts(tf, frames, base, stand_ins)
    if tp in found:
        try:
            beams = geom.mounts(found[tp])
        except TfProblem as e:
            problems[tp] = f"the laser is {e}"
    _tf_problem(reader, source, problems, frames)
    if missing:
        raise InputError(
            reader.path,
            f"no {cfg.topics.tf_static} mount for {tp} (frame {geom.frame!r})"
            + _nor_tf(reader, cfg),
        )
    if not tf:  # the scan is stamped in the base frame itself
        source = f"none needed: {tp} is in the base frame {base!r}"
    return RangeSensor(
        "scan",
        [tp],
        beams,
        _mounts_source(reader, source, stand_ins, base),
        geom,
        float(np.deg2rad(rp.beam_width_deg)),
        laser=found[tp],
        zero=rp.scan_zero,
        min_range=rp.min_range_m,
    )


def open_ranges(
    reader: LogReader, cfg: Any, choice: str | None = None, base: str = "base_link"
) -> RangeSensor:
    """The log's range sensor (module docstring).

    Parameters
    ----------
    reader : LogReader
        The log.
    cfg : Config
        The config (``topics``, ``ranges``, ``sonar``, ``robot``).
    choice : str, optional
        ``--ranges``: overrides ``cfg.ranges.source`` (one of :data:`SOURCES`).
    base : str
        The robot's base frame the mounts are expressed in: the odometry's child frame
        (``TfFrames.base`` of :func:`fuzzyslam.slam.log_setup.tf_frames`).

    Returns
    -------
    RangeSensor

    Raises
    ------
    InputError
        Naming the topics and config keys when the sensor is absent, or the topics whose
        /tf_static mount is missing or cannot be composed.
    """
    source = choice or cfg.ranges.source
    if source not in SOURCES:
        raise ValueError(f"ranges source must be one of {', '.join(SOURCES)}, got {source!r}")
    sonars = present_sonar_topics(reader.topics, cfg.topics.sonar_prefix)
    has_scan = reader.has(cfg.topics.scan)
    if source == "auto":
        source = "sonar" if sonars else "scan" if has_scan else ""
    if source == "sonar" and sonars:
        return _sonar(reader, cfg, sonars, base)
    if source == "scan" and has_scan:
        return _scan(reader, cfg, base)
    sonar = f"{cfg.topics.sonar_prefix}00..{cfg.topics.sonar_prefix}NN (topics.sonar_prefix)"
    scan = f"{cfg.topics.scan} (topics.scan)"
    looked = {"sonar": sonar, "scan": scan, "": f"{sonar} or {scan}"}[source]
    have = ", ".join(sorted(reader.topics)) or "none"
    raise InputError(reader.path, f"missing stream(s) {looked}; the log has: {have}")


INVALID_SHARE = 1 / 3  # more of the readings invalid than this: a note and a count


def invalid_ranges(stats: RingStats, sensor: RangeSensor) -> dict[str, Any] | None:
    """The summary's ``invalid_ranges`` when more than ``INVALID_SHARE`` of the range
    readings read were invalid by the log's own doing, else None: a property of the log
    (its driver, its limits), not of the filter, so it is said apart from
    ``filter_health``. The echoes ``ranges.min_range_m`` drops are the config's choice
    (the robot's body in the view): counted, but they do not make the note.

    Parameters
    ----------
    stats : RingStats
        The sensor's counts over the log (or the map's window).
    sensor : RangeSensor
        The sensor read (its kind, topics, ``zero`` and ``min_range``).

    Returns
    -------
    dict or None
        ``readings``, ``invalid``, ``share`` (of the readings), and the invalid ones by
        cause: ``zero_invalid`` (a laser's exact 0.0 read as invalid:
        ``ranges.scan_zero`` ``invalid``, or on a beam that had not echoed yet),
        ``too_near`` (``ranges.min_range_m``) and ``other`` (NaN,
        -inf, outside the message's limits); with ``sensor`` (its first topic),
        ``scan_zero`` and ``min_range_m``.
    """
    if stats.readings <= 0 or stats.invalid - stats.too_near <= INVALID_SHARE * stats.readings:
        return None
    zeros = stats.zero_invalid if sensor.kind == "scan" else 0
    return {
        "sensor": sensor.topics[0] if len(sensor.topics) == 1 else sensor.kind,
        "readings": stats.readings,
        "invalid": stats.invalid,
        "share": round(stats.invalid / stats.readings, 4),
        "zero_invalid": zeros,
        "too_near": stats.too_near,
        "other": stats.invalid - zeros - stats.too_near,
        "scan_zero": sensor.zero if sensor.kind == "scan" else None,
        "min_range_m": sensor.min_range,
    }


def invalid_note(found: dict[str, Any]) -> str:
    """The stderr line for the summary's ``invalid_ranges`` (:func:`invalid_ranges`):
    the counts by cause, commonest first, and what to set for the commonest.

    Parameters
    ----------
    found : dict
        ``invalid_ranges`` as :func:`invalid_ranges` gives it.

    Returns
    -------
    str
    """
    zeros = (
        "exact 0.0 below the laser's range_min (ranges.scan_zero: invalid; no_echo reads "
        "them as no return, what drivers such as a TurtleBot3's LDS-01 mean by 0.0)"
        if found["scan_zero"] == "invalid"
        else "exact 0.0 on beams that had never echoed (blocked by the robot's own body, "
        "or outside the laser's real view: not read as open space)"
    )
    causes = {
        "zero_invalid": zeros,
        "too_near": (
            f"echoes nearer than ranges.min_range_m = {found['min_range_m']:g} m (lower it "
            "if these are walls, not the robot)"
        ),
        "other": (
            "NaN, -inf or outside the messages' [range_min, range_max) (the driver's own "
            "limits: check them against its ranges)"
        ),
    }
    ranked = sorted((k for k in causes if found[k] > 0), key=lambda k: -found[k])
    parts = "; ".join(f"{found[k]} {causes[k]}" for k in ranked)
    return (
        f"{found['sensor']}: {found['invalid']} of {found['readings']} range readings "
        f"({100 * found['share']:.0f} %) are invalid and not used: {parts} "
        "(the summary's invalid_ranges)"
    )
