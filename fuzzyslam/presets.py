"""The config a stage uses when ``--config`` is not given: the preset for the kind of robot
the log records.

fuzzyslam ships one embedded config per kind of robot: ``paper.yaml`` (the simulated
Nomad: wheel encoders, 16 sonars, a ceiling camera), ``real_detections.yaml`` (wheel
odometry and landmark detections, as the UTIAS MRCLAM robots), and
``real_building_scan.yaml`` / ``real_building_sonar.yaml`` (odometry and a laser, or a
sonar ring, in a building without lamps). A log says which kind it is by its streams, so
``run`` and ``map`` without ``--config`` take the preset of its kind (:func:`choose`, the
first rule that applies):

1. a log written by ``fuzzyslam simulate`` (its ``fuzzyslam.scenario`` or
   ``fuzzyslam.world`` record) or with the paper config's lamps (``topics.image``,
   its compressed stream, or ``topics.detections``): ``paper``;
2. ``real_detections``' ``topics.detections`` as geometry_msgs/PoseArray or
   vision_msgs/Detection3DArray: ``real_detections``;
3. a range sensor and no lamps: ``real_building_sonar`` when its ``topics.sonar_prefix``
   NN topics are sensor_msgs/Range, else ``real_building_scan`` when its ``topics.scan``
   is a sensor_msgs/LaserScan (the ring first, as ``--ranges`` chooses by default; a
   ``--ranges`` given picks its own sensor's preset);
4. anything else: ``paper``, the default.

``run --map FGMDIR`` first takes the config its map was built with (the map's
summary.json ``config``), so that the run reads the ranges as the map did.
:func:`resolve` is the stages' entry: the config given, else the map's, else the
log's kind; its :class:`ConfigChoice` goes into the summaries (``config``).
"""

from __future__ import annotations

import json
import os
from collections.abc import Mapping
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

from fuzzyslam.config import embedded_names, load_config
from fuzzyslam.streams.messages import DETECTION3D_ARRAY, IMAGE, LASER_SCAN, POSE_ARRAY, RANGE
from fuzzyslam.streams.topics import Topics

DETECTIONS = (POSE_ARRAY, DETECTION3D_ARRAY)
SIMULATED = ("fuzzyslam.scenario", "fuzzyslam.world")  # streams/logmeta.py's records
PAPER, DETECTED, SCAN, SONAR = (
    "paper",
    "real_detections",
    "real_building_scan",
    "real_building_sonar",
)


@dataclass(frozen=True)
class ConfigChoice:
    """The config a stage runs with and why (the summaries' ``config``)."""

    source: str  # an embedded config's name or a YAML file's path, as given
    why: str  # "--config", "the map's config (DIR)", "the log's streams: ...", "default"

    def as_dict(self, name: str, outdir: str | os.PathLike | None = None) -> dict[str, str]:
        """The summaries' ``config``.

        Parameters
        ----------
        name : str
            The loaded config's ``name``.
        outdir : path, optional
            A map's directory: a config file's path is also recorded relative to it
            (``file_from_map``), which a run on the map reads wherever it starts, as
            long as the map and the config move together.

        Returns
        -------
        dict
            ``name``, ``source`` (as given, so that a summary does not name the folder
            it was made in), ``chosen_by``; ``file_from_map`` (``outdir`` given and
            ``source`` a file).
        """
        from fuzzyslam.summary import path_text

        out = {"name": name, "source": path_text(self.source), "chosen_by": self.why}
        if outdir is not None and Path(self.source).is_file():
            rel = os.path.relpath(Path(self.source).resolve(), Path(outdir).resolve())
            out["file_from_map"] = path_text(rel)
        return out


@lru_cache(maxsize=8)
def preset_topics(name: str) -> Topics:
    """An embedded preset's ``topics`` (its YAML parsed once per process; read only).

    Parameters
    ----------
    name : str
        The preset's name.

    Returns
    -------
    Topics
    """
    return load_config(name).topics


def _sonar_topics(topics: Mapping[str, str], prefix: str) -> list[str]:
    """``prefix`` + digits topics carrying sensor_msgs/Range."""
    from fuzzyslam.streams.sonar import present_sonar_topics

    return [t for t in present_sonar_topics(topics, prefix) if topics[t] == RANGE]


def choose(
    topics: Mapping[str, str], simulated: bool = False, ranges: str | None = None
) -> tuple[str, str]:
    """The preset for a log's streams (module docstring: the rules).

    Parameters
    ----------
    topics : mapping of str to str
        The log's topics and their message types.
    simulated : bool
        The log carries ``fuzzyslam simulate``'s world or scenario.
    ranges : str, optional
        ``--ranges`` (sonar|scan): the range sensor the caller will read.

    Returns
    -------
    name : str
        An embedded config's name.
    why : str
        What in the log chose it, for the summary and the note.
    """
    if simulated:
        return PAPER, "a simulated log"
    paper = preset_topics(PAPER)
    lamps = [t for t in (paper.image, paper.image + "/compressed", paper.detections) if t in topics]
    if lamps:
        return PAPER, f"lamps on {', '.join(lamps)}"
    det = preset_topics(DETECTED).detections
    if topics.get(det) in DETECTIONS:
        return DETECTED, f"landmark detections on {det}, no lamps"
    sonar_cfg, scan_cfg = preset_topics(SONAR), preset_topics(SCAN)
    sonars = _sonar_topics(topics, sonar_cfg.sonar_prefix)
    scan = topics.get(scan_cfg.scan) == LASER_SCAN
    ring = f"{len(sonars)} sonars on {sonar_cfg.sonar_prefix}NN"
    if sonars and ranges != "scan":
        return SONAR, f"{ring}, no lamps"
    if scan and ranges != "sonar":
        return SCAN, f"a laser scan on {scan_cfg.scan}, no lamps"
    return PAPER, "none of the presets' streams"


def _map_config(map_dir: str | os.PathLike) -> str | None:
    """The config a map was built with (its summary.json ``config``), when that config
    can still be loaded: an embedded name, or a file found from the map's directory
    (``file_from_map``) or, failing that, where it was given (``source``)."""
    try:
        config = json.loads((Path(map_dir) / "summary.json").read_text())["config"]
        source, rel = config["source"], config.get("file_from_map")
    except (OSError, ValueError, KeyError, TypeError, AttributeError):
        return None  # a map of older code, or not a map: the aids' own checks say so
    if not isinstance(source, str):
        return None
    if rel is None and (source in embedded_names() or source + ".yaml" in embedded_names()):
        return source
    if isinstance(rel, str) and (Path(map_dir) / rel).is_file():
        return str(Path(map_dir) / rel)
    return source if Path(source).is_file() else None


def resolve(
    config: str | None,
    log: str | os.PathLike,
    map_dir: str | os.PathLike | None = None,
    ranges: str | None = None,
) -> ConfigChoice:
    """The config of a stage: ``config`` when given, else the map's (``map_dir``), else
    the preset of the log's kind (:func:`choose`); a log that cannot be opened gets the
    default, and the stage's own read of it says what is wrong.

    Parameters
    ----------
    config : str or None
        ``--config``: a YAML path or an embedded name.
    log : path
        The log.
    map_dir : path, optional
        ``run --map``'s directory.
    ranges : str, optional
        ``--ranges``.

    Returns
    -------
    ConfigChoice
    """
    if config is not None:
        return ConfigChoice(config, "--config")
    if map_dir is not None:
        found = _map_config(map_dir)
        if found is not None:
            return ConfigChoice(found, f"the map's config ({map_dir})")
    from fuzzyslam.errors import InputError
    from fuzzyslam.streams.reader import LogReader

    try:
        reader = LogReader(log)
    except (InputError, OSError):
        return ConfigChoice(PAPER, "default")
    simulated = any(k in reader.metadata for k in SIMULATED)
    name, why = choose(reader.topics, simulated, ranges)
    return ConfigChoice(name, f"the log's streams: {why}")


def chosen_note(log: str | os.PathLike, config: dict[str, str]) -> None:
    """One line on stderr when a stage runs with a config it chose other than the default
    ``paper``: which, and from what. Said once the log has opened and its streams are
    found, so that a failing command still says one line.

    Parameters
    ----------
    log : path
        The log.
    config : dict
        The summary's ``config`` (:meth:`ConfigChoice.as_dict`).
    """
    if config["chosen_by"] == "--config" or config["source"] == PAPER:
        return  # given, or what a stage without --config has always used
    from fuzzyslam.progress import note

    note(
        f"{log}: no --config: {config['name']}, from {config['chosen_by']} "
        "(--config NAME for another)"
    )


# the sensor streams a preset reads, by message type: (preset, its topics key)
READS = {
    POSE_ARRAY: (DETECTED, "detections"),
    DETECTION3D_ARRAY: (DETECTED, "detections"),
    IMAGE: (PAPER, "image"),
    LASER_SCAN: (SCAN, "scan"),
}


def unread_streams(topics: Mapping[str, str], read: object) -> list[str]:
    """The log's sensor streams that the config does not read, each with the config
    that would: a preset that reads it (``--config real_detections``), or one extended
    with its topic (``extends: real_detections`` and ``topics: {detections: /markers}``).

    Parameters
    ----------
    topics : mapping of str to str
        The log's topics and their message types.
    read : Topics
        The config's ``topics`` (``fuzzyslam.streams.topics.Topics``).

    Returns
    -------
    list of str
        One text per stream, in topic order (empty: every such stream is read).
    """
    out = []
    for topic, kind in sorted(topics.items()):
        if kind in READS and topic != getattr(read, READS[kind][1]):
            preset, key = READS[kind]
            own = getattr(preset_topics(preset), key) == topic
            how = (
                f"--config {preset}"
                if own
                else f"a config with 'extends: {preset}' and 'topics: {{{key}: {topic}}}'"
            )
            out.append(f"{topic} ({kind.rsplit('/', 1)[-1]}: {how} reads it)")
    return out
