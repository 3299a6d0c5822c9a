"""The repository explains itself: no file cites a document that is not in the repository, and every
`docs/<page>.md#<anchor>` a file cites is a heading of that page. Pure Python (git and the files only).

The code cites the publications (GPU Pro 7, S15, GDC22, Hillaire 2016, Wrenninge et al.) or the
project's own docs/ pages; docs/sources.md lists the sources and the choices made between them.
"""

from __future__ import annotations

import re
import subprocess
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
THIS = Path(__file__).resolve().relative_to(ROOT).as_posix()

# Citations of documents outside the repository: the design notes' section numbers ("SPEC 2.5"), their
# open questions ("Q16") and markers ("[IMPL]"), their source ids (HABR, GPU7, GDC22N), the notes
# themselves and their folder of papers, and the issue tracker ("issue 3").
FOREIGN = re.compile(
    r"\bSPEC\b|\bQ[0-9]{1,2}\b|\[IMPL\]|\[SRC\b|\[DERIVED\]|DESIGN\.md|PLATFORM\.md|\bchecklist\b|§|seeds/"
    r"|\bHABR\b|\bGPU7\b|\bGDC22N\b|(?i:\bissue ?#?[0-9]+\b)"
)

BINARY_SUFFIXES = {".png", ".jpg", ".jpeg", ".exr", ".vdb", ".blend", ".zip", ".npy", ".npz", ".gz", ".whl"}
# "docs/page.md" or "docs/page.md#anchor" anywhere; within docs/, also "](page.md#anchor)" and "](#anchor)".
DOC_CITATION = re.compile(r"docs/([A-Za-z0-9_\-]+\.md)(?:#([A-Za-z0-9_\-]+))?")
DOC_LINK = re.compile(r"\]\(([A-Za-z0-9_\-]*\.md)?#([A-Za-z0-9_\-]+)\)")


def tracked_text_files() -> dict[str, str]:
    """Every file git tracks that is text, by its path relative to the repository."""
    listing = subprocess.run(["git", "ls-files", "-z"], cwd=ROOT, capture_output=True, check=True).stdout
    files = {}
    for raw in listing.split(b"\0"):
        if not raw:
            continue
        rel = raw.decode("utf-8")
        path = ROOT / rel
        if path.suffix.lower() in BINARY_SUFFIXES or not path.is_file():
            continue
        data = path.read_bytes()
        if b"\0" in data:
            continue
        files[rel] = data.decode("utf-8", errors="replace")
    return files


def github_anchors(markdown: str) -> set[str]:
    """The anchors GitHub gives a page's headings: lower case, punctuation dropped, spaces to hyphens,
    a repeated heading numbered -1, -2, ..."""
    anchors: set[str] = set()
    counts: dict[str, int] = {}
    in_fence = False
    for line in markdown.splitlines():
        if line.startswith("```"):
            in_fence = not in_fence
        m = None if in_fence else re.match(r"#{1,6}\s+(.*?)\s*#*\s*$", line)
        if not m:
            continue
        text = re.sub(r"[`*_]|\[([^\]]*)\]\([^)]*\)", lambda g: g.group(1) or "", m.group(1))
        slug = re.sub(r"[^\w\- ]", "", text.strip().lower()).replace(" ", "-")
        n = counts.get(slug, 0)
        counts[slug] = n + 1
        anchors.add(slug if n == 0 else f"{slug}-{n}")
    return anchors


def test_no_file_cites_a_document_outside_the_repository():
    files = tracked_text_files()
    assert "README.md" in files and any(f.startswith("shaders/") for f in files), "git ls-files saw no sources"
    hits = []
    for rel, text in files.items():
        if rel == THIS:
            continue
        for number, line in enumerate(text.splitlines(), 1):
            if FOREIGN.search(line):
                hits.append(f"{rel}:{number}: {line.strip()}")
    assert not hits, "cite the publication or docs/ (docs/sources.md) instead:\n" + "\n".join(hits)


def test_every_cited_docs_anchor_is_a_heading():
    files = tracked_text_files()
    pages = {rel.removeprefix("docs/"): text for rel, text in files.items() if re.fullmatch(r"docs/[^/]+\.md", rel)}
    assert "sources.md" in pages, "docs/sources.md is missing"
    anchors = {page: github_anchors(text) for page, text in pages.items()}
    cited = 0
    missing = []
    for rel, text in files.items():
        if rel == THIS:
            continue
        refs = [(m.group(1), m.group(2)) for m in DOC_CITATION.finditer(text)]
        if rel.startswith("docs/"):
            here = rel.removeprefix("docs/")
            refs += [(m.group(1) or here, m.group(2)) for m in DOC_LINK.finditer(text)]
        for page, anchor in refs:
            cited += 1
            if page not in pages:
                missing.append(f"{rel}: docs/{page} does not exist")
            elif anchor and anchor not in anchors[page]:
                missing.append(f"{rel}: docs/{page}#{anchor} is not a heading of docs/{page}")
    assert cited > 50, f"only {cited} citations of docs/ pages found: is the pattern still right?"
    assert not missing, "\n".join(sorted(set(missing)))


def test_anchor_rules_match_github():
    anchors = github_anchors("# Sources\n## Rain and storm absorption\n### Henyey-Greenstein\n## `x` (y)\n## Sources\n")
    assert anchors == {"sources", "rain-and-storm-absorption", "henyey-greenstein", "x-y", "sources-1"}
