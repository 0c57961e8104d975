"""The scenario plan: world, true drive, encoders and the event schedule (pure).

Everything that does not need per-frame rendering is computed here, up front, from
the config and the seed (a few arrays of the robot rate: kilobytes). Sensors that
produce bulk data (sonar rings, camera frames) are simulated later while streaming.

Randomness: one ``np.random.SeedSequence(seed)`` spawned into independent child
streams, one per sensor (encoders, sonar, camera) and one for the driver, so draws do not
depend on another's and the same seed gives byte-identical files.

Lamp indices in ``scenario.lamp_failures`` are 0-based indices into the world's
lamp list. Failures and bumps scheduled for runs beyond ``scenario.runs`` are not
simulated (so a shorter variant can extend the paper config).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from fuzzyslam.errors import ConfigError
from fuzzyslam.sim.encoders import Encoders, simulate_encoders
from fuzzyslam.sim.obstacles import Track, plan_tracks
from fuzzyslam.sim.path import Drive, drive
from fuzzyslam.sim.world import build_world, centreline_array
from fuzzyslam.streams.logmeta import Event, World

STREAMS = ("encoders", "sonar", "camera", "drive")


def rng_streams(seed: int) -> dict[str, np.random.Generator]:
    """Independent generators per sensor from one SeedSequence(seed).

    Parameters
    ----------
    seed : int
        The simulation's seed.

    Returns
    -------
    dict of str to numpy.random.Generator
    """
    children = np.random.SeedSequence(seed).spawn(len(STREAMS))
    return {name: np.random.default_rng(c) for name, c in zip(STREAMS, children, strict=True)}


@dataclass
class Plan:
    """World, true motion, encoder readings and the sorted event list of one simulation."""

    world: World
    drive: Drive
    encoders: Encoders
    events: list[Event]
    obstacles: list[Track] = field(default_factory=list)  # boxes and people (issue 8)

    @property
    def start_pose(self) -> np.ndarray:
        return self.drive.pose[0].copy()


def lamp_failure_events(cfg, drive_events: list[Event], n_lamps: int, source: str) -> list[Event]:
    """A lamp_failure event at the start of each configured run (validated indices).

    Parameters
    ----------
    cfg : Config
        The simulation's config (``scenario.lamp_failures``).
    drive_events : list of Event
        The drive's run events.
    n_lamps : int
        Lamps in the world.
    source : str
        The config's name (for error messages).

    Returns
    -------
    list of Event
    """
    starts = {e.run: e.t for e in drive_events if e.kind == "run_start"}
    out = []
    for i, f in enumerate(cfg.scenario.lamp_failures):
        bad = [j for j in f.lamps if not 0 <= j < n_lamps]
        if bad:
            raise ConfigError(
                source,
                f"'scenario.lamp_failures[{i}].lamps' has indices {bad} outside 0..{n_lamps - 1}",
            )
        if f.run in starts and f.lamps:
            out.append(Event(t=starts[f.run], kind="lamp_failure", run=f.run, lamps=list(f.lamps)))
    return out


def lamps_lit(events: list[Event], n_lamps: int, t: float) -> np.ndarray:
    """Mask of lamps lit at time t (failures take effect at their event time).

    Parameters
    ----------
    events : list of Event
        The plan's events.
    n_lamps : int
        Lamps in the world.
    t : float
        The time (s).

    Returns
    -------
    ndarray of bool, shape (n_lamps,)
    """
    lit = np.ones(n_lamps, dtype=bool)
    for e in events:
        if e.kind == "lamp_failure" and e.t <= t:
            lit[e.lamps] = False
    return lit


def make_plan(cfg, rngs: dict[str, np.random.Generator], source: str = "config") -> Plan:
    """The plan of a config: world, drive, encoders, events (sorted by time).

    Parameters
    ----------
    cfg : Config
        The simulation's config.
    rngs : dict of str to numpy.random.Generator
        :func:`rng_streams`.
    source : str
        The config's name (for error messages).

    Returns
    -------
    Plan
    """
    world = build_world(cfg.world, cfg.camera, source)
    centre = centreline_array(cfg.world, source)
    dr = drive(centre, cfg.robot, cfg.scenario, rngs["drive"])
    enc = simulate_encoders(dr.d_trans, dr.d_rot, cfg.robot, dr.pose[0], rngs["encoders"])
    events = dr.events + lamp_failure_events(cfg, dr.events, len(world.lamps), source)
    order = {"run_end": 0, "run_start": 1, "lamp_failure": 2, "bump": 3}
    events.sort(key=lambda e: (e.t, order.get(e.kind, 9)))
    starts = {e.run: e.t for e in events if e.kind == "run_start"}
    ends = {e.run: e.t for e in events if e.kind == "run_end"}
    intervals = {r: (t0, ends.get(r, dr.duration)) for r, t0 in starts.items()}
    tracks = plan_tracks(cfg.scenario.obstacles, intervals, source)
    return Plan(world, dr, enc, events, tracks)
