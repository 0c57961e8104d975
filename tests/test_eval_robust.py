"""``evaluate`` on awkward inputs: a run with one or two accepted updates of a kind (the
running mean of the consistency figure), NaN metrics printed as strict JSON, a landmarks
truth without landmarks, and its progress and warnings on stderr."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import yaml
from test_eval_cli import _cli

from fuzzyslam.evaluation.core import Estimate, Truth, Updates, evaluate
from fuzzyslam.evaluation.figures import fig_consistency, running_mean
from fuzzyslam.evaluation.params import EvalParams
from fuzzyslam.rundir import read_landmarks
from fuzzyslam.streams.tum import write_tum
from fuzzyslam.summary import summary_text

# --- the running mean -----------------------------------------------------------------


def _loop_mean(v: np.ndarray, frac: float = 0.02) -> np.ndarray:
    """The running mean of ``figures.running_mean`` by its definition, one sample at a
    time: the finite values of the window of w = max(5, frac n) samples around i (numpy's
    ``convolve(mode="same")`` window, (w - 1) // 2 after i) that exist."""
    n = v.size
    w = max(5, int(frac * n))
    after = (w - 1) // 2
    out = np.full(n, np.nan)
    for i in range(n):
        window = [v[j] for j in range(i - (w - 1 - after), i + after + 1) if 0 <= j < n]
        finite = [x for x in window if np.isfinite(x)]
        if finite:
            out[i] = sum(finite) / len(finite)
    return out


@pytest.mark.parametrize("n", [0, 1, 2, 3, 4, 5, 6, 17, 299, 300, 1000])
def test_running_mean_is_the_windowed_mean_of_every_length(n: int) -> None:
    """One value per sample for any length (shorter than the window too), each the mean
    of the finite values of its window, NaN only where the window holds none."""
    rng = np.random.default_rng(n)
    v = rng.normal(3.0, 1.0, n)
    v[::4] = np.nan
    got = running_mean(v)
    assert got.shape == (n,)
    np.testing.assert_allclose(got, _loop_mean(v), rtol=1e-12, atol=1e-12)


def test_running_mean_of_a_constant_is_the_constant() -> None:
    """A constant series (with gaps) is its own running mean, at every length."""
    for n in (1, 2, 4, 7, 500):
        v = np.full(n, 2.5)
        v[1::3] = np.nan
        got = running_mean(v)
        assert got.shape == (n,) and np.allclose(got, 2.5)


def test_consistency_figure_with_two_accepted_updates(tmp_path: Path) -> None:
    """Two accepted updates of one kind and a five-sample NEES: drawn, not a crash."""
    t = np.arange(5.0)
    poses = np.column_stack([t, np.zeros(5), np.zeros(5)])
    cov = np.repeat(np.diag([0.01, 0.01, 0.001])[None], 5, axis=0)
    est = Estimate(
        t,
        poses + np.array([0.05, 0.0, 0.0]),
        cov=cov,
        updates=Updates(
            t=np.array([1.0, 3.0]),
            kind=np.array(["lamp", "lamp"]),
            id=np.array([0, 1]),
            dof=np.array([2, 2]),
            nis=np.array([1.0, 3.0]),
            accepted=np.array([True, True]),
        ),
    )
    ev = evaluate(Truth(t, poses), est, EvalParams())
    assert fig_consistency(tmp_path / "c.png", Truth(t, poses), est, ev)
    assert (tmp_path / "c.png").stat().st_size > 0


# --- strict JSON on stdout ------------------------------------------------------------


def _strict_loads(text: str) -> object:
    def refuse(name: str) -> None:
        raise ValueError(f"non-standard JSON constant {name}")

    return json.loads(text, parse_constant=refuse)


def test_summary_text_is_strict_json_with_null_for_non_finite() -> None:
    """NaN and infinities (Python and numpy, alone, in lists and arrays) print as null;
    finite numbers keep their values."""
    s = {
        "nan": float("nan"),
        "inf": float("-inf"),
        "np_nan": np.float64("nan"),
        "np32_inf": np.float32("inf"),
        "array": np.array([1.5, np.nan]),
        "nested": {"list": [np.inf, 2, (np.int64(3), float("nan"))]},
        "ok": np.float64(0.25),
    }
    got = _strict_loads(summary_text(s))
    assert got == {
        "nan": None,
        "inf": None,
        "np_nan": None,
        "np32_inf": None,
        "array": [1.5, None],
        "nested": {"list": [None, 2, [3, None]]},
        "ok": 0.25,
    }


# --- a small run directory, evaluated by the CLI --------------------------------------


def _case(root: Path, cov_scale: float = 1.0) -> tuple[Path, Path]:
    """A TUM truth (a straight 10 s drive at 10 Hz) and a run directory 5 cm off it, its
    covariance ``cov_scale`` times (5 cm)^2, no lamp and two accepted lamp updates."""
    t = 1.6e9 + np.arange(0.0, 10.0, 0.1)
    truth = np.column_stack([0.3 * (t - t[0]), np.zeros_like(t), np.zeros_like(t)])
    write_tum(root / "truth.tum", t, truth)
    run = root / "run"
    run.mkdir()
    write_tum(run / "trajectory.tum", t, truth + np.array([0.05, 0.0, 0.0]))
    var = cov_scale * 0.05**2
    rows = [f"{ti:.6f},{var},0,0,{var},0,{var * 0.1}" for ti in t]
    (run / "covariance.csv").write_text(
        "t,pxx,pxy,pxt,pyy,pyt,ptt\n" + "\n".join(rows) + "\n", encoding="utf-8"
    )
    (run / "updates.csv").write_text(
        f"t,kind,id,dof,nis,accepted\n{t[10]:.6f},lamp,0,2,1.5,1\n{t[50]:.6f},lamp,0,2,2.5,1\n",
        encoding="utf-8",
    )
    (run / "landmarks.yaml").write_text("frame: map\nlandmarks: []\n", encoding="utf-8")
    return root / "truth.tum", run


@pytest.mark.slow
def test_two_updates_and_nan_lamp_error_evaluated_as_strict_json(tmp_path: Path) -> None:
    """A lamp-less run (its landmarks.yaml empty, accepted) with two accepted updates,
    against a true landmark far from any estimate: exit 0, the consistency figure drawn,
    and stdout strict JSON whose lamp error (no match: NaN) is null, as in metrics.json."""
    truth, run = _case(tmp_path)
    lm = tmp_path / "lm.yaml"
    lm.write_text(yaml.safe_dump({"landmarks": [{"id": 1, "x": 50.0, "y": 50.0}]}))
    r = _cli("evaluate", truth, run, "-o", tmp_path / "ev", "--landmarks-truth", lm)
    assert r.returncode == 0, r.stderr
    out = _strict_loads(r.stdout)
    assert isinstance(out, dict) and "consistency.png" in out["files"]
    metrics = _strict_loads((tmp_path / "ev" / "metrics.json").read_text())
    assert metrics["lamps"]["matched"] == 0
    assert out["lamp_error_mean_m"] is None and metrics["lamps"]["error_m"]["mean"] is None


@pytest.mark.parametrize(
    ("text", "needle"),
    [
        ("foo: 1\n", "no 'landmarks' list"),
        ("- {id: 1, x: 1, y: 2}\n", "a bare list"),
        ("1600000000.0 0 0 0 0 0 0 1\n1600000000.1 0 0 0 0 0 0 1\n", "plain text"),
        ("landmarks: []\n", "holds no landmark"),
        ("landmarks:\n", "holds no landmark"),
        ("# nothing\n", "no 'landmarks' list"),
    ],
)
def test_landmarks_truth_without_landmarks_is_bad_input(
    tmp_path: Path, text: str, needle: str
) -> None:
    """A --landmarks-truth file that holds no landmark: exit 3, one line naming the file
    and the problem, nothing written."""
    truth, run = _case(tmp_path)
    lm = tmp_path / "lm.yaml"
    lm.write_text(text, encoding="utf-8")
    out = tmp_path / "ev"
    r = _cli("evaluate", truth, run, "-o", out, "--landmarks-truth", lm)
    assert r.returncode == 3
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and str(lm) in lines[0] and needle in lines[0]
    assert r.stdout == "" and not out.exists()


def test_empty_landmarks_accepted_for_a_run_refused_for_the_truth(tmp_path: Path) -> None:
    """The reader itself: a run's empty landmarks.yaml is no lamp; as the truth, an error
    naming the file."""
    from fuzzyslam.errors import InputError

    p = tmp_path / "landmarks.yaml"
    p.write_text("frame: map\nlandmarks: []\n", encoding="utf-8")
    xy, ids = read_landmarks(p)
    assert xy.shape == (0, 2) and ids == []
    with pytest.raises(InputError, match="holds no landmark") as info:
        read_landmarks(p, truth=True)
    assert info.value.path == str(p)


# --- stderr ---------------------------------------------------------------------------


@pytest.mark.slow  # end to end, 1-3 s: the fast tier stays under a minute
def test_progress_and_warnings_on_stderr(tmp_path: Path, monkeypatch) -> None:
    """With progress on (stderr not a terminal): the start and end lines of the work;
    an overconfident estimate's warning as a one-line note, also in the JSON. With
    FUZZYSLAM_NO_PROGRESS: the note alone."""
    truth, run = _case(tmp_path, cov_scale=1e-4)  # 5 cm errors, 0.5 mm stated
    monkeypatch.delenv("FUZZYSLAM_NO_PROGRESS", raising=False)
    r = _cli("evaluate", truth, run, "-o", tmp_path / "ev")
    assert r.returncode == 0, r.stderr
    (warning,) = [w for w in json.loads(r.stdout)["warnings"] if "overconfident" in w]
    lines = r.stderr.splitlines()
    label = "evaluate: metrics, figures and report"
    assert lines[0] == label
    assert any(x.startswith(f"{label}: done in ") for x in lines)
    notes = [x for x in lines if x.startswith("fuzzyslam: note: ")]
    assert notes == [f"fuzzyslam: note: warning: {' '.join(warning.split())}"]
    monkeypatch.setenv("FUZZYSLAM_NO_PROGRESS", "1")
    r = _cli("evaluate", truth, run, "-o", tmp_path / "ev2")
    assert r.returncode == 0 and r.stderr.splitlines() == notes
