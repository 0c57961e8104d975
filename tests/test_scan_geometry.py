"""Laser scans whose geometry varies within a log (streams/scan.py): angles that jitter
by float32 noise, beam counts that alternate (an RPLidar's 180 / 179), a first scan one
beam short, scans of shifted or coarser angles read onto the first scan's kept beams
with their own mounts, and the scans still refused counted, said on stderr and counted
into a run's lost events (slam/run_results.py ``lost_events``).

The map-stage tests rewrite the real excerpt (data/carmen_fr079_excerpt: 360 beams of
0.5 deg, every 4th kept by real_building_scan).
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from test_robust_logs import cli, rewrite

from fuzzyslam.config import load_config
from fuzzyslam.maps import build
from fuzzyslam.se2 import compose
from fuzzyslam.slam.run_results import LOST_SHARE, LateEvents, lost_events
from fuzzyslam.streams import messages as M
from fuzzyslam.streams.reader import LogReader
from fuzzyslam.streams.scan import ANGLE_TOL, FEW_REFUSED, scan_geometry, scan_rings
from fuzzyslam.streams.sonar import RingStats
from fuzzyslam.streams.tf import Rigid

EXCERPT = Path(__file__).resolve().parents[1] / "data" / "carmen_fr079_excerpt"
N, A_MIN, A_INC = 181, -math.pi / 2, math.radians(1.0)
LASER = np.array([0.2, -0.1, 0.3])  # a planar mount (x, y, yaw)


def scan(t: float, ranges, a_min: float = A_MIN, a_inc: float = A_INC, **kw) -> SimpleNamespace:
    """A LaserScan log message stamped ``t``."""
    msg = M.laser_scan(t, "laser", np.asarray(ranges, dtype=float), a_min, a_inc, **kw)
    return SimpleNamespace(topic="/scan", msg=msg)


def beam_ranges(n: int = N, a_min: float = A_MIN, a_inc: float = A_INC) -> np.ndarray:
    """A range that tells each beam's angle: 2 m + 1 m per radian (float32-exact enough)."""
    return 2.0 + (a_min + np.arange(n) * a_inc + math.pi)


def read(msgs, step: int = 1, laser=LASER, first=None) -> tuple[list, RingStats, object]:
    """The rings of ``msgs`` on the geometry of ``first`` (default the first message)."""
    geom = scan_geometry((first or msgs[0]).msg, step)
    st = RingStats()
    return list(scan_rings(msgs, geom, math.radians(1.0), st, laser)), st, geom


# --- one geometry: float32 jitter ----------------------------------------------------------


def test_jittering_angles_are_the_first_scans_geometry() -> None:
    """angle_min off by up to 2e-5 rad and an increment whose last beam is off by less
    than ANGLE_TOL: the same beams and mounts, nothing resampled or refused; a shift of
    ten times ANGLE_TOL is another geometry."""
    jitter = ANGLE_TOL / 5 / (N - 1)
    msgs = [
        scan(1.0 + k, beam_ranges(), A_MIN + 1e-5 * (k % 3), A_INC + jitter * (k % 2))
        for k in range(6)
    ]
    rings, st, geom = read(msgs, step=3)
    assert len(rings) == 6 and st.extra["bad_scans"] == 0 and st.extra["resampled_scans"] == 0
    for r in rings:
        assert r.mounts is None  # the sensor's mounts
        np.testing.assert_allclose(r.ranges, beam_ranges()[geom.kept], atol=1e-5)
    shifted = scan(9.0, beam_ranges(), A_MIN + 10 * ANGLE_TOL)
    assert not geom.matches(shifted.msg) and geom.matches(msgs[1].msg)


# --- another beam count ------------------------------------------------------------------


@pytest.mark.parametrize("step", [1, 4])
def test_alternating_beam_counts_keep_one_ring_of_m_beams(step: int) -> None:
    """180 / 179 beams alternating (an RPLidar): every scan a ring of the first scan's M
    beams, the short scans' last kept beam NaN (``missing``) only where the 179 beams do
    not reach it, the others the same ranges as a full scan; no own mounts (the beams lie
    at the kept angles)."""
    n = 180
    msgs = [scan(1.0 + k, beam_ranges(n - k % 2, A_MIN)) for k in range(8)]
    rings, st, geom = read(msgs, step)
    assert len(rings) == 8 and st.extra["bad_scans"] == 0
    assert st.extra["resampled_scans"] == 4
    full = beam_ranges(n)[geom.kept]
    lost = geom.kept == n - 1  # the 180th beam, kept only when step divides 179
    assert st.missing == 4 * int(lost.sum())
    for k, r in enumerate(rings):
        assert r.ranges.shape == (len(geom.kept),) and r.mounts is None
        gone = lost if k % 2 else np.zeros_like(lost)
        assert np.isnan(r.ranges[gone]).all()
        np.testing.assert_allclose(r.ranges[~gone], full[~gone], atol=1e-5)


def test_a_first_scan_one_beam_short_reads_every_later_scan() -> None:
    """Only the first scan short (179 beams, the others 180): all scans read, on the
    first scan's 179 beams (the audit's case: 439 of 440 dropped, a map without
    references)."""
    msgs = [scan(1.0, beam_ranges(179))] + [scan(2.0 + k, beam_ranges(180)) for k in range(5)]
    rings, st, geom = read(msgs)
    assert len(rings) == 6 and st.extra["bad_scans"] == 0 and st.missing == 0
    assert all(len(r.ranges) == geom.beams == 179 for r in rings)
    for r in rings:
        np.testing.assert_allclose(r.ranges, beam_ranges(179), atol=1e-5)


# --- other angles: their own mounts ------------------------------------------------------


def test_shifted_angles_read_onto_the_kept_beams_with_their_own_mounts() -> None:
    """A scan whose beams sit 0.3 increments off the first scan's: each kept beam takes
    the nearest beam, placed at that beam's own angle by the laser mount (a planar one,
    and one upside down: heading ``yaw - angle``); the kept beam beyond its last beam
    reads NaN."""
    shift = 0.3 * A_INC
    msgs = [scan(1.0, beam_ranges()), scan(2.0, beam_ranges(N - 1, A_MIN + shift), A_MIN + shift)]
    rings, st, _ = read(msgs)
    own = rings[1].mounts
    assert rings[0].mounts is None and own is not None and own.shape == (N, 3)
    angles = A_MIN + shift + np.arange(N) * A_INC
    # kept beam k takes the shifted beam k (0.3 increments away), the last one beam k-1
    # would be 0.7 away: none is nearer than half an increment to the last kept beam
    beams = compose(LASER, np.c_[np.zeros((N - 1, 2)), angles[:-1]])
    np.testing.assert_allclose(own[:-1], beams, atol=1e-6)  # float32 angles
    np.testing.assert_allclose(rings[1].ranges[:-1], beam_ranges(N - 1, A_MIN + shift), atol=1e-5)
    assert np.isnan(rings[1].ranges[-1]) and st.missing == 1
    # upside down (roll pi) at yaw 0.4: beam a heads 0.4 - a
    flipped = Rigid.planar(0.1, 0.0, 0.4).compose(Rigid(np.zeros(3), np.diag([1.0, -1.0, -1.0])))
    rings, *_ = read(msgs, laser=flipped)
    heading = np.angle(np.exp(1j * (0.4 - angles[:-1])))
    np.testing.assert_allclose(rings[1].mounts[:-1, 2], heading, atol=1e-6)


def test_a_coarser_scan_uses_each_of_its_beams_once() -> None:
    """A scan of 2-degree beams read onto 1-degree kept beams: each of its beams serves
    the one kept beam within half a degree (none twice), the kept beams between read NaN."""
    coarse = scan(2.0, beam_ranges(91, A_MIN, 2 * A_INC), A_MIN, 2 * A_INC)
    rings, st, _ = read([scan(1.0, beam_ranges()), coarse])
    r = rings[1]
    got = np.isfinite(r.ranges)
    assert got.sum() == 91 and st.missing == N - 91
    np.testing.assert_array_equal(np.flatnonzero(got), np.arange(0, N, 2))
    np.testing.assert_allclose(r.ranges[got], beam_ranges()[got], atol=1e-5)


def test_a_resampled_scan_with_time_increment_is_at_its_last_beam() -> None:
    """Beams 1 ms apart: a resampled scan (170 beams shifted 0.3 increments) is at its
    last beam taken, each kept beam's offset its own beam's time before that, NaN where
    none."""
    ti = 1e-3
    msgs = [
        scan(1.0, beam_ranges(), time_increment=ti),
        scan(2.0, beam_ranges(170, A_MIN + 0.3 * A_INC), A_MIN + 0.3 * A_INC, time_increment=ti),
    ]
    rings, *_ = read(msgs, step=2)
    r = rings[1]
    # kept beams are the even ones; kept beam 170 takes beam 169 (0.7 increments away,
    # nearer than half the kept spacing of 2), the later ones none: the last taken is 169
    assert r.t == pytest.approx(2.0 + 169 * ti)
    off = r.offsets
    assert np.isnan(off[86:]).all()
    np.testing.assert_allclose(off[:86], (np.r_[np.arange(0, 170, 2), 169] - 169) * ti)


def test_a_scan_with_one_beam_read_is_at_that_beams_time() -> None:
    """Beams 1 ms apart, a scan of three 1-rad beams of which only the third is in the
    first scan's view: its ring is at that beam's time (stamp + 2 ms), not the stamp."""
    ti, d = 1e-3, 1.0
    a_min = A_MIN + 10 * A_INC - 2 * d
    msgs = [
        scan(1.0, beam_ranges(), time_increment=ti),
        scan(2.0, beam_ranges(3, a_min, d), a_min, d, time_increment=ti),
    ]
    rings, st, _ = read(msgs)
    r = rings[1]
    assert np.count_nonzero(np.isfinite(r.ranges)) == 1 and st.extra["resampled_scans"] == 1
    assert r.t == pytest.approx(2.0 + 2 * ti, abs=1e-9) and r.offsets is None


# --- refused scans -----------------------------------------------------------------------


def test_refused_scans_are_counted_said_and_lost(capsys) -> None:
    """Scans with no beam in the first scan's field of view or a range_max that is not a
    positive number: counted (``bad_scans``), the first one's stamp kept, said in one
    line on stderr when more than FEW_REFUSED; a run counts them as lost events when
    they are more than LOST_SHARE of the scans."""
    good = [scan(1.0 + k, beam_ranges()) for k in range(10)]
    off_fov = [scan(20.0 + k, np.ones(50), 2.0, 0.01) for k in range(FEW_REFUSED)]
    no_max = [scan(30.0, beam_ranges(), range_max=math.nan)]
    rings, st, _ = read(good + off_fov + no_max)
    assert len(rings) == 10 and st.extra["bad_scans"] == FEW_REFUSED + 1
    assert st.first_refused_at == pytest.approx(20.0)
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and f"/scan: {FEW_REFUSED + 1} laser scans refused" in err[0]
    # a few: no line
    read(good + off_fov[:FEW_REFUSED])
    assert capsys.readouterr().err == ""
    counts = SimpleNamespace(frames_stale_odometry=0, frames=100, odometry=1000)
    lost = {"frames": 0, "readings": 0}
    assert lost_events(LateEvents(), counts, lost, st.readings, st) == ("events_lost", 20.0)
    assert lost_events(LateEvents(), counts, lost, st.readings) is None  # no stats: unseen
    few = RingStats(rings=1000, extra={"bad_scans": int(LOST_SHARE * 1000) - 1})
    few.first_refused_at = 5.0
    assert lost_events(LateEvents(), counts, lost, 0, few) is None


# --- the map stage on the real excerpt ---------------------------------------------------


def rewrite_scans(dst: Path, change) -> Path:
    """The excerpt with each /scan message replaced by ``change(k, msg)``."""
    count = [0]

    def fault(m):
        msg = m.msg
        if m.topic == "/scan":
            msg = change(count[0], msg)
            count[0] += 1
        return [(m.topic, m.typename, msg, m.t)]

    return rewrite(EXCERPT / "log.mcap", dst, fault)


def rescan(msg, ranges, a_min):
    """A copy of a LaserScan with other ranges and angle_min."""
    return M.laser_scan(
        M.stamp_to_sec(msg.header.stamp), msg.header.frame_id, ranges, a_min,
        float(msg.angle_increment), float(msg.range_min), float(msg.range_max),
    )  # fmt: skip


def fgm_masses(out: Path) -> np.ndarray:
    with np.load(out / "fgm.npz") as z:
        return np.stack([z[k] for k in ("m_e", "m_o", "m_t", "m_c")])


def map_of(log: Path, out: Path) -> tuple[int, str, str]:
    return cli(
        "map", log, "--trajectory", EXCERPT / "truth.tum", "--config", "real_building_scan",
        "--ranges", "scan", "--no-figures", "-o", out,
    )  # fmt: skip


@pytest.fixture(scope="module")
def clean_map(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("clean") / "fgm"
    code, _, err = map_of(EXCERPT / "log.mcap", out)
    assert code == 0, err
    return out


def test_an_rplidar_like_log_maps_as_the_clean_one(
    tmp_path: Path, clean_map: Path, monkeypatch
) -> None:
    """The first scan one beam short and every other scan too (360 / 359 beams): the map
    stage reads every scan and, the lost last beam never kept by ``scan_step`` 4, builds
    exactly the clean log's map; its progress line says laser scans."""

    def short(k, msg):
        r = np.asarray(msg.ranges)
        return rescan(msg, r[:-1] if k % 2 == 0 else r, float(msg.angle_min))

    log = rewrite_scans(tmp_path / "short.mcap", short)
    monkeypatch.delenv("FUZZYSLAM_NO_PROGRESS", raising=False)  # progress lines on
    code, out, err = map_of(log, tmp_path / "fgm")
    assert code == 0, err
    np.testing.assert_array_equal(fgm_masses(tmp_path / "fgm"), fgm_masses(clean_map))
    assert json.loads(out)["sonar_stats"]["resampled_scans"] > 0
    assert "map: fusing laser scans" in err and "sonar rings" not in err


def test_scans_of_shifted_angles_are_placed_by_their_own_mounts(tmp_path: Path) -> None:
    """Every other scan's beams 0.4 increments further left: the map stage reads all of
    them, each shifted scan's mounts (N, M, 3) its kept beams turned by the shift (a
    laser mounted flat), the others the sensor's; and it maps."""
    cfg = load_config("real_building_scan")

    def shift(k, msg):
        a0 = float(msg.angle_min) + (0.4 * float(msg.angle_increment) if k % 2 else 0.0)
        return rescan(msg, np.asarray(msg.ranges), a0)

    log = rewrite_scans(tmp_path / "shift.mcap", shift)
    reader = LogReader(log)
    times, rr, _rmax, _fov, mounts, stats, _off = build.read_rings_compact(
        reader, cfg, np.inf, "scan"
    )
    assert stats.extra["bad_scans"] == 0 and stats.extra["resampled_scans"] == len(times) // 2
    assert mounts.ndim == 3 and mounts.shape[0] == len(times)
    inc = float(next(iter(reader.messages(["/scan"]))).msg.angle_increment)
    turn = np.angle(np.exp(1j * (mounts[1] - mounts[0])[:, 2]))
    np.testing.assert_allclose(turn[np.isfinite(rr[1])], 0.4 * inc, atol=1e-6)
    np.testing.assert_array_equal(mounts[0], mounts[2])
    code, _, err = map_of(log, tmp_path / "fgm")
    assert code == 0, err
