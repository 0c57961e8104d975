"""The shared geometry: pose interpolation (se2), directions mod pi, polygons."""

from __future__ import annotations

import numpy as np
import pytest

from fuzzyslam.polygons import (
    distance_to_polygon,
    edges_contain,
    edges_within,
    points_in_polygon,
    polygon_edges,
)
from fuzzyslam.se2 import direction_mod_pi, interpolate_pose, interpolate_poses, wrap_angle

L_SHAPE = np.array([[0, 0], [4, 0], [4, 1], [1, 1], [1, 3], [0, 3]], float)


def test_interpolate_poses_short_way_round_and_outside():
    t = np.array([0.0, 1.0, 2.0])
    poses = np.array([[0.0, 0.0, 3.0], [1.0, 2.0, -3.0], [3.0, 2.0, -2.9]])
    q = interpolate_poses(t, poses, [-0.5, 0.5, 1.5, 2.5])
    assert np.isnan(q[0]).all() and np.isnan(q[3]).all()
    assert q[1, :2] == pytest.approx([0.5, 1.0])
    # 3.0 -> -3.0 crosses pi: half way is pi (or -pi), not 0
    assert abs(abs(q[1, 2]) - np.pi) < 1e-12
    held = interpolate_poses(t, poses, [-0.5, 2.5], outside="hold")
    assert np.array_equal(held[0], poses[0]) and held[1] == pytest.approx(poses[2])
    with pytest.raises(ValueError):
        interpolate_poses(t, poses, [0.5], outside="extrapolate")


def test_scalar_interpolation_agrees_with_the_vectorised_one():
    rng = np.random.default_rng(3)
    t = np.cumsum(rng.uniform(0.05, 0.2, 50))
    poses = np.column_stack(
        [rng.normal(size=(50, 2)), wrap_angle(np.cumsum(rng.normal(0, 0.4, 50)))]
    )
    tq = rng.uniform(t[0], t[-1], 200)
    many = interpolate_poses(t, poses, tq)
    one = np.array([interpolate_pose(t, poses, x) for x in tq])
    assert np.allclose(many[:, :2], one[:, :2], atol=1e-12)
    assert np.allclose(wrap_angle(many[:, 2] - one[:, 2]), 0.0, atol=1e-12)


def test_direction_mod_pi():
    assert direction_mod_pi(-np.pi / 4) == pytest.approx(3 * np.pi / 4)
    assert direction_mod_pi(np.pi) == 0.0 and isinstance(direction_mod_pi(1.0), float)
    assert np.allclose(direction_mod_pi(np.array([0.1, 0.1 + np.pi, 0.1 - 2 * np.pi])), 0.1)


def test_points_in_polygon_and_distance():
    pts = np.array([[0.5, 0.5], [2.0, 2.0], [3.5, 0.5], [0.5, 2.5], [5.0, 0.5], [2.0, 1.5]])
    inside = points_in_polygon(pts, L_SHAPE)
    assert inside.tolist() == [True, False, True, True, False, False]
    d = distance_to_polygon(pts, L_SHAPE)
    assert d[inside].tolist() == [0.0, 0.0, 0.0]
    assert d[1] == pytest.approx(1.0) and d[4] == pytest.approx(1.0) and d[5] == pytest.approx(0.5)
    # the same test whichever way round the corners go
    assert np.array_equal(points_in_polygon(pts, L_SHAPE[::-1]), inside)


def test_references_yaml_round_trip(tmp_path):
    """One Reference type and one reader and writer of references.yaml: what the map stage
    writes the fixes read back (angle mod pi wrapped to (-pi/2, pi/2], the region)."""
    from fuzzyslam.errors import InputError
    from fuzzyslam.references import Reference, read_references, write_references

    box = np.array([[0, 0], [4, 0], [4, 1], [0, 1]], float)
    refs = [Reference(0, "a", 0.1, 2.0, box, cells=7), Reference(3, "b", 3.0, 1.0, box + 5)]
    write_references(tmp_path / "references.yaml", refs)
    back = read_references(tmp_path / "references.yaml")
    assert [r.id for r in back] == [0, 3] and back[0].name == "a" and back[1].strength == 1.0
    assert back[0].angle == pytest.approx(0.1) and back[1].angle == pytest.approx(3.0 - np.pi)
    assert np.array_equal(back[1].polygon, box + 5) and back[1].contains((6.0, 5.5))
    assert not back[1].contains((1.0, 0.5))
    (tmp_path / "bad.yaml").write_text("references: [{id: 1, angle: 0.3}]\n")
    with pytest.raises(InputError, match="region"):
        read_references(tmp_path / "bad.yaml")


def test_one_point_polygon_tests_answer_as_the_array_code() -> None:
    """edges_contain and edges_within (the corridor selection's one-point paths) against
    points_in_polygon and distance_to_polygon (a second implementation): the same answer
    for random points around random polygons, on corners and edges too (within is None,
    'ask the array code', only within 1e-9 of the margin)."""
    rng = np.random.default_rng(3)
    for _ in range(60):
        k = int(rng.integers(3, 9))
        ang = np.sort(rng.uniform(0, 2 * np.pi, k))
        poly = np.column_stack([np.cos(ang), np.sin(ang)]) * rng.uniform(0.5, 3, (k, 1))
        pts = np.vstack([rng.uniform(-4, 4, (200, 2)), poly, (poly + np.roll(poly, 1, 0)) / 2])
        edges = polygon_edges(poly)
        inside = points_in_polygon(pts, poly)
        dist = distance_to_polygon(pts, poly)
        margin = float(rng.uniform(0.0, 1.0))
        for (x, y), want_in, d in zip(pts.tolist(), inside, dist, strict=True):
            assert edges_contain(edges, x, y) == bool(want_in)
            near = edges_within(edges, x, y, margin)
            if near is None:
                assert abs(d - margin) <= 1e-9 * max(d, margin)
            else:
                assert near == (d <= margin)
