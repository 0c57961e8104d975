"""Non-ASCII paths under a locale that cannot decode them (``LC_ALL=C`` without UTF-8 mode):
every command succeeds, and every path in a text output (JSON summaries, report.md,
stderr lines) is the path's bytes read as UTF-8 (fuzzyslam/summary.py ``path_text``), not
the lone surrogates Python decodes it to (which no UTF-8 file holds and matplotlib
cannot draw)."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from fuzzyslam.errors import InputError
from fuzzyslam.summary import as_json, path_text, summary_text, valid_text

ROOT = Path(__file__).resolve().parents[1]
SAMPLE = ROOT / "data" / "sample.mcap"
MICRO = ROOT / "tests" / "micro.yaml"

# Python decodes the path's UTF-8 bytes with the C locale's ASCII and surrogateescape
C_LOCALE = {
    "LC_ALL": "C",
    "PYTHONCOERCECLOCALE": "0",
    "PYTHONUTF8": "0",
    "FUZZYSLAM_NO_PROGRESS": "1",
}
LOG = "é/lög.mcap"


def fuzzyslam(cwd: Path, *args: str, code: int = 0) -> subprocess.CompletedProcess:
    """``python -m fuzzyslam ARGS`` under the C locale (:data:`C_LOCALE`), in ``cwd``,
    its outputs as bytes; its exit code must be ``code``.

    Parameters
    ----------
    cwd : Path
        The working directory (the relative paths of ``args`` are in it).
    *args : str
        The command line.
    code : int
        The expected exit code.

    Returns
    -------
    CompletedProcess
        stdout and stderr as bytes.
    """
    # the arguments as the bytes a shell would pass (UTF-8), whatever this process's locale
    argv = [sys.executable, "-m", "fuzzyslam", *(a.encode("utf-8") for a in args)]
    env = {k: v for k, v in os.environ.items() if not k.startswith("LC_") and k != "LANG"}
    env.update(C_LOCALE)
    p = subprocess.run(argv, cwd=cwd, env=env, capture_output=True, timeout=600)
    assert p.returncode == code, p.stderr.decode("utf-8", "replace")
    return p


def utf8_json(data: bytes) -> dict:
    """A JSON file or stdout read as strict UTF-8, every text in it valid Unicode (no lone
    surrogate escapes such as ``\\udcc3``).

    Parameters
    ----------
    data : bytes
        The JSON text.

    Returns
    -------
    dict
        The object.
    """
    obj = json.loads(data.decode("utf-8"))
    json.dumps(obj, ensure_ascii=False).encode("utf-8")  # raises on a lone surrogate
    return obj


@pytest.fixture
def sample_dir(tmp_path: Path) -> Path:
    """A working directory holding a copy of data/sample.mcap as ``é/lög.mcap``."""
    (tmp_path / "é").mkdir()
    shutil.copy(SAMPLE, tmp_path / LOG)
    return tmp_path


def test_path_text_reads_the_bytes_as_utf8() -> None:
    """A path decoded with surrogateescape (the C locale's ASCII, or a Latin-1 name under
    a UTF-8 locale) is shown as its UTF-8 characters, a byte that is not UTF-8 as U+FFFD;
    valid text passes unchanged, also inside a summary (``as_json``)."""
    raw = "é/lög.mcap".encode()
    assert path_text(raw) == "é/lög.mcap"
    assert path_text(raw.decode("ascii", "surrogateescape")) == "é/lög.mcap"
    assert path_text(Path(os.fsdecode(raw))) == "é/lög.mcap"
    assert path_text(b"l\xe9t/log.mcap") == "l\ufffdt/log.mcap"
    assert path_text("\ud800x") == "\ufffd" * 3 + "x"  # not an escaped byte: replaced
    assert valid_text("lâbel") == "lâbel"
    broken = raw.decode("ascii", "surrogateescape")
    assert as_json({"log": broken, "n": [broken]}) == {"log": LOG, "n": [LOG]}
    assert "\\udc" not in summary_text({"log": broken})
    exc = InputError(broken, "log does not exist")
    assert str(exc) == f"{LOG}: log does not exist" and exc.path == broken


@pytest.mark.slow  # end to end (sweeps or run + evaluate in subprocesses)
def test_run_and_evaluate_under_the_c_locale(sample_dir: Path) -> None:
    """run and evaluate of a log under a non-ASCII directory, under the C locale: exit 0,
    run's summary (file and stdout), evaluate's metrics.json and report.md name the log in
    valid UTF-8; the figures' titles (from the log's name and the label) are drawn."""
    out = fuzzyslam(sample_dir, "run", LOG, "-o", "é/rün")
    for summary in (out.stdout, (sample_dir / "é/rün/summary.json").read_bytes()):
        assert utf8_json(summary)["log"] == LOG
    ev = fuzzyslam(sample_dir, "evaluate", LOG, "é/rün", "-o", "é/ëv", "--label", "lâbel")
    assert utf8_json(ev.stdout)["files"]
    metrics = utf8_json((sample_dir / "é/ëv/metrics.json").read_bytes())
    assert (metrics["truth"], metrics["estimate"], metrics["label"]) == (LOG, "é/rün", "lâbel")
    report = (sample_dir / "é/ëv/report.md").read_bytes().decode("utf-8")
    assert "# Evaluation: lâbel" in report and f"`{LOG}`" in report
    assert (sample_dir / "é/ëv/fig3_errors.png").stat().st_size > 0


def test_an_error_line_names_the_path_in_utf8(tmp_path: Path) -> None:
    """The one-line error on stderr names a missing non-ASCII path as its UTF-8 bytes."""
    p = fuzzyslam(tmp_path, "run", "é/nöne.mcap", "-o", "out", code=3)
    line = p.stderr.decode("utf-8").strip().splitlines()[-1]
    assert line == "fuzzyslam: error: é/nöne.mcap: log does not exist"


@pytest.mark.slow
def test_every_command_under_the_c_locale(tmp_path: Path) -> None:
    """simulate (with its preview), run, map (with its figures), run --map --fix pose and
    evaluate --map --compare, every path and label non-ASCII, under the C locale: exit 0
    and every summary's paths in valid UTF-8."""
    (tmp_path / "é").mkdir()
    shutil.copy(MICRO, tmp_path / "é/mïcro.yaml")
    sim = utf8_json(
        fuzzyslam(
            tmp_path,
            "simulate",
            "é/mïcro.yaml",
            "-o",
            "é/sïm.mcap",
            "--preview",
            "é/prév.png",
            "--truth-tum",
            "é/trüth.tum",
        ).stdout
    )
    assert (sim["file"], sim["preview"], sim["truth_tum"]) == (
        "é/sïm.mcap",
        "é/prév.png",
        "é/trüth.tum",
    )
    fuzzyslam(tmp_path, "run", "é/sïm.mcap", "-o", "é/rün")
    fuzzyslam(tmp_path, "map", "é/sïm.mcap", "--trajectory", "é/rün/trajectory.tum", "-o", "é/mäp")
    fgm = utf8_json((tmp_path / "é/mäp/summary.json").read_bytes())
    assert (fgm["log"], fgm["trajectory"], fgm["output"]) == (
        "é/sïm.mcap",
        "é/rün/trajectory.tum",
        "é/mäp",
    )
    assert (tmp_path / "é/mäp/hough.png").is_file()
    fuzzyslam(tmp_path, "run", "é/sïm.mcap", "--map", "é/mäp", "--fix", "pose", "-o", "é/pöse")
    assert utf8_json((tmp_path / "é/pöse/summary.json").read_bytes())["log"] == "é/sïm.mcap"
    fuzzyslam(
        tmp_path,
        "evaluate",
        "é/sïm.mcap",
        "é/pöse",
        "--map",
        "é/mäp",
        "--label",
        "pöse",
        "--compare",
        "ötherl=é/rün",
        "-o",
        "é/ëv",
    )
    metrics = utf8_json((tmp_path / "é/ëv/metrics.json").read_bytes())
    rows = [(r["label"], r["estimate"]) for r in metrics["comparison"]]
    assert rows == [("pöse", "é/pöse"), ("ötherl", "é/rün")]
    assert (tmp_path / "é/ëv/compare.png").is_file()


def test_valid_names_stay_as_they_are_under_a_latin1_locale(monkeypatch) -> None:
    """Under a Latin-1 locale Python decodes every name right: ``Café`` is valid text and
    is shown as it is, by path_text, valid_text and an error line alike (re-encoding it
    with the locale's Latin-1 and decoding as UTF-8 made it ``Caf\\ufffd``)."""
    monkeypatch.setattr(os, "fsencode", lambda s: os.fspath(s).encode("latin-1", "surrogateescape"))
    name = "Café/log.mcap"
    assert path_text(name) == valid_text(name) == name
    assert str(InputError(name, "log does not exist")) == f"{name}: log does not exist"
