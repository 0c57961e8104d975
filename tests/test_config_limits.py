"""Configs that hung or exhausted memory (issue 14, class 5): every one is exit 3 with
one short line naming the config, in well under a second of CPU time (CPU, not wall
time: a loaded machine must not fail it)."""

from __future__ import annotations

import time
from pathlib import Path

import pytest
from test_robust_logs import cli, error_lines

from fuzzyslam.config import embedded_names
from fuzzyslam.errors import EXIT_INPUT

BOMB = "a: &a [x, x, x, x, x, x, x, x, x, x]\n" + "".join(
    f"{c}: &{c} [*{p}, *{p}, *{p}, *{p}, *{p}, *{p}, *{p}, *{p}, *{p}, *{p}]\n"
    for p, c in zip("abcdefgh", "bcdefghi", strict=True)
)  # 10^9 leaves

Q = "extends: quick.yaml\n"
BAD = {
    "alias bomb": BOMB + "extends: quick.yaml\n",
    "alias bomb in a value": BOMB.replace("i: &i", "scenario:\n  runs: &i"),
    "huge value quoted": "extends: quick.yaml\nscenario: {runs: '" + "9" * 900_000 + "'}\n",
    "huge file": "extends: quick.yaml\n# " + "x" * 2_000_000 + "\n",
    "inf start offset": "extends: quick.yaml\nscenario: {start_offset: .inf}\n",
    "nan start offset": "extends: quick.yaml\nscenario: {start_offset: .nan}\n",
    "huge start offset": "extends: quick.yaml\nscenario: {start_offset: 1.0e300}\n",
    "inf centreline": Q + "world: {centerline: [[0, 0], [10, 0], [.inf, 7], [0, 7]]}\n",
    "huge centreline": Q + "world: {centerline: [[0, 0], [1e9, 0], [1e9, 7], [0, 7]]}\n",
    "centreline of 3-vectors": Q + "world: {centerline: [[0, 0, 1], [10, 0, 1], [5, 7, 1]]}\n",
    "lamps 10^5": "extends: quick.yaml\nworld:\n  lamps: [" + "[1, 1], " * 100_000 + "]\n",
    "integer overflow": "extends: quick.yaml\nscenario: {start_offset: " + "9" * 400 + "}\n",
    "camera 16 GiB": "extends: quick.yaml\ncamera: {width: 4096, height: 4096, supersample: 16}\n",
    "endless drive": "extends: quick.yaml\nrobot: {cruise_speed: 0.01, max_speed: 0.01}\n"
    "scenario: {runs: 1000}\n",
    "nested brackets": "extends: quick.yaml\nx: " + "[" * 1200 + "]" * 1200 + "\n",
    "nested mappings": "extends: quick.yaml\nx: " + "{a: " * 1200 + "1" + "}" * 1200 + "\n",
    "start pose too short": Q + "slam: {start_pose: [1.0, 2.0]}\n",
    "negative odometry variance": Q + "slam: {rot_var_per_rad: -1e-3}\n",
    "start sigma zero": "extends: quick.yaml\nslam: {start_sigma: [0, 0, 0]}\n",
    "extends outside": "extends: ../outside.yaml\n",
    "extends absolute": "extends: /etc/hostname\n",
    "repeated key": Q + "robot: {radius: 0.2, radius: 0.3}\n",
    "repeated section": Q + "robot: {radius: 0.2}\nrobot: {radius: 0.3}\n",
    "repeated key in a list": Q + "world: {lamps: [{a: 1, a: 2}]}\n",
    "repeated key in an alias bomb": BOMB + "z: {k: *i, k: 1}\n" + Q,
}


@pytest.mark.parametrize("kind", sorted(BAD))
def test_bad_config_is_refused_fast(kind: str, tmp_path: Path) -> None:
    d = tmp_path / "cfg"
    d.mkdir()
    (tmp_path / "outside.yaml").write_text("name: outside\n", encoding="utf-8")
    cfg = d / "bad.yaml"
    cfg.write_text(BAD[kind], encoding="utf-8")
    t0 = time.process_time()
    code, out, err = cli("simulate", cfg, "-o", tmp_path / "x.mcap")
    took = time.process_time() - t0
    lines = error_lines(err)
    assert code == EXIT_INPUT, err[:500]
    assert len(lines) == 1 and lines[0].startswith(f"fuzzyslam: error: {cfg}: "), err[:500]
    assert len(lines[0]) < 300 + len(str(cfg)), lines[0][:500]
    assert took < 1.0, f"{kind}: {took:.2f} s"
    assert out == "" and not (tmp_path / "x.mcap").exists()


def test_long_extends_chain_is_refused(tmp_path: Path) -> None:
    """1200 configs each extending the next: refused at the chain limit, fast."""
    for i in range(1200):
        (tmp_path / f"c{i}.yaml").write_text(f"extends: c{i + 1}.yaml\n", encoding="utf-8")
    (tmp_path / "c1200.yaml").write_text("extends: quick.yaml\n", encoding="utf-8")
    t0 = time.process_time()
    code, _, err = cli("simulate", tmp_path / "c0.yaml", "-o", tmp_path / "x.mcap")
    assert code == EXIT_INPUT and "'extends' chain longer" in err, err[:500]
    assert time.process_time() - t0 < 1.0


def test_extends_below_and_embedded_still_work(tmp_path: Path) -> None:
    """What stays allowed: a file in a folder below the config, and embedded names."""
    from fuzzyslam.config import load_config

    (tmp_path / "base").mkdir()
    (tmp_path / "base" / "b.yaml").write_text("extends: quick.yaml\nname: b\n", encoding="utf-8")
    (tmp_path / "top.yaml").write_text("extends: base/b.yaml\nseed: 7\n", encoding="utf-8")
    cfg = load_config(tmp_path / "top.yaml")
    assert (cfg.name, cfg.seed, cfg.scenario.runs) == ("b", 7, load_config("quick").scenario.runs)


@pytest.mark.parametrize(
    ("text", "says"),
    [
        (Q + "robot: {radius: 0.2, radius: 0.3}\n",
         "repeated key 'robot.radius' at line 2 (first at line 2)"),
        (Q + "seed: 1\nrobot:\n  radius: 0.2\nseed: 2\n",
         "repeated key 'seed' at line 5 (first at line 2)"),
        (Q + "slam:\n  start_pose: [0, 0, 0]\n  gate: 9\n  start_pose: [1, 1, 1]\n",
         "repeated key 'slam.start_pose' at line 5 (first at line 3)"),
        (Q + "extends: paper.yaml\n", "repeated key 'extends' at line 2 (first at line 1)"),
        (Q + "world: {lamps: [{a: 1, a: 2}]}\n", "repeated key 'world.lamps[0].a' at line 2"),
        (BOMB + "z: {k: *i, k: 1}\n", "repeated key 'z.k' at line 10 (first at line 10)"),
        ("extends: nonexist\n", "extends 'nonexist': config not found"),
    ],
)  # fmt: skip
def test_repeated_keys_and_missing_extends_name_the_file_and_key(
    text: str, says: str, tmp_path: Path
) -> None:
    """Plain YAML keeps the last of a repeated key silently; a config refuses it, naming
    the file, the dotted key and both lines. A missing ``extends`` names the config that
    holds it and the key."""
    cfg = tmp_path / "c.yaml"
    cfg.write_text(text, encoding="utf-8")
    code, out, err = cli("simulate", cfg, "-o", tmp_path / "x.mcap")
    lines = error_lines(err)
    assert code == EXIT_INPUT and len(lines) == 1, err
    assert lines[0].startswith(f"fuzzyslam: error: {cfg}: {says}"), lines[0]
    assert out == "" and not (tmp_path / "x.mcap").exists()


def test_a_missing_extends_deeper_in_the_chain_names_its_own_file(tmp_path: Path) -> None:
    (tmp_path / "sub").mkdir()
    mid = tmp_path / "sub" / "mid.yaml"
    mid.write_text("extends: gone.yaml\n", encoding="utf-8")
    (tmp_path / "top.yaml").write_text("extends: sub/mid.yaml\n", encoding="utf-8")
    code, _, err = cli("simulate", tmp_path / "top.yaml", "-o", tmp_path / "x.mcap")
    assert code == EXIT_INPUT
    assert error_lines(err) == [
        f"fuzzyslam: error: {mid}: extends 'gone.yaml': config not found "
        f"(not a file, nor one of the embedded: {', '.join(embedded_names())})"
    ]


def test_merge_keys_and_anchors_still_load(tmp_path: Path) -> None:
    """A ``<<`` merge may be overridden by the mapping's own keys, and one anchored
    mapping used twice is not a repeat (the raw mapping, before the keys are checked)."""
    from fuzzyslam.config import config_layers

    cfg = tmp_path / "m.yaml"
    cfg.write_text(
        Q + "base: &r {radius: 0.2, wheel_noise: 0.01}\nrobot:\n  <<: *r\n  radius: 0.3\n"
        "again: *r\n",
        encoding="utf-8",
    )
    raw, chain = config_layers(str(cfg))
    assert (raw["robot"]["radius"], raw["robot"]["wheel_noise"]) == (0.3, 0.01)
    assert raw["again"] == raw["base"] == {"radius": 0.2, "wheel_noise": 0.01}
    assert chain[:2] == [str(cfg), "<embedded quick.yaml>"]
