"""The ``run`` stage: open a log, run EKF-SLAM over it, write the outputs atomically.

:func:`run` is the stage's entry (the ``run`` command's arguments); :func:`run_stage`
the same on a loaded config and built aids."""

from __future__ import annotations

import contextlib
import copy
import importlib
import itertools
import os
import time
from collections.abc import Iterator
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from fuzzyslam.config import Config
from fuzzyslam.errors import InputError
from fuzzyslam.fileio import OutputDir, check_outputs
from fuzzyslam.forked import ChildCalls
from fuzzyslam.presets import ConfigChoice, chosen_note, unread_streams
from fuzzyslam.presets import resolve as resolve_config
from fuzzyslam.progress import Progress, note
from fuzzyslam.rundir import OPTIONAL_OUTPUTS, RUN_OUTPUTS
from fuzzyslam.slam import calibration as cal
from fuzzyslam.slam import calibration_files
from fuzzyslam.slam.events import Event
from fuzzyslam.slam.health import WINDOW_REASONS
from fuzzyslam.slam.inputs import LogInputs, open_inputs
from fuzzyslam.slam.latency import MotionTap, delay_note
from fuzzyslam.slam.log_setup import slow_odometry_note
from fuzzyslam.slam.noise import DetectionNoiseEstimate, corroborated, suggestion
from fuzzyslam.slam.outputs import StreamingOutputs, write_outputs, write_summary
from fuzzyslam.slam.prefetch import input_events
from fuzzyslam.slam.prefetch import wanted as prefetch_wanted
from fuzzyslam.slam.run_results import (
    FilterHealth,
    filter_health,
    lost_events,
    reason_causes,
    with_finding,
)
from fuzzyslam.slam.runner import SlamResult, SlamRunner
from fuzzyslam.slam.summary import RunSummary
from fuzzyslam.slam.turn_check import (
    distance_note,
    distance_ratio,
    rotation_factor,
    translation_factor,
    turn_note,
    turn_ratio,
)
from fuzzyslam.streams.ranges import invalid_note, invalid_ranges
from fuzzyslam.summary import OMIT, as_json

TWIST = ("", " twist")  # an Odometry whose twist alone is read (LogInputs.odom_twist)


def make_summary(
    res: SlamResult,
    inputs,
    wall: float,
    aids: list,
    streamed: StreamingOutputs,
    config: dict[str, str] = OMIT,
) -> RunSummary:
    """The run's summary (stdout and summary.json); row statistics from ``streamed``.

    Parameters
    ----------
    res : SlamResult
        The filter's result (slam/runner.py), with its health and calibration.
    inputs : slam.inputs.Inputs
        The opened log (sources, start pose, warnings, damage, ring statistics).
    wall : float
        Wall-clock seconds of the run.
    aids : list
        The fix plug-ins (their ``summary()`` under ``aids``).
    streamed : StreamingOutputs
        The written rows (trajectory rows, the lamps' mean NIS).
    config : dict, optional
        The summary's ``config`` (``fuzzyslam.presets.ConfigChoice.as_dict``).

    Returns
    -------
    RunSummary
    """
    duration = max(inputs.end - inputs.start, 0.0)
    est = res.noise_estimate
    return RunSummary(
        log=str(inputs.reader.path),
        config=config,
        odometry_source=_odometry_source(inputs),
        lamp_source=f"{inputs.lamp_source} ({inputs.lamp_topic})",
        start_pose=[float(v) for v in inputs.start_pose],
        log_duration_s=round(duration, 3),
        counts=res.counts,
        filter_health=res.health,
        lamps=len(res.lamps),
        duplicates_guarded=res.counts.duplicates_guarded,
        mean_nis_lamp=streamed.lamp_nis.mean(),
        final_pose=[float(v) for v in res.poses[-1]] if len(res.poses) else None,
        final_pose_sigma=(
            [float(np.sqrt(res.cov[-1][k])) for k in (0, 3, 5)] if len(res.cov) else None
        ),
        trajectory_rows=streamed.rows,
        warnings=dict(sorted(inputs.warnings.items())),
        truncated_log=inputs.reader.damage()["truncated"],
        log_damage=inputs.reader.damage(),
        wall_time_s=round(wall, 3),
        real_time_factor=round(duration / wall, 1) if wall > 0 else None,
        first_warning=inputs.first_problem or OMIT,
        noise_estimate=(
            (est.as_dict() if est is not None else None)
            if inputs.lamp_source == "detections"
            else OMIT
        ),
        odometry_delay_estimate=(
            (res.delay_estimate.as_dict() if res.delay_estimate is not None else None)
            if inputs.lamp_source == "detections"
            else OMIT
        ),
        calibration=res.calibration if res.calibration is not None else OMIT,
        odometry_turn_check=res.turn_check.as_dict() if res.turn_check is not None else None,
        odometry_distance_check=(
            res.distance_check.as_dict() if res.distance_check is not None else None
        ),
        aids={type(a).__name__: a.summary() for a in aids} if aids else OMIT,
        rings=inputs.ring_stats.as_dict() if aids else OMIT,
        range_sensor=(inputs.ranges.describe() if aids and inputs.ranges is not None else OMIT),
        invalid_ranges=_invalid_ranges(inputs) if aids else OMIT,
    )


def _invalid_ranges(inputs: LogInputs) -> dict[str, Any]:
    """The summary's ``invalid_ranges``: the range sensor's invalid readings by cause,
    when more than a third of them were (:func:`fuzzyslam.streams.ranges.invalid_ranges`),
    else OMIT."""
    found = None
    if inputs.ranges is not None:
        found = invalid_ranges(inputs.ring_stats, inputs.ranges)
    return found if found is not None else OMIT


def run(
    log: str | os.PathLike,
    outdir: str | os.PathLike,
    config: str | None = None,
    seed: int | None = None,
    map_dir: str | os.PathLike | None = None,
    fix: str | None = None,
    fix_from: float | None = None,
    ranges: str | None = None,
    start_pose: tuple[float, float, float] | None = None,
    adapt_noise: bool = False,
    calibration: str | os.PathLike | None = None,
    prefetch: bool = False,
    figures: ChildCalls | None = None,
    live_map: bool = False,
) -> dict:
    """The ``run`` stage on ``log`` into ``outdir``: the config ``config`` (a YAML path or
    an embedded name; default the map's, else the preset of the log's streams:
    fuzzyslam/presets.py) with ``seed``; with ``map_dir``, the fixes
    ``fix`` (heading|pose|none; default the config's ``fixes.mode``) from ``fix_from``
    (``fixes.aids.aids_for_log``, the plug-ins loaded on demand); ``calibration``: a
    run's calibration.yaml to start the odometry self-calibration from (default with a
    map and ``slam.calibrate``: the map's, its calibration at the freeze time);
    ``prefetch``: the log's events made in a child process on a second core where
    ``slam.prefetch.wanted`` allows it (``fuzzyslam run``'s default; off for reproduce's
    steps); ``figures``: a figure process the caller started (``cli/run.py`` forks it
    before its imports), drawing the aids' figures if they draw, else closed at once;
    ``live_map``: pose fixes against a map built while localising (grid SLAM,
    ``fixes/live_map.py``) instead of a frozen one.
    Returns the JSON summary (:class:`RunSummary` as JSON); UsageError for options that
    do not go together.

    Parameters
    ----------
    log : path
        The MCAP log.
    outdir : path
        The output directory.
    config : str or None
        A YAML path or an embedded name.
    seed : int or None
        Overrides the config's.
    map_dir : path or None
        ``--map``.
    fix : str or None
        ``--fix``.
    fix_from : float, LogTime or None
        ``--fix-from`` (a plain number: the log's own stamp).
    ranges : str or None
        ``--ranges`` (sonar|scan).
    start_pose : (float, float, float) or None
        ``--start-pose``.
    adapt_noise : bool
        ``--adapt-noise``.
    calibration : path or None
        ``--calibration``.
    prefetch : bool
        ``--prefetch`` / ``--no-prefetch``.
    figures : ChildCalls or None
        A started figure process (``fuzzyslam.forked.ChildCalls``; the caller reaps it).
    live_map : bool
        ``--live-map``.

    Returns
    -------
    dict
        The JSON summary.
    """
    from fuzzyslam.config import load_config
    from fuzzyslam.errors import UsageError

    if fix_from is not None and map_dir is None:  # it would be ignored
        raise UsageError("--fix-from needs --map FGMDIR (a frozen map from 'map')")
    choice = resolve_config(config, log, map_dir, ranges)
    cfg = load_config(choice.source, seed)
    if map_dir is not None:  # the map's directory is an input: a run never writes into it
        check_outputs([map_dir], [outdir])
    if calibration is not None and Path(outdir).is_dir():  # refused now, not after the run
        check_outputs([calibration], [Path(outdir) / n for n in RUN_OUTPUTS])
    if map_dir is None and fix in (None, "none") and not live_map:
        aids = []  # lamps only (aids_for_log's answer), the plug-ins not even imported
    else:
        from fuzzyslam.fixes.aids import aids_for_log  # the plug-ins (fixes/) sit above slam/

        aids = aids_for_log(
            Path(map_dir) if map_dir is not None else None, fix, cfg, log, fix_from, live_map
        )
    if adapt_noise and aids:
        raise UsageError("--adapt-noise cannot be combined with heading or pose fixes")
    if calibration is None and map_dir is not None and cfg.slam.calibrate:
        found = Path(map_dir) / "calibration.yaml"  # maps/build.py: at the freeze time
        calibration = found if found.is_file() else None
    return run_stage(
        log,
        outdir,
        cfg,
        aids,
        adapt_noise=adapt_noise,
        ranges=ranges,
        start_pose=start_pose,
        calibration=calibration,
        prefetch=prefetch_wanted(prefetch),
        figures=figures,
        choice=choice,
    )


def run_stage(
    log: str | os.PathLike,
    outdir: str | os.PathLike,
    cfg: Config,
    aids: list | None = None,
    adapt_noise: bool = False,
    ranges: str | None = None,
    start_pose: tuple[float, float, float] | None = None,
    calibration: str | os.PathLike | None = None,
    prefetch: bool = False,
    figures: ChildCalls | None = None,
    choice: ConfigChoice | None = None,
) -> dict[str, Any]:
    """Run EKF-SLAM on ``log`` and write docs/contracts.md sec. 2 files into ``outdir``.

    The rows are streamed into the staging directory of ``OutputDir`` as they come
    (:class:`StreamingOutputs`: memory flat in the log length); the directory replaces
    the outputs only when everything is written, so an error or Ctrl-C leaves nothing.

    ``adapt_noise``: a first pass estimates the detection noise from the innovations
    (``slam.noise``); the outputs come from a second pass with that noise (the summary's
    ``noise_adapted`` gives it). Without it, a configured noise that the innovations
    contradict is told on stderr in one line (which keys to change, to what).

    ``ranges`` (sonar|scan) chooses the aids' range sensor, ``start_pose`` overrides the
    start pose (slam/inputs.py). ``calibration``: a calibration.yaml whose factors and
    covariance start the odometry self-calibration (slam/calibration.py; implies it).
    A log without lamps and without aids is dead reckoning: a one-line note on stderr
    says so. ``prefetch``: the events are made in a forked child process
    (slam/prefetch.py; the outputs are the same, byte for byte).

    Parameters
    ----------
    log : path
        The MCAP log.
    outdir : path
        The output directory.
    cfg : Config
        The loaded config.
    aids : list of FixAid, optional
        The fix plug-ins.
    adapt_noise : bool
        Two passes, the second with the estimated detection noise.
    ranges : str or None
        The aids' range sensor.
    start_pose : (float, float, float) or None
        Overrides the log's start pose.
    calibration : path or None
        A calibration.yaml to start from.
    prefetch : bool
        Make the events in a child process (as decided: ``prefetch.wanted``).
    figures : ChildCalls or None
        A started figure process for the aids' figures (the caller reaps it); None: one
        is forked here when an aid draws and ``prefetch``.
    choice : ConfigChoice or None
        Where ``cfg`` came from (:func:`fuzzyslam.presets.resolve`; the summary's
        ``config``); None: given as it is.

    Returns
    -------
    dict
        The JSON summary (:class:`RunSummary` as JSON).
    """
    if adapt_noise:
        if aids:
            raise ValueError("adapt_noise: the aids of a first pass cannot be reused")
        first = _run_once(
            log, outdir, cfg, [], True, ranges, start_pose, calibration, prefetch, choice=choice
        )
        est = first.noise_estimate or None
        if est:
            cfg = copy.deepcopy(cfg)
            for key in (
                "detection_sigma_range",
                "detection_sigma_range_per_m",
                "detection_sigma_bearing_deg",
            ):
                if est[key] is not None:  # None: not measurable (slam.noise)
                    setattr(cfg.slam, key, float(est[key]))
        # the second pass says what it finds in the log (once), its summary told below
        summary = _run_once(
            log, outdir, cfg, [], False, ranges, start_pose, calibration, prefetch,
            tell=False, choice=choice,
        )  # fmt: skip
        summary = replace(summary, noise_adapted=est)
        _tell(summary)
        return as_json(summary)
    once = _run_once(
        log, outdir, cfg, aids, False, ranges, start_pose, calibration, prefetch,
        figures=figures, choice=choice,
    )  # fmt: skip
    return as_json(once)


def _no_odometry(inputs: LogInputs) -> str:
    """Why a log gave no usable odometry increment, in one line: its glitch counts and,
    when every increment was faster than the robot can move, what to check (encoder
    angles in ticks or degrees rather than radians, the robot's wheel radius and base)."""
    rejected = inputs.warnings.get("implausible_odometry", 0)
    line = f"no usable odometry on {inputs.odom_topic}"
    if rejected:
        hint = (
            "are the wheel angles in radians and robot.wheel_radius, wheel_base right?"
            if inputs.odom_source == "encoders"
            else "robot.max_speed and max_turn_rate bound them"
        )
        line += (
            f": all {rejected} increments faster than the robot can move "
            f"(warnings.implausible_odometry; {hint})"
        )
    elif inputs.first_problem:
        line += f" ({inputs.first_problem})"
    return line


def unchecked_delay_note(lamp_source: str, aids: bool, delay: float) -> str:
    """One line when a non-zero ``slam.odometry_delay_s`` is configured and nothing in
    the log checks it: the delay estimate (``odometry_delay_estimate``, slam/latency.py)
    is made from PoseArray detections only, so a log whose lamps come as camera frames,
    or that has none but fixes from a map, runs on the configured delay unchecked (the
    sample's camera frames with the real_detections preset's 0.2 s: APE 0.77 m against
    0.16 m with 0 s, nothing said).

    Parameters
    ----------
    lamp_source : str
        ``LogInputs.lamp_source``: detections, frames or none.
    aids : bool
        Whether fix plug-ins run (with no lamps and no aids the delay moves nothing).
    delay : float
        ``slam.odometry_delay_s`` (s).

    Returns
    -------
    str
        The line, or ''.
    """
    if not delay > 0 or lamp_source == "detections" or (lamp_source == "none" and not aids):
        return ""
    what = "camera frames" if lamp_source == "frames" else "range rings, no lamp detections"
    return (
        f"slam.odometry_delay_s is {delay:g} s and this log's lamps come as {what}: "
        "nothing here measures the delay (odometry_delay_estimate needs PoseArray "
        "detections); a wrong one misplaces every detection made while turning: check "
        "it (0 if the odometry is stamped when the wheels move)"
    )


def _odometry_source(inputs: LogInputs) -> str:
    """The summary's ``odometry_source``: the kind, its topic, and for /tf its frames
    (``tf (/tf odom -> base_link)``)."""
    pair = f" {inputs.odom_pair[0]} -> {inputs.odom_pair[1]}" if inputs.odom_pair else ""
    return f"{inputs.odom_source}{TWIST[inputs.odom_twist]} ({inputs.odom_topic}{pair})"


def start_time(events: Iterator[Event], t0: float) -> tuple[Iterator[Event], float]:
    """The time of the run's start pose: the first log time of the streams it reads
    (``LogInputs.start``) put on the stamps' clock (``LogInputs.clock_offset``: a log
    whose stamps start at 0 while it was logged in Unix time), or the first event's stamp
    when that is earlier (a sensor stamps its messages before the recorder logs them),
    so that no trajectory row comes before the start row.

    Parameters
    ----------
    events : iterator of Event
        The run's events, in time order.
    t0 : float
        The streams' first log time on the stamps' clock (s).

    Returns
    -------
    (iterator of Event, float)
        The same events (the first one read put back) and the start time (s).
    """
    first = next(events, None)
    if first is None:
        return iter(()), t0
    return itertools.chain([first], events), min(t0, first.t)


def _trouble_line(health: FilterHealth) -> str:
    """The flagged line's text: since when the filter looks in trouble, why, and, where
    windows were out of bounds, over which spans, in seconds into the log.

    A window test decides from the windows seen so far (``nis_rate``: more windows out
    of bounds than chance allows), so ``diverged_at`` is when it decided, possibly long
    after the first window out of bounds: a run flagged by window tests alone is said
    to be in trouble from its first span's start, with the spans listed (at most the
    summary's five) and the decision's time.

    Parameters
    ----------
    health : FilterHealth
        The run's filter_health (flagged).

    Returns
    -------
    str
    """
    after = health.diverged_after_start_s
    when, windows = f"t = {health.diverged_at:.3f} s", ""
    if isinstance(after, float):  # the log's start known: seconds into the log
        start = float(health.diverged_at) - after
        spans = [(a - start, b - start) for a, b in health.out_of_bounds_spans]
        since, found = after, ""
        if spans and set(health.reasons) <= WINDOW_REASONS:
            since, found = min(a for a, _ in spans), f", found at {after:.1f} s"
        when = f"{since:.1f} s into the log"
        if spans:
            listed = ", ".join(f"{a:.1f}-{b:.1f}" for a, b in spans)
            windows = f"; windows out of bounds {listed} s into the log{found}"
    causes = reason_causes(health.reasons) or "NIS or association windows"
    return (
        f"filter_health: the filter looks inconsistent or lost from {when} ({causes}"
        f"{windows}; see the summary's filter_health): do not trust this estimate"
    )


def _tell(summary: RunSummary, cfg: Config | None = None) -> None:
    """The one-line notes on stderr: the filter in trouble, the noise to change."""
    health = summary.filter_health
    if health.diverged:
        note(_trouble_line(health))
    if summary.invalid_ranges is not OMIT:  # the log's, not the filter's (a driver's 0.0)
        note(invalid_note(summary.invalid_ranges))
    turns = summary.odometry_turn_check
    encoders = cfg is not None and summary.odometry_source.startswith("encoders")
    if turns and turns["flagged"]:
        note(turn_note(turns, cfg.robot.wheel_base if encoders else None))
    moves = summary.odometry_distance_check
    if moves and moves["flagged"]:
        note(distance_note(moves, cfg.robot.wheel_radius if encoders else None))
    stale = summary.counts.frames_stale_odometry
    if stale:  # the driver stopped (or paused): say which stream, not only that frames were lost
        limit = f" over slam.odometry_stale_s = {cfg.slam.odometry_stale_s:g} s" if cfg else ""
        note(
            f"odometry {summary.odometry_source} fell silent{limit} while the log went on: "
            f"{stale} frames skipped, the estimate held still meanwhile (its driver stopped? "
            "the summary's counts.frames_stale_odometry)"
        )
    delay = summary.odometry_delay_estimate
    if cfg is not None and delay:
        line = delay_note(
            delay["delay_s"],
            cfg.slam.odometry_delay_s,
            delay["residual_drop_z"] if delay["residual_drop_z"] is not None else 0.0,
            delay["at_search_edge"],
        )
        if line:
            note(line)
    est = summary.noise_estimate
    if cfg is not None and est:
        line = suggestion(
            DetectionNoiseEstimate(
                est["samples"],
                est["detection_sigma_range"],
                est["detection_sigma_range_per_m"],
                est["detection_sigma_bearing_deg"],
            ),
            cfg.slam,
            corroborated=corroborated(health),
        )
        if line:
            note(line)


def _run_once(
    log: str | os.PathLike,
    outdir: str | os.PathLike,
    cfg: Config,
    aids: list,
    _quiet: bool,
    ranges: str | None = None,
    start_pose: tuple[float, float, float] | None = None,
    calibration: str | os.PathLike | None = None,
    prefetch: bool = False,
    tell: bool = True,
    figures: ChildCalls | None = None,
    choice: ConfigChoice | None = None,
) -> RunSummary:
    """One run of the filter over the log into ``outdir``; ``_quiet``: no notes on
    stderr (a first pass), ``tell``: the summary's own notes after it (``_tell``);
    ``choice``: the config's source and why (the summary's ``config``);
    ``figures``: a figure process the caller started (:func:`run`)."""
    aids = list(aids or [])
    wall0 = time.perf_counter()
    check_outputs([log], [outdir])
    inputs = open_inputs(log, cfg, bool(aids), ranges, start_pose)
    if not _quiet:
        if choice is not None:  # once the log is known to open (an error: one line)
            chosen_note(log, choice.as_dict(cfg.name))
        for line in inputs.notes:  # said once, also when the log is opened twice
            note(line)
    if inputs.lamp_source == "none" and not aids and not _quiet:
        unread = unread_streams(inputs.reader.topics, cfg.topics)
        note(
            f"{log}: no lamps (topics.image {cfg.topics.image}, "
            f"topics.detections {cfg.topics.detections}) and no map: the estimate is dead "
            "reckoning (give --map FGMDIR --fix pose|heading, or --live-map to build a map "
            "from the range sensor while localising on it"
            + (f"; not read: {'; '.join(unread)}" if unread else "")
            + ")"
        )
    slow = slow_odometry_note(inputs.odom_topic, inputs.odom_period_s)
    if slow and not _quiet:
        note(f"{log}: {slow}")
    unchecked = unchecked_delay_note(inputs.lamp_source, bool(aids), cfg.slam.odometry_delay_s)
    if unchecked and not _quiet:
        note(f"{log}: {unchecked}")
    model = calibration_model(inputs, cfg, calibration)
    staged = OutputDir(outdir, owns=OPTIONAL_OUTPUTS)
    # the aids' figures drawn in a child that imports matplotlib while the filter runs
    # (fuzzyslam/forked.py), where the events come from a child too (a second core): the
    # caller's, started before its imports, or one forked now; the modules that draw
    # imported there meanwhile
    drawing = [a for a in aids if getattr(a, "draws_figures", False)]
    if not drawing and figures is not None:
        figures.close()  # started early, nothing to draw
        figures = None
    elif drawing and figures is None and prefetch:
        figures = ChildCalls()
    with (
        staged as tmp,
        figures or contextlib.nullcontext() as drawer,  # reaped before the directory goes
        StreamingOutputs(tmp, cfg, inputs.start_pose, inputs.frames) as streamed,
    ):
        if drawer is not None:
            drawer.preload(*sorted({type(a).__module__ for a in drawing}))
        if aids:  # the map the fixes use first in estimates.mcap, at the log's start
            from fuzzyslam.fixes.viewer import map_messages

            t_map = inputs.start + inputs.clock_offset
            for aid in aids:
                shown = getattr(aid, "viewer_map", None)
                streamed.write_messages(map_messages(shown, cfg.topics, t_map))
        res = _run_filter(inputs, cfg, aids, streamed, model, prefetch)
        # the figures first: the figure process draws them while this one writes the
        # aids' files, their messages and the run's outputs (none of which they read)
        drawings = []
        for aid in aids:
            for fn, args in aid.figures(tmp) if hasattr(aid, "figures") else ():
                if drawer is not None:
                    drawings.append(drawer.submit(fn, *args))
                else:
                    fn(*args)
        for aid in aids:
            aid.write(tmp)
        extra = [  # the aids' own messages for estimates.mcap (their map is written)
            m for aid in aids if hasattr(aid, "messages") for m in aid.messages(cfg.topics, None)
        ]  # fmt: skip
        write_outputs(tmp, streamed, res, extra)
        # the odometry's turns and distances against the estimate's, from the rows
        # written: scales that the innovations hide (slam/turn_check.py), tested against
        # the factors the filter's odometry model implies (1, or the calibration's)
        calib = res.calibration
        names, factors = (calib.names, calib.factors) if calib is not None else ([], [])
        turns = turn_ratio(*streamed.headings().T, expected=rotation_factor(names, factors))
        moves = distance_ratio(*streamed.positions(), expected=translation_factor(names, factors))
        if turns is not None and calib is not None:
            turns = replace(turns, calibrated=True)
        if moves is not None:  # not judged against a dead reckoning bent by wrong turns
            moves = replace(moves, calibrated=calib is not None).judged(turns)
        res.turn_check, res.distance_check = turns, moves
        start = inputs.start + inputs.clock_offset
        for check, reason in (
            (res.turn_check, "odometry_turn_scale"),
            (res.distance_check, "odometry_distance_scale"),
        ):
            if check is not None and check.flagged:
                res.health = with_finding(res.health, reason, check.flagged_at, start)
        for drawing in drawings:
            drawing.result()
        config = (choice or ConfigChoice(cfg.name, "given")).as_dict(cfg.name)
        summary = make_summary(res, inputs, time.perf_counter() - wall0, aids, streamed, config)
        write_summary(tmp, as_json(summary))
    restarts = inputs.restart_line()  # found while reading the events
    if restarts and not _quiet:
        note(restarts)
    if tell and not _quiet:
        _tell(summary, cfg)
        for aid in aids:  # an aid's own word on the run (the pose aid's skipped rings)
            line = aid.run_note(inputs.lamp_source != "none") if hasattr(aid, "run_note") else ""
            if line:
                note(line)
    return summary


def calibration_model(inputs, cfg: Config, path) -> cal.Calibration | None:
    """The run's odometry calibration (slam/calibration.py): None when ``slam.calibrate``
    is off and no file is given; else the model of the log's odometry (``wheels`` for
    encoders, ``odom`` for Odometry poses) from the config's prior or from ``path``.

    Parameters
    ----------
    inputs : Inputs
        The opened log (its odometry source).
    cfg : Config
        The run's config (``slam.calibrate`` and the priors).
    path : path or None
        A calibration.yaml to start from.

    Returns
    -------
    Calibration or None
    """
    if not cfg.slam.calibrate and path is None:
        return None
    kind = "wheels" if inputs.odom_source == "encoders" else "odom"
    model = cal.prior(kind, cfg.slam, cfg.robot.wheel_base)
    return model if path is None else calibration_files.load(path, model)


def _run_filter(
    inputs, cfg: Config, aids: list, sink: StreamingOutputs, model=None, prefetch: bool = False
) -> SlamResult:
    """The filter over the log's events (rows to ``sink``; made in a child process with
    ``prefetch``), its health, input checks; with ``model``, the calibration files into
    the sink's directory."""
    runner = SlamRunner(
        cfg.slam,
        inputs.start_pose,
        aids,
        inputs.mounts,
        cfg.slam.landmarks_period,
        sink,
        calibration=model,
        # only detections' summaries give the noise estimate (make_summary)
        estimate_noise=inputs.lamp_source == "detections",
    )
    # frames are tiny: OpenCV's thread pool only costs here (OpenCV is not even loaded
    # for logs whose lamps come as detections and that have no aids: 0.3 s of start-up)
    cv2 = importlib.import_module("cv2") if inputs.lamp_source == "frames" or aids else None
    threads = cv2.getNumThreads() if cv2 is not None else 0
    if cv2 is not None:
        cv2.setNumThreads(1)
    try:
        with Progress(max(inputs.end - inputs.start, 1e-6), "run: EKF-SLAM") as bar:
            t0 = inputs.start + inputs.clock_offset  # on the stamps' clock, as the events
            ring_start = min((a.start_time for a in aids), default=None)
            with input_events(inputs, bool(aids), ring_start, prefetch, aids) as events:
                events, t0 = start_time(events, t0)
                tap = MotionTap(events) if inputs.lamp_source == "detections" else None
                res = runner.run(
                    events if tap is None else iter(tap), lambda t: bar.update_to(t - t0), t0=t0
                )
    finally:
        if cv2 is not None:
            cv2.setNumThreads(threads)
    res.ekf.check_covariance()
    if model is not None:
        res.calibration = _write_calibration(runner, model, sink.tmp)
    res.noise_estimate = runner.noise.estimate() if runner.noise is not None else None
    if tap is not None:  # the odometry latency the bearings imply (slam/latency.py)
        res.delay_estimate = tap.estimate(cfg.slam.odometry_delay_s)
    # numerical guards, the divergence tests, orphan landmarks (slam/run_results.py)
    res.health = filter_health(
        res.ekf.guards,
        runner.health,
        inputs.gap_seconds,
        res.lamps,
        runner.map_motion,
        aids,
        lost_events(
            runner.late, res.counts, inputs.lost, inputs.ring_stats.readings, inputs.ring_stats
        ),
        start=inputs.start + inputs.clock_offset,  # diverged_after_start_s: for the notes
    )
    if inputs.lamp_source == "detections":
        res.counts = replace(
            res.counts,
            detections_own_covariance=inputs.own_covariances,
            detections_own_floored=inputs.own_floored,
        )
    if res.counts.odometry == 0:
        raise InputError(inputs.reader.path, _no_odometry(inputs))
    if inputs.lamp_source == "frames" and res.counts.frames == 0:
        problem = inputs.first_problem or "no frames"
        raise InputError(inputs.reader.path, f"no usable camera frame ({problem})")
    return res


def _write_calibration(runner: SlamRunner, model: cal.Calibration, outdir) -> cal.CalibrationEntry:
    """calibration.csv (the factors over time, a last row at the end) and calibration.yaml
    (the final factors and covariance: ``run --calibration`` reads it); the summary entry."""
    ekf = runner.ekf
    c, cov = ekf.calib, ekf.calib_cov
    t_end = runner.last_time
    rows = runner.calib_rows
    if not rows or float(rows[-1][0]) < t_end:
        rows.append(calibration_files.csv_row(t_end, c, cov))
    calibration_files.write_csv(Path(outdir) / "calibration.csv", model, rows)
    final = calibration_files.as_dict(model, t_end, c, cov)
    calibration_files.write_yaml(Path(outdir) / "calibration.yaml", final)
    prior = model.factors
    return cal.CalibrationEntry(
        model=model.kind,
        start=model.source,
        start_factors=[float(v) for v in prior],
        **{k: final[k] for k in ("names", "factors", "sigma")},
    )
