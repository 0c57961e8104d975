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


def _plain_flm(ranges, max_range, fov, mounts, params):
    """An FLM as built before the per-reading cache: ring_evidence of the whole ring."""
    from fuzzyslam.maps.evidence import ring_evidence
    from fuzzyslam.maps.flm import flm_grid
    from fuzzyslam.maps.grid import BeliefMap
    from fuzzyslam.maps.tbm import clip_masses

    grid = flm_grid(params)
    bm = BeliefMap.vacuous(grid)
    ev = ring_evidence(grid, np.zeros(3), ranges, max_range, fov, mounts, params)
    for arr, val in zip((bm.m_e, bm.m_o, bm.m_t, bm.m_c), clip_masses(ev.masses), strict=True):
        arr.ravel()[ev.cells] = val
    return bm


@pytest.mark.parametrize("fov_deg", [25.0, 7.5])
def test_flm_reading_cache_equals_ring_evidence(fov_deg):
    from fuzzyslam.maps import flm
    from fuzzyslam.maps.params import MapParams

    rng = np.random.default_rng(9)
    params = MapParams()
    a = np.linspace(0.0, 2 * np.pi, 16, endpoint=False)
    mounts = np.column_stack([0.2 * np.cos(a), 0.2 * np.sin(a), a])
    max_range = np.full(16, 5.0)
    fov = np.deg2rad(fov_deg)
    values = np.round(rng.uniform(0.15, 5.2, 40) / 0.0254) * 0.0254  # few, quantised
    values = np.concatenate([values, [5.0, np.nan, 0.0, 0.85, 0.9, 1.0]])
    rings = rng.choice(values, (120, 16))
    rings[7] = np.nan  # a ring without a reading
    for ranges in rings:
        new = flm.build_flm(ranges, max_range, fov, mounts, params)
        old = _plain_flm(ranges, max_range, fov, mounts, params)
        for m in ("m_e", "m_o", "m_t", "m_c"):
            assert np.array_equal(getattr(new, m), getattr(old, m))
    # the cache was used: fewer pieces than readings
    assert 0 < len(flm._READINGS.pieces) < np.isfinite(rings).sum() / 2
    # a ring that does not fit the mounts goes the plain way (the same error)
    with pytest.raises(ValueError):
        flm.build_flm(rings[0][:5], 5.0, fov, mounts, params)
