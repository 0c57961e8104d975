"""``sweep`` and ``reproduce`` inputs checked before anything is written: a bad config or
``--set`` value is one line naming the user's config or option (never a file the command
generates), exit 3, and no output folder; sweep's OUTDIR is absent, empty or a previous
sweep output, any other non-empty directory is refused. Fast: no pipeline step runs."""

from __future__ import annotations

from pathlib import Path

import pytest
from test_robust_logs import cli, error_lines

from fuzzyslam.errors import EXIT_INPUT, InputError


def _tree(folder: Path) -> list[str]:
    return sorted(str(p.relative_to(folder)) for p in folder.rglob("*"))


def _one_error(code: int, out: str, err: str) -> str:
    lines = error_lines(err)
    assert code == EXIT_INPUT, err
    assert out == "" and len(lines) == 1, err
    return lines[0]


def test_sweep_config_with_an_unknown_key_names_it_and_writes_nothing(tmp_path: Path) -> None:
    cfg = tmp_path / "unk.yaml"
    cfg.write_text("extends: quick.yaml\nrobot: {radiuss: 0.2}\n", encoding="utf-8")
    out = tmp_path / "C15"
    line = _one_error(*cli("sweep", cfg, "--set", "robot.wheel_noise=0.1", "--seeds", "1",
                           "-o", out))  # fmt: skip
    assert line.startswith(f"fuzzyslam: error: {cfg}: unknown key 'robot.radiuss'"), line
    assert not out.exists()


@pytest.mark.parametrize(
    ("option", "says"),
    [
        ("robot.wheel_noise=abc", "must be a number, got 'abc'"),
        ("robot.wheel_noise=0.1,abc", "must be a number, got 'abc'"),  # the second point
        ("robot.nope=1,2", "unknown key 'robot.nope'"),
        ("robot.wheel_noise=[1", "not YAML"),  # was an internal error (exit 1)
        ("robot.wheel_noise", "must be KEY=V1,V2"),
        ("extends=paper", "'extends' cannot be set"),
    ],
)
def test_sweep_bad_set_names_the_option_and_writes_nothing(
    option: str, says: str, tmp_path: Path
) -> None:
    out = tmp_path / "SWb"
    line = _one_error(*cli("sweep", "quick", "--set", option, "--seeds", "1", "-o", out))
    assert line.startswith(f"fuzzyslam: error: --set {option}: "), line
    assert says in line and "g0.yaml" not in line, line
    assert not out.exists()


def test_sweep_error_of_a_combination_names_every_option(tmp_path: Path) -> None:
    """Each value is fine alone; one grid point's camera is too large: all options named."""
    out = tmp_path / "sw"
    line = _one_error(*cli("sweep", "quick", "--set", "camera.width=4096",
                           "--set", "camera.height=4096", "--set", "camera.supersample=1,16",
                           "--seeds", "1", "-o", out))  # fmt: skip
    assert line.startswith(
        "fuzzyslam: error: --set camera.width=4096 --set camera.height=4096 "
        "--set camera.supersample=1,16: 'camera' width x height"
    ), line
    assert not out.exists()


def test_a_key_in_two_sets_is_refused(tmp_path: Path) -> None:
    out = tmp_path / "sw"
    twice = ("--set", "robot.wheel_noise=0.1", "--set", "robot.wheel_noise=0.2")
    line = _one_error(*cli("sweep", "quick", *twice, "--seeds", "1", "-o", out))
    assert "more than one --set" in line and not out.exists(), line
    line = _one_error(*cli("reproduce", "--quick", *twice, "--seeds", "1", "-o", out))
    assert "more than one --set" in line and not out.exists(), line


def test_sweep_of_a_config_extending_a_missing_one_names_it(tmp_path: Path) -> None:
    cfg = tmp_path / "ext.yaml"
    cfg.write_text("extends: nonexist\n", encoding="utf-8")
    out = tmp_path / "sw"
    line = _one_error(*cli("sweep", cfg, "--set", "robot.wheel_noise=0.1", "--seeds", "1",
                           "-o", out))  # fmt: skip
    assert line.startswith(f"fuzzyslam: error: {cfg}: extends 'nonexist': config not found"), line
    assert not out.exists()


def test_sweep_of_a_config_extending_a_file_is_refused_up_front(tmp_path: Path) -> None:
    """base.yaml in OUTDIR could not find the file it extends: refused, nothing written."""
    (tmp_path / "sub").mkdir()
    (tmp_path / "sub" / "ok.yaml").write_text("extends: quick.yaml\n", encoding="utf-8")
    cfg = tmp_path / "top.yaml"
    cfg.write_text("extends: sub/ok.yaml\n", encoding="utf-8")
    out = tmp_path / "sw"
    line = _one_error(*cli("sweep", cfg, "--set", "robot.wheel_noise=0.1", "--seeds", "1",
                           "-o", out))  # fmt: skip
    assert line.startswith(f"fuzzyslam: error: {cfg}: extends the file "), line
    assert not out.exists()


def test_reproduce_bad_set_names_the_option_not_a_generated_file(tmp_path: Path) -> None:
    out = tmp_path / "r"
    line = _one_error(*cli("reproduce", "--quick", "--set", "robot.nope=1", "--seeds", "1",
                           "-o", out))  # fmt: skip
    assert line.startswith("fuzzyslam: error: --set robot.nope=1: unknown key 'robot.nope'"), line
    assert "set_" not in line
    assert not out.exists() and _tree(tmp_path) == []


def test_sweep_refuses_a_non_empty_directory_that_is_no_sweep_output(tmp_path: Path) -> None:
    out = tmp_path / "run_out"
    out.mkdir()
    (out / "trajectory.tum").write_text("keep me\n", encoding="utf-8")
    line = _one_error(*cli("sweep", "quick", "--set", "robot.wheel_noise=0.1", "--seeds", "1",
                           "-o", out))  # fmt: skip
    assert line.startswith(f"fuzzyslam: error: {out}: exists and is not a sweep output"), line
    assert _tree(out) == ["trajectory.tum"]
    assert (out / "trajectory.tum").read_text(encoding="utf-8") == "keep me\n"


def _no_steps(monkeypatch: pytest.MonkeyPatch) -> list:
    """Run sweep() without its steps and figures: the list of steps it would execute."""
    import fuzzyslam.reproduce.sweep as sw
    import fuzzyslam.reproduce.sweep_plot as plot

    ran: list = []
    monkeypatch.setattr(sw, "execute", lambda steps, *a, **k: ran.extend(steps))
    monkeypatch.setattr(plot, "plot_sweep", lambda *a, **k: [])
    return ran


def test_sweep_accepts_an_absent_an_empty_and_a_previous_sweep_directory(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Absent and empty: written. A previous sweep's (``.sweep/``, other files too): gone on
    with, its files kept. The grid point files load as the configs checked in memory."""
    from fuzzyslam.config import load_config
    from fuzzyslam.reproduce.overrides import check_grid
    from fuzzyslam.reproduce.sweep import sweep

    ran = _no_steps(monkeypatch)
    sets = [("robot.wheel_noise", [0.01, 0.02]), ("slam.calibrate", [True])]
    empty = tmp_path / "empty"
    empty.mkdir()
    for out in (tmp_path / "absent", empty):
        summary = sweep("quick", sets, [0], out)
        assert summary["steps"] == 6 and (out / ".sweep").is_dir()
        assert sorted(p.name for p in out.glob("g*.yaml")) == ["g0.yaml", "g1.yaml"]
    assert len(ran) == 12
    checked = check_grid("quick", sets)
    assert [load_config(str(empty / f"g{i}.yaml")) for i in range(2)] == checked
    assert checked[1].robot.wheel_noise == 0.02 and checked[1].slam.calibrate
    (empty / "notes.txt").write_text("mine\n", encoding="utf-8")
    sweep("quick", sets, [0], empty)
    assert (empty / "notes.txt").read_text(encoding="utf-8") == "mine\n"
    (empty / ".sweep").rmdir()  # no record folder: not taken for a sweep's output
    with pytest.raises(InputError, match="not a sweep output"):
        sweep("quick", sets, [0], empty)


def test_a_grid_point_config_of_the_outdir_is_not_taken_as_config(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    from fuzzyslam.reproduce.sweep import sweep

    _no_steps(monkeypatch)
    out = tmp_path / "sw"
    cfg = tmp_path / "my.yaml"
    cfg.write_text("extends: quick.yaml\nseed: 3\n", encoding="utf-8")
    sweep(str(cfg), [("robot.wheel_noise", [0.01])], [0], out)
    before = (out / "g0.yaml").read_text(encoding="utf-8")
    with pytest.raises(InputError):
        sweep(str(out / "g0.yaml"), [("robot.wheel_noise", [0.02])], [0], out)
    assert (out / "g0.yaml").read_text(encoding="utf-8") == before
