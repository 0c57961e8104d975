"""The heading aid's off-map watch (fixes/off_map.py): the distance to the map's free
space against a brute-force second implementation, the watch's rule on a synthetic
corridor, and the committed Freiburg excerpt (data/carmen_fr079_excerpt) run with heading
fixes from a wrong start pose: lost and said (``pose_off_map``), while the run from the
right start stays healthy."""

from __future__ import annotations

import json
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from test_robust_logs import cli

from fuzzyslam.fixes.off_map import MIN_RINGS, SPAN_S, OffMapWatch, free_distance
from fuzzyslam.maps.grid import Grid

EXCERPT = Path(__file__).resolve().parents[1] / "data" / "carmen_fr079_excerpt"


def test_free_distance_is_the_euclidean_distance_to_the_nearest_free_cell() -> None:
    """Against all pairs of cell centres (brute force), on a random map; no free cell at
    all gives infinity."""
    rng = np.random.default_rng(5)
    m_e = np.where(rng.random((23, 31)) < 0.08, 0.9, 0.1)
    got = free_distance(m_e, 0.1)
    fy, fx = np.nonzero(m_e > 0.5)
    yy, xx = np.mgrid[0:23, 0:31]
    want = np.sqrt((yy[..., None] - fy) ** 2 + (xx[..., None] - fx) ** 2).min(axis=-1) * 0.1
    np.testing.assert_allclose(got, want, atol=1e-4)
    assert np.isinf(free_distance(np.zeros((4, 4)), 0.1)).all()


def corridor_watch() -> OffMapWatch:
    """A 20 m x 2 m free corridor along y = 0 in a 30 m x 20 m map at 0.1 m."""
    grid = Grid((-5.0, -10.0), 0.1, (200, 300))
    m_e = np.zeros(grid.shape)
    m_e[90:110, 50:250] = 0.9  # y in [-1, 1), x in [0, 20)
    return OffMapWatch(SimpleNamespace(grid=grid, m_e=m_e))


@pytest.mark.parametrize(
    ("y", "sigma", "lost"),
    [(0.0, 0.05, False), (1.3, 0.05, False), (4.0, 0.05, True), (4.0, 1.5, False)],
    ids=["in", "within_0.5_m", "off", "off_but_uncertain"],
)
def test_the_watch_flags_a_sure_estimate_off_the_map(y: float, sigma: float, lost: bool) -> None:
    """Rings every 0.5 s for 2 minutes at (10, y): in the corridor, or 0.3 m outside it,
    never lost; 3 m outside it with a 5 cm sigma, lost once most rings of a minute were
    (at the MIN_RINGS-th ring); as far out but with a 1.5 m sigma (4.5 m at 3 sigma),
    not."""
    watch = corridor_watch()
    for k in range(240):
        watch.observe(0.5 * k, 10.0, y, sigma**2)
    assert (watch.found_at is not None) == lost
    if lost:
        assert watch.found_at == pytest.approx(0.5 * (MIN_RINGS - 1))
        assert watch.rings_off == 240


def test_a_short_excursion_is_not_lost() -> None:
    """An estimate that leaves the free space for 20 s of a minute's rings: not lost."""
    watch = corridor_watch()
    for k in range(240):
        t = 0.5 * k
        watch.observe(t, 10.0, 4.0 if 30.0 <= t < 30.0 + SPAN_S / 3 else 0.0, 0.05**2)
    assert watch.found_at is None and watch.rings_off == 40


@pytest.fixture(scope="module")
def excerpt_map(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("offmap") / "fgm"
    code, _, err = cli("map", EXCERPT / "log.mcap", "--trajectory", EXCERPT / "truth.tum",
                       "--config", "real_building_scan", "--ranges", "scan", "--no-figures",
                       "-o", out)  # fmt: skip
    assert code == 0, err
    return out


@pytest.mark.parametrize(("start", "lost"), [(None, False), ("5,5,1.57", True)])
def test_heading_fixes_from_a_wrong_start_are_said_lost(
    excerpt_map: Path, tmp_path: Path, start: str | None, lost: bool
) -> None:
    """The excerpt with heading fixes from its start: from the log's own start pose the
    run stays on the map and healthy; from a pose 20 m and 90 deg off, its fixes lock onto
    the wrong walls (before: healthy), and filter_health says pose_off_map."""
    args = ["run", EXCERPT / "log.mcap", "--config", "real_building_scan", "--map",
            excerpt_map, "--fix", "heading", "--fix-from", "0", "-o", tmp_path / "est"]  # fmt: skip
    if start is not None:
        args.append(f"--start-pose={start}")
    code, out, err = cli(*args)
    assert code == 0, err
    health = json.loads(out)["filter_health"]
    assert ("pose_off_map" in health["reasons"]) == lost
    assert health["diverged"] == lost
