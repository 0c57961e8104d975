"""Copy a `fuzzyslam reproduce` output into data/results/: the report, results.json,
commands.sh, summary.png and seed 0's figures; every link of report.md to a file that is
not copied (the per-seed reports and the other seeds' figures, about 28 MB) becomes plain
text, so that the committed report has no broken link.

    python benchmarks/publish_results.py REPRODUCE_DIR [data/results]
"""

from __future__ import annotations

import re
import shutil
import sys
from pathlib import Path

KEEP = ("report.md", "results.json", "commands.sh", "summary.png")
FIGURES = (
    "seed0/eval_AB/fig3_errors.png",
    "seed0/eval_C/fig1_paths.png",
    "seed0/eval_C/fig3_errors.png",
    "seed0/eval_C/fig4_lamps.png",
    "seed0/eval_D/fig3_errors.png",
    "seed0/eval_D/fig4_lamps.png",
    "seed0/fgm/fgm.png",
    "seed0/fgm/hough.png",
    "seed0/people_pose/changes.png",
)
LINK = re.compile(r"(!?)\[([^\]]*)\]\(([^)]+)\)")


def unlink_missing(text: str, root: Path) -> str:
    """Markdown links (and images) whose local target is not under ``root``: their text."""

    def fix(m: re.Match) -> str:
        _bang, label, target = m.groups()
        if target.startswith(("http://", "https://", "#")) or (root / target).exists():
            return m.group(0)
        return f"{label or target} (`{target}`, not committed: rerun reproduce)"

    return LINK.sub(fix, text)


def main() -> None:
    src = Path(sys.argv[1])
    dst = Path(sys.argv[2]) if len(sys.argv) > 2 else Path("data/results")
    for rel in (*KEEP, *FIGURES):
        (dst / rel).parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(src / rel, dst / rel)
    rep = dst / "report.md"
    rep.write_text(unlink_missing(rep.read_text(encoding="utf-8"), dst), encoding="utf-8")


if __name__ == "__main__":
    main()
