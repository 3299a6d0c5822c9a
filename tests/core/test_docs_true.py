"""The docs stay true to the code they describe, read from the code itself (pure Python, no Blender):

- **The command line.** Every option of every command, as the real argument parser (`cli.build_parser()`)
  accepts it, is in that command's synopsis in docs/cli.md (the ```text block at its top, one entry per
  command: the line `python -m nubis_addon COMMAND ...` and the indented lines under it) and in the same
  synopsis in the module docstring of nubis_addon/cli.py; no synopsis names a command or an option the
  parser does not have; and every option is explained in docs/cli.md's prose (outside the code blocks).
- **The modules.** Every module of the package (every .py file under nubis_addon/) is named in
  docs/architecture.md, and every module that page names exists. A module is named by its path: below a
  subpackage from the subpackage's folder (`core/vdbcheck.py`, `blender/__init__.py`, optionally with
  `nubis_addon/` in front), at the top always whole (`nubis_addon/cli.py`, `nubis_addon/__init__.py`), so
  the repository's own `__init__.py` is not taken for the package's. A path counts only whole: not
  preceded by a word character, `/` or `.`, not followed by a word character. The docstring of
  nubis_addon/blender/__init__.py lists every folder of blender/ (and registration.py) top down, as the
  floors of tests/core/test_architecture.py stand, and each folder's docstring names its modules and what
  it may import.
- **The presets.** Every preset that ships (what core/presets.py lists: the .toml files directly in
  presets/, so presets/quality/ is none) is in the README's gallery (the table after "**Presets.**"), its
  picture, where it has one, presets/gallery/<name>.png; the gallery shows nothing else; and the README's
  count of skies ("**Presets.** Nine skies") is the number of presets, written as an English word.

Each failure says what is missing and where to add it.
"""

from __future__ import annotations

import ast
import re
from pathlib import Path

from test_architecture import BLENDER_FLOORS

from nubis_addon import cli
from nubis_addon.core import schema
from nubis_addon.core.presets import list_presets, preset_dir

ROOT = Path(__file__).resolve().parents[2]
PACKAGE = ROOT / "nubis_addon"
CLI_DOC = ROOT / "docs" / "cli.md"
ARCHITECTURE = ROOT / "docs" / "architecture.md"
README = ROOT / "README.md"
ENTRY = re.compile(r"^python -m nubis_addon (\S+)")
OPTION = re.compile(r"(?<![\w-])--[a-z][a-z0-9-]*")
NUMBERS = (
    "zero one two three four five six seven eight nine ten eleven twelve thirteen fourteen fifteen sixteen "
    "seventeen eighteen nineteen twenty"
).split()


# ---- the command line ------------------------------------------------------------------------------------


def parser_options() -> dict[str, set[str]]:
    """Each command's long options, from the parser the command line runs (`--help` aside)."""
    parser = cli.build_parser()
    commands = parser._subparsers._group_actions[0].choices
    return {
        name: {o for action in sub._actions for o in action.option_strings if o.startswith("--")} - {"--help"}
        for name, sub in commands.items()
    }


def synopsis(text: str) -> dict[str, str]:
    """Each command's synopsis entry in `text`: its `python -m nubis_addon COMMAND` line (leading whitespace
    aside) and the lines under it that are indented further."""
    entries: dict[str, str] = {}
    current, indent = None, 0
    for line in text.splitlines():
        stripped = line.lstrip()
        depth = len(line) - len(stripped)
        m = ENTRY.match(stripped)
        if m:
            current, indent = m.group(1), depth
            entries[current] = entries.get(current, "") + " " + stripped
        elif current is not None and stripped and depth > indent:
            entries[current] += " " + stripped
        else:
            current = None
    return entries


def _fenced(text: str, inside: bool) -> str:
    """The lines of a Markdown page inside (or outside) its ``` blocks."""
    kept, fence = [], False
    for line in text.splitlines():
        if line.startswith("```"):
            fence = not fence
            continue
        if fence == inside:
            kept.append(line)
    return "\n".join(kept)


def _check_synopsis(entries: dict[str, str], where: str) -> list[str]:
    problems = []
    for command, options in sorted(parser_options().items()):
        if command not in entries:
            problems.append(
                f"{where} has no synopsis of `{command}`: add a line `python -m nubis_addon {command} ...` "
                f"with its options ({' '.join(sorted(options))})"
            )
            continue
        named = set(OPTION.findall(entries[command]))
        if missing := sorted(options - named):
            problems.append(f"{where}: the synopsis of `{command}` lacks {', '.join(missing)}: add them to it")
        if stale := sorted(named - options):
            problems.append(
                f"{where}: the synopsis of `{command}` names {', '.join(stale)}, which `{command}` does not take: "
                "remove them (or add them to cli.build_parser())"
            )
    for command in sorted(set(entries) - set(parser_options())):
        problems.append(f"{where} has a synopsis of `{command}`, which is no command: remove it")
    return problems


def test_parser_is_read():
    options = parser_options()
    assert {"render", "bake", "compare"} <= set(options), "cli.build_parser() no longer has its subcommands"
    assert "--out" in options["render"] and "--passes" in options["render"], "the parser's options are not read"


def test_every_option_is_in_the_synopsis_of_docs_cli():
    text = _fenced(CLI_DOC.read_text(encoding="utf-8"), inside=True)
    problems = _check_synopsis(synopsis(text), "docs/cli.md (the ```text block at the top)")
    assert not problems, "\n".join(problems)


def test_every_option_is_in_the_synopsis_of_the_cli_docstring():
    problems = _check_synopsis(synopsis(cli.__doc__ or ""), "the module docstring of nubis_addon/cli.py")
    assert not problems, "\n".join(problems)


def test_every_option_is_explained_in_docs_cli():
    prose = _fenced(CLI_DOC.read_text(encoding="utf-8"), inside=False)
    named = set(OPTION.findall(prose))
    missing = {}
    for command, options in parser_options().items():
        for option in options - named:
            missing.setdefault(option, []).append(command)
    assert not missing, (
        "docs/cli.md explains no use of "
        + "; ".join(f"{option} (of {', '.join(sorted(commands))})" for option, commands in sorted(missing.items()))
        + ": say what each does in the prose under the synopsis (in the bullet of its command)"
    )


# ---- the modules -----------------------------------------------------------------------------------------


def module_names() -> dict[str, Path]:
    """Every module of the package by the name architecture.md gives it (the module docstring's rule)."""
    names = {}
    for path in sorted(PACKAGE.rglob("*.py")):
        rel = path.relative_to(PACKAGE).as_posix()
        names[rel if "/" in rel else f"nubis_addon/{rel}"] = path
    return names


def _named(name: str, text: str) -> bool:
    # A top-level module is named whole (nubis_addon/cli.py); one below a subpackage from there or whole.
    pattern = re.escape(name) if name.startswith("nubis_addon/") else f"(?:nubis_addon/)?{re.escape(name)}"
    return re.search(rf"(?<![\w/.]){pattern}(?!\w)", text) is not None


def test_every_module_is_in_docs_architecture():
    text = ARCHITECTURE.read_text(encoding="utf-8")
    modules = module_names()
    assert "nubis_addon/cli.py" in modules and "core/presets.py" in modules, "the package's modules are not found"
    missing = [name for name in modules if not _named(name, text)]
    assert not missing, (
        "docs/architecture.md does not name "
        + ", ".join(missing)
        + ": add each, written as here, with a few words on what it does, to the list of its folder under "
        "'## Modules'"
    )


def test_every_module_docs_architecture_names_exists():
    text = ARCHITECTURE.read_text(encoding="utf-8")
    named = set(re.findall(r"(?<![\w/.])(?:nubis_addon/)?(?:[a-z_]+/)?[a-z_]+\.py(?!\w)", text))
    gone = sorted(n for n in named if not (PACKAGE / n.removeprefix("nubis_addon/")).is_file())
    assert not gone, (
        f"docs/architecture.md names {', '.join(gone)}, not in nubis_addon/: remove or rename them (a module "
        "below a subpackage is written from its folder, core/x.py; one at the top whole, nubis_addon/x.py)"
    )


def blender_listing() -> list[str]:
    """The folders (and registration.py) the docstring of blender/__init__.py lists, in its order (read
    without importing bpy): its items start '- name/:' or '- name.py:'."""
    path = PACKAGE / "blender" / "__init__.py"
    doc = ast.get_docstring(ast.parse(path.read_text(encoding="utf-8"))) or ""
    return [m.group(1) for m in re.finditer(r"^- ([a-z_0-9]+)(?:/|\.py):", doc, re.M)]


def test_the_blender_docstring_lists_every_folder_top_down():
    listed = blender_listing()
    rooms = sorted(
        p.parent.name if p.name == "__init__.py" else p.stem for p in (PACKAGE / "blender").glob("*/__init__.py")
    ) + sorted(p.stem for p in (PACKAGE / "blender").glob("*.py") if p.stem != "__init__")
    assert sorted(listed) == sorted(rooms), (
        f"the docstring of nubis_addon/blender/__init__.py lists {listed}, the folder holds {rooms}: give each "
        "folder a '- name/: what it holds;' item, top down"
    )
    floors = [room for rooms_on in reversed(BLENDER_FLOORS) for room in sorted(rooms_on)]
    rank = {room: i for i, rooms_on in enumerate(reversed(BLENDER_FLOORS)) for room in rooms_on}
    order = [rank[room] for room in listed]
    assert order == sorted(order), f"list them top down as the floors stand: {floors}"


def test_each_blender_folder_names_its_modules():
    """Each folder's docstring names every module in it, and what it may import."""
    missing = []
    for init in sorted((PACKAGE / "blender").glob("*/__init__.py")):
        doc = ast.get_docstring(ast.parse(init.read_text(encoding="utf-8"))) or ""
        assert "May import:" in doc, f"{init.relative_to(ROOT)}: its docstring does not say what it may import"
        for module in sorted(init.parent.glob("*.py")):
            if module.stem != "__init__" and not re.search(rf"(?<![\w.]){module.stem}(?!\w)", doc):
                missing.append(f"{init.parent.name}/{module.name}")
    assert not missing, f"the folders' docstrings do not name {', '.join(missing)}: say in a few words what each holds"


# ---- the presets -----------------------------------------------------------------------------------------


def _readme_presets() -> tuple[str, list[str]]:
    """The README's "**Presets.**" paragraph and the cells of the gallery table under it."""
    lines = README.read_text(encoding="utf-8").splitlines()
    start = next((i for i, line in enumerate(lines) if line.startswith("**Presets.**")), None)
    assert start is not None, "README.md has no paragraph starting '**Presets.**': the gallery's home is gone"
    paragraph, cells, i = [], [], start
    while i < len(lines) and lines[i].strip() and not lines[i].startswith("|"):
        paragraph.append(lines[i])
        i += 1
    while i < len(lines) and not lines[i].startswith("|"):
        i += 1
    while i < len(lines) and lines[i].startswith("|"):
        cells += [c.strip() for c in lines[i].strip().strip("|").split("|")]
        i += 1
    return " ".join(paragraph), [c for c in cells if c and not re.fullmatch(r":?-+:?", c)]


def test_every_preset_is_in_the_readme_gallery():
    presets = list_presets()
    assert "default" in presets and all((preset_dir() / f"{p}.toml").is_file() for p in presets)
    _paragraph, cells = _readme_presets()
    shown = {}
    for cell in cells:
        pictures = re.findall(r"!\[[^\]]*\]\(([^)]+)\)", cell)
        name = re.sub(r"!\[[^\]]*\]\([^)]*\)", "", cell).strip().strip("`")
        shown[name] = pictures
    missing = [p for p in presets if p not in shown]
    assert not missing, (
        f"README.md's gallery (the table under '**Presets.**') lacks {', '.join(missing)}: add a cell "
        "'![](presets/gallery/NAME.png) NAME' for each (the name alone where there is no picture)"
    )
    extra = sorted(set(shown) - set(presets))
    assert not extra, f"README.md's gallery shows {', '.join(extra)}, which no preset in presets/ is: remove them"
    wrong = [f"{name}: {pics}" for name, pics in shown.items() if pics not in ([], [f"presets/gallery/{name}.png"])]
    assert not wrong, "README.md's gallery: each preset's picture is presets/gallery/<name>.png: " + "; ".join(wrong)


def test_the_readme_counts_the_presets():
    count = len(list_presets())
    assert count < len(NUMBERS), f"{count} presets: extend NUMBERS in this test to name the count"
    paragraph, _cells = _readme_presets()
    m = re.match(r"\*\*Presets\.\*\* (\w+) skies\b", paragraph)
    assert m, "README.md: the '**Presets.**' paragraph opens with the count of skies ('**Presets.** Nine skies')"
    word = m.group(1).lower()
    assert word in NUMBERS, f"README.md: write the count of skies as a word ('{NUMBERS[count].title()}'), not '{word}'"
    assert NUMBERS.index(word) == count, (
        f"README.md says '{m.group(1)} skies' but {count} presets ship in presets/: "
        f"write '**Presets.** {NUMBERS[count].title()} skies'"
    )


# ---- the paths ------------------------------------------------------------------------------------------

# A path a doc names from the repository's root: a top folder of the repository, then folders and a file name
# with an extension. Names with a wildcard or a placeholder (`out/<name>.png`, `f_####`) are left out, as are
# the folders a run writes (out/, build/) and the virtual environments.
REPO_PATH = re.compile(
    r"(?<![\w/.<-])((?:tests|shaders|nubis_addon|presets|docs|\.ci)/[\w./-]*\w\.(?:py|glsl|md|toml|png|json|js|txt))(?![\w/<*#])"
)


def _named_paths() -> list[tuple[str, int, str]]:
    """(doc, line, path) for every repository path the README and docs/ name."""
    found = []
    for doc in [README, *sorted((ROOT / "docs").glob("*.md"))]:
        for n, line in enumerate(doc.read_text(encoding="utf-8").splitlines(), 1):
            for m in REPO_PATH.finditer(line):
                found.append((doc.relative_to(ROOT).as_posix(), n, m.group(1)))
    return found


def test_the_path_reader_finds_paths():
    """The reader itself: a doc's paths are found (a pattern that matched nothing would pass anything)."""
    paths = {p for _d, _n, p in _named_paths()}
    assert {"tests/core/test_docs_true.py", "shaders/nubis_density_lib.glsl"} <= paths, sorted(paths)[:20]


def test_every_path_a_doc_names_exists():
    dead = [f"{doc}:{n}: {path}" for doc, n, path in _named_paths() if not (ROOT / path).exists()]
    assert not dead, "these paths do not exist; name the file as it is now:\n" + "\n".join(dead)


# ---- the panels and their labels -------------------------------------------------------------------------

GUIDE = ROOT / "docs" / "guide.md"
# What the guide's panel list may set in bold besides the code's labels: keys and icon buttons.
KEYS = {"+", "-", "Esc"}


def _classes_of_blender() -> list[ast.ClassDef]:
    return [
        node
        for path in sorted((PACKAGE / "blender").rglob("*.py"))
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8")))
        if isinstance(node, ast.ClassDef)
    ]


def _label(node: ast.ClassDef) -> str | None:
    for stmt in node.body:
        if isinstance(stmt, ast.Assign) and any(getattr(t, "id", "") == "bl_label" for t in stmt.targets):
            return stmt.value.value if isinstance(stmt.value, ast.Constant) else None
    return None


def sidebar_panels() -> set[str]:
    """The Nubis tab's panels by label: the main panel, every SidebarPanel subclass, and the panels the
    schema generates (core/schema.py PANELS)."""
    labels = {label for _id, label in schema.PANELS}
    for node in _classes_of_blender():
        bases = {getattr(b, "id", None) or getattr(b, "attr", None) for b in node.bases}
        if node.name == "NUBIS_PT_main" or ("SidebarPanel" in bases and node.name.startswith("NUBIS_PT_")):
            label = _label(node)
            if label:
                labels.add(label)
    return labels


def code_labels() -> set[str]:
    """Every label the interface shows: classes' bl_label, text= and name= strings in blender/, the schema's
    settings' labels and enum items' names, and its panels'."""
    labels = {label for _id, label in schema.PANELS} | {s.label for s in schema.ALL}
    labels |= {item[1] for s in schema.ALL for item in s.items}
    labels |= {lab for node in _classes_of_blender() if (lab := _label(node))}
    for path in (PACKAGE / "blender").rglob("*.py"):
        labels |= set(re.findall(r'\b(?:text|name)="([^"]+)"', path.read_text(encoding="utf-8")))
    return labels


def _guide_panel_list() -> str:
    text = GUIDE.read_text(encoding="utf-8")
    start = text.index("What each panel holds:")
    end = text.find("\n## ", start)
    return text[start : end if end >= 0 else len(text)]


def test_the_guide_lists_every_sidebar_panel_by_its_label():
    listed = set(re.findall(r"^- \*\*([^*]+)\*\*", _guide_panel_list(), re.M))
    panels = sidebar_panels()
    assert len(panels) >= 12, sorted(panels)
    missing, unknown = sorted(panels - listed), sorted(listed - panels)
    assert not missing, f"docs/guide.md's panel list lacks {missing}: add a '- **Label**: ...' item for each"
    assert not unknown, f"docs/guide.md lists {unknown}, which no sidebar panel is called: use the panel's label"


def test_every_label_the_guide_sets_in_bold_is_the_interface_s():
    bold = set(re.findall(r"\*\*([^*]+)\*\*", _guide_panel_list()))
    assert len(bold) > 30, sorted(bold)
    wrong = sorted(bold - code_labels() - KEYS)
    assert not wrong, (
        f"docs/guide.md names {wrong} in bold, which the interface does not show: write the label as it is"
    )
