"""One stage convention: every stage package's entry is ``stage.run``; the CLI parses and
calls it, and reproduce calls it with the same arguments as its commands.sh lines."""

from __future__ import annotations

import importlib
import inspect
from pathlib import Path

import pytest

from fuzzyslam.cli import _register, cli
from fuzzyslam.reproduce.execute import STAGES
from fuzzyslam.reproduce.plan import FULL, QUICK, build_plan
from fuzzyslam.reproduce.sweep import sweep_steps

_register()

# the CLI's parameter names that differ from the stage entry's
RENAMED = {"map": {"no_figures": ("figures", lambda v: not v)}}
# how a command runs, not what it computes (the outputs are the same byte for byte): run's
# input process (slam/prefetch.py), the CLI's default, which reproduce's and sweep's pool
# steps leave at the stage entry's (off: the pool already fills the cores), and the figure
# process the CLI starts before its imports (fuzzyslam/forked.py; the pool's steps: none)
HOW = {"run": {"prefetch", "figures"}}


def _as_call(argv: tuple[str, ...]) -> dict:
    """What the CLI passes to the stage entry for ``fuzzyslam ARGV``."""
    cmd = cli.commands[argv[0]]
    params = cmd.make_context(argv[0], list(argv[1:])).params
    out = {}
    for name, value in params.items():
        if name in HOW.get(argv[0], set()):
            continue
        name, value = (
            (RENAMED[argv[0]][name][0], RENAMED[argv[0]][name][1](value))
            if name in RENAMED.get(argv[0], {})
            else (name, value)
        )
        out[name] = str(value) if isinstance(value, Path) else value
    return out


@pytest.mark.parametrize("suite", [FULL, QUICK])
def test_reproduce_calls_the_stages_with_its_commands_arguments(suite):
    """Each step's call of ``stage.run`` is what the CLI makes of the step's command line
    (commands.sh): the keyword arguments given are the parsed options, the others are at
    the entry's defaults."""
    calibrated = frozenset({"paper", "dark"})  # maps with --calibration
    steps = build_plan([0, 2], suite, calibrated=calibrated)
    steps += sweep_steps([("quick.yaml", {})], [1])
    assert any("--calibration" in s.argv for s in steps)
    assert {s.kind for s in steps} == set(STAGES)
    for s in steps:
        entry = importlib.import_module(STAGES[s.kind]).run
        defaults = {
            k: p.default
            for k, p in inspect.signature(entry).parameters.items()
            if p.default is not inspect.Parameter.empty and k not in HOW.get(s.kind, set())
        }
        assert not set(dict(s.call)) & HOW.get(s.kind, set()), s.key  # the entry's default
        want = _as_call(s.argv)
        got = {**defaults, **dict(s.call)}
        assert set(got) == set(want), s.key
        for k, v in want.items():
            assert got[k] == (tuple(v) if isinstance(v, list) else v), (s.key, k)


def test_every_stage_package_has_a_run_entry():
    for package in ("sim", "slam", "maps", "evaluation", "reproduce"):
        mod = importlib.import_module(f"fuzzyslam.{package}.stage")
        assert callable(mod.run), package
