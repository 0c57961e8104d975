"""The map stage's edge: log + trajectory in, FGMDIR out (docs/contracts.md sec. 3).

Reads the log's sonar rings and mounts, places each ring at the trajectory's pose at
the ring's time (linear in x, y; heading interpolated on the circle; a ring fired in
sequence reading by reading, each at its own stamp:
:func:`fuzzyslam.streams.sonar.deskewed_mounts`), builds the FGM up
to the freeze time, freezes it, extracts corridor references and writes fgm.npz,
fgm.yaml + fgm.pgm, references.yaml, fgm.mcap (the map for a viewer), figures and
summary.json through
:class:`fuzzyslam.fileio.OutputDir` (nothing partial is left on failure).
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from fuzzyslam.config import Config
from fuzzyslam.errors import InputError
from fuzzyslam.fileio import OutputDir, check_outputs
from fuzzyslam.maps import mapio
from fuzzyslam.maps.fgm import FgmBuilder
from fuzzyslam.maps.params import MapParams
from fuzzyslam.maps.quality import wall_quality
from fuzzyslam.maps.references import Reference, extract_references
from fuzzyslam.maps.summary import MapSummary, ReferenceEntry, ReferenceTruth, WallQuality
from fuzzyslam.presets import chosen_note
from fuzzyslam.progress import Progress, note
from fuzzyslam.se2 import interpolate_poses, wrap_angle_period
from fuzzyslam.slam import calibration_files
from fuzzyslam.slam.log_setup import base_frame
from fuzzyslam.stamps import SAME_INSTANT_S, LogTime, log_time
from fuzzyslam.streams.logmeta import World, read_scenario, read_world
from fuzzyslam.streams.ranges import invalid_note, invalid_ranges, open_ranges
from fuzzyslam.streams.reader import LogReader
from fuzzyslam.streams.sonar import RingStats, deskewed_mounts
from fuzzyslam.streams.tum import read_tum
from fuzzyslam.summary import OMIT, as_json, path_text


@dataclass
class MapOptions:
    """Command-line choices of the map stage."""

    until_run: int | None = None
    until: float | LogTime | None = None  # a plain number: the log's own stamp
    skip_uncovered: bool = False
    landmarks: Path | None = None
    figures: bool = True
    explicit_config: bool = False
    ranges: str | None = None
    sort: bool = False
    # the trajectory's run's calibration.csv (default: beside the trajectory, when there)
    calibration: Path | None = None
    # the config's name, source and why (the summary's ``config``: fuzzyslam/presets.py)
    config: dict[str, str] | None = None


def covered(tq: np.ndarray, t: np.ndarray, max_gap: float) -> np.ndarray:
    """Whether each query time lies within the trajectory, between samples at most
    ``max_gap`` seconds apart, or on a sample (within ``SAME_INSTANT_S``, an absolute
    tolerance: the same at 0 s as at Unix times).

    Parameters
    ----------
    tq : ndarray, shape (K,)
        Query times (s).
    t : ndarray, shape (N,)
        The trajectory's times (sorted).
    max_gap : float
        Largest gap (s) between samples.

    Returns
    -------
    ndarray of bool, shape (K,)
    """
    tq = np.asarray(tq, dtype=float)
    j = np.searchsorted(t, tq)
    lo = t[np.clip(j - 1, 0, len(t) - 1)]
    hi = t[np.clip(j, 0, len(t) - 1)]
    exact = (np.abs(lo - tq) <= SAME_INSTANT_S) | (np.abs(hi - tq) <= SAME_INSTANT_S)
    inside = (tq >= t[0]) & (tq <= t[-1]) & (hi - lo <= max_gap)
    return exact | inside


def _gaps(tq: np.ndarray, ok: np.ndarray) -> list[tuple[float, float]]:
    """Time spans (first, last ring time) of runs of uncovered rings."""
    bad = np.concatenate([[0], (~ok).astype(np.int8), [0]])
    e = np.flatnonzero(np.diff(bad))
    return [(float(tq[a]), float(tq[b - 1])) for a, b in zip(e[::2], e[1::2], strict=True)]


def freeze_time(reader: LogReader, cfg: Config, opts: MapOptions) -> tuple[float, str]:
    """The window's end and how it was chosen.

    Parameters
    ----------
    reader : LogReader
        The log (its scenario).
    cfg : Config
        ``fgm.freeze_run``.
    opts : MapOptions
        ``--until``, ``--until-run``.

    Returns
    -------
    t : float
        The freeze time (s).
    how : str
        How it was chosen.
    """
    if opts.until is not None:
        t = log_time(opts.until, reader.start)
        if t < reader.start:  # e.g. 600 on a log stamped in Unix time
            raise InputError(
                reader.path,
                f"--until {opts.until} s is before the log's first message at "
                f"{reader.start:.3f} s (log times are the log's own stamps; +S is S seconds "
                "after its start)",
            )
        if t > reader.end:  # every ring is in the map, frozen at a time the log never saw
            note(
                f"{reader.path}: --until {opts.until} s is after the log's last message at "
                f"{reader.end:.3f} s; the map holds the whole log and records freeze_time "
                f"{t:.3f} s"
            )
        return t, "--until"
    scenario = read_scenario(reader)
    if opts.until_run is not None:
        run, how = opts.until_run, "--until-run"
    else:
        run, how = cfg.fgm.freeze_run, "config fgm.freeze_run"
        if not opts.explicit_config and scenario is not None:
            fr = scenario.config.get("fgm", {}).get("freeze_run") if scenario.config else None
            if isinstance(fr, int):
                run, how = fr, "the log's fgm.freeze_run"
    if scenario is None:
        if opts.until_run is not None:
            raise InputError(reader.path, "the log has no scenario (no run events); use --until")
        return float(reader.end), "end of log (no scenario)"
    t = scenario.run_end_time(run)
    if t is None:
        runs = [r for r, _a, _b in scenario.run_intervals()]
        raise InputError(
            reader.path,
            f"the log has no run {run} (runs: {runs}); choose --until-run N or --until T",
        )
    return float(t), f"end of run {run} ({how})"


class _RingTable:
    """Rings appended one by one into preallocated float32 blocks (no Python object per
    ring: the map stage's memory grows by 200 bytes a ring of 16, not ~600). float32 is
    lossless here: sensor_msgs/Range's range and max_range are float32 (or NaN); the
    readings' offsets from their ring's time (0 for a ring stamped alike, NaN where
    none) to a tenth of a microsecond."""

    block = 4096

    def __init__(self, count: int) -> None:
        self.count = count
        self.blocks: list[tuple[np.ndarray, ...]] = []
        self.n = 0  # rings in the last block

    def append(
        self, t: float, ranges: np.ndarray, rmax: np.ndarray, offsets: np.ndarray | None = None
    ) -> None:
        if not self.blocks or self.n == self.block:
            shape = (self.block, self.count)
            self.blocks.append(
                (np.empty(self.block), *(np.empty(shape, np.float32) for _ in range(3)))
            )
            self.n = 0
        ts, rs, ms, os_ = self.blocks[-1]
        ts[self.n], rs[self.n], ms[self.n] = t, ranges, rmax
        os_[self.n] = 0.0 if offsets is None else offsets
        self.n += 1

    def arrays(self) -> tuple[np.ndarray, ...]:
        """times (N,) float64; ranges, max ranges and offsets (N, M) float32."""
        if not self.blocks:
            return np.zeros(0), *(np.zeros((0, self.count), np.float32),) * 3
        self.blocks[-1] = tuple(a[: self.n] for a in self.blocks[-1])
        out = tuple(np.concatenate(parts) for parts in zip(*self.blocks, strict=True))
        self.blocks = []
        return out


def read_rings(reader: LogReader, cfg: Config, t_end: float, ranges: str | None = None):
    """(times (N,), ranges (N, M), max ranges (N, M), fov, mounts (M, 3), or (N, M, 3)
    when some ring has its own (a laser scan of another geometry), stats, offsets (N, M):
    each reading's stamp minus its ring's, s; 0 for rings stamped alike).

    Parameters
    ----------
    reader : LogReader
        The log.
    cfg : Config
        Topics and range sensor.
    t_end : float
        The window's end (s).
    ranges : str or None
        sonar|scan (None: the config's).
    """
    times, rr, rmax, *rest = read_rings_compact(reader, cfg, t_end, ranges)
    return times, rr.astype(float), rmax.astype(float), *rest


def read_rings_compact(
    reader: LogReader, cfg: Config, t_end: float, ranges: str | None = None, sensor=None
):
    """``read_rings`` with ranges and max ranges as float32 (the exact values of the
    Range and LaserScan messages, a quarter of the memory of lists of float64 rings;
    _RingTable). The range sensor is ``sensor`` or the log's (``open_ranges``, with
    ``ranges`` = sonar|scan|None overriding ``ranges.source``).

    Parameters
    ----------
    reader : LogReader
        The log.
    cfg : Config
        Topics and range sensor.
    t_end : float
        The window's end (s).
    ranges : str or None
        sonar|scan (None: the config's).
    sensor : RangeSensor, optional
        An opened range sensor.
    """
    if sensor is None:
        sensor = open_ranges(reader, cfg, ranges, base=base_frame(reader, cfg))
    mounts = sensor.mounts
    stats = RingStats()
    table, fov = _RingTable(len(mounts)), 0.0
    own: dict[int, np.ndarray] = {}  # ring -> its own mounts (a scan of another geometry)
    for k, ring in enumerate(sensor.rings(reader.messages(sensor.topics), stats)):
        if ring.t > t_end + 1e-9:
            break
        table.append(ring.t, ring.ranges, ring.max_range, ring.offsets)
        if ring.mounts is not None:
            own[k] = ring.mounts
        fov = ring.fov
    times, rr, rmax, offsets = table.arrays()
    if not len(times):
        raise InputError(reader.path, f"no {sensor.kind} readings in the window [0, {t_end:.2f}] s")
    if own:  # each ring's mounts (N, M, 3): the sensor's, or the ring's own
        mounts = np.repeat(np.asarray(mounts, dtype=float)[None], len(times), axis=0)
        mounts[list(own)] = np.stack(list(own.values()))
    return times, rr, rmax, fov, mounts, stats, offsets


def reference_truth(refs: list[Reference], world: World | None) -> list[ReferenceTruth]:
    """Each reference against the nearest true corridor axis (by centre-line distance).

    Parameters
    ----------
    refs : list of Reference
        The map's references.
    world : World or None
        The simulated world.

    Returns
    -------
    list of ReferenceTruth
    """
    if world is None or not world.corridors:
        return []
    out = []
    for ref in refs:
        c = ref.stretch.point if ref.stretch is not None else ref.region.mean(axis=0)
        best, bd = None, np.inf
        for cor in world.corridors:  # a handful of corridors
            a, b = np.asarray(cor.a, float), np.asarray(cor.b, float)
            u = np.clip(np.dot(c - a, b - a) / max(np.dot(b - a, b - a), 1e-12), 0.0, 1.0)
            d = float(np.hypot(*(a + u * (b - a) - c)))
            if d < bd:
                best, bd = cor, d
        err = float(wrap_angle_period(ref.angle - best.axis, np.pi))
        out.append(
            ReferenceTruth(
                id=ref.id,
                true_corridor=best.name,
                true_axis_deg=float(np.rad2deg(best.axis)),
                error_deg=float(np.rad2deg(err)),
            )
        )
    return out


def _write_viewer_log(path: Path, fgm, refs: list[Reference], t: float, cfg: Config) -> None:
    """fgm.mcap: the frozen FGM (/map), its conflict layer and its corridor references
    (maps/viewer.py), stamped at the log's start so that a viewer shows them over the
    whole sensor log."""
    from fuzzyslam.maps.viewer import fgm_messages
    from fuzzyslam.streams.writer import LogWriter

    ref_rows = [(r.id, r.name, r.angle, r.region) for r in refs]
    with LogWriter(path, latched=cfg.topics.latched(), ros_distro=cfg.output.ros_distro) as w:
        for topic, typename, msg, tm in fgm_messages(fgm, ref_rows, t, cfg.topics):
            w.write(topic, typename, msg, tm)


def build_map(
    log_path: str | Path, traj_path: str | Path, outdir: str | Path, cfg: Config, opts: MapOptions
) -> dict[str, Any]:
    """Run the map stage; returns the JSON summary (:class:`MapSummary` as JSON, also
    written as summary.json).

    Parameters
    ----------
    log_path : path
        The log.
    traj_path : path
        The TUM trajectory.
    outdir : path
        The map directory.
    cfg : Config
        The loaded config.
    opts : MapOptions
        The command's choices.

    Returns
    -------
    dict
        The JSON summary.
    """
    wall0 = time.perf_counter()
    params: MapParams = cfg.fgm
    outdir = Path(outdir)
    check_outputs([log_path, traj_path], [outdir])
    owns = ("fgm.png", "conflict.png", "hough.png", "calibration.yaml")
    staged = OutputDir(outdir, owns=owns)
    staged.check()  # an unusable output said now, not after the work (as run's)
    run_dir = Path(traj_path).resolve().parent
    if outdir.resolve() == run_dir and (run_dir / "summary.json").is_file():
        raise InputError(
            outdir,
            "output directory is the trajectory's run directory; the map would replace "
            "its summary.json and calibration.yaml: choose another directory",
        )
    reader = LogReader(log_path)
    t_traj, p_traj, tum_dropped = read_tum(traj_path, sort=opts.sort, report=True)
    t_end, how = freeze_time(reader, cfg, opts)
    sensor = open_ranges(reader, cfg, opts.ranges, base=base_frame(reader, cfg))
    if opts.config is not None:  # the log and its range sensor found (an error: one line)
        chosen_note(log_path, opts.config)
    what = "laser scans" if sensor.kind == "scan" else "sonar rings"
    times, ranges, rmax, fov, mounts, stats, offsets = read_rings_compact(
        reader, cfg, t_end, sensor=sensor
    )
    ok = covered(times, t_traj, params.max_pose_gap)
    skipped_readings = int(np.isfinite(ranges[~ok]).sum())
    if not ok.all():
        gaps = _gaps(times, ok)
        desc = ", ".join(f"{a:.2f}-{b:.2f} s" for a, b in gaps[:3])
        if not opts.skip_uncovered:
            raise InputError(
                traj_path,
                f"trajectory ({t_traj[0]:.2f}-{t_traj[-1]:.2f} s) does not cover {what} "
                f"at {desc}{' ...' if len(gaps) > 3 else ''} ({int((~ok).sum())} rings); "
                "pass --skip-uncovered to skip them",
            )
        if ok.sum() == 0:
            raise InputError(traj_path, f"trajectory covers none of the {what} ({desc})")
    if not ok.all():
        times, ranges, rmax, offsets = times[ok], ranges[ok], rmax[ok], offsets[ok]
        if mounts.ndim == 3:
            mounts = mounts[ok]
    poses = interpolate_poses(t_traj, p_traj, times, outside="hold")

    def placed(sl: slice) -> np.ndarray:
        """The mounts of rings ``sl``: deskewed when a run deskews them (each reading at
        its stamp, slam/deskew.py), a batch at a time (memory: a long laser log's)."""
        m = mounts if mounts.ndim == 2 else mounts[sl]
        if not sensor.stamped_apart:
            return m
        return deskewed_mounts(m, offsets[sl].astype(float), times[sl], t_traj, p_traj)

    try:
        builder = FgmBuilder.for_path(poses[:, :2], params)
    except ValueError as exc:  # a path too long for a map (or not finite)
        raise InputError(traj_path, str(exc)) from None
    t_build = time.perf_counter()
    batch = 64
    with Progress(len(times), f"map: fusing {what}") as bar:
        for k in range(0, len(times), batch):  # batches of rings, in time order
            sl = slice(k, k + batch)
            r, m = ranges[sl].astype(float), rmax[sl].astype(float)  # exact (float32)
            builder.add_rings(poses[sl], r, m, fov, placed(sl))
            bar.update_to(min(k + batch, len(times)))
    build_s = time.perf_counter() - t_build
    fgm = builder.freeze(t_end)
    touched = int((fgm.m_t < 1.0).sum())
    if touched == 0:  # an empty map: no references, nothing to localise against
        why = (
            f"{stats.extra.get('bad_scans', 0)} scans refused"
            if sensor.kind == "scan"
            else f"{stats.bad_fov} with no valid field of view"
        )
        raise InputError(
            log_path,
            f"no map written: the {len(times)} {what} put evidence in no map cell "
            f"({stats.readings} readings: {stats.invalid} invalid, {stats.no_echo} no echo; "
            f"{why})",
        )
    invalid = invalid_ranges(stats, sensor)  # a driver's 0.0 read as invalid, ...
    if invalid is not None:  # (a map refused above says its counts in its one line)
        note(invalid_note(invalid))
    refs = extract_references(fgm, poses[:, :2], params)
    world = read_world(reader)
    world_dict = world.to_dict() if world is not None else None
    log_id = mapio.log_identity(world_dict, reader.fingerprint())
    truth = reference_truth(refs, world)
    quality = None
    if world is not None:
        q = wall_quality(fgm, world.wall_array)
        quality = WallQuality(
            precision=q.precision,
            recall=q.recall,
            map_cells=q.map_cells,
            true_cells=q.true_cells,
        )
    # the odometry calibration of the trajectory's run at the freeze time (run --map starts
    # from it: slam/calibration.py), when that run had one
    calib_csv = opts.calibration or Path(traj_path).parent / "calibration.csv"
    calib = calibration_files.at_time(calib_csv, t_end)
    summary = MapSummary(
        log=path_text(log_path),
        config=opts.config if opts.config is not None else OMIT,
        trajectory=path_text(traj_path),
        output=path_text(outdir),
        log_id=log_id,
        cells=int(np.prod(fgm.grid.shape)),
        shape=list(fgm.grid.shape),
        origin=list(fgm.grid.origin),
        resolution=fgm.grid.resolution,
        rings_used=builder.rings,
        readings_used=builder.readings,
        readings_skipped=skipped_readings,
        rings_skipped=int((~ok).sum()),
        sonar_stats=stats.as_dict(),
        range_sensor=sensor.describe(),
        invalid_ranges=invalid if invalid is not None else OMIT,
        trajectory_repeats_dropped=tum_dropped,
        cell_updates=builder.cell_updates,
        cells_touched=touched,
        freeze_time=t_end,
        freeze_rule=how,
        references=[
            ReferenceEntry(
                id=r.id,
                name=r.name,
                angle_deg=float(np.rad2deg(r.angle)),
                strength=r.strength,
                ambiguous=r.ambiguous,
            )
            for r in refs
        ],
        reference_truth=truth,
        wall_quality=quality,
        build_seconds=build_s,
        log_damage=reader.damage(),
        calibration=calib if calib is not None else OMIT,
    )
    with staged as tmp:
        mapio.save_fgm(tmp / "fgm.npz", fgm, True, t_end, log_id)
        if calib is not None:
            calibration_files.write_yaml(tmp / "calibration.yaml", calib)
        mapio.save_nav2(tmp / "fgm.yaml", tmp / "fgm.pgm", fgm)
        mapio.save_references(tmp / "references.yaml", [r.to_dict() for r in refs])
        _write_viewer_log(tmp / "fgm.mcap", fgm, refs, float(reader.start), cfg)
        if opts.figures:
            from fuzzyslam.maps import figures

            k_flm = figures.pick_flm_ring(poses, refs)  # write_all picks the same
            m_flm = placed(slice(k_flm, k_flm + 1))  # its mounts: the sensor's, or its own
            figures.write_all(
                tmp,
                fgm,
                poses,
                refs,
                world,
                opts.landmarks,
                times,
                ranges.astype(float),
                rmax.astype(float),
                fov,
                m_flm[0] if m_flm.ndim == 3 else m_flm,
                params,
                log=str(log_path),
            )
        out = as_json(replace(summary, wall_seconds=time.perf_counter() - wall0))
        (tmp / "summary.json").write_text(
            json.dumps(out, indent=2, sort_keys=True) + "\n", encoding="utf-8"
        )
    return out
