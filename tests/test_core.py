"""SE(2) identities, config validation and atomic outputs."""

from __future__ import annotations

import numpy as np
import pytest

from fuzzyslam import se2
from fuzzyslam.config import dump_config, load_config
from fuzzyslam.errors import ConfigError, InputError
from fuzzyslam.fileio import OutputDir, atomic_path, check_outputs


def test_wrap_angle_range_and_pi():
    a = np.linspace(-20, 20, 2001)
    w = se2.wrap_angle(a)
    assert np.all(w > -np.pi) and np.all(w <= np.pi)
    assert np.allclose(np.sin(w), np.sin(a)) and np.allclose(np.cos(w), np.cos(a))
    assert se2.wrap_angle(np.pi) == pytest.approx(np.pi)
    assert se2.wrap_angle(-np.pi) == pytest.approx(np.pi)


def test_compose_inverse_identity():
    rng = np.random.default_rng(0)
    for _ in range(50):
        a = rng.uniform([-5, -5, -4], [5, 5, 4])
        b = rng.uniform([-5, -5, -4], [5, 5, 4])
        ident = se2.compose(a, se2.inverse(a))
        assert np.allclose(ident, 0.0, atol=1e-12)
        assert np.allclose(se2.compose(se2.inverse(a), se2.compose(a, b))[:2], b[:2])
        pts = rng.normal(size=(4, 2))
        back = se2.inverse_transform_points(a, se2.transform_points(a, pts))
        assert np.allclose(back, pts)


def test_compose_jacobians_numeric():
    a = np.array([1.0, -2.0, 0.7])
    b = np.array([0.3, 0.5, -1.1])
    ja, jb = se2.jacobians_compose(a, b)
    eps = 1e-6
    for j, (arg, jac) in enumerate([(0, ja), (1, jb)]):
        del j
        num = np.zeros((3, 3))
        for k in range(3):
            d = np.zeros(3)
            d[k] = eps
            if arg == 0:
                diff = se2.compose(a + d, b) - se2.compose(a - d, b)
            else:
                diff = se2.compose(a, b + d) - se2.compose(a, b - d)
            diff[2] = se2.wrap_angle(diff[2])
            num[:, k] = diff / (2 * eps)
        assert np.allclose(num, jac, atol=1e-6)


def test_quaternion_roundtrip():
    th = np.linspace(-3.1, 3.1, 50)
    assert np.allclose(se2.quaternion_to_yaw(se2.yaw_to_quaternion(th)), th)


def test_embedded_configs_load_and_roundtrip(tmp_path):
    cfg = load_config()
    assert cfg.name == "paper"
    text = dump_config(cfg)
    p = tmp_path / "c.yaml"
    p.write_text(text)
    assert load_config(p) == cfg
    assert load_config("quick", seed=5).seed == 5


@pytest.mark.parametrize(
    "text, fragment",
    [
        ("slam: {gate_chi3: 2}", "unknown key 'slam.gate_chi3'"),
        ("sonar: {count: 0}", "'sonar.count' must be >= 1"),
        ("sonar: {count: abc}", "'sonar.count' must be an integer"),
        ("robot: [1", "malformed YAML"),
        ("fixes: {mode: magic}", "'fixes.mode' must be one of"),
        ("- 1\n- 2", "must be a YAML mapping"),
    ],
)
def test_bad_config_is_one_clear_line(tmp_path, text, fragment):
    p = tmp_path / "bad.yaml"
    p.write_text(text)
    with pytest.raises(ConfigError) as err:
        load_config(p)
    msg = str(err.value)
    assert fragment in msg and str(p) in msg and "\n" not in msg


def test_missing_config():
    with pytest.raises(ConfigError, match="config not found"):
        load_config("/nonexistent/cfg.yaml")


def test_atomic_path_leaves_nothing_on_error(tmp_path):
    target = tmp_path / "out.txt"
    target.write_text("old")
    with pytest.raises(RuntimeError), atomic_path(target) as tmp:
        tmp.write_text("partial")
        raise RuntimeError("boom")
    assert target.read_text() == "old"
    assert list(tmp_path.iterdir()) == [target]


def test_output_dir_commits_only_on_success(tmp_path):
    out = tmp_path / "res"
    with pytest.raises(KeyboardInterrupt), OutputDir(out) as tmp:
        (tmp / "a.txt").write_text("x")
        raise KeyboardInterrupt
    assert not out.exists() and list(tmp_path.iterdir()) == []
    with OutputDir(out) as tmp:
        (tmp / "a.txt").write_text("x")
    assert (out / "a.txt").read_text() == "x" and len(list(tmp_path.iterdir())) == 1


@pytest.mark.parametrize("maker", ["mkdtemp", "mkstemp"])
def test_a_signal_just_after_the_temporary_is_made_leaves_nothing(
    tmp_path, monkeypatch, maker: str
) -> None:
    """SIGTERM arriving right after OutputDir's (or atomic_path's) temporary folder (file)
    is made, before its name is kept: Terminated is raised and nothing is left. An
    interrupted sweep had left an empty ``.eval.*.part`` folder so (the exception raised
    in __enter__, where __exit__ does not run)."""
    import os
    import signal
    import tempfile

    from fuzzyslam.interrupts import Terminated, install, raise_terminated

    real = getattr(tempfile, maker)

    def hit(*args, **kwargs):
        made = real(*args, **kwargs)
        os.kill(os.getpid(), signal.SIGTERM)
        return made

    monkeypatch.setattr(tempfile, maker, hit)
    out = tmp_path / "res"
    before = signal.signal(signal.SIGTERM, raise_terminated)
    install()  # a new command: its first SIGTERM raises
    try:
        with pytest.raises(Terminated):
            with OutputDir(out) if maker == "mkdtemp" else atomic_path(out) as tmp:
                tmp.joinpath("a.txt").write_text("x") if tmp.is_dir() else tmp.write_text("x")
    finally:
        signal.signal(signal.SIGTERM, before)
    assert list(tmp_path.iterdir()) == []


def test_a_second_sigterm_does_not_cut_the_clean_up_short(tmp_path, monkeypatch) -> None:
    """SIGTERM inside a command, then a second one while its temporary output is being
    removed (a process group's SIGTERM, then its parent's to the workers): the first
    raises Terminated, the second is not raised, and nothing is left."""
    import os
    import signal

    import fuzzyslam.fileio as fileio
    from fuzzyslam.interrupts import Terminated, install, raise_terminated

    real = fileio.shutil.rmtree

    def hit(*args, **kwargs):
        os.kill(os.getpid(), signal.SIGTERM)
        return real(*args, **kwargs)

    monkeypatch.setattr(fileio.shutil, "rmtree", hit)
    out = tmp_path / "res"
    before = signal.signal(signal.SIGTERM, raise_terminated)
    install()
    try:
        with pytest.raises(Terminated), OutputDir(out) as tmp:
            (tmp / "a.txt").write_text("x")
            os.kill(os.getpid(), signal.SIGTERM)
            (tmp / "b.txt").write_text("never")
    finally:
        signal.signal(signal.SIGTERM, before)
    assert list(tmp_path.iterdir()) == []


def test_check_outputs_refuses_input(tmp_path):
    inp = tmp_path / "in.mcap"
    inp.write_text("x")
    with pytest.raises(InputError, match="same as an input"):
        check_outputs([inp], [inp])
    with pytest.raises(InputError, match="does not exist"):
        check_outputs([inp], [tmp_path / "nodir" / "x.mcap"])
