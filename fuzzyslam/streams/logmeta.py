"""The world and the scenario carried inside a simulated log (MCAP metadata records).

Written at the start of the file (so a truncated recording keeps them):

- ``fuzzyslam.world``: walls, true lamps, corridors (centre-line segment, width,
  true axis angle, polygon), ceiling height;
- ``fuzzyslam.scenario``: name, seed, start pose, duration, the resolved config
  and the events: run boundaries, lamp failures and bumps.

Each record is ``{"json": <text>}``. Logs from real robots have neither record;
readers return None and stages fall back to the config.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

from fuzzyslam.errors import InputError
from fuzzyslam.streams.reader import LogReader

WORLD_KEY = "fuzzyslam.world"
SCENARIO_KEY = "fuzzyslam.scenario"


@dataclass
class Corridor:
    """A straight corridor: centre-line segment a -> b, width, true axis angle (mod pi)."""

    name: str
    a: list[float]
    b: list[float]
    width: float
    axis: float
    polygon: list[list[float]]


@dataclass
class World:
    """Walls (N, 4) as x0 y0 x1 y1, true lamps (M, 2), corridors, ceiling height above the lens."""

    walls: list[list[float]]
    lamps: list[list[float]]
    lamp_radius: float
    corridors: list[Corridor]
    centerline: list[list[float]]
    ceiling_height: float

    @property
    def wall_array(self) -> np.ndarray:
        return np.asarray(self.walls, dtype=float).reshape(-1, 4)

    @property
    def lamp_array(self) -> np.ndarray:
        return np.asarray(self.lamps, dtype=float).reshape(-1, 2)

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> World:
        d = dict(d)
        d["corridors"] = [Corridor(**c) for c in d.get("corridors", [])]
        return cls(**d)


@dataclass
class Event:
    """A scenario event at time t (s).

    kind: ``run_start`` (run, direction +1/-1), ``run_end`` (run),
    ``lamp_failure`` (lamps: indices going dark), ``bump`` (run, angle rad).
    """

    t: float
    kind: str
    run: int = 0
    direction: int = 0
    lamps: list[int] = field(default_factory=list)
    angle: float = 0.0


@dataclass
class Scenario:
    """What was simulated: name, seed, start pose, duration, events, resolved config."""

    name: str
    seed: int
    start_pose: list[float]
    duration: float
    events: list[Event]
    config: dict[str, Any] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> Scenario:
        d = dict(d)
        d["events"] = [Event(**e) for e in d.get("events", [])]
        return cls(**d)

    def run_intervals(self) -> list[tuple[int, float, float]]:
        """[(run, t_start, t_end)] from the run_start/run_end events."""
        starts = {e.run: e.t for e in self.events if e.kind == "run_start"}
        ends = {e.run: e.t for e in self.events if e.kind == "run_end"}
        return [(r, starts[r], ends.get(r, self.duration)) for r in sorted(starts)]

    def run_end_time(self, run: int) -> float | None:
        """End time of run ``run`` (1-based), or None if the log has no such run."""
        for r, _t0, t1 in self.run_intervals():
            if r == run:
                return t1
        return None


def read_world(reader: LogReader) -> World | None:
    data = reader.json_metadata(WORLD_KEY)
    if data is None:
        return None
    try:
        return World.from_dict(data)
    except (TypeError, KeyError) as exc:
        raise InputError(reader.path, f"metadata '{WORLD_KEY}' is malformed: {exc}") from None


def read_scenario(reader: LogReader) -> Scenario | None:
    data = reader.json_metadata(SCENARIO_KEY)
    if data is None:
        return None
    try:
        return Scenario.from_dict(data)
    except (TypeError, KeyError) as exc:
        raise InputError(reader.path, f"metadata '{SCENARIO_KEY}' is malformed: {exc}") from None
