"""Sonar evidence, the FGM from analytic rings, the FLM, Hough directions and references."""

from __future__ import annotations

import dataclasses

import cv2
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from maps_synth import corridor_lines, ring_in_lines, room_lines

from fuzzyslam.maps.evidence import reading_masses, ring_evidence
from fuzzyslam.maps.fgm import FgmBuilder, FrozenMapError
from fuzzyslam.maps.flm import build_flm, build_flm_rings
from fuzzyslam.maps.grid import BeliefMap, Grid
from fuzzyslam.maps.hough import (
    dominant_direction,
    flm_wall_direction,
    hough_accumulator,
    wall_weights,
)
from fuzzyslam.maps.params import MapParams
from fuzzyslam.maps.quality import wall_quality
from fuzzyslam.maps.references import extract_references
from fuzzyslam.references import read_references, write_references
from fuzzyslam.robot import sonar_mounts
from fuzzyslam.se2 import between, compose, wrap_angle_period

FOV = np.deg2rad(25.0)
RMAX = 6.5
MOUNTS = sonar_mounts()


def angle_error_deg(a: float, b: float) -> float:
    return float(np.rad2deg(abs(wrap_angle_period(a - b, np.pi))))


# --- one reading ----------------------------------------------------------------------


@pytest.mark.parametrize("empty_reach", [100.0, 0.9])
def test_single_reading_against_a_wall(empty_reach):
    """Occupied evidence only on the arc |rho - r| < dr inside the cone, empty only
    inside the cone short of r (and of the empty reach), nothing elsewhere."""
    params = MapParams(empty_reach=empty_reach)
    grid = Grid.centred(61, 0.1)
    r, dr, half = 2.0, params.range_tolerance, FOV / 2
    ev = ring_evidence(grid, np.zeros(3), [r], RMAX, FOV, np.zeros((1, 3)), params)
    bm = BeliefMap.vacuous(grid)
    for arr, val in zip((bm.m_e, bm.m_o, bm.m_t, bm.m_c), ev.masses, strict=True):
        arr.ravel()[ev.cells] = val
    X, Y = grid.centres()
    rho, phi = np.hypot(X, Y), np.arctan2(Y, X)
    in_cone = np.abs(phi) <= half
    occ = bm.m_o > 0
    emp = bm.m_e > 0
    assert occ.any() and emp.any()
    assert np.all(np.abs(rho[occ] - r) < dr) and np.all(in_cone[occ])
    assert np.all(rho[emp] < r) and np.all(in_cone[emp])
    assert np.all(rho[emp] <= empty_reach + 1e-9)
    # on the axis: occupied at the arc, empty well inside
    iy, ix = grid.cell_of(np.array([[r - 0.05, 0.0 + 1e-3], [0.5, 1e-3]]))
    assert bm.m_o[iy[0], ix[0]] > 0.1 and bm.m_e[iy[1], ix[1]] > 0.1
    # nothing outside the cone or beyond the arc
    untouched = ~in_cone | (rho > r + dr)
    assert np.all(bm.m_t[untouched] == 1.0)
    np.testing.assert_allclose(bm.m_e + bm.m_o + bm.m_t + bm.m_c, 1.0, atol=1e-6)


def test_no_echo_reading_has_no_occupied_evidence():
    params = MapParams()
    ev = ring_evidence(
        Grid.centred(61, 0.1), np.zeros(3), [RMAX], RMAX, FOV, np.zeros((1, 3)), params
    )
    assert np.all(ev.masses[1] == 0.0)
    assert np.all(ev.masses[0] <= params.no_echo_empty + 1e-12)


# --- FGM --------------------------------------------------------------------------------


ROOM = (0.0, 0.0, 6.0, 4.0)


def room_path(n: int = 160) -> np.ndarray:
    """A loop 1.2 m inside the room's walls, heading along the path."""
    s = np.linspace(0, 2 * np.pi, n, endpoint=False)
    x = 3.0 + 1.8 * np.cos(s)
    y = 2.0 + 0.8 * np.sin(s)
    th = np.arctan2(0.8 * np.cos(s), -1.8 * np.sin(s))
    return np.column_stack([x, y, th])


@pytest.fixture(scope="module")
def room_fgm():
    # Analytic ranges have no multipath echoes, so empty evidence may reach the whole cone
    # (empty_reach limits it only against the bounced echoes of specular walls).
    params = MapParams(empty_reach=100.0)
    poses = room_path()
    lines = room_lines(*ROOM)
    ranges = np.array([ring_in_lines(p, MOUNTS, lines, FOV, RMAX) for p in poses])
    b = FgmBuilder.for_path(poses[:, :2], params)
    b.add_rings(poses, ranges, RMAX, FOV, MOUNTS)
    return b, params


def test_room_walls_within_one_cell(room_fgm):
    b, _params = room_fgm
    x0, y0, x1, y1 = ROOM
    walls = np.array([[x0, y0, x1, y0], [x1, y0, x1, y1], [x1, y1, x0, y1], [x0, y1, x0, y0]])
    q = wall_quality(b.map, walls, tolerance=1)
    assert q.map_cells > 50
    assert q.precision >= 0.98, q
    assert q.recall >= 0.9, q


def test_fgm_masses_valid_and_frozen(room_fgm):
    b, _ = room_fgm
    m = b.map
    total = m.m_e + m.m_o + m.m_t + m.m_c
    np.testing.assert_allclose(total, 1.0, atol=1e-5)
    for a in (m.m_e, m.m_o, m.m_t, m.m_c):
        assert a.min() >= 0.0 and a.max() <= 1.0
    frozen = FgmBuilder(m.grid, b.params)
    frozen.freeze(1.0)
    with pytest.raises(FrozenMapError):
        frozen.add_ring(np.zeros(3), np.full(16, 1.0), RMAX, FOV, MOUNTS)


def test_batched_equals_ring_by_ring(room_fgm):
    """add_rings (one vectorised evidence pass) against add_ring called per ring."""
    b, params = room_fgm
    poses = room_path(40)
    lines = room_lines(*ROOM)
    ranges = np.array([ring_in_lines(p, MOUNTS, lines, FOV, RMAX) for p in poses])
    one = FgmBuilder(b.grid, params)
    for p, r in zip(poses, ranges, strict=True):
        one.add_ring(p, r, RMAX, FOV, MOUNTS)
    batch = FgmBuilder(b.grid, params)
    batch.add_rings(poses, ranges, RMAX, FOV, MOUNTS)
    for a, c in zip(
        (one.map.m_e, one.map.m_o, one.map.m_c),
        (batch.map.m_e, batch.map.m_o, batch.map.m_c),
        strict=True,
    ):
        np.testing.assert_allclose(a, c, atol=1e-6)


@settings(max_examples=25, deadline=None)
@given(
    st.lists(
        st.tuples(
            st.floats(-1.0, 1.0),
            st.floats(-1.0, 1.0),
            st.floats(-np.pi, np.pi),
            st.lists(st.floats(0.2, 7.0), min_size=16, max_size=16),
        ),
        min_size=1,
        max_size=12,
    ),
    st.floats(0.0, 1.0),
)
def test_fgm_masses_sum_to_one_after_any_rings(rings, gamma):
    params = MapParams(forgetting_gamma=gamma)
    b = FgmBuilder(Grid.centred(61, 0.1), params)
    for x, y, th, rr in rings:
        b.add_ring(np.array([x, y, th]), np.minimum(rr, RMAX), RMAX, FOV, MOUNTS)
    m = b.map
    arr = np.array([m.m_e, m.m_o, m.m_t, m.m_c])
    assert arr.min() >= 0.0 and arr.max() <= 1.0
    np.testing.assert_allclose(arr.sum(axis=0), 1.0, atol=1e-5)


# --- Hough --------------------------------------------------------------------------------


def test_accumulator_peak_agrees_with_opencv():
    """Our weighted accumulator against cv2.HoughLines on a binary image of one line."""
    img = np.zeros((101, 101), np.uint8)
    cv2.line(img, (5, 20), (95, 70), 255, 1)
    ys, xs = np.nonzero(img)
    plane = hough_accumulator(xs, ys, np.ones(len(xs)), np.deg2rad(1.0), 1.0)
    _i, j = np.unravel_index(np.argmax(plane.acc), plane.acc.shape)
    ours = plane.thetas[j]
    lines = cv2.HoughLines(img, 1, np.deg2rad(1.0), 30)
    theirs = float(lines[0][0][1])
    assert angle_error_deg(ours, theirs) <= 1.0 + 1e-9
    truth = np.arctan2(50, 90) + np.pi / 2  # the normal of the drawn line
    assert angle_error_deg(ours, truth) <= 1.0


@pytest.mark.parametrize("angle_deg", [0.0, 23.7, 70.35, 128.0])
def test_refined_direction_of_weighted_lines(angle_deg):
    """Two parallel lines of cells at a known angle: sub-bin direction within 0.1 deg."""
    a = np.deg2rad(angle_deg)
    grid = Grid.covering(-5, -5, 5, 5, 0.1)
    X, Y = grid.centres()
    d = -np.sin(a) * X + np.cos(a) * Y
    w = np.where(np.abs(np.abs(d) - 1.0) < 0.05, 0.8, 0.0)
    wd = dominant_direction(X, Y, w, MapParams())
    assert angle_error_deg(wd.angle, a) < 0.1
    assert not wd.ambiguous


@pytest.mark.parametrize("axis_deg", [0.0, 31.0, 70.35])
def test_reference_angle_of_synthetic_corridor(axis_deg):
    """FGM from analytic rings along a corridor at a known angle: the reference within
    0.5 deg (the whole chain: evidence, fusion, path segmentation, Hough, refinement)."""
    params = MapParams()
    a = np.deg2rad(axis_deg)
    s = np.linspace(0.0, 9.0, 121)
    poses = np.column_stack([s * np.cos(a), s * np.sin(a), np.full_like(s, a)])
    lines = corridor_lines(a, 1.0)
    ranges = np.array([ring_in_lines(p, MOUNTS, lines, FOV, RMAX) for p in poses])
    b = FgmBuilder.for_path(poses[:, :2], params)
    b.add_rings(poses, ranges, RMAX, FOV, MOUNTS)
    refs = extract_references(b.freeze(0.0), poses[:, :2], params)
    assert len(refs) == 1
    assert angle_error_deg(refs[0].angle, a) < 0.5, np.rad2deg(refs[0].angle)
    assert refs[0].strength > 1.0


@pytest.mark.parametrize("heading_deg", [-35.0, -10.0, 0.0, 4.0, 17.0, 40.0])
def test_flm_wall_direction_in_straight_corridor(heading_deg):
    """FLM of one analytic ring in a 2 m corridor: the wall direction in the robot frame
    is minus the heading (mod pi), within ~1 deg on average over lateral offsets."""
    params = MapParams()
    h = np.deg2rad(heading_deg)
    errs = []
    for y in (-0.25, 0.0, 0.2):
        r = ring_in_lines(np.array([0.0, y, h]), MOUNTS, corridor_lines(0.0, 1.0), FOV, RMAX)
        flm = build_flm(r, RMAX, FOV, MOUNTS, params)
        assert flm.grid.shape == (41, 41)
        wd = flm_wall_direction(flm, params)
        errs.append(angle_error_deg(wd.angle, -h))
    assert np.mean(errs) < 1.5, errs


def test_flm_equals_fgm_evidence_at_the_origin():
    """One implementation: an FLM is a one-ring FGM at the identity pose."""
    params = dataclasses.replace(MapParams(), forgetting_gamma=1.0)
    r = ring_in_lines(np.array([0.0, 0.1, 0.3]), MOUNTS, corridor_lines(0.0, 1.0), FOV, RMAX)
    flm = build_flm(r, RMAX, FOV, MOUNTS, params)
    b = FgmBuilder(flm.grid, params)
    b.add_ring(np.zeros(3), r, RMAX, FOV, MOUNTS)
    np.testing.assert_allclose(flm.m_o, b.map.m_o, atol=1e-6)
    np.testing.assert_allclose(flm.m_e, b.map.m_e, atol=1e-6)


def test_multi_ring_flm():
    """build_flm_rings: one ring at the identity is build_flm; rings taken along the
    corridor and placed by their relative poses keep the wall direction."""
    params = MapParams()
    h = np.deg2rad(12.0)
    lines = corridor_lines(0.0, 1.0)
    poses = np.array([[-0.3 * np.cos(h), 0.1 - 0.3 * np.sin(h), h], [0.0, 0.1, h]])
    rings = np.array([ring_in_lines(p, MOUNTS, lines, FOV, RMAX) for p in poses])
    one = build_flm_rings(np.zeros((1, 3)), rings[1:], RMAX, FOV, MOUNTS, params)
    np.testing.assert_allclose(
        one.m_o, build_flm(rings[1], RMAX, FOV, MOUNTS, params).m_o, atol=1e-6
    )
    rel = between(poses[-1], poses)
    wd = flm_wall_direction(build_flm_rings(rel, rings, RMAX, FOV, MOUNTS, params), params)
    assert angle_error_deg(wd.angle, -h) < 1.5


# --- batched fusion with forgetting and the cone enumeration ------------------------------


@pytest.mark.parametrize("gamma", [0.0, 0.6, 1.0])
def test_batched_fusion_is_bitwise_ring_by_ring_with_forgetting(gamma):
    """add_rings over batches (one evidence pass per batch) against add_ring per ring,
    with contradicting (noisy) rings so that forgetting acts: identical to the last bit."""
    rng = np.random.default_rng(int(10 * gamma))
    params = MapParams(forgetting_gamma=gamma)
    poses = room_path(60) + rng.normal(0.0, [0.05, 0.05, 0.03], (60, 3))
    ranges = np.array([ring_in_lines(p, MOUNTS, room_lines(*ROOM), FOV, RMAX) for p in poses])
    ranges = ranges * (1 + 0.02 * rng.standard_normal(ranges.shape))
    grid = FgmBuilder.for_path(poses[:, :2], params).grid
    batch, one = FgmBuilder(grid, params), FgmBuilder(grid, params)
    for k in range(0, 60, 25):
        batch.add_rings(poses[k : k + 25], ranges[k : k + 25], RMAX, FOV, MOUNTS)
    for p, r in zip(poses, ranges, strict=True):
        one.add_ring(p, r, RMAX, FOV, MOUNTS)
    assert batch.cell_updates == one.cell_updates > 0
    assert (one.map.m_c > 0.01).any()  # contradiction, so forgetting acts
    for a, b in zip(
        (batch.map.m_e, batch.map.m_o, batch.map.m_t, batch.map.m_c),
        (one.map.m_e, one.map.m_o, one.map.m_t, one.map.m_c),
        strict=True,
    ):
        np.testing.assert_array_equal(a, b)


def test_cone_enumeration_misses_no_cell():
    """rings_evidence (bounding boxes of cell centres) against a brute-force evaluation of
    the same mass function on EVERY cell of the grid: the same cells, the same masses."""
    rng = np.random.default_rng(5)
    params = MapParams()
    grid = Grid.centred(71, 0.1)
    for trial in range(20):
        fov = FOV if trial % 2 else np.deg2rad(rng.uniform(5.0, 80.0))
        pose = np.array([rng.uniform(-0.5, 0.5), rng.uniform(-0.5, 0.5), rng.uniform(-3, 3)])
        r = np.minimum(rng.uniform(0.3, 4.0, 16), RMAX)
        r[rng.integers(0, 16, 3)] = RMAX
        ev = ring_evidence(grid, pose, r, RMAX, fov, MOUNTS, params)
        X, Y = grid.centres()
        sensors = compose(np.repeat(pose[None], 16, 0), MOUNTS)
        dx = X.ravel()[None, :] - sensors[:, 0:1]
        dy = Y.ravel()[None, :] - sensors[:, 1:2]
        rho = np.hypot(dx, dy)
        phi = wrap_angle_period(np.arctan2(dy, dx) - sensors[:, 2:3], 2 * np.pi)
        inside = np.abs(phi) <= fov / 2
        m_e, m_o = reading_masses(rho, phi, r[:, None], (r < RMAX)[:, None], fov / 2, params)
        m_e, m_o = np.where(inside, m_e, 0.0), np.where(inside, m_o, 0.0)
        touched = np.flatnonzero(((m_e > 0) | (m_o > 0)).any(axis=0))
        np.testing.assert_array_equal(np.sort(ev.cells), touched)
        # combined masses of the brute force: product of commonalities over readings
        q_e = np.prod(1 - m_o, axis=0)[touched]
        q_o = np.prod(1 - m_e, axis=0)[touched]
        q_t = np.prod(1 - m_e - m_o, axis=0)[touched]
        order = np.argsort(ev.cells)
        np.testing.assert_allclose(ev.masses[2][order], q_t, atol=1e-9)
        np.testing.assert_allclose(ev.masses[0][order], q_e - q_t, atol=1e-9)
        np.testing.assert_allclose(ev.masses[1][order], q_o - q_t, atol=1e-9)


def _paint_segment(bm: BeliefMap, a, b, mass: float = 0.8) -> None:
    """Wall evidence m(O) = mass on the cells whose centres lie within half a cell of the
    segment a-b (the rest of the masses stays ignorance)."""
    X, Y = bm.grid.centres()
    a, b = np.asarray(a, float), np.asarray(b, float)
    e = b - a
    u = np.clip(((X - a[0]) * e[0] + (Y - a[1]) * e[1]) / (e @ e), 0.0, 1.0)
    d = np.hypot(X - a[0] - u * e[0], Y - a[1] - u * e[1])
    on = d <= 0.5 * bm.grid.resolution
    bm.m_o[on] = mass
    bm.m_t[on] = 1.0 - mass


def test_a_stub_beside_the_path_gives_no_confident_reference():
    """A 7 m corridor (walls y = +-1) and a 4 m leg of path beside which the only wall is
    a 1.5 m stub at 80 deg (a room's corner, a doorway): without a bound the stub makes a
    confident reference 10 deg off the building's 90; with ``reference_min_strength`` of
    a corridor segment's length it is flagged ambiguous, and the corridor is not."""
    grid = Grid.covering(-2.0, -3.0, 13.0, 6.0, 0.1)
    bm = BeliefMap.vacuous(grid)
    for y in (-1.0, 1.0):
        _paint_segment(bm, (0.0, y), (7.0, y))
    a80 = np.deg2rad(80.0)
    _paint_segment(bm, (10.0, 1.5), (10.0 + 1.5 * np.cos(a80), 1.5 + 1.5 * np.sin(a80)))
    path = np.concatenate(
        [np.column_stack([np.linspace(0, 9, 91), np.zeros(91)]),
         np.column_stack([np.full(41, 9.0), [*np.linspace(0.1, 4.0, 40).tolist(), 4.0]])]
    )  # fmt: skip
    loose = extract_references(bm, path, MapParams())
    bound = extract_references(bm, path, MapParams(reference_min_strength=3.0))
    assert len(loose) == len(bound) == 2
    corr = [r for r in bound if angle_error_deg(r.angle, 0.0) < 1.0]
    stub = [r for r in bound if angle_error_deg(r.angle, a80) < 2.0]
    assert len(corr) == 1 and len(stub) == 1, [np.rad2deg(r.angle) for r in bound]
    assert not corr[0].ambiguous and corr[0].strength > 3.0
    assert stub[0].ambiguous and stub[0].strength < 1.5
    assert not next(r for r in loose if angle_error_deg(r.angle, a80) < 2.0).ambiguous


def test_a_stretch_without_walls_is_an_ambiguous_reference_that_loads(tmp_path):
    """A 7 m corridor (walls y = +-1) and then a 6 m drive across an empty hall (no wall
    cell within its band): the hall's reference has no Hough direction, so it takes the
    path's (90 deg) with strength 0, flagged ambiguous, and references.yaml round-trips
    (a NaN angle was written, and every run on the map refused it). The corridor's
    reference, read from its region's bounding box only, equals the one read from the
    whole grid (the Hough's points and their order are the same)."""
    grid = Grid.covering(-2.0, -3.0, 13.0, 12.0, 0.1)
    bm = BeliefMap.vacuous(grid)
    for y in (-1.0, 1.0):
        _paint_segment(bm, (0.0, y), (7.0, y))
    path = np.concatenate(
        [np.column_stack([np.linspace(0, 9, 91), np.zeros(91)]),
         np.column_stack([np.full(90, 9.0), np.linspace(0.1, 9.0, 90)])]
    )  # fmt: skip
    params = MapParams()
    refs = extract_references(bm, path, params)
    assert len(refs) == 2
    corr, hall = sorted(refs, key=lambda r: r.stretch.point[1])
    assert hall.cells == 0 and hall.strength == 0.0 and hall.ambiguous
    assert angle_error_deg(hall.angle, np.pi / 2) < 1.0
    assert not corr.ambiguous and angle_error_deg(corr.angle, 0.0) < 0.5
    X, Y = grid.centres()
    st = corr.stretch
    s = (X - st.point[0]) * st.direction[0] + (Y - st.point[1]) * st.direction[1]
    q = (X - st.point[0]) * -st.direction[1] + (Y - st.point[1]) * st.direction[0]
    mask = (s >= st.s0) & (s <= st.s1) & (np.abs(q) <= params.segment_band)
    whole = dominant_direction(
        X, Y, np.where(mask, wall_weights(bm, params.wall_threshold), 0.0), params,
        rho_step=grid.resolution,
    )  # fmt: skip
    assert (whole.angle, whole.strength, whole.cells) == (corr.angle, corr.strength, corr.cells)
    path_yaml = tmp_path / "references.yaml"
    write_references(path_yaml, refs)
    back = read_references(path_yaml)
    assert [r.ambiguous for r in back] == [r.ambiguous for r in refs]
    assert all(np.isfinite(r.angle) for r in back)
