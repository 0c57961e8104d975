"""The ``evaluate`` stage's entry: the command's arguments in, the report directory out
(:func:`fuzzyslam.evaluation.evaluate.run_evaluate` does the work)."""

from __future__ import annotations

import os
from collections.abc import Sequence
from typing import Any

from fuzzyslam.config import load_config
from fuzzyslam.evaluation.evaluate import run_evaluate, summary


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
    """Evaluate ``estimate`` (a run directory or TUM file) against ``truth`` (a simulated
    log or a TUM file) into ``outdir`` with the config's ``evaluation`` section (the
    defaults without ``config``). Returns the headline figures (JSON summary)."""
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
