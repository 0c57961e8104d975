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


@pytest.mark.slow
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
        for box in (
            (slice(3, 17), slice(0, 40)),
            (slice(0, 1), slice(5, 6)),
            (slice(9, 9), slice(2, 8)),
        ):
            bx, by = g.box_centres(box)  # the references' Hough reads boxes of a big map
            assert np.array_equal(bx, x[box]) and np.array_equal(by, y[box])


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
    from fuzzyslam.maps.tangent import readings_in_frame

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
        # the echoes from the composed mounts: readings_in_frame's, bit for bit
        echoes = readings_in_frame(np.zeros((1, 3)), ranges[None], max_range, fov, mounts)
        assert np.array_equal(new.readings.sensors, echoes.sensors)
        assert np.array_equal(new.readings.ranges, echoes.ranges)
        assert new.readings.half_angle == echoes.half_angle
    # the cache was used: fewer pieces than readings
    assert 0 < len(flm._READINGS.pieces) < np.isfinite(rings).sum() / 2
    # a ring that does not fit the mounts goes the plain way (the same error)
    with pytest.raises(ValueError):
        flm.build_flm(rings[0][:5], 5.0, fov, mounts, params)


def _plain_fit_walls(rd, psi0, sigma_frac, quantum, tolerance, delta_max, walls, iterations):
    """The tangent fit written wall by wall (one prediction per wall, readings assigned
    in the walls' order, the Jacobian's columns filled per wall): the fit before its
    walls were predicted together."""
    from fuzzyslam.maps.tangent import TangentFit, predict_ranges
    from fuzzyslam.se2 import wrap_angle

    def offset(psi):
        n = np.array([np.cos(psi), np.sin(psi)])
        delta = np.maximum(np.abs(wrap_angle(psi - rd.sensors[:, 2])) - rd.half_angle, 0.0)
        ok = delta < delta_max
        if not ok.any():
            return float("nan")
        ci = rd.sensors[ok, :2] @ n + rd.ranges[ok] * np.cos(delta[ok])
        ci = ci[ci > 0]
        if ci.size == 0:
            return float("nan")
        support = (np.abs(ci[:, None] - ci[None, :]) < tolerance).sum(axis=1)
        return float(ci[support == support.max()].min())

    psi = float(psi0)
    cs = np.array([offset(psi + w) for w in walls])
    n = len(rd)
    sig = np.hypot(sigma_frac * rd.ranges, quantum / np.sqrt(12.0))
    assign = np.full(n, -1)
    normal = None
    for _ in range(iterations):
        active = np.flatnonzero(np.isfinite(cs))
        if active.size == 0:
            break
        best, assign = np.full(n, np.inf), np.full(n, -1)
        j_psi, j_c, resid = np.zeros(n), np.zeros(n), np.zeros(n)
        for j in active:
            r, dpsi, dc, delta, p = predict_ranges(psi + walls[j], cs[j], rd.sensors, rd.half_angle)
            e = rd.ranges - r
            take = (delta < delta_max) & (p > 0) & (np.abs(e) < tolerance) & (np.abs(e) < best)
            best[take], assign[take] = np.abs(e)[take], j
            j_psi[take], j_c[take], resid[take] = dpsi[take], dc[take], e[take]
        sel = assign >= 0
        if sel.sum() < 3:
            return TangentFit(psi, cs, sel, assign, float("inf"))
        a = np.zeros((int(sel.sum()), 1 + active.size), order="F")
        a[:, 0] = j_psi[sel] / sig[sel]
        for q, j in enumerate(active):
            rows = assign[sel] == j
            a[rows, 1 + q] = (j_c[sel] / sig[sel])[rows]
        b = resid[sel] / sig[sel]
        normal = a.T @ a
        try:
            dx = np.linalg.solve(normal, a.T @ b)
        except np.linalg.LinAlgError:
            return TangentFit(psi, cs, sel, assign, float("inf"))
        psi += float(dx[0])
        cs[active] += dx[1:]
        dof = int(sel.sum()) - 1 - active.size
        res = b - a @ dx
        birge = float(np.sqrt(res @ res / dof)) if dof > 0 else float("nan")
    if normal is None:
        return TangentFit(psi, cs, assign >= 0, assign, float("inf"))
    try:
        var = float(np.linalg.inv(normal)[0, 0])
    except np.linalg.LinAlgError:
        var = float("inf")
    sigma = float(np.sqrt(var)) if np.isfinite(var) and var >= 0 else float("inf")
    return TangentFit(float(wrap_angle(psi)), cs, assign >= 0, assign, sigma, birge)


def test_predict_ranges_of_several_walls_equals_one_by_one():
    from fuzzyslam.maps.tangent import predict_ranges

    rng = np.random.default_rng(5)
    for n in (1, 3, 16, 37, 160):
        sensors = np.column_stack([rng.uniform(-3, 3, (n, 2)), rng.uniform(-4, 4, n)])
        psi = rng.uniform(-4.0, 4.0, 3)
        c = rng.uniform(-1.0, 3.0, 3)
        many = predict_ranges(psi, c, sensors, 0.2)
        for k in range(3):
            one = predict_ranges(float(psi[k]), float(c[k]), sensors, 0.2)
            for x, y in zip(one, many, strict=True):
                assert np.array_equal(x, y[k], equal_nan=True)


def test_fit_walls_equals_wall_by_wall_fit():
    """fit_walls (walls predicted together) against the plain wall-by-wall fit, bit for
    bit, on corridor rings with noise, outliers and missing echoes, from starts near and
    far from the truth, with one, two and three walls."""
    from maps_synth import corridor_lines, ring_in_lines

    from fuzzyslam.maps.tangent import fit_walls, readings_in_frame
    from fuzzyslam.robot import sonar_mounts

    rng = np.random.default_rng(6)
    mounts, fov = sonar_mounts(), np.deg2rad(25.0)
    kw = {"sigma_frac": 0.01, "quantum": 0.0254, "tolerance": 0.06,
          "delta_max": np.deg2rad(20.0), "iterations": 4}  # fmt: skip
    fits = 0
    for trial in range(150):
        k = 1 + trial % 4
        poses = np.column_stack([rng.uniform(-1, 1, k), rng.uniform(-0.3, 0.3, k),
                                 rng.uniform(-0.6, 0.6, k)])  # fmt: skip
        ranges = np.array([ring_in_lines(p, mounts, corridor_lines(0.0, 1.2), fov, 6.5)
                           for p in poses])  # fmt: skip
        ranges = ranges * (1 + rng.normal(0, 0.01, ranges.shape))
        ranges[rng.random(ranges.shape) < 0.15] = rng.uniform(0.2, 3.0)  # bounces
        ranges[rng.random(ranges.shape) < 0.1] = np.nan
        rd = readings_in_frame(poses - poses[-1] * [0, 0, 0], ranges, 6.5, fov, mounts)
        psi0 = np.pi / 2 + rng.normal(0, [0.02, 0.3][trial % 2])
        walls = [(0.0, np.pi), (0.0,), (0.0, np.pi, np.pi / 2)][trial % 3]
        new = fit_walls(rd, psi0, walls=walls, **kw)
        old = _plain_fit_walls(rd, psi0, walls=walls, **kw)
        for f in ("psi", "sigma", "birge"):
            assert np.array_equal(getattr(new, f), getattr(old, f), equal_nan=True), f
        for f in ("offsets", "inliers", "wall_of"):
            assert np.array_equal(getattr(new, f), getattr(old, f), equal_nan=True), f
        fits += new.ok
    assert fits > 50  # most trials converge: the comparison covers full fits


def test_conjunctive_grouped_equals_one_bincount_per_commonality():
    """tbm.conjunctive_grouped (the three commonalities in one bincount) against the plain
    form, one bincount per commonality, bit for bit, with zero commonalities and empty
    groups."""
    from fuzzyslam.maps.tbm import commonality, conjunctive_grouped, from_commonality

    def plain(m, groups, ngroups):
        out = []
        for q in commonality(m):
            q = np.asarray(q, dtype=float)
            zero = q <= 0.0
            logq = np.log(np.where(zero, 1.0, q))
            s = np.bincount(groups, weights=logq, minlength=ngroups)
            nz = np.bincount(groups, weights=zero.astype(float), minlength=ngroups)
            out.append(np.where(nz > 0, 0.0, np.exp(s)))
        return from_commonality(*out)

    rng = np.random.default_rng(8)
    for n, ngroups in ((0, 3), (1, 1), (50, 7), (3000, 400)):
        raw = rng.dirichlet([1.0, 1.0, 1.0], n)
        raw[rng.random(n) < 0.2, 0] = 0.0  # m(E) = 0 and m(T) = 0: q(E) = 0
        e, o = raw[:, 0], raw[:, 1]
        t = np.where(rng.random(n) < 0.1, 0.0, 1.0 - e - o)
        m = (e, o, t, np.zeros(n))
        groups = rng.integers(0, ngroups, n)
        new, old = conjunctive_grouped(m, groups, ngroups), plain(m, groups, ngroups)
        for a, b in zip(new, old, strict=True):
            assert a.shape == (ngroups,) and np.array_equal(a, b)


def test_local_map_pickles_sparse_bit_for_bit():
    """An FLM pickled (slam/prefetch.py's pipe) keeps only its non-vacuous cells and comes
    back with the same bits in every mass (-0.0 and NaN included), the same dtype, shape
    and layout, and its echoes; masses not of the grid's float32 shape pickle whole."""
    import pickle

    from fuzzyslam.maps.flm import LocalMap, build_flm
    from fuzzyslam.maps.params import MapParams

    ang = np.arange(16) * (2 * np.pi / 16)
    mounts = np.column_stack([0.2 * np.cos(ang), 0.2 * np.sin(ang), ang])
    ranges = np.linspace(0.4, 3.0, 16)
    ranges[3] = np.nan
    flm = build_flm(ranges, 6.5, np.deg2rad(25.0), mounts, MapParams())
    flm.m_e[0, 0] = -0.0  # bits that compare equal to the vacuous value
    flm.m_c[0, 1] = np.nan
    data = pickle.dumps(flm, pickle.HIGHEST_PROTOCOL)
    assert len(data) < len(pickle.dumps(flm.__dict__, pickle.HIGHEST_PROTOCOL)) / 2
    back = pickle.loads(data)
    assert type(back) is LocalMap and back.grid == flm.grid
    for name in ("m_e", "m_o", "m_t", "m_c"):
        a, b = getattr(flm, name), getattr(back, name)
        assert a.dtype == b.dtype and a.shape == b.shape and b.flags.c_contiguous
        assert np.array_equal(a.view(np.uint32), b.view(np.uint32))
    assert np.array_equal(back.readings.sensors, flm.readings.sensors)
    assert np.array_equal(back.readings.ranges, flm.readings.ranges)
    odd = LocalMap(flm.grid, flm.m_e.astype(float), flm.m_o, flm.m_t, flm.m_c, None)
    again = pickle.loads(pickle.dumps(odd))
    assert again.m_e.dtype == float and np.array_equal(again.m_e, odd.m_e)


def test_heading_decision_replace_is_dataclasses_replace():
    """HeadingDecision.replace (the heading aid's, 3-4 a ring): dataclasses.replace's
    decision, and its TypeError for a name that is not a field."""
    import dataclasses

    from fuzzyslam.fixes.heading_measure import HeadingDecision

    d = HeadingDecision(1.5, 2, 0.25, 0.5, True, "ok", 0.75, sigma=0.01)
    for changes in ({}, {"x": 1.0, "y": -2.0}, {"nis": 3.0, "accepted": False, "reason": "gated"}):
        a, b = dataclasses.replace(d, **changes), d.replace(**changes)
        assert type(b) is HeadingDecision and a == b and vars(a) == vars(b) and b is not d
    with pytest.raises(TypeError):
        d.replace(bogus=1)
    with pytest.raises(dataclasses.FrozenInstanceError):
        d.replace(x=0.0).x = 1.0
