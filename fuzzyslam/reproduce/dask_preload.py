"""Dask worker preload: ``dask worker ADDRESS --preload fuzzyslam.reproduce.dask_preload``.

A Dask worker then imports every stage and what its steps import on demand once, when it
starts (:func:`fuzzyslam.reproduce.execute.preload`, what the local pool does before it
forks), instead of in the first step it runs: that step's time in ``results.json`` is then
the step's own, like the others'.
"""

from __future__ import annotations

import sys

from fuzzyslam.reproduce.execute import preload


def dask_setup(worker) -> None:
    """Dask's preload hook, called once in the worker's process as it starts.

    Parameters
    ----------
    worker : distributed.Worker
        The starting worker (unused: the imports are the process's).
    """
    preload()


def stages_loaded() -> bool:
    """Whether this process holds the stages' modules (a check for ``Client.run``: this
    module alone does not import them)."""
    return "fuzzyslam.slam.stage" in sys.modules
