"""Every relative link of README.md and docs/ resolves: the file is in the repository and, for a Markdown
page with an anchor, the anchor is one of its headings. The README stays a five-minute read: at most 300
lines, a handful of dated lines, both commands near the top and the install steps with a picture of the
extension in Blender within its first 60 lines."""

from __future__ import annotations

import re
from pathlib import Path

from test_citations import github_anchors

ROOT = Path(__file__).resolve().parents[2]
LINK = re.compile(r"!?\[[^\]]*\]\(([^)\s]+)\)")
DATE = re.compile(r"\b20[0-9]{2}-[01][0-9]-[0-3][0-9]\b")


def _pages() -> list[Path]:
    return [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]


def _links(page: Path) -> list[str]:
    text, fence = [], False
    for line in page.read_text(encoding="utf-8").splitlines():
        if line.startswith("```"):
            fence = not fence
            continue
        if not fence:
            text.append(line)
    return LINK.findall("\n".join(text))


def test_every_relative_link_resolves():
    broken = []
    checked = 0
    for page in _pages():
        for target in _links(page):
            if re.match(r"[a-z]+://|mailto:", target):
                continue
            path, _, anchor = target.partition("#")
            dest = (page.parent / path).resolve() if path else page
            checked += 1
            if not dest.exists():
                broken.append(f"{page.relative_to(ROOT)}: {target} (no such file)")
            elif anchor and dest.suffix == ".md" and anchor not in github_anchors(dest.read_text(encoding="utf-8")):
                broken.append(f"{page.relative_to(ROOT)}: {target} (no such heading)")
    assert checked > 50, "the pages hold their links"
    assert broken == []


def test_the_readme_is_a_five_minute_read():
    lines = (ROOT / "README.md").read_text(encoding="utf-8").splitlines()
    assert len(lines) <= 300
    assert sum(bool(DATE.search(line)) for line in lines) <= 5
    fences = [i for i, line in enumerate(lines) if line.startswith("```")]
    assert len(fences) >= 4 and fences[3] < 40, "both commands within the first 40 lines"
    head = "\n".join(lines[:60])
    assert "## Install in Blender" in head and "Install from Disk" in head
    assert re.search(r"!\[[^\]]*Blender[^\]]*\]\(presets/gallery/blender_app\.png\)", head)
