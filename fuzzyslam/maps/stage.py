"""The ``map`` stage's entry: the command's arguments in, the map directory out
(:func:`fuzzyslam.maps.build.build_map` does the work)."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

from fuzzyslam.config import load_config
from fuzzyslam.errors import InputError, UsageError
from fuzzyslam.fileio import check_input_file
from fuzzyslam.maps.build import MapOptions, build_map
from fuzzyslam.presets import resolve as resolve_config
from fuzzyslam.rundir import read_landmarks
from fuzzyslam.stamps import LogTime


def run(
    log: str | os.PathLike,
    trajectory: str | os.PathLike,
    outdir: str | os.PathLike,
    config: str | None = None,
    until_run: int | None = None,
    until: float | LogTime | None = None,
    skip_uncovered: bool = False,
    landmarks: str | os.PathLike | None = None,
    figures: bool = True,
    ranges: str | None = None,
    sort: bool = False,
    calibration: str | os.PathLike | None = None,
) -> dict[str, Any]:
    """The FGM of ``log``'s range readings along ``trajectory`` (TUM) into ``outdir``, frozen
    at the end of run ``until_run`` or at the log time ``until`` (at most one; default the
    config's ``fgm.freeze_run``). Returns the JSON summary (also summary.json).

    Parameters
    ----------
    log : path
        The log.
    trajectory : path
        The TUM trajectory.
    outdir : path
        The map directory.
    config : str or None
        A YAML path or an embedded name.
    until_run : int or None
        ``--until-run``.
    until : float, LogTime or None
        ``--until``.
    skip_uncovered : bool
        ``--skip-uncovered``.
    landmarks : path or None
        ``--landmarks``.
    figures : bool
        Draw the PNGs.
    ranges : str or None
        ``--ranges``.
    sort : bool
        ``--sort``.
    calibration : path or None
        ``--calibration``: the trajectory's run's calibration.csv, whose factors at the
        freeze time go into calibration.yaml (default: the one beside the trajectory,
        when there).

    Returns
    -------
    dict
        The JSON summary (:class:`~fuzzyslam.maps.summary.MapSummary` as JSON).
    """
    if until is not None and until_run is not None:
        raise UsageError("give at most one of --until-run and --until")
    choice = resolve_config(config, log, None, ranges)
    cfg = load_config(choice.source)
    opts = MapOptions(
        until_run=until_run,
        until=until,
        skip_uncovered=skip_uncovered,
        landmarks=Path(landmarks) if landmarks else None,
        figures=figures,
        explicit_config=config is not None,
        ranges=ranges,
        sort=sort,
        calibration=Path(calibration) if calibration else None,
        config=choice.as_dict(cfg.name, outdir),
    )
    # the optional inputs checked before the work (a FIFO: not a regular file, at once)
    if opts.calibration is not None and not opts.calibration.exists():
        raise InputError(opts.calibration, "no such calibration file (--calibration)")
    if opts.calibration is not None:
        check_input_file(opts.calibration, "calibration file (--calibration)")
    if opts.landmarks is not None:
        check_input_file(opts.landmarks, "landmarks file (--landmarks)")
        read_landmarks(opts.landmarks)  # its content too (a TUM file: not lamps)
    return build_map(log, trajectory, outdir, cfg, opts)
