"""The package's structure, read from its source (no Blender): the layers import one way, no module
imports another that imports it back (function-level imports included), and the settings schema is
consistent."""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

from conftest import ROOT

PACKAGE = ROOT / "nubis_addon"


def _module_name(path: Path) -> str:
    parts = path.relative_to(ROOT).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _modules() -> dict[str, Path]:
    return {_module_name(p): p for p in PACKAGE.rglob("*.py")}


def _resolve(importer: str, is_package: bool, level: int, module: str | None) -> str:
    base = importer.split(".")
    if not is_package:
        base = base[:-1]
    if level > 1:
        base = base[: len(base) - (level - 1)]
    return ".".join([*base, *([module] if module else [])])


def import_graph() -> dict[str, set[str]]:
    """Each module's imports of the package's own modules, at any depth of the source (inside
    functions too). ``from . import x`` names the module x when there is one, else the package."""
    modules = _modules()
    graph: dict[str, set[str]] = {m: set() for m in modules}
    for name, path in modules.items():
        is_package = path.name == "__init__.py"
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            targets: list[str] = []
            if isinstance(node, ast.Import):
                targets = [a.name for a in node.names if a.name.startswith("nubis_addon")]
            elif isinstance(node, ast.ImportFrom):
                if node.level == 0:
                    if not (node.module or "").startswith("nubis_addon"):
                        continue
                    base = node.module
                else:
                    base = _resolve(name, is_package, node.level, node.module)
                for alias in node.names:
                    sub = f"{base}.{alias.name}"
                    targets.append(sub if sub in modules else base)
            graph[name].update(t for t in targets if t in modules and t != name)
    return graph


def _cycle(graph: dict[str, set[str]]) -> list[str] | None:
    state: dict[str, int] = {}
    stack: list[str] = []

    def visit(node: str) -> list[str] | None:
        state[node] = 1
        stack.append(node)
        for nxt in sorted(graph[node]):
            if state.get(nxt) == 1:
                return stack[stack.index(nxt) :] + [nxt]
            if nxt not in state:
                found = visit(nxt)
                if found:
                    return found
        stack.pop()
        state[node] = 2
        return None

    for node in sorted(graph):
        if node not in state:
            found = visit(node)
            if found:
                return found
    return None


def test_no_import_cycle_function_level_imports_included():
    graph = import_graph()
    assert len(graph) > 40  # the walk found the package
    assert "nubis_addon.blender.scene.cloudstate" in graph["nubis_addon.blender.live.viewport"]  # and its edges
    cycle = _cycle(graph)
    assert cycle is None, " -> ".join(cycle)


def test_the_cycle_finder_finds_a_cycle():
    assert _cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}}) == ["a", "b", "c", "a"]
    assert _cycle({"a": {"b"}, "b": set()}) is None


# blender/'s folders from the bottom up; folders on one floor do not import one another
# (nubis_addon/blender/__init__.py).
BLENDER_FLOORS = (("host",), ("scene",), ("live", "jobs"), ("f12",), ("sidebar",), ("registration",), ("headless",))


def _blender_room(module: str) -> str | None:
    parts = module.split(".")
    if parts[:2] != ["nubis_addon", "blender"] or len(parts) < 3:
        return None
    return parts[2]


def test_blender_folders_import_one_way():
    """Every Blender-side module lives in a folder of purpose (registration alone beside them), and a
    folder imports only folders on the floors below it: none back up, none beside it."""
    floor = {room: i for i, rooms in enumerate(BLENDER_FLOORS) for room in rooms}
    graph = import_graph()
    rooms = {_blender_room(m) for m in graph} - {None}
    assert rooms == set(floor), f"rooms without a floor or floors without a room: {rooms ^ set(floor)}"
    bad = []
    for name, targets in graph.items():
        src = _blender_room(name)
        if src is None:
            continue
        for target in targets:
            dst = _blender_room(target)
            if dst is None or dst == src:
                continue
            if floor[dst] >= floor[src]:
                bad.append(f"{name} -> {target}")
    assert not bad, "imports that run back up or sideways: " + ", ".join(sorted(bad))


def test_the_floor_check_sees_an_import_back_up():
    assert _blender_room("nubis_addon.blender.scene.sky") == "scene"
    assert _blender_room("nubis_addon.blender") is None
    floor = {room: i for i, rooms in enumerate(BLENDER_FLOORS) for room in rooms}
    assert floor["scene"] < floor["live"] == floor["jobs"] < floor["f12"]


def _external_imports(path: Path) -> set[str]:
    out = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            out.update(a.name.split(".")[0] for a in node.names)
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            out.add(node.module.split(".")[0])
    return out


def test_layers_import_one_way():
    """core/ imports no bpy, gpu or mathutils; render/ nothing from blender/ or the command line;
    nothing below cli.py imports it."""
    graph = import_graph()
    for name, path in _modules().items():
        if name.startswith("nubis_addon.core"):
            assert not _external_imports(path) & {"bpy", "gpu", "gpu_extras", "mathutils", "bmesh"}, name
            assert all(t.startswith("nubis_addon.core") for t in graph[name]), (name, graph[name])
        if name.startswith("nubis_addon.render"):
            assert all(t.startswith(("nubis_addon.core", "nubis_addon.render")) for t in graph[name]), name
        if name.startswith(("nubis_addon.blender", "nubis_addon.render", "nubis_addon.core")):
            assert "nubis_addon.cli" not in graph[name], name
            assert "nubis_addon" not in graph[name], name


def test_functions_stay_short_and_take_an_options_object():
    """No function of the package is longer than 100 lines or takes more than 8 parameters (self and cls
    not counted; *args and **kwargs count one each): a job's options travel as one object."""
    too_big = []
    for name, path in _modules().items():
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if not isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                continue
            a = node.args
            params = [x.arg for x in a.posonlyargs + a.args + a.kwonlyargs if x.arg not in ("self", "cls")]
            params += [x.arg for x in (a.vararg, a.kwarg) if x is not None]
            lines = node.end_lineno - node.lineno + 1
            if lines > 100 or len(params) > 8:
                too_big.append(f"{name}.{node.name}: {lines} lines, {len(params)} parameters")
    assert not too_big, too_big


# Modules allowed past MODULE_LINES, for good: the settings' table and the noise (docs/architecture.md).
MODULE_LINES = 600
LONG_MODULES = {
    "core.schema": None,
    "core.noise": None,
}


def test_modules_stay_under_600_lines():
    too_long = []
    for name, path in _modules().items():
        lines = len(path.read_text(encoding="utf-8").splitlines())
        key = name.removeprefix("nubis_addon.")
        ceiling = LONG_MODULES.get(key, MODULE_LINES)
        if ceiling is not None and lines > ceiling:
            too_long.append(f"{name}: {lines} lines (at most {ceiling})")
    assert not too_long, "split these by concern: " + ", ".join(too_long)
    held = {k for k, v in LONG_MODULES.items() if v is not None}
    names = {n.removeprefix("nubis_addon.") for n in _modules()}
    assert held <= names, f"no such module: {sorted(held - names)}: take it off LONG_MODULES"


def test_core_imports_without_blender():
    """In a fresh interpreter, every core module imports and none pulls in bpy."""
    code = (
        "import importlib, pkgutil, sys, nubis_addon.core as c\n"
        "for m in pkgutil.iter_modules(c.__path__): importlib.import_module('nubis_addon.core.' + m.name)\n"
        "bad = [m for m in ('bpy', 'gpu', 'mathutils') if m in sys.modules]\n"
        "print(bad); sys.exit(1 if bad else 0)\n"
    )
    r = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True)
    assert r.returncode == 0, r.stdout + r.stderr


def test_schema_is_consistent_and_every_setting_has_a_panel_or_a_reason():
    from nubis_addon.core import schema

    schema.check_schema()
    assert len(schema.SCENE) > 60 and len(schema.FIELD_LAYER) > 15 and len(schema.STORM) > 15
    drawn = [s for s in schema.ALL if s.panel]
    internal = [s for s in schema.ALL if s.internal]
    assert len(drawn) + len(internal) == len(schema.ALL)
    # The settings the review found without UI are drawn now.
    for key in (
        "cirrus_altitude",
        "cirrus_wind_speed",
        "storm_anvil_shift",
        "storm_glow_height",
        "rule_cumulonimbus_top",
        "rule_horizon_start",
    ):
        assert schema.BY_KEY[key].panel, key


def test_one_name_per_setting_on_the_gpu():
    """The shaders read each setting by its key (P.lighting_powder): the uniform block's members are
    the schema's GPU settings plus the derived values, and no positional packing."""
    from nubis_addon.core import schema
    from nubis_addon.render import uniforms

    members = {name for name, _type, _n in uniforms.struct_members()}
    for s in schema.gpu_settings():
        assert s.key in members, s.key
    shaders = "\n".join(p.read_text() for p in (ROOT / "shaders").glob("*.glsl"))
    for s in schema.gpu_settings():
        assert f"P.{s.key}" in shaders, f"{s.key} reaches the GPU but no shader reads it"
