"""Corridor segments of a weaving path (docs/models.md sec. 8, ``maps/references.py``):
split-and-merge of the path at the across-track tolerance L_min sin(turn), trimmed at its
corners, not at its ends."""

from __future__ import annotations

import numpy as np
import pytest

from fuzzyslam.maps.grid import BeliefMap, Grid
from fuzzyslam.maps.params import MapParams
from fuzzyslam.maps.references import (
    extract_references,
    merge_pieces,
    resample_path,
    split_path,
    straight_stretches,
)
from fuzzyslam.se2 import wrap_angle_period

HALF = 1.0  # corridor half-width (m)


def _paint_segment(bm: BeliefMap, a, b, mass: float = 0.8) -> None:
    """Wall evidence m(O) = mass on the cells within half a cell of the segment a-b."""
    X, Y = bm.grid.centres()
    a, b = np.asarray(a, float), np.asarray(b, float)
    e = b - a
    u = np.clip(((X - a[0]) * e[0] + (Y - a[1]) * e[1]) / (e @ e), 0.0, 1.0)
    on = np.hypot(X - a[0] - u * e[0], Y - a[1] - u * e[1]) <= 0.5 * bm.grid.resolution
    bm.m_o[on] = mass
    bm.m_t[on] = 1.0 - mass


def _unit(a: float) -> np.ndarray:
    return np.array([np.cos(a), np.sin(a)])


def _offset_corner(a, v, b, off: float) -> np.ndarray:
    """The corner of the polyline a-v-b offset by ``off`` to its left (line intersection)."""
    d1, d2 = (v - a) / np.linalg.norm(v - a), (b - v) / np.linalg.norm(b - v)
    n1, n2 = np.array([-d1[1], d1[0]]), np.array([-d2[1], d2[0]])
    # v + off n1 + t d1 = v + off n2 + u d2
    t, _u = np.linalg.solve(np.column_stack([d1, -d2]), off * (n2 - n1))
    return v + off * n1 + t * d1


def weaving_l(axis: float, turn: float, a: float, lam: float, radius: float = 0.5):
    """An L of two corridors (12 m along ``axis``, then 9 m along ``axis`` + ``turn``),
    walls HALF either side of the centre line, and a path along the centre line that
    rounds the corner with ``radius`` and weaves across it, a sin(2 pi s / lam).

    Returns (belief map, path (N, 2), centre-line vertices (3, 2))."""
    p0 = np.zeros(2)
    v = p0 + 12.0 * _unit(axis)
    p1 = v + 9.0 * _unit(axis + turn)
    lo = np.minimum.reduce([p0, v, p1]) - 3.0
    hi = np.maximum.reduce([p0, v, p1]) + 3.0
    grid = Grid.covering(lo[0], lo[1], hi[0], hi[1], 0.1)
    bm = BeliefMap.vacuous(grid)
    for off in (HALF, -HALF):
        n0 = off * _unit(axis + np.pi / 2)
        n1 = off * _unit(axis + turn + np.pi / 2)
        c = _offset_corner(p0, v, p1, off)
        _paint_segment(bm, p0 + n0, c)
        _paint_segment(bm, c, p1 + n1)
    # centre line with the corner rounded: an arc tangent to both legs
    t = radius * np.tan(abs(turn) / 2)
    d0, d1 = _unit(axis), _unit(axis + turn)
    leg0 = p0 + np.outer(np.arange(0.0, 12.0 - t, 0.01), d0)
    leg1 = v + np.outer(np.arange(t, 9.0, 0.01), d1)
    side = np.sign(turn)
    centre = v - t * d0 + side * radius * _unit(axis + np.pi / 2)
    phi = axis - side * np.pi / 2 + np.linspace(0.0, turn, 52)[1:-1]
    arc = centre + radius * np.column_stack([np.cos(phi), np.sin(phi)])
    line = np.concatenate([leg0, arc, leg1])
    seg = np.hypot(*np.diff(line, axis=0).T)
    s = np.concatenate([[0.0], np.cumsum(seg)])
    tangent = np.gradient(line, s, axis=0)
    normal = np.column_stack([-tangent[:, 1], tangent[:, 0]])
    normal /= np.hypot(*normal.T)[:, None]
    path = line + (a * np.sin(2 * np.pi * s / lam))[:, None] * normal
    return bm, path, np.array([p0, v, p1])


def tls_direction_bound(a: float, length: float) -> float:
    """Largest direction error (rad) of the total-least-squares line of points spread
    evenly over ``length`` along a line and at most ``a`` across it: tan 2 phi =
    2 Sxy / (Sxx - Syy), |Sxy| <= a E|s - mean| = a L / 4, Sxx = L^2 / 12, Syy <= a^2."""
    return 0.5 * np.arctan((6 * a / length) / (1 - 12 * a**2 / length**2))


def test_split_and_merge_of_a_weave_and_a_corner():
    """Split-and-merge at tol = L_min sin(turn) (0.35 m): a straight path weaving
    0.25 m across (more than tol / 2, so its chords, which end on the weave, split it)
    is one piece after the merge step (its TLS line is within 0.25 m of every point);
    an L's pieces meet at the corner (the sample farthest from the chord)."""
    tol = MapParams().segment_min_length * np.sin(np.deg2rad(MapParams().segment_turn_deg))
    s = np.arange(1.0, 11.05, 0.1)  # from a crest to a trough: the chord is tilted
    weave = np.column_stack([s, 0.25 * np.sin(2 * np.pi * s / 4.0)])
    split = split_path(weave, tol)
    assert len(split) > 2  # the split alone cuts the weave
    np.testing.assert_array_equal(merge_pieces(weave, split, tol), [0, len(s) - 1])
    s = np.arange(0.0, 12.05, 0.1)
    ell = np.concatenate([np.column_stack([s, 0 * s]), np.column_stack([0 * s + 12.0, s])[1:]])
    ell = resample_path(ell, 0.1)
    v = merge_pieces(ell, split_path(ell, tol), tol)
    assert len(v) == 3 and np.hypot(*(ell[v[1]] - [12.0, 0.0])) < 0.11


@pytest.mark.parametrize(
    ("axis_deg", "turn_deg", "a", "lam"),
    [(0.0, 90.0, 0.1, 3.5), (25.0, 80.0, 0.2, 4.0), (-10.0, -70.0, 0.2, 3.0)],
)
def test_weaving_l_finds_both_corridors(axis_deg, turn_deg, a, lam):
    """A path weaving across the centre line of an L (the simulator's 0.1 m over 3.5 m,
    and twice that, +-17-23 deg of direction, which splits every 1-metre chord test)
    gives one reference per corridor: its stretch's direction within the TLS bound of
    its length, its reference angle within 0.5 deg (the walls'), its region from the
    path's own end (less the end trim) to no nearer the corner than the chord test's
    reach (1 m: where a sharp corner's straight samples end) plus the end trim, less
    0.1 m for the corner placed at the crossing of the fitted lines (the junction,
    whose cells carry the other corridor's walls, stays out). The 1-metre chord test
    alone finds no stretch on any of these paths."""
    params = MapParams()
    axis, turn = np.deg2rad(axis_deg), np.deg2rad(turn_deg)
    bm, path, (p0, v, p1) = weaving_l(axis, turn, a, lam)
    refs = extract_references(bm, path, params)
    assert len(refs) == 2, [np.rad2deg(r.angle) for r in refs]
    trim = params.segment_end_trim
    reach = 1.0  # straight_stretches' chord test: +-2 windows of 0.5 m
    for ref, (start, end, ax) in zip(
        sorted(refs, key=lambda r: float(np.hypot(*(r.stretch.point - p0)))),
        [(p0, v, axis), (p1, v, axis + turn)],
        strict=True,
    ):
        st = ref.stretch
        assert not ref.ambiguous
        err = abs(float(wrap_angle_period(st.angle - ax, np.pi)))
        assert err <= tls_direction_bound(a, st.length + 2 * trim), np.rad2deg(err)
        assert np.rad2deg(abs(float(wrap_angle_period(ref.angle - ax, np.pi)))) < 0.5
        u = _unit(ax)
        s_ends = sorted(
            float((st.point + sv * st.direction - start) @ u * np.sign((end - start) @ u))
            for sv in (st.s0, st.s1)
        )
        corridor = float(np.hypot(*(end - start)))
        assert s_ends[0] <= trim + 0.3, s_ends  # from the path's end
        assert corridor - s_ends[1] >= reach + trim - 0.1, s_ends  # short of the junction


def test_weaving_straight_path_is_one_stretch_to_its_ends():
    """A weaving path with no corner: one stretch from its first sample to its last (the
    chord test's window does not fit within 1 m of the ends)."""
    s = np.arange(0.0, 6.0, 0.01)
    path = np.column_stack([s, 0.2 * np.sin(2 * np.pi * s / 4.0)])
    (st,) = straight_stretches(path, MapParams())
    assert st.s1 - st.s0 == pytest.approx(5.9, abs=0.1)
    assert np.rad2deg(min(st.angle, np.pi - st.angle)) <= np.rad2deg(tls_direction_bound(0.2, 5.9))
