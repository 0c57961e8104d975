"""The figures do not depend on the user's matplotlib settings: with MPLCONFIGDIR holding a
matplotlibrc (fonts, grid, colours, line widths), every PNG is byte for byte the one of a
default environment (fuzzyslam/figsave.py ``figure_style``: the project's style on
matplotlib's defaults, not on the user's rcParams)."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import matplotlib
import pytest

from fuzzyslam import figsave

ROOT = Path(__file__).resolve().parents[1]
MICRO = ROOT / "tests" / "micro.yaml"

# a user's settings that change every figure drawn on them: fonts, grid, colours, lines
USER_RC = """\
font.size: 13
font.family: serif
axes.grid: True
grid.color: red
grid.linewidth: 2
lines.linewidth: 3.5
lines.markersize: 11
axes.prop_cycle: cycler('color', ['ff00ff', '00ff00', '0000ff'])
axes.facecolor: eeeeee
axes.titleweight: bold
legend.frameon: False
image.cmap: magma
"""

# figures of evaluate and map drawn on small synthetic inputs (a real log's truth,
# an estimate in its own frame, a belief map): printed after them, axes.grid outside the
# figures' style (True where the user's matplotlibrc was read)
DRAW = textwrap.dedent(
    """
    import sys
    from pathlib import Path

    import matplotlib
    import numpy as np

    from fuzzyslam.evaluation import figures as ef
    from fuzzyslam.evaluation.core import Estimate, Truth, evaluate
    from fuzzyslam.evaluation.params import EvalParams
    from fuzzyslam.maps import figures as mf
    from fuzzyslam.maps.grid import BeliefMap, Grid

    out = Path(sys.argv[1])
    t = 1.6e9 + np.arange(0.0, 60.0, 0.5)
    a = t - t[0]
    xy = np.column_stack([3.0 * np.cos(a / 12.0) + 1.0, 2.0 * np.sin(a / 9.0) - 0.5])
    heading = np.arctan2(np.gradient(xy[:, 1]), np.gradient(xy[:, 0]))
    truth = Truth(t, np.column_stack([xy, heading]), source="/data/mrclam6/log.mcap")
    truth.landmarks = np.array([[4.5, 2.0], [-2.5, -3.0], [1.0, 3.5]])
    noise = np.random.default_rng(3).normal(0.0, 0.02, xy.shape)
    est = Estimate(t.copy(), np.column_stack([xy + noise, heading]),
                   odometry=(t.copy(), np.column_stack([xy * 1.05, heading])),
                   landmarks=truth.landmarks + 0.05, label="run")
    est.cov = np.tile(np.diag([0.01, 0.01, 0.001]), (t.size, 1, 1))
    ev = evaluate(truth, est, EvalParams(), align=True)
    ef.fig1_paths(out / "fig1_paths.png", truth, est, None, ev.lamp_match, to_truth=ev.to_truth)
    ef.fig3_errors(out / "fig3_errors.png", truth, ev)
    fgm = BeliefMap.vacuous(Grid((-5.0, -2.0), 0.1, (60, 150)))
    fgm.m_c[10:20, 30:40] = 0.4
    mf.fig_conflict(out / "conflict.png", fgm, log="/data/aces/log.mcap")
    print(matplotlib.rcParams["axes.grid"])
    """
)


def environments(tmp_path: Path) -> dict[str, dict[str, str]]:
    """The environment of a default session and of a user's with a matplotlibrc in
    MPLCONFIGDIR, each with a config directory of its own (the font cache copied, when
    there is one: no rebuild) and no other matplotlibrc (MATPLOTLIBRC unset; the
    commands run in an empty directory, where matplotlib looks first).

    Parameters
    ----------
    tmp_path : Path
        A test's temporary directory.

    Returns
    -------
    dict
        ``{"default": env, "user": env}``.
    """
    cache = Path(matplotlib.get_cachedir())
    envs = {}
    for name in ("default", "user"):
        conf = tmp_path / f"mpl_{name}"
        conf.mkdir()
        for f in cache.glob("fontlist-*.json"):
            shutil.copy(f, conf / f.name)
        if name == "user":
            (conf / "matplotlibrc").write_text(USER_RC, encoding="utf-8")
        env = {k: v for k, v in os.environ.items() if k not in ("MATPLOTLIBRC", "MPLBACKEND")}
        env.update(MPLCONFIGDIR=str(conf), FUZZYSLAM_NO_PROGRESS="1")
        envs[name] = env
    return envs


def run_both(tmp_path: Path, commands: list[list[str]]) -> dict[str, Path]:
    """Run ``commands`` (``{out}`` in an argument: the environment's output directory) in
    the default and the user's environment side by side, from an empty directory each.

    Parameters
    ----------
    tmp_path : Path
        A test's temporary directory.
    commands : list of list of str
        Command lines, run one after the other in each environment.

    Returns
    -------
    dict
        ``{"default": output directory, "user": output directory}``; the last command's
        stdout is in ``stdout.txt`` there.
    """
    outs = {}
    procs = {}
    for name, env in environments(tmp_path).items():
        out = tmp_path / name
        (out / "cwd").mkdir(parents=True)
        outs[name] = out
        script = " && ".join(
            subprocess.list2cmdline([a.replace("{out}", str(out)) for a in cmd]) for cmd in commands
        )
        procs[name] = subprocess.Popen(
            ["sh", "-c", f"{script} > {out}/stdout.txt"],
            cwd=out / "cwd",
            env=env,
            stderr=subprocess.PIPE,
            text=True,
        )
    for name, p in procs.items():
        _, err = p.communicate(timeout=600)
        assert p.returncode == 0, (name, err)
    return outs


def assert_same_pngs(outs: dict[str, Path], expected: set[str]) -> None:
    """The PNG files under the two output directories: the same names (``expected``
    among them) and the same bytes.

    Parameters
    ----------
    outs : dict
        :func:`run_both`'s output directories.
    expected : set of str
        PNG file names that must be there.
    """
    found = {
        name: {p.relative_to(out): p.read_bytes() for p in sorted(out.rglob("*.png"))}
        for name, out in outs.items()
    }
    assert expected <= {p.name for p in found["default"]}, sorted(found["default"])
    assert found["user"].keys() == found["default"].keys()
    differ = [str(p) for p, b in found["default"].items() if found["user"][p] != b]
    assert not differ, f"the user's matplotlibrc changed {differ}"


def test_the_style_starts_from_matplotlibs_defaults() -> None:
    """Inside the figures' style, every setting of the picture is matplotlib's default or
    the project's (:data:`figsave.STYLE`), whatever was set before; the backend is left
    as it was, and everything is restored after."""
    user = {
        "axes.grid": True,
        "lines.linewidth": 3.5,
        "font.family": ["serif"],
        "axes.prop_cycle": matplotlib.cycler(color=["#ff00ff", "#00ff00"]),
    }
    backend = matplotlib.get_backend()
    with matplotlib.rc_context(user):
        before = dict(matplotlib.rcParams)
        with figsave.figure_style():
            rc = matplotlib.rcParams
            assert rc["axes.grid"] is False
            assert rc["font.family"] == matplotlib.rcParamsDefault["font.family"]
            assert rc["axes.prop_cycle"] == matplotlib.rcParamsDefault["axes.prop_cycle"]
            for key, value in figsave.STYLE.items():
                assert rc[key] == value, key
            assert matplotlib.get_backend() == backend
        assert dict(matplotlib.rcParams) == before


@pytest.mark.slow  # end to end in subprocesses (the fast tier's minute)
def test_a_users_matplotlibrc_changes_no_evaluation_or_map_figure(tmp_path) -> None:
    """evaluate's Fig. 1 and Fig. 3 and map's conflict.png drawn with a user's matplotlibrc
    in MPLCONFIGDIR are byte for byte those of a default environment (every figure of the
    commands: the slow test below)."""
    outs = run_both(tmp_path, [[sys.executable, "-c", DRAW, "{out}"]])
    # the user's matplotlibrc was read (else the test proves nothing)
    assert (outs["user"] / "stdout.txt").read_text().split() == ["True"]
    assert (outs["default"] / "stdout.txt").read_text().split() == ["False"]
    assert_same_pngs(outs, {"fig1_paths.png", "fig3_errors.png", "conflict.png"})


@pytest.mark.slow  # end to end in subprocesses (the fast tier's minute)
def test_a_users_matplotlibrc_changes_no_simulate_preview(tmp_path) -> None:
    """``fuzzyslam simulate --preview``'s PNG with a user's matplotlibrc is byte for byte
    the default environment's."""
    cmd = [
        sys.executable,
        "-m",
        "fuzzyslam",
        "simulate",
        str(MICRO),
        "-o",
        "{out}/s.mcap",
        "--preview",
        "{out}/sim.png",
    ]
    outs = run_both(tmp_path, [cmd])
    assert_same_pngs(outs, {"sim.png"})


@pytest.mark.slow
def test_a_users_matplotlibrc_changes_no_png_of_the_commands(tmp_path) -> None:
    """Every PNG of simulate, map, run (changes.png, drawn in the run's forked figure
    process) and evaluate, with a user's matplotlibrc, is byte for byte the default
    environment's."""
    fz = [sys.executable, "-m", "fuzzyslam"]
    commands = [
        [*fz, "simulate", str(MICRO), "-o", "{out}/s.mcap", "--preview", "{out}/sim.png"],
        [*fz, "run", "{out}/s.mcap", "-o", "{out}/run"],
        [
            *fz,
            "map",
            "{out}/s.mcap",
            "--trajectory",
            "{out}/run/trajectory.tum",
            "-o",
            "{out}/fgm",
        ],
        [*fz, "run", "{out}/s.mcap", "--map", "{out}/fgm", "--fix", "pose", "-o", "{out}/pose"],
        [
            *fz,
            "evaluate",
            "{out}/s.mcap",
            "{out}/pose",
            "--map",
            "{out}/fgm",
            "--compare",
            "{out}/run",
            "-o",
            "{out}/ev",
        ],
    ]
    outs = run_both(tmp_path, commands)
    assert_same_pngs(
        outs,
        {
            "sim.png",
            "fgm.png",
            "conflict.png",
            "hough.png",
            "changes.png",
            "fig1_paths.png",
            "fig3_errors.png",
            "compare.png",
        },
    )
