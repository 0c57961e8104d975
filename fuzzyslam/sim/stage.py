"""The ``simulate`` stage: a config in, one MCAP recording (and optionally its preview
and true trajectory) out, atomically."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

from fuzzyslam.config import DEFAULT_CONFIG, load_config
from fuzzyslam.errors import InputError
from fuzzyslam.fileio import atomic_paths, check_outputs


def run(
    config: str | None,
    output: str | os.PathLike,
    seed: int | None = None,
    preview: str | None = None,
    truth_tum: str | None = None,
) -> dict[str, Any]:
    """Simulate ``config`` (a YAML path or an embedded name; default paper.yaml) with
    ``seed`` into the MCAP file ``output``; ``preview`` (PNG) and ``truth_tum`` (the true
    trajectory as TUM) are written too when given, every file complete before any is
    renamed into place (``fileio.atomic_paths``). Returns the JSON summary.

    Parameters
    ----------
    config : str or None
        A YAML path or an embedded name.
    output : path
        The MCAP file.
    seed : int or None
        Overrides the config's.
    preview : str or None
        A PNG of the world and the paths.
    truth_tum : str or None
        The true trajectory as TUM.

    Returns
    -------
    dict
        The JSON summary.
    """
    from fuzzyslam.sim.record import simulate_to_mcap

    cfg_name = config if config is not None else DEFAULT_CONFIG
    inputs = [cfg_name] if Path(cfg_name).is_file() else []
    extras = [p for p in (preview, truth_tum) if p]
    check_outputs(inputs, [output, *extras], kind="file")
    if len({Path(p).resolve() for p in [output, *extras]}) != 1 + len(extras):
        raise InputError(
            extras[0], "the recording, --preview and --truth-tum must be different files"
        )
    cfg = load_config(cfg_name, seed)
    if not extras:
        summary, _ = simulate_to_mcap(cfg, output, source=cfg_name)
        return summary
    from fuzzyslam.sim.preview import save_preview
    from fuzzyslam.sim.record import write_truth_tum

    # every file complete before any is renamed into place: never a new log beside an
    # old preview or truth, nor a new preview beside an old log
    with atomic_paths([output, *extras]) as staged:
        summary, plan = simulate_to_mcap(cfg, staged[0], source=cfg_name)
        named = dict(zip(extras, staged[1:], strict=True))
        if preview:
            save_preview(plan, named[preview], title=f"{cfg.name}, seed {cfg.seed}")
        if truth_tum:
            write_truth_tum(plan, named[truth_tum])
    summary["file"] = str(Path(output))
    if preview:
        summary["preview"] = preview
    if truth_tum:
        summary["truth_tum"] = truth_tum
    return summary
