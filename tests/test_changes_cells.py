"""Change detection computes the conflict only on the FLM cells that can exceed the
threshold: the same conflict there, and the same detections as from the whole image."""

from __future__ import annotations

import numpy as np

from fuzzyslam.fixes import changes
from fuzzyslam.maps.grid import BeliefMap, Grid


def _belief(grid: Grid, rng: np.random.Generator, occupied: float) -> BeliefMap:
    m = BeliefMap.vacuous(grid)
    o = np.where(rng.uniform(size=grid.shape) < occupied, rng.uniform(0, 1, grid.shape), 0)
    e = (1 - o) * rng.uniform(0, 1, grid.shape)
    m.m_o, m.m_e = o.astype(np.float32), e.astype(np.float32)
    m.m_t = (1 - m.m_o - m.m_e).astype(np.float32)
    return m


def _detect_on_whole_image(t, flm, pose, grid, free, min_conflict, min_cells, link):
    """detect_changes with the conflict computed on every cell (the reference)."""
    whole = changes.conflict_image(flm, pose, grid, free)
    real = changes.conflict_image
    try:
        changes.conflict_image = lambda *a, **k: whole
        return changes.detect_changes(t, flm, pose, grid, free, min_conflict, min_cells, link)
    finally:
        changes.conflict_image = real


def test_conflict_on_some_cells_is_the_whole_image_there():
    rng = np.random.default_rng(11)
    fgm = _belief(Grid((-6.0, -6.0), 0.1, (120, 130)), rng, 0.3)
    flm = _belief(Grid((-2.0, -2.0), 0.05, (80, 80)), rng, 0.2)
    free = changes.free_space(fgm, 1)
    pose = np.array([0.7, -0.4, 0.9])
    whole = changes.conflict_image(flm, pose, fgm.grid, free)
    cells = rng.choice(whole.size, 900, replace=False)
    part = changes.conflict_image(flm, pose, fgm.grid, free, cells)
    assert part.dtype == whole.dtype
    assert np.array_equal(part.ravel()[cells], whole.ravel()[cells])
    rest = np.setdiff1d(np.arange(whole.size), cells)
    assert not part.ravel()[rest].any()


def test_detections_equal_those_of_the_whole_conflict_image():
    rng = np.random.default_rng(12)
    fgm = _belief(Grid((-6.0, -6.0), 0.1, (120, 130)), rng, 0.2)
    fgm.m_e[30:90, 30:100] = 0.97  # a free hall: conflicts where the FLM sees walls
    fgm.m_o[30:90, 30:100] = 0.0
    free = changes.free_space(fgm, 1)
    found = 0
    for k in range(20):
        flm = _belief(Grid((-2.0, -2.0), 0.05, (80, 80)), rng, 0.05 + 0.01 * k)
        pose = np.array([rng.uniform(-1, 1), rng.uniform(-1, 1), rng.uniform(-3, 3)])
        for thr in (0.1, 0.15, 0.5):
            got = changes.detect_changes(1.0, flm, pose, fgm.grid, free, thr, 3, 1)
            ref = _detect_on_whole_image(1.0, flm, pose, fgm.grid, free, thr, 3, 1)
            assert got == ref
            found += len(got)
    assert found > 20  # detections were compared, not only empty lists
