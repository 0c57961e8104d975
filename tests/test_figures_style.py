"""The figures' audit fixes, on small synthetic inputs (fast): Fig. 1 in the truth's frame
with the evaluation's alignment, time axes from the log's start, the shared print style
(fonts, widths, dpi), landmarks called landmarks on real logs, hough.png's strongest
corridors and max-pooled walls, conflict.png's colour bar, the sweep's ticks, log axes
from the data."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
import pytest
from PIL import Image

from fuzzyslam import figsave
from fuzzyslam.evaluation import figures as ef
from fuzzyslam.evaluation.core import Estimate, Truth, evaluate
from fuzzyslam.evaluation.params import EvalParams
from fuzzyslam.maps import figures as mf
from fuzzyslam.maps.grid import BeliefMap, Grid

T0 = 1.6e9  # a real log's Unix stamps


def _capture(monkeypatch, module, name: str = "_save") -> list:
    """The figures ``module`` draws, kept open (its saving function ``name`` still writes
    the PNG)."""
    figs: list = []
    real = getattr(module, name)

    def keep(fig, path, *args, **kwargs):
        figs.append(fig)
        fig.canvas.draw()
        real_close = plt.close
        monkeypatch.setattr(plt, "close", lambda *_a, **_k: None)
        try:
            real(fig, path, *args, **kwargs)
        finally:
            monkeypatch.setattr(plt, "close", real_close)

    monkeypatch.setattr(module, name, keep)
    return figs


def _rot(theta: float) -> np.ndarray:
    c, s = np.cos(theta), np.sin(theta)
    return np.array([[c, -s], [s, c]])


def _real_case(noise: float = 0.02) -> tuple[Truth, Estimate]:
    """A real log's truth (Unix stamps, true landmarks, no world) and an estimate in its
    own odometry frame: the truth moved by 2.5 m and 30 deg, with a little noise."""
    rng = np.random.default_rng(3)
    t = T0 + np.arange(0.0, 120.0, 0.5)
    a = t - T0
    truth_xy = np.column_stack([3.0 * np.cos(a / 12.0) + 1.0, 2.0 * np.sin(a / 9.0) - 0.5])
    heading = np.arctan2(np.gradient(truth_xy[:, 1]), np.gradient(truth_xy[:, 0]))
    truth = Truth(t, np.column_stack([truth_xy, heading]), source="/data/mrclam6/log.mcap")
    truth.landmarks = np.array([[4.5, 2.0], [-2.5, -3.0], [1.0, 3.5]])
    r, shift = _rot(np.deg2rad(30.0)), np.array([2.5, -1.0])
    inv = r.T
    est_xy = (truth_xy - shift) @ inv.T + rng.normal(0.0, noise, truth_xy.shape)
    est_lm = (truth.landmarks - shift) @ inv.T + 0.05
    est = Estimate(t.copy(), np.column_stack([est_xy, heading - np.deg2rad(30.0)]),
                   odometry=(t.copy(), np.column_stack([est_xy * 1.05, heading])),
                   landmarks=est_lm, label="mr_run")  # fmt: skip
    return truth, est


def _line(ax, label: str):
    lines = [ln for ln in ax.get_lines() if ln.get_label() == label]
    assert lines, [ln.get_label() for ln in ax.get_lines()]
    return np.column_stack([np.asarray(v, dtype=float) for v in lines[0].get_data()])


@pytest.mark.slow
def test_fig1_draws_the_estimate_in_the_truth_frame_with_the_evaluations_alignment(
    tmp_path, monkeypatch
) -> None:
    truth, est = _real_case()
    ev = evaluate(truth, est, EvalParams(), align=True)
    ape = float(np.sqrt(np.mean(np.sum(ev.errors[:, :2] ** 2, axis=1))))
    assert ape < 0.1 and ev.to_truth is not None
    figs = _capture(monkeypatch, ef)
    ef.draw_all(tmp_path, truth, est, ev, None)
    fig = figs[0]
    ax = fig.axes[0]
    drawn_est, drawn_truth = _line(ax, "estimate"), _line(ax, "true path")
    # the same samples: the drawn estimate lies on the drawn truth within the APE
    d = np.hypot(*(drawn_est - drawn_truth).T)
    assert np.sqrt(np.mean(d**2)) <= ape + 1e-9
    # the estimated and the true landmarks: drawn, inside the axes, named landmarks
    labels = [c.get_label() for c in ax.collections]
    assert "true landmarks" in labels and "estimated landmarks" in labels
    (x0, x1), (y0, y1) = ax.get_xlim(), ax.get_ylim()
    for c in ax.collections:
        xy = np.asarray(c.get_offsets())
        assert ((xy[:, 0] >= x0) & (xy[:, 0] <= x1) & (xy[:, 1] >= y0) & (xy[:, 1] <= y1)).all()
    assert "log.mcap" in ax.get_title() and "mr_run" in ax.get_title()
    assert "lamp" not in " ".join(t.get_text() for t in ax.get_legend().get_texts())


def test_fig1_without_alignment_draws_the_estimate_as_written(tmp_path, monkeypatch) -> None:
    """A simulated log's frames agree: no alignment, the estimate drawn as the run wrote it."""
    truth, est = _real_case()
    ev = evaluate(truth, est, EvalParams(), align=False)
    assert ev.to_truth is None
    figs = _capture(monkeypatch, ef)
    ef.fig1_paths(tmp_path / "f.png", truth, est, None, ev.lamp_match, to_truth=ev.to_truth)
    np.testing.assert_allclose(_line(figs[0].axes[0], "estimate"), est.poses[:, :2])


@pytest.mark.parametrize("name", ["fig3", "consistency", "compare"])
def test_time_axes_start_at_the_logs_start(tmp_path, monkeypatch, name) -> None:
    truth, est = _real_case()
    n = est.t.size
    est.cov = np.tile(np.diag([0.01, 0.01, 0.001]), (n, 1, 1))
    ev = evaluate(truth, est, EvalParams(), align=True)
    figs = _capture(monkeypatch, ef)
    if name == "fig3":
        ef.fig3_errors(tmp_path / "f.png", truth, ev)
    elif name == "consistency":
        assert ef.fig_consistency(tmp_path / "f.png", truth, est, ev)
    else:
        ef.fig_compare(tmp_path / "f.png", truth, [("a", ev), ("b", ev)])
    fig = figs[0]
    ax = fig.axes[-1] if name != "consistency" else fig.axes[0]
    x = np.concatenate([np.asarray(ln.get_xdata(), dtype=float) for ln in ax.get_lines()
                        if ln.get_transform() == ax.transData])  # fmt: skip
    assert x.min() == pytest.approx(0.0, abs=1.0) and x.max() < 200.0
    assert fig.axes[-1].get_xlabel() == "time since the log's start (s)"


def test_an_estimate_kind_has_one_style_in_summary_and_compare(tmp_path, monkeypatch) -> None:
    """summary.png and compare.png style an estimate by its kind (figsave.ESTIMATE_KINDS):
    the run directories of the summary's panels and of the compare figures' labels get the
    same colour, dashes and marker; heading and pose fixes differ in all three; labels of
    no kind take colours no kind drawn uses."""
    from matplotlib.colors import to_hex

    from fuzzyslam.reproduce.plan import compare_label
    from fuzzyslam.reproduce.report import SUMMARY_PANELS

    def look(style: dict) -> tuple:
        return style["color"], style["ls"], style["marker"]

    for _log, _title, runs in SUMMARY_PANELS:
        for name, label in runs:
            assert look(figsave.series_styles([label])[0]) == look(
                figsave.series_styles([compare_label(name)])[0]
            ), (name, label)
    lamps, heading, pose = (look(figsave.ESTIMATE_KINDS[k][1])
                            for k in ("lamps only", "heading fixes", "pose fixes"))  # fmt: skip
    assert all(a != b for a, b in zip(heading, pose, strict=True))
    assert figsave.estimate_kind("all lamps off: no fixes") == "lamps only"
    assert figsave.estimate_kind("lamps only (A, B)") == "lamps only"
    other = figsave.series_styles(["x", "A+B: lamps only"])[0]["color"]
    assert other not in (lamps[0], heading[0], pose[0])
    # compare.png draws them so, whatever the order of its estimates
    truth, est = _real_case()
    ev = evaluate(truth, est, EvalParams(), align=True)
    figs = _capture(monkeypatch, ef)
    ef.fig_compare(tmp_path / "f.png", truth,
                   [("C: heading fixes (paper)", ev), ("A+B: lamps only", ev)])  # fmt: skip
    lines = {ln.get_label(): ln for ln in figs[0].axes[0].get_lines()}
    assert to_hex(lines["A+B: lamps only"].get_color()) == to_hex(lamps[0])
    assert lines["C: heading fixes (paper)"].get_marker() == heading[2]


def test_fig3_legend_lies_under_the_axes(tmp_path, monkeypatch) -> None:
    """fig3's legend of the error and its band is the figure's, under the axes (over no
    data, no band and no run label)."""
    truth, est = _real_case()
    est.cov = np.tile(np.diag([0.01, 0.01, 0.001]), (est.t.size, 1, 1))
    ev = evaluate(truth, est, EvalParams(), align=True)
    figs = _capture(monkeypatch, ef)
    ef.fig3_errors(tmp_path / "f.png", truth, ev)
    fig = figs[0]
    assert all(ax.get_legend() is None for ax in fig.axes)
    (leg,) = fig.legends
    assert {t.get_text() for t in leg.get_texts()} >= {"±2σ (filter)", "estimate − truth"}
    renderer = fig.canvas.get_renderer()
    assert leg.get_window_extent(renderer).y1 < fig.axes[-1].get_window_extent(renderer).y0


def test_consistency_breaks_running_means_at_gaps_and_marks_values_below(
    tmp_path, monkeypatch
) -> None:
    """A kind's NIS running mean is not joined across a stretch without its updates (a NaN
    in the gap), and values under the log axis's floor are marked on its bottom edge."""
    from fuzzyslam.evaluation.core import Updates

    t, v = ef.break_gaps(np.array([0.0, 1.0, 2.0, 3.0, 50.0, 51.0]), np.ones(6))
    assert np.isnan(v).sum() == 1 and 3.0 < t[np.isnan(v)][0] < 50.0
    truth, est = _real_case()
    n = est.t.size
    est.cov = np.tile(np.diag([0.01, 0.01, 0.001]), (n, 1, 1))
    tu = np.concatenate([est.t[:40], est.t[-40:]])  # a gap in the middle
    nis = np.full(tu.size, 1.5)
    nis[5] = 0.0  # under any floor
    est.updates = Updates(t=tu, kind=np.array(["lamp"] * tu.size), id=np.zeros(tu.size, int),
                          dof=np.full(tu.size, 2), nis=nis,
                          accepted=np.ones(tu.size, bool))  # fmt: skip
    ev = evaluate(truth, est, EvalParams(), align=True)
    figs = _capture(monkeypatch, ef)
    assert ef.fig_consistency(tmp_path / "f.png", truth, est, ev)
    ax = figs[0].axes[1]
    mean = next(ln for ln in ax.get_lines() if ln.get_label() == "lamp, running mean")
    x, y = (np.asarray(a, dtype=float) for a in mean.get_data())
    gap = np.isnan(y)
    assert gap.sum() == 1 and tu[39] - T0 < x[gap][0] < tu[40] - T0
    edge = [ln for ln in ax.get_lines() if ln.get_marker() == "v"]
    assert edge and len(edge[0].get_xdata()) == 1
    assert "below the axis (on its edge)" in [t.get_text() for t in ax.get_legend().get_texts()]


def test_the_shared_style_sizes_text_for_print() -> None:
    with figsave.figure_style():
        rc = matplotlib.rcParams
        keys = ("font.size", "axes.titlesize", "axes.labelsize", "xtick.labelsize",
                "ytick.labelsize", "legend.fontsize")  # fmt: skip
        sizes = [rc[k] for k in keys]
        assert all(8.0 <= float(s) <= 9.0 for s in sizes), sizes
        assert rc["lines.linewidth"] >= 1.0
    assert figsave.COLUMN_W == pytest.approx(3.5, abs=0.1)
    assert figsave.WIDE_W <= 7.2 and figsave.PRINT_DPI >= 300


@pytest.mark.slow  # end to end, about 1 s: the fast tier stays under a minute
def test_evaluation_figures_are_print_sized(tmp_path, monkeypatch) -> None:
    """Every figure of evaluate: at most double-column wide (single column for Fig. 1, 3,
    4), its text 8-9 pt, written at 300 dpi."""
    truth, est = _real_case()
    est.cov = np.tile(np.diag([0.01, 0.01, 0.001]), (est.t.size, 1, 1))
    ev = evaluate(truth, est, EvalParams(), align=True)
    figs = _capture(monkeypatch, ef)
    out = ef.draw_all(tmp_path, truth, est, ev, None)
    ef.fig4_lamp_errors(tmp_path / "fig4.png", {"run": np.array([0.1, np.nan, 0.2])},
                        noun="landmark")  # fmt: skip
    assert {"fig1", "fig3", "consistency"} <= set(out)
    for fig in figs:
        w = fig.get_size_inches()[0]
        assert w <= figsave.WIDE_W + 1e-9
        for text in fig.findobj(matplotlib.text.Text):
            if text.get_text().strip() and text.get_visible():
                assert 7.0 <= text.get_fontsize() <= 9.0, (text.get_text(), text.get_fontsize())
    for name in ("fig1_paths.png", "fig3_errors.png", "fig4.png"):
        im = Image.open(tmp_path / name)
        assert im.info["dpi"][0] == pytest.approx(300, abs=0.5)
        assert im.size[0] <= 3.7 * 300  # one column (the crop keeps it narrower)
    assert figs[-1].axes[0].get_xlabel().startswith("true landmark index")


def test_landmark_noun() -> None:
    truth, _est = _real_case()
    assert ef.landmark_noun(truth) == "landmarks"


def test_log_floor_follows_the_data() -> None:
    v = np.concatenate([np.linspace(1.0, 100.0, 1000), [1e-7]])
    floor = ef.log_floor(v)
    assert 0.4 < floor < 1.0  # not 1e-7: the 1st percentile over two
    assert ef.log_floor(np.zeros(3)) == 1e-3


def _fgm(shape=(120, 300), res=0.1) -> BeliefMap:
    grid = Grid((-5.0, -2.0), res, shape)
    m = BeliefMap.vacuous(grid)
    m.m_c[10:20, 30:40] = 0.4
    return m


def test_conflict_colour_bar_matches_the_map(tmp_path, monkeypatch) -> None:
    figs = _capture(monkeypatch, mf)
    mf.fig_conflict(tmp_path / "c.png", _fgm(), log="/data/aces/log.mcap")
    fig = figs[0]
    ax = fig.axes[0]
    cax = ax.child_axes[0]  # an inset of the map's axes: as tall as they are
    fig.canvas.draw()
    a, c = ax.get_window_extent(), cax.get_window_extent()
    assert c.height == pytest.approx(a.height, abs=2.0)
    assert "m(∅)" in cax.get_ylabel()
    # the figure's shape follows the map's (wide map: a short figure)
    w, h = fig.get_size_inches()
    assert w <= figsave.COLUMN_W + 1e-9 and h < 0.8 * w
    assert "aces/log.mcap" in ax.get_title()


def test_max_pool_keeps_thin_walls() -> None:
    v = np.zeros((100, 400))
    v[50, :] = 1.0  # a wall one cell thick
    v[:, 201] = 0.5
    pooled, ext = mf.max_pool(v, (0.0, 40.0, 0.0, 10.0), 4)
    assert pooled.shape == (25, 100)
    assert pooled[12].min() == 1.0 and pooled[:, 50].min() >= 0.5
    assert ext == pytest.approx((0.0, 40.0, 0.0, 10.0))
    assert mf.pool_factor(400, 1.5, 300) == 2 and mf.pool_factor(40, 1.5, 300) == 1
    same, ext1 = mf.max_pool(v, (0.0, 40.0, 0.0, 10.0), 1)
    assert same is v and ext1 == (0.0, 40.0, 0.0, 10.0)


def test_hough_shows_the_strongest_references_only() -> None:
    class Ref:
        def __init__(self, k: int, strength: float) -> None:
            self.id, self.strength = k, strength

    refs = [Ref(k, s) for k, s in enumerate([1.0, 11.0, 0.5, 4.3, 2.0, 9.0])]
    kept = mf.strongest(refs)  # type: ignore[arg-type]
    assert [r.id for r in kept] == [1, 3, 5] and mf.HOUGH_REFS == 3


def test_hough_titles_say_what_the_strength_is() -> None:
    assert mf.strongest_title(4.987) == "strongest line: 4.99 m of wall"
    assert mf.strongest_title(0.18, "FLM: ") == "FLM: strongest line: 0.18 m of wall"
    fig, ax = plt.subplots()
    mf._hough_panel(ax, None, mf.strongest_title(0.0), {})
    assert ax.get_title() == "no wall evidence (no Hough plane)"
    plt.close(fig)


def test_fgm_true_lamps_are_rings_over_the_estimates(tmp_path, monkeypatch) -> None:
    """fgm.png: the true lamps hollow, larger and drawn over the estimated ones."""
    figs = _capture(monkeypatch, mf)
    world = type("W", (), {"lamps": [0, 1], "lamp_array": np.array([[1.0, 1.0], [2.0, 1.0]]),
                           "wall_array": np.zeros((0, 4))})()  # fmt: skip
    mf.fig_fgm(tmp_path / "f.png", _fgm(), np.zeros((2, 3)), [], world,  # type: ignore[arg-type]
               np.array([[1.0, 1.0], [2.0, 1.0]]))  # fmt: skip
    ax = figs[0].axes[0]
    true = next(ln for ln in ax.get_lines() if ln.get_label() == "true lamps")
    est = next(ln for ln in ax.get_lines() if ln.get_label().startswith("estimated"))
    assert true.get_markerfacecolor() == "none"
    assert true.get_markersize() > est.get_markersize() and true.get_zorder() > est.get_zorder()


def test_sweep_ticks_at_the_swept_values_on_a_log_axis(tmp_path, monkeypatch) -> None:
    from fuzzyslam.reproduce import sweep_plot

    values = [0.001, 0.01, 0.1]
    rows = [{"values": {"robot.wheel_noise": v},
             "measures": {m: {"mean": 1.0 + v, "min": 0.5, "max": 2.0, "n": 2}
                          for m in ("a (cm)", "b (cm)", "c (deg)")}} for v in values]  # fmt: skip
    figs = _capture(monkeypatch, sweep_plot, "save_png")
    sweep_plot.plot_sweep(tmp_path, rows, ["robot.wheel_noise"], 2, "seeds")
    fig = figs[0]
    assert fig.get_size_inches()[0] <= figsave.WIDE_W + 1e-9
    for ax in fig.axes:
        assert ax.get_xscale() == "log"
        np.testing.assert_allclose(ax.get_xticks(), values)
    assert not sweep_plot.log_x([0.005, 0.02]) and sweep_plot.log_x([0.001, 0.1])


def test_a_sweep_over_two_keys_draws_a_plot_per_key(tmp_path) -> None:
    """Two swept keys: one PNG per key, each with a line per value of the other key (the
    second key's plot once failed: the layout reused the table rows' name)."""
    from fuzzyslam.reproduce import sweep_plot

    rows = [{"values": {"a.x": x, "b.y": y},
             "measures": {"e (cm)": {"mean": x + y, "min": x, "max": x + 2 * y, "n": 2}}}
            for x in (1.0, 2.0) for y in (10.0, 20.0, 30.0)]  # fmt: skip
    paths = sweep_plot.plot_sweep(tmp_path, rows, ["a.x", "b.y"], 2, "seeds")
    assert [p.name for p in paths] == ["sweep_a.x.png", "sweep_b.y.png"]
    assert all(p.stat().st_size > 1000 for p in paths)


def test_a_boolean_sweep_draws_categories_and_one_figure_legend(tmp_path, monkeypatch) -> None:
    """A boolean key: categorical ticks False, True (points, no joining line), one legend
    for the figure (none in the panels), room over the highest mark, "1 seed"."""
    from fuzzyslam.reproduce import sweep_plot

    rows = [{"values": {"slam.calibrate": c, "robot.wheel_noise": w},
             "measures": {m: {"mean": 0.3 + w + c, "min": 0.2, "max": 0.5 + w + c, "n": 1}
                          for m in ("a (cm)", "b (deg)")}}
            for c in (True, False) for w in (0.005, 0.02)]  # fmt: skip
    figs = _capture(monkeypatch, sweep_plot, "save_png")
    sweep_plot.plot_sweep(tmp_path, rows, ["slam.calibrate", "robot.wheel_noise"], 1, "seeds")
    fig = figs[0]
    assert len(fig.legends) == 1 and len(fig.legends[0].get_texts()) == 2
    assert "mean over 1 seed," in fig._suptitle.get_text()
    for ax in fig.axes:
        assert ax.get_legend() is None
        assert [t.get_text() for t in ax.get_xticklabels()] == ["False", "True"]
        for ln in ax.get_lines():
            if len(ln.get_xdata()) > 1:  # the means (the caps are markers alone too)
                assert ln.get_linestyle() == "None"
        assert ax.get_ylim()[1] > 0.5 + 0.02 + 1.0  # the highest bar inside, with room
    # the number line of the other key keeps its joining lines
    num = figs[1]
    assert any(ln.get_linestyle() == "-" for ln in num.axes[0].get_lines())
    assert len(num.legends) == 1


def test_sweep_labels_its_evaluations_with_the_grid_value_and_seed() -> None:
    from fuzzyslam.reproduce.sweep import sweep_steps

    steps = sweep_steps([("g0.yaml", {"robot.wheel_noise": 0.005})], [1])
    ev = next(s for s in steps if s.key.endswith("/eval"))
    assert "robot.wheel_noise=0.005, seed 1" in ev.argv


def test_changes_time_colour_bar_from_the_runs_start(tmp_path, monkeypatch) -> None:
    """changes.png's times are since the run's first ring (the detector's t_first), and
    its colour bar says so; the log is named in the title."""
    from fuzzyslam.fixes import changes

    cs = [changes.Change(T0 + 100.0 + k, 0.5 * k, 1.0, 0.3, 4, 0.5) for k in range(5)]
    assert not hasattr(changes, "save_png")  # imported inside the drawing function
    seen = _capture(monkeypatch, figsave, "save_png")
    changes.draw_changes(tmp_path / "changes.png", _fgm(), cs, t0=T0, log="people.mcap")
    fig = seen[0]
    sc = fig.axes[0].collections[0]
    assert np.asarray(sc.get_array()).min() == pytest.approx(100.0)
    assert fig.axes[0].child_axes[0].get_ylabel() == "time since the run's start (s)"
    assert fig.axes[0].get_title().endswith("\npeople.mcap")
    assert Image.open(tmp_path / "changes.png").size[0] <= figsave.COLUMN_W * 300 + 1
    assert fig.get_size_inches()[0] <= figsave.COLUMN_W + 1e-9
    assert Path(tmp_path / "changes.png").is_file()


def test_preview_bumps_have_a_legend_entry_over_the_lamps(tmp_path, monkeypatch) -> None:
    from types import SimpleNamespace

    from fuzzyslam.sim import preview

    t = np.arange(0.0, 10.0, 0.1)
    pose = np.column_stack([t, np.sin(t), np.zeros_like(t)])
    plan = SimpleNamespace(
        world=SimpleNamespace(wall_array=np.array([[0.0, -2.0, 10.0, -2.0]]),
                              lamp_array=np.array([[2.0, 1.0], [5.0, 1.0]])),
        drive=SimpleNamespace(pose=pose, dt=0.1, duration=10.0),
        encoders=SimpleNamespace(dead_reckoning=pose * 1.01),
        events=[SimpleNamespace(kind="bump", t=5.0),
                SimpleNamespace(kind="lamp_failure", t=2.0, lamps=[1])],
        start_pose=pose[0],
    )  # fmt: skip
    figs = _capture(monkeypatch, preview, "save_png")
    preview.save_preview(plan, tmp_path / "p.png", title="t")  # type: ignore[arg-type]
    ax = figs[0].axes[0]
    texts = [x.get_text() for x in ax.get_legend().get_texts()]
    assert "bump (1)" in texts and "lamp (failed)" in texts
    bump = next(ln for ln in ax.get_lines() if ln.get_label() == "bump (1)")
    assert bump.get_zorder() > max(c.get_zorder() for c in ax.collections)
    assert figs[0].get_size_inches()[0] <= figsave.COLUMN_W + 1e-9
    assert Image.open(tmp_path / "p.png").info["dpi"][0] == pytest.approx(300, abs=0.5)
