"""A hostile round over final renders with objects in the clouds and over layered skies on the command
line: the surfaces an earlier round left unprobed. Each probe runs in a child process of its own under an 8 GB
address-space cap with a timeout (tests/benchmarks/hostile_round.py's Child), and ends as

- held:   exit 0 and every check the probe makes holds (printed as one `HR-RESULT {...}` line);
- defect: anything else (a signal, a traceback, an exit code, a check that failed, the timeout).

    .venv-5.3/bin/python tests/benchmarks/render_round.py [--match TEXT] [--list]

Prints a table (probe, outcome, seconds, what it measured) for docs/measurements.md.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve()
ROOT = HERE.parents[2]
sys.path[:0] = [str(HERE.parent), str(ROOT), str(ROOT / "tests")]

TIMEOUT = 900.0
TAG = "HR-RESULT "


# ---- what each probe does, in its child -------------------------------------------------------------------


def _scene(engine: str = "CYCLES", size=(64, 36)):
    """The suite's small cloudscape (tests/gpu/render_animation_child.py), one sample."""
    sys.path.insert(0, str(ROOT / "tests" / "gpu"))
    from render_animation_child import small_cloudscape

    return small_cloudscape(engine, size, samples=1)


def _f12(scene, out: Path) -> dict:
    """F12 to a PNG; what the frame composed, and whether the World is the artist's again."""
    import bpy

    from nubis_addon.blender.f12 import composition

    world = scene.world.name
    scene.render.filepath = str(out)
    t = time.perf_counter()
    bpy.ops.render.render(write_still=True)
    return {
        "seconds": round(time.perf_counter() - t, 1),
        "veil": composition.last_frame.get("veil"),
        "world_back": scene.world.name == world,
        "written": out.is_file(),
    }


def _rss_mb() -> float:
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2**20


def probe_five_million_faces(d: Path) -> dict:
    """A 5-million-face mesh standing in the clouds: the depth pre-pass draws it."""
    import bpy

    scene = _scene()
    bpy.ops.mesh.primitive_grid_add(x_subdivisions=2237, y_subdivisions=2237, size=6000.0, location=(0, 6000, 2000))
    grid = bpy.context.object
    grid.rotation_euler = (math.radians(90.0), 0.0, 0.0)
    faces = len(grid.data.polygons)
    got = _f12(scene, d / "five_million.png")
    from nubis_addon.blender.f12 import composition

    return {**got, "faces": faces, "depth_s": round(composition.last_frame.get("depth_s", -1), 2), "rss_mb": _rss_mb()}


def probe_ten_thousand_instances(d: Path) -> dict:
    """10,000 geometry-nodes instances of a cube in the clouds."""
    import bpy

    scene = _scene()
    bpy.ops.mesh.primitive_plane_add(size=8000.0, location=(0, 6000, 2000))
    plane = bpy.context.object
    plane.rotation_euler = (math.radians(90.0), 0.0, 0.0)
    tree = bpy.data.node_groups.new("Scatter", "GeometryNodeTree")
    tree.interface.new_socket("Geometry", in_out="INPUT", socket_type="NodeSocketGeometry")
    tree.interface.new_socket("Geometry", in_out="OUTPUT", socket_type="NodeSocketGeometry")
    nodes = tree.nodes
    grid = nodes.new("GeometryNodeMeshGrid")
    grid.inputs["Size X"].default_value = grid.inputs["Size Y"].default_value = 8000.0
    grid.inputs["Vertices X"].default_value = grid.inputs["Vertices Y"].default_value = 100
    cube = nodes.new("GeometryNodeMeshCube")
    cube.inputs["Size"].default_value = (60.0, 60.0, 60.0)
    inst = nodes.new("GeometryNodeInstanceOnPoints")
    out = nodes.new("NodeGroupOutput")
    tree.links.new(grid.outputs["Mesh"], inst.inputs["Points"])
    tree.links.new(cube.outputs["Mesh"], inst.inputs["Instance"])
    tree.links.new(inst.outputs["Instances"], out.inputs[0])
    mod = plane.modifiers.new("Scatter", "NODES")
    mod.node_group = tree
    depsgraph = bpy.context.evaluated_depsgraph_get()
    instances = sum(1 for i in depsgraph.object_instances if i.is_instance)
    got = _f12(scene, d / "instances.png")
    from nubis_addon.blender.f12 import composition

    return {**got, "instances": instances, "depth_s": round(composition.last_frame.get("depth_s", -1), 2)}


def probe_view_layers(d: Path) -> dict:
    """Two view layers, the wall's collection excluded from the second: every layer renders with the clouds."""
    import bpy

    scene = _scene()
    coll = bpy.data.collections.new("Wall")
    scene.collection.children.link(coll)
    bpy.ops.mesh.primitive_cube_add(size=1.0, location=(0, 3000, 2000), scale=(6000, 60, 400))
    wall = bpy.context.object
    for c in wall.users_collection:
        c.objects.unlink(wall)
    coll.objects.link(wall)
    second = scene.view_layers.new("No wall")
    second.layer_collection.children["Wall"].exclude = True
    scene.render.use_single_layer = False
    got = _f12(scene, d / "layers.png")
    return {**got, "view_layers": len(scene.view_layers)}


def probe_hair_and_points(d: Path) -> dict:
    """Hair curves and a point cloud in the clouds (the depth pre-pass leaves them out: docs/limits.md)."""
    import bpy

    scene = _scene()
    curves = bpy.data.hair_curves.new("Hair") if hasattr(bpy.data, "hair_curves") else None
    points = bpy.data.pointclouds.new("Points") if hasattr(bpy.data, "pointclouds") else None
    made = []
    for data, name in ((curves, "Hair"), (points, "Points")):
        if data is None:
            continue
        obj = bpy.data.objects.new(name, data)
        obj.location = (0, 3000, 2000)
        obj.scale = (500.0, 500.0, 500.0)
        scene.collection.objects.link(obj)
        made.append(name)
    if points is not None:
        points.points.add(1000) if hasattr(points.points, "add") else None
    got = _f12(scene, d / "hair.png")
    return {**got, "objects": made}


def probe_layer_operators_with_undo(d: Path) -> dict:
    """The Cloud Layers buttons with undo and redo between them, then F12."""
    import bpy

    scene = _scene()
    steps = []
    for op in ("cloud_layer_add", "cloud_layer_add", "cloud_layer_move", "cloud_layer_remove"):
        fn = getattr(bpy.ops.nubis, op)
        kwargs = {"direction": "UP"} if op == "cloud_layer_move" else {}
        try:
            steps.append((op, sorted(fn(**kwargs))))
        except RuntimeError as err:  # a refusal is a report, and must be one sentence
            steps.append((op, str(err).splitlines()[0]))
        bpy.ops.ed.undo_push(message=op)
    undo = []
    for _ in range(3):
        try:
            undo.append(sorted(bpy.ops.ed.undo()))
        except RuntimeError as err:
            undo.append(str(err).splitlines()[0])
    try:
        undo.append(sorted(bpy.ops.ed.redo()))
    except RuntimeError as err:
        undo.append(str(err).splitlines()[0])
    scene = bpy.context.scene
    got = _f12(scene, d / "undo.png")
    return {**got, "steps": steps, "undo": undo, "layers": len(scene.nubis.cloud_layers)}


def probe_layer_added_during_animation(d: Path) -> dict:
    """A cloud layer added and its altitude changed from a handler between two frames of Render Animation."""
    import bpy

    scene = _scene()
    bpy.ops.mesh.primitive_cube_add(size=1.0, location=(0, 3000, 2000), scale=(6000, 60, 400))
    changed = []

    def between(sc, *_a):
        if sc.name == scene.name and sc.frame_current == 1 and not changed:
            changed.append(sorted(bpy.ops.nubis.cloud_layer_add()))

    bpy.app.handlers.render_post.append(between)
    scene.frame_start, scene.frame_end = 1, 3
    scene.render.filepath = str(d / "during" / "f_####")
    world = scene.world.name
    bpy.ops.render.render(animation=True)
    files = sorted(os.listdir(d / "during"))
    return {
        "files": files,
        "added": changed,
        "layers": len(scene.nubis.cloud_layers),
        "world_back": scene.world.name == world,
    }


def probe_vdb_replaced_between_frames(d: Path) -> dict:
    """A marked Volume's file replaced on disk by another cloud after frame 1 and by garbage after frame 2."""
    import bpy
    from vdb_helpers import write_cumulus

    scene = _scene()
    path = write_cumulus(d / "cloud.vdb", base=(-1500.0, 2000.0, 1500.0), n_xy=20, n_z=16)
    other = write_cumulus(d / "other.vdb", base=(-500.0, 3000.0, 1800.0), n_xy=12, n_z=10)
    vol = bpy.data.volumes.new("Cloud")
    vol.filepath = str(path)
    obj = bpy.data.objects.new("Cloud", vol)
    scene.collection.objects.link(obj)
    vol.nubis_cloud.enabled = True
    seen = []

    def swap(sc, *_a):
        if sc.name != scene.name:
            return
        seen.append(sc.frame_current)
        if sc.frame_current == 1:
            os.replace(other, path)
        elif sc.frame_current == 2:
            path.write_bytes(b"not a VDB any more" * 100)

    bpy.app.handlers.render_post.append(swap)
    scene.frame_start, scene.frame_end = 1, 3
    scene.render.filepath = str(d / "vdb" / "f_####")
    bpy.ops.render.render(animation=True)
    from nubis_addon.blender.host import status

    return {
        "files": sorted(os.listdir(d / "vdb")),
        "frames": seen,
        "volume_renders_again": not obj.hide_render,
        "said": status.last_error()[:200],
    }


def probe_still_then_quit(d: Path) -> dict:
    """A still F12 with the veil, then the script ends normally (not os._exit): the exit status is the check."""
    import bpy

    scene = _scene()
    bpy.ops.mesh.primitive_cube_add(size=1.0, location=(0, 3000, 2000), scale=(6000, 60, 400))
    return _f12(scene, d / "quit.png")


PROBES = {
    "five million faces in the depth pre-pass": (probe_five_million_faces, lambda r: r["written"] and r["veil"] == 1.0),
    "10,000 geometry-nodes instances": (
        probe_ten_thousand_instances,
        lambda r: r["written"] and r["instances"] >= 10000 and r["veil"] == 1.0,
    ),
    "two view layers, one without the object": (probe_view_layers, lambda r: r["written"] and r["world_back"]),
    "hair curves and a point cloud": (probe_hair_and_points, lambda r: r["written"] and r["world_back"]),
    "Cloud Layers operators with undo and redo": (probe_layer_operators_with_undo, lambda r: r["written"]),
    "a cloud layer added between animation frames": (
        probe_layer_added_during_animation,
        lambda r: r["files"] == ["f_0001.png", "f_0002.png", "f_0003.png"] and r["world_back"],
    ),
    "a VDB file replaced on disk between frames": (
        probe_vdb_replaced_between_frames,
        lambda r: r["files"] == ["f_0001.png", "f_0002.png", "f_0003.png"] and r["volume_renders_again"],
    ),
    "F12 with the veil, then the script ends": (probe_still_then_quit, lambda r: r["written"]),
}

# Layered skies through the command line (each `python -m nubis_addon ...`, output checked to exist).
LAYERED = "altocumulus_over_stratocumulus"
COMMANDS = {
    "preview on a layered preset": (["preview", "--frames", "1-2", "--width", "64", "--height", "36"], "preview"),
    "bake on a layered preset": (["bake", "--voxel-size", "400", "--camera-only"], "cloud.vdb"),
    "compare --draft on a layered preset": (["compare", "--draft", "--width", "64", "--height", "36"], "compare"),
    "benchmark on a layered preset": (["benchmark", "--width", "64", "--height", "36"], "bench"),
}


# ---- the parent -------------------------------------------------------------------------------------------


def child_main(name: str, scratch: Path) -> None:
    fn, _ok = PROBES[name]
    scratch.mkdir(parents=True, exist_ok=True)
    result = fn(scratch)
    print(TAG + json.dumps(result, default=str), flush=True)
    # The script ends as a pipeline's does: no os._exit, so an exit crash is a defect.


def run_probe(name: str, scratch: Path):
    from hostile_round import run_child

    d = scratch / name.replace(" ", "_").replace(",", "")
    if name in PROBES:
        argv = [sys.executable, str(HERE), "--child", name, "--scratch", str(d)]
    else:
        args, out = COMMANDS[name]
        d.mkdir(parents=True, exist_ok=True)
        argv = [sys.executable, "-m", "nubis_addon", args[0], "--preset", LAYERED, "--out", str(d / out), *args[1:]]
    r = run_child(argv, ROOT, scratch / "io", TIMEOUT)
    if r.timed_out:
        return "defect", f"timed out after {r.secs:.0f} s", r.secs
    line = next((x for x in r.out.splitlines() if x.startswith(TAG)), None)
    if r.rc != 0:
        tail = [x for x in r.err.splitlines() if x.strip() and "leaked" not in x and "EGL" not in x][-2:]
        if line is not None:  # the probe's own work ended; the process did not end well
            held = PROBES[name][1](json.loads(line[len(TAG) :]))
            return "defect", f"exit {r.rc} after its checks {'held' if held else 'failed'}", r.secs
        return "defect", f"exit {r.rc} before its checks: {' | '.join(tail)[:300]}", r.secs
    if "Traceback" in r.err:
        return "defect", "a traceback on stderr", r.secs
    if name in COMMANDS:
        out = d / COMMANDS[name][1]
        made = out.exists() and (out.is_file() or any(out.iterdir()))
        return ("held" if made else "defect"), ("wrote " + out.name if made else f"nothing at {out.name}"), r.secs
    if line is None:
        return "defect", "no result line", r.secs
    result = json.loads(line[len(TAG) :])
    ok = PROBES[name][1](result)
    return ("held" if ok else "defect"), json.dumps(result)[:400], r.secs


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--match", default="")
    ap.add_argument("--list", action="store_true")
    ap.add_argument("--child", default="")
    ap.add_argument("--scratch", default="")
    args = ap.parse_args()
    if args.child:
        child_main(args.child, Path(args.scratch))
        return 0
    names = [n for n in [*PROBES, *COMMANDS] if args.match.lower() in n.lower()]
    if args.list:
        print("\n".join(names))
        return 0
    scratch = Path(tempfile.mkdtemp(prefix="nubis-render-round-"))
    rows = []
    for name in names:
        kind, what, secs = run_probe(name, scratch)
        print(f"{kind:7s} {secs:6.0f} s  {name}: {what}", flush=True)
        rows.append((name, kind, secs, what))
    print("\n| probe | outcome | seconds | measured |\n|---|---|---|---|")
    for name, kind, secs, what in rows:
        print(f"| {name} | {kind} | {secs:.0f} | {what.replace('|', '/')} |")
    held = sum(k == "held" for _n, k, _s, _w in rows)
    print(f"\n{len(rows)} probes, {held} held, {len(rows) - held} defects")
    return 0 if held == len(rows) else 1


if __name__ == "__main__":
    sys.exit(main())
