"""The local engine of reproduce: what a pool worker pays once (imports) and per step."""

from __future__ import annotations

import subprocess
import sys

from fuzzyslam.reproduce.execute import PRELOAD, STAGES, execute
from fuzzyslam.reproduce.plan import Step


def _python(code: str) -> str:
    """Run ``code`` in a fresh interpreter (a clean sys.modules); its stdout."""
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    return p.stdout.strip()


def test_a_step_outside_dask_does_not_import_dask() -> None:
    # asking "which Dask worker am I?" must not cost a local worker the import of distributed
    out = _python(
        "import sys; from fuzzyslam.reproduce.execute import _where; "
        "print(_where(), 'distributed' in sys.modules)"
    )
    assert out == "local False"


def test_preload_loads_every_stage_and_its_on_demand_modules() -> None:
    names = (*STAGES.values(), *PRELOAD)
    out = _python(
        "import sys; from fuzzyslam.reproduce.execute import preload, STAGES, PRELOAD; "
        "preload(); print(all(m in sys.modules for m in (*STAGES.values(), *PRELOAD)), "
        "'matplotlib.pyplot' in sys.modules)"
    )
    assert out == "True True"
    assert "fuzzyslam.evaluation.figures" in names and "fuzzyslam.maps.figures" in names


def test_a_forked_pool_runs_its_steps_locally(tmp_path) -> None:
    steps = [Step(f"v{i}", ("--version",), kind="version") for i in range(3)]
    done = execute(steps, tmp_path, jobs=2)
    assert sorted(done) == ["v0", "v1", "v2"]
    assert all(r.ok and r.worker == "local" and "version" in r.summary for r in done.values())
