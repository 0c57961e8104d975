"""The ``evaluate`` stage's entry: the command's arguments in, the report directory out
(:func:`fuzzyslam.evaluation.evaluate.run_evaluate` does the work)."""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from fuzzyslam import rundir as R
from fuzzyslam.config import load_config
from fuzzyslam.evaluation.evaluate import run_evaluate, summary
from fuzzyslam.fileio import check_input_file, check_outputs


def run(
    truth: str | os.PathLike,
    estimate: str | os.PathLike,
    outdir: str | os.PathLike,
    config: str | None = None,
    map_dir: str | os.PathLike | None = None,
    label: str | None = None,
    compare: Sequence[str | os.PathLike] = (),
    landmarks_truth: str | os.PathLike | None = None,
    align: bool = False,
) -> dict[str, Any]:
    """Evaluate ``estimate`` (a run directory or TUM file) against ``truth`` (a log with
    ground truth, simulated or real, or a TUM file) into ``outdir`` with the config's
    ``evaluation`` section (the defaults without ``config``). Returns the headline figures
    (JSON summary).

    Checked first: ``outdir`` is not the map's directory (an input, as for ``run``), and
    a run directory's trajectory.tum that exists is a regular file (a FIFO is "not a
    regular file", not a directory without one)."""
    if map_dir is not None:  # the map's directory is an input: never written into
        check_outputs([map_dir], [outdir])
    for est in [estimate, *(R.split_label(c)[1] for c in compare)]:
        traj = Path(est) / R.TRAJECTORY
        if Path(est).is_dir() and (traj.exists() or traj.is_symlink()):
            check_input_file(traj, "trajectory")
    params = load_config(config).evaluation if config else None
    res = run_evaluate(
        truth,
        estimate,
        outdir,
        params=params,
        map_dir=map_dir,
        label=label,
        compare=compare,
        landmarks_truth=landmarks_truth,
        align=align,
    )
    return summary(res)
