"""A pipeline's own bpy script rendering the default cloudscape with a wall standing in the clouds, run in a
child process by tests/gpu/test_render_animation.py (a crash is then one failed test, not the suite's end).

    python render_animation_child.py ENGINE OUTDIR RENDERS

It renders those of these named in RENDERS (comma-separated), in this order, writing one JSON line per
render to stdout ("RESULT {...}"):
- still:    F12 at 101 x 57 and 33 % (a percentage that does not divide evenly);
- anim:     Render Animation of frames 1-3: the wall under the ground in frame 1 and in the clouds from
            frame 2 (the veil comes in mid-animation, the shadow casters' stack grows), after the still;
- failing:  Render Animation whose frame 2 cannot be written (a folder stands where its file goes);
- vdb:      (not a render) a marked VDB cloud in the scene for all of them;
and then ends as a script ends (no os._exit): the test reads its exit status.
"""

from __future__ import annotations

import json
import math
import os
import sys
from pathlib import Path

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
sys.path.insert(0, ROOT)

import bpy  # noqa: E402

from nubis_addon.blender import ensure_registered  # noqa: E402
from nubis_addon.blender.f12 import composition, scene_render, shadows  # noqa: E402
from nubis_addon.core import imageio  # noqa: E402

ENGINE, OUT, RENDERS = "", "", []  # from the command line (main)
FRAMES: list[dict] = []


def report(name: str, **values) -> None:
    print("RESULT " + json.dumps({"render": name, **values}), flush=True)


def small_cloudscape(engine: str, size: tuple[int, int] = (64, 36), samples: int = 2):
    """The default cloudscape, a camera 2 km up looking level into the layer, a small fast render in
    `engine` (CYCLES, or EEVEE under the line's name for it). Also the render round's scene
    (tests/benchmarks/render_round.py)."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    ensure_registered()
    assert bpy.ops.nubis.new_cloudscape(preset="default") == {"FINISHED"}
    scene = bpy.context.scene
    cam = scene.camera
    cam.location, cam.rotation_euler = (0.0, 0.0, 2000.0), (math.radians(90.0), 0.0, 0.0)
    cam.data.lens, cam.data.clip_end = 30.0, 100000.0
    r = scene.render
    r.resolution_x, r.resolution_y, r.resolution_percentage = *size, 100
    if engine.startswith("BLENDER_EEVEE") or engine == "EEVEE":
        items = {e.identifier for e in bpy.types.RenderSettings.bl_rna.properties["engine"].enum_items}
        engine = "BLENDER_EEVEE_NEXT" if "BLENDER_EEVEE_NEXT" in items else "BLENDER_EEVEE"
    r.engine = engine
    r.image_settings.file_format = "PNG"
    scene.cycles.device, scene.cycles.samples, scene.cycles.use_denoising = "CPU", samples, False
    scene.eevee.taa_render_samples = 1
    scene.eevee.shadow_resolution_scale = 0.25
    scene.nubis.sky_environment_width = 64
    scene.nubis.sky_shadow_resolution = 64
    return scene


def scene_with_a_wall():
    scene = small_cloudscape(ENGINE)
    bpy.ops.mesh.primitive_cube_add(size=1.0, location=(0.0, 3000.0, 2000.0), scale=(6000.0, 60.0, 400.0))
    return scene, bpy.context.object


def add_vdb_cloud(scene) -> None:
    """A small cumulus in a marked Volume (its visibility once changed every frame: a crash at frame 2)."""
    sys.path.insert(0, os.path.join(ROOT, "tests"))
    from vdb_helpers import write_cumulus

    path = write_cumulus(Path(OUT) / "cloud.vdb", base=(-1500.0, 2000.0, 1500.0), n_xy=16, n_z=12)
    volume = bpy.data.volumes.new("Cloud")
    volume.filepath = str(path)
    obj = bpy.data.objects.new("Cloud", volume)
    scene.collection.objects.link(obj)
    volume.nubis_cloud.enabled = True


def on_pre(scene, *_args) -> None:
    """What each frame of the scene's own renders composed, read after Nubis's own render_pre handler
    prepared it (the World capture's renders are left out). A frame that fails to be written gets no
    render_post, so it is read here."""
    if scene.name == bpy.context.scene.name and composition.last_frame:
        veil = bpy.data.objects.get(composition.VEIL_NAME)
        FRAMES.append(
            {
                "frame": scene.frame_current,
                "veil": composition.last_frame.get("veil"),
                "veil_shown": not composition.stowed(veil),
                "casters": len(shadows.in_use(scene)),
            }
        )


def after(scene, world: str) -> dict:
    """What a render must leave as it found it."""
    veil = bpy.data.objects.get(composition.VEIL_NAME)
    casters = [o for o in bpy.data.objects if o.name.startswith(shadows.CASTER_NAME)]
    volumes = [o for o in scene.objects if o.type == "VOLUME"]
    return {
        "volumes_back": all(not o.hide_render for o in volumes),
        "world_back": scene.world is not None and scene.world.name == world,
        "veil_out": veil is None or veil.hide_render,
        "casters_out": all(o.hide_render for o in casters),
        "swapped": sorted(scene_render._swapped),
    }


def main() -> None:
    global ENGINE, OUT, RENDERS
    ENGINE, OUT, RENDERS = sys.argv[-3], sys.argv[-2], sys.argv[-1].split(",")
    scene, wall = scene_with_a_wall()
    if "vdb" in RENDERS:  # a marked VDB cloud beside the wall: stepped aside for the whole render, and back
        add_vdb_cloud(scene)
    world = scene.world.name
    bpy.app.handlers.render_pre.append(on_pre)  # after the extension's, registered with it
    r = scene.render

    if "still" in RENDERS:
        r.resolution_x, r.resolution_y, r.resolution_percentage = 101, 57, 33
        r.filepath = os.path.join(OUT, "still.png")
        bpy.ops.render.render(write_still=True)
        size = list(imageio.read_image(r.filepath).shape[:2])
        report("still", image=size, clouds=list(bpy.data.images[scene_render.CAMERA_IMAGE].size), **after(scene, world))

    r.resolution_x, r.resolution_y, r.resolution_percentage = 64, 36, 100
    wall.location.z = -5000.0
    wall.keyframe_insert("location", index=2, frame=1)
    wall.location.z = 2000.0
    wall.keyframe_insert("location", index=2, frame=2)
    scene.frame_set(1)  # as the interface evaluates a keyed object: under the ground at frame 1
    scene.frame_start, scene.frame_end = 1, 3
    r.filepath = os.path.join(OUT, "anim", "f_####")
    FRAMES.clear()
    bpy.ops.render.render(animation=True)
    files = sorted(os.listdir(os.path.join(OUT, "anim")))
    report("anim", files=files, frames=list(FRAMES), **after(scene, world))

    if "failing" not in RENDERS:
        return
    r.filepath = os.path.join(OUT, "failing", "f_####")
    os.makedirs(os.path.join(OUT, "failing", "f_0002.png"))
    FRAMES.clear()
    try:
        bpy.ops.render.render(animation=True)
        refused = ""
    except RuntimeError as err:
        refused = str(err)
    report("failing", refused=refused, frames=list(FRAMES), **after(scene, world))


if __name__ == "__main__":
    main()
    if bpy.app.version < (5, 0, 0):
        # Blender 4.5 as a module ends a script that registered the extension in a crash or a hang of its
        # own teardown (its draw handlers' arguments freed after Python, its GPU worker waited on):
        # docs/limits.md. Such scripts end with os._exit there, as the command line does everywhere.
        sys.stdout.flush()
        os._exit(0)
