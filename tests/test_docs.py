"""Every ``*.md`` the code names exists in the repository, and every section it cites exists.

Fast: reads text files only.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SOURCES = sorted(
    [*(ROOT / "fuzzyslam").rglob("*.py"), *(ROOT / "configs").glob("*.yaml")],
)
# names of files the stages write (outputs), not documents of the repository
OUTPUT_NAMES = {"report.md", "sweep.md", "OUTDIR/sweep.md"}  # files the commands write
MD_REF = re.compile(r"\b[\w/]+\.md\b")
SEC_REF = re.compile(r"\b(models|contracts)\.md sec\. (\d+)(?:\s*-\s*(\d+))?")
# the topic each cited section must be about: a word of its heading
TOPICS = {
    ("models", 2): "odometry",
    ("models", 3): "camera",
    ("models", 4): "ekf",
    ("models", 5): "evidence",
    ("models", 6): "belief",
    ("models", 7): "local",
    ("models", 8): "hough",
    ("models", 9): "heading",
    ("models", 10): "pose",
    ("models", 11): "sonar",
    ("contracts", 2): "run",
    ("contracts", 3): "map",
}


def texts() -> list[tuple[Path, str]]:
    return [(p, p.read_text(encoding="utf-8")) for p in SOURCES]


def headings(doc: str) -> dict[int, str]:
    """Numbered section headings ``## N. Title`` of docs/<doc>.md: {N: title}."""
    text = (ROOT / "docs" / f"{doc}.md").read_text(encoding="utf-8")
    return {int(m[1]): m[2] for m in re.finditer(r"^## (\d+)\. (.+)$", text, re.M)}


def test_sources_found() -> None:
    assert len(SOURCES) > 50


def test_every_md_named_in_the_code_exists() -> None:
    missing = []
    for path, text in texts():
        for m in MD_REF.finditer(text):
            name = m.group(0)
            if name in OUTPUT_NAMES:
                continue
            if not (ROOT / name).is_file():
                missing.append(f"{path.relative_to(ROOT)}: {name}")
    assert not missing, "\n".join(missing)


def cited_sections() -> list[tuple[str, str, int]]:
    out = []
    for path, text in texts():
        for m in SEC_REF.finditer(text):
            lo = int(m[2])
            hi = int(m[3]) if m[3] else lo
            out += [(str(path.relative_to(ROOT)), m[1], n) for n in range(lo, hi + 1)]
    return out


def test_sections_are_cited() -> None:
    docs = {doc for _, doc, _ in cited_sections()}
    assert docs == {"models", "contracts"}


@pytest.mark.parametrize("doc", ["models", "contracts"])
def test_every_cited_section_exists_and_is_on_its_topic(doc: str) -> None:
    secs = headings(doc)
    bad = []
    for where, d, n in cited_sections():
        if d != doc:
            continue
        if n not in secs:
            bad.append(f"{where}: docs/{d}.md sec. {n} does not exist")
        elif (d, n) in TOPICS and TOPICS[(d, n)] not in secs[n].lower():
            bad.append(f"{where}: docs/{d}.md sec. {n} is '{secs[n]}'")
    assert not bad, "\n".join(bad)


def test_sections_are_numbered_in_order() -> None:
    for doc in ("models", "contracts"):
        assert list(headings(doc)) == list(range(1, len(headings(doc)) + 1)), doc


def test_committed_reports_have_no_broken_link():
    """Every local link of README.md, docs/*.md and data/results/report.md names a file of
    the repository (the committed results are a subset of a reproduce output: links to
    what is not committed are plain text, benchmarks/publish_results.py)."""
    import re

    root = Path(__file__).resolve().parents[1]
    pages = [root / "README.md", root / "data" / "results" / "report.md"]
    pages += sorted((root / "docs").glob("*.md"))
    broken = []
    for page in pages:
        for target in re.findall(r"\]\(([^)\s]+)\)", page.read_text(encoding="utf-8")):
            if target.startswith(("http://", "https://", "#", "mailto:")):
                continue
            if not (page.parent / target.split("#")[0]).exists():
                broken.append(f"{page.relative_to(root)} -> {target}")
    assert not broken, broken
