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


# options the README's command table leaves out on purpose
TABLE_OMITS = {"run": {"--seed"}}  # accepted for pipelines, changes nothing


def test_readme_command_table_names_every_option() -> None:
    """The README's command table (``| command | does |``): a row per command whose
    synopsis names every option of the command (but :data:`TABLE_OMITS`) and none it
    does not have, checked against the CLI itself."""
    from fuzzyslam.cli import COMMANDS, _register, cli

    _register()
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    rows = dict(re.findall(r"^\| `fuzzyslam (\w+) (.*?)` \|", readme, re.M))
    assert sorted(rows) == sorted(COMMANDS)
    bad = []
    for name, synopsis in rows.items():
        given = set(re.findall(r"(?<![\w-])(--?[a-z][\w-]*)", synopsis))
        spellings = [
            set(p.opts + p.secondary_opts) for p in cli.commands[name].params
            if p.param_type_name == "option"
        ]  # fmt: skip
        known = set().union(*spellings)
        bad += [f"{name}: {o} is no option of the command" for o in sorted(given - known)]
        bad += [
            f"{name}: {'/'.join(sorted(o))} missing from the table"
            for o in spellings
            if not o & given and not o & TABLE_OMITS.get(name, set())
        ]
    assert not bad, "\n".join(bad)


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


# --- numpydoc on the public functions of the cores (issue 15 step 6) -----------------------

CORE_PACKAGES = ("slam", "maps", "fixes", "sim")
CORE_MODULES = (
    "evaluation.core",
    "evaluation.metrics",
    "evaluation.consistency",
    "evaluation.lamps",
    "evaluation.results",
    "se2",
    "polygons",
)
# Public functions exempt from the rule, with the reason.
EXEMPT = {
    # protocols: their implementations carry the documentation
    "fuzzyslam.slam.events.Aid.on_ring": "protocol (fixes/ implement it)",
    "fuzzyslam.fixes.scan_heading.ScanLineHeadingAid.on_ring": "implements Aid.on_ring",
    "fuzzyslam.slam.events.Aid.summary": "protocol (fixes/ implement it)",
    "fuzzyslam.slam.events.Aid.write": "protocol (fixes/ implement it)",
    "fuzzyslam.slam.events.RowSink.row": "protocol (slam/outputs.py implements it)",
    "fuzzyslam.fixes.base.Row.row": "protocol (the decisions implement it)",
    # a RowSink kept in memory: its methods are those of the protocol, documented there
    **{
        f"fuzzyslam.slam.events.MemorySink.{m}": "implements RowSink (slam/events.py)"
        for m in ("row", "odometry_start", "odometry", "update", "snapshot")
    },
    **{
        f"fuzzyslam.slam.outputs.StreamingOutputs.{m}": "implements RowSink (slam/events.py)"
        for m in ("row", "odometry_start", "odometry", "update", "snapshot")
    },
}
# Functions documented before this rule, still without the sections: the list may only
# shrink (a function in it that gains them must leave it; a new function must have them).
GAPS_FILE = ROOT / "tests" / "numpydoc_gaps.txt"


def core_modules() -> list[str]:
    import importlib
    import pkgutil

    names = [f"fuzzyslam.{m}" for m in CORE_MODULES]
    for pkg in CORE_PACKAGES:
        p = importlib.import_module(f"fuzzyslam.{pkg}")
        names += [f"fuzzyslam.{pkg}.{m.name}" for m in pkgutil.iter_modules(p.__path__)]
    return sorted(names)


def public_functions() -> list[tuple[str, object]]:
    """(qualified name, function) of each module-level function and each method of a
    class defined in a core module, neither starting with an underscore."""
    import importlib
    import inspect

    out = []
    for name in core_modules():
        mod = importlib.import_module(name)
        for n, obj in vars(mod).items():
            if n.startswith("_") or getattr(obj, "__module__", None) != name:
                continue
            if inspect.isfunction(obj):
                out.append((f"{name}.{n}", obj))
            elif inspect.isclass(obj):
                for mn, m in vars(obj).items():
                    if not mn.startswith("_") and inspect.isfunction(m):
                        out.append((f"{name}.{n}.{mn}", m))
    return out


def missing_sections(fn) -> list[str]:
    """What the docstring of ``fn`` lacks: a docstring, Parameters (when it takes
    arguments besides self/cls), Returns or Yields (when it is annotated to return
    something other than None)."""
    import inspect

    doc = inspect.getdoc(fn) or ""
    sig = inspect.signature(fn)
    args = [p for p in sig.parameters if p not in ("self", "cls")]
    returns = sig.return_annotation not in (inspect.Signature.empty, None, "None")
    out = [] if doc else ["docstring"]
    if args and not re.search(r"^Parameters\n-{3,}", doc, re.M):
        out.append("Parameters")
    if returns and not re.search(r"^(Returns|Yields)\n-{3,}", doc, re.M):
        out.append("Returns")
    return out


def test_section_check_sees_a_missing_section() -> None:
    def documented(a: int) -> int:
        """Twice a.

        Parameters
        ----------
        a : int
            A number.

        Returns
        -------
        int
            2 a.
        """
        return 2 * a

    def undocumented(a: int) -> int:
        """Twice a."""
        return 2 * a

    assert missing_sections(documented) == []
    assert missing_sections(undocumented) == ["Parameters", "Returns"]


def test_public_functions_of_the_cores_have_numpydoc_sections() -> None:
    funcs = public_functions()
    assert len(funcs) > 250  # the walk found the cores
    assert set(EXEMPT) <= {name for name, _ in funcs}, "an exemption names no function"
    gaps = {
        line.split()[0]
        for line in GAPS_FILE.read_text(encoding="utf-8").splitlines()
        if line.strip() and not line.startswith("#")
    }
    lacking = {name: missing_sections(fn) for name, fn in funcs if name not in EXEMPT}
    lacking = {k: v for k, v in lacking.items() if v}
    new = sorted(f"{k}: {', '.join(v)}" for k, v in lacking.items() if k not in gaps)
    assert not new, "public functions without numpydoc sections:\n" + "\n".join(new)
    done = sorted(gaps - set(lacking))
    assert not done, f"documented now, remove from {GAPS_FILE.name}:\n" + "\n".join(done)
