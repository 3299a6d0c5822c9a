"""Any Volume object as a Nubis cloud: File > Import > OpenVDB (or a VDB sequence, the extension's own
bake, a Mesh to Volume result), then Nubis Cloud on in the Volume's properties or the sidebar.

A marked Volume is drawn by the real-time renderer with the procedural clouds (core/vdbread.py,
render/vdbatlas.py): the same light model, its object's transform live, its frame's file for a
sequence. Its values are extinction as Blender's Principled Volume reads them at Density 1, per unit of
its Render > Space (as Cycles reads them), times the Density here; a file too large for the GPU budget
(a preference) is drawn from a coarser level of it, and the sidebar says so. Blender's own drawing of it
steps aside: the viewport shows its bounds only, and final renders draw it through the extension's path
(blender/f12/scene_render.py), never both at once.
"""

from __future__ import annotations

import contextlib
import os
import re
from collections import OrderedDict

import bpy
from bpy.props import BoolProperty, FloatProperty, StringProperty

from ...core import console, vdbcheck, vdbplacement, vdbread
from ...core.errors import NubisError
from ...core.sequence import human_bytes
from ...render import vdbatlas as gpu_side
from ..host import runtime, status
from ..host.ui import SidebarPanel, property_group_registration, redraw_views
from . import cycles_setup

# Clouds read from disk, by (path, modification time, size, grid): a few, as Blender's own volume cache.
_CACHE_ENTRIES = 8
_cache: OrderedDict = OrderedDict()
_problems: dict[str, str] = {}  # object name -> why it is not drawn (the sidebar shows it)
_levels: dict[str, int] = {}  # object name -> the level it is drawn at, when coarser than its file
_level_noted: set[tuple[str, int]] = set()  # (cloud, level) the console has been told of
_noted: set[str] = set()  # the clouds left out that the console has been told of


def _redraw(_self=None, _context=None) -> None:
    redraw_views(("VIEW_3D", "PROPERTIES"))


def _on_toggle(self, context) -> None:
    """Marked: Blender's grey volume preview gives way to the bounds; unmarked: back to the preview."""
    volume = self.id_data
    for obj in bpy.data.objects:
        if obj.data == volume:
            obj.display_type = "BOUNDS" if self.enabled else "TEXTURED"
    _redraw()


class NubisVolumeCloud(bpy.types.PropertyGroup):
    enabled: BoolProperty(
        name="Nubis Cloud",
        description="Draw this volume with the Nubis clouds: the same light, in the viewport and in final renders",
        default=False,
        update=_on_toggle,
    )
    grid: StringProperty(
        name="Grid",
        description="The float grid to draw (empty: 'density', or the file's only float grid)",
        default="",
        update=_redraw,
    )
    density: FloatProperty(
        name="Density",
        description="Multiplier on the grid's values, read as extinction per metre (Principled Volume's Density)",
        default=1.0,
        min=0.0,
        soft_max=10.0,
        update=_redraw,
    )


def all_marked(scene) -> list:
    """The scene's Volume objects marked as Nubis clouds and shown in renders, in a stable order (by name)."""
    return [
        obj
        for obj in sorted(scene.objects, key=lambda o: o.name)
        if obj.type == "VOLUME" and obj.data.nubis_cloud.enabled and (not obj.hide_render or obj.name in _stepped_aside)
    ]


def marked(scene) -> list:
    """The marked Volumes that are drawn: the first vdbplacement.MAX_CLOUDS by name (left_out() says the rest)."""
    return all_marked(scene)[: vdbplacement.MAX_CLOUDS]


def left_out(scene) -> list:
    return all_marked(scene)[vdbplacement.MAX_CLOUDS :]


def left_out_sentence(obj) -> str:
    return (
        f"the Nubis cloud '{obj.name}' is left out: at most {vdbplacement.MAX_CLOUDS} VDB clouds are drawn at once "
        "(the first by name); unmark one, or join clouds into one file"
    )


# ---- final renders: one path for each cloud ------------------------------------------------------------

_stepped_aside: set[str] = set()  # marked Volumes hidden from a final render while the extension draws them


def step_aside(scene) -> None:
    """Before a final render that draws the clouds through the extension's path (blender/f12/scene_render.py):
    the marked Volumes are hidden from Blender's own volume render for the frame, so each cloud is
    rendered once. A cloud left out (beyond the four drawn) is hidden too, as in the viewport, where it shows
    its bounds only."""
    for obj in all_marked(scene):
        if not obj.hide_render:
            obj.hide_render = True
            _stepped_aside.add(obj.name)


def step_back(scene) -> None:
    """After the frame: the Volumes render as the artist left them."""
    for name in list(_stepped_aside):
        obj = scene.objects.get(name) or bpy.data.objects.get(name)
        if obj is not None:
            obj.hide_render = False
        _stepped_aside.discard(name)


@contextlib.contextmanager
def native(scene):
    """Around a Cycles render of the comparison: the marked Volumes render natively, each with the clouds'
    material reading its grid times its Density (blender/scene/cycles_setup.py), so Cycles sees the same file
    with the same material as the viewport; their own materials are put back after."""
    kept, hidden = [], []
    try:
        for obj in left_out(scene):  # not drawn by the real-time renderer: not rendered by Cycles either
            obj.hide_render = True
            hidden.append(obj)
        for obj in marked(scene):
            settings = obj.data.nubis_cloud
            path = volume_file(obj, scene.frame_current)
            if path is None:
                continue
            cloud = read(path, settings.grid.strip())
            mat = cycles_setup.build_material(
                scene.nubis,
                grid=cloud.grid,
                scale=float(settings.density) * cloud.value_scale,
                name=f"Nubis VDB Cloud {obj.data.name}",
            )
            kept.append((obj.data, list(obj.data.materials)))
            obj.data.materials.clear()
            obj.data.materials.append(mat)
        yield
    finally:
        for obj in hidden:
            obj.hide_render = False
        for volume, materials in kept:
            volume.materials.clear()
            for m in materials:
                volume.materials.append(m)


def volume_file(obj, frame: int | None = None) -> str | None:
    """The file the Volume reads at `frame` (the scene's current one by default): for a sequence, its frame's
    file by Blender's own rule (start, offset, duration and mode), or None where a clipped sequence has
    none. Computed here rather than read from the evaluated Volume, which the viewport's draw must not ask
    for."""
    volume = obj.data
    path = bpy.path.abspath(volume.filepath, library=volume.library)
    if not volume.is_sequence:
        return path
    if frame is None:
        frame = bpy.context.scene.frame_current
    n = sequence_frame(frame, volume.frame_start, volume.frame_duration, volume.frame_offset, volume.sequence_mode)
    if n is None:
        return None
    head, name = os.path.split(path)
    runs = list(re.finditer(r"\d+", name))
    if not runs:
        return path
    run = runs[-1]
    return os.path.join(head, f"{name[: run.start()]}{n:0{len(run.group())}d}{name[run.end() :]}")


def sequence_frame(frame: int, start: int, duration: int, offset: int, mode: str) -> int | None:
    """Blender's Volume sequence: the file number shown at scene frame `frame`, None outside a clipped one."""
    n = frame - start + 1
    duration = max(duration, 1)
    if mode == "CLIP":
        if n < 1 or n > duration:
            return None
    elif mode == "EXTEND":
        n = min(max(n, 1), duration)
    elif mode == "REPEAT":
        n = (n - 1) % duration + 1
    else:  # PING_PONG
        period = max(2 * (duration - 1), 1)
        k = (n - 1) % period
        n = (k if k < duration else period - k) + 1
    return n + offset


def gpu_budget() -> int:
    """Bytes the VDB clouds may take on the GPU together (Preferences > VDB Cloud GPU Budget)."""
    return runtime.vdb_gpu_budget()


def read(path: str, grid: str, budget: int | None = None) -> vdbread.VdbCloud:
    """The packed cloud of a file, read once per change of the file on disk or of the GPU budget (the
    preference's by default): the finest level of it that fits the budget (core/vdbread.py)."""
    vdbcheck.check(path)  # missing, a folder, damaged: one sentence before OpenVDB opens it
    st = os.stat(path)
    budget = gpu_budget() if budget is None else budget
    key = (path, st.st_mtime_ns, st.st_size, grid, budget)
    if key in _cache:
        _cache.move_to_end(key)
        return _cache[key]
    cloud = vdbread.read_cloud(path, grid, budget)
    _cache[key] = cloud
    while len(_cache) > _CACHE_ENTRIES:
        _cache.popitem(last=False)
    return cloud


def forget_notes() -> None:
    """A new command says its notes again (clouds left out, coarser levels): they are said once per command,
    not once per Blender session, so a second command in the same session, or another file's cloud of
    the same name, is told as the first was."""
    _noted.clear()
    _level_noted.clear()


def placements(scene, strict: bool = True) -> tuple:
    """Where the marked clouds stand now. `strict` (renders, bakes) raises the first cloud's problem; the
    viewport's draw leaves the cloud out and shows why in the sidebar."""
    out = []
    _problems.clear()
    _levels.clear()
    budget = gpu_budget()  # one reading of the preference for every cloud of this call
    left = left_out(scene)
    for obj in left:
        _problems[obj.name] = left_out_sentence(obj)
        if not strict:
            status.set_error(left_out_sentence(obj))
        elif obj.name not in _noted:  # once, though a command reads the clouds more than once
            console.current().line(f"nubis: note: {left_out_sentence(obj)}")
    if strict:
        _noted.clear()
        _noted.update(o.name for o in left)
    for obj in marked(scene):
        settings = obj.data.nubis_cloud
        path = volume_file(obj, scene.frame_current)
        if path is None:
            continue  # a clipped sequence before its first frame or after its last
        try:
            cloud = read(path, settings.grid.strip(), budget)
            matrix = [list(r) for r in obj.matrix_world]
            placed = vdbplacement.Placement(cloud, matrix, float(settings.density), obj.data.render.space)
            placed.check(obj.name)
            crowded = vdbplacement.why_not_together([*out, placed], budget)
            if crowded:
                raise NubisError(f"it is left out: {crowded}; unmark a cloud or use coarser ones")
        except NubisError as err:
            if strict:
                raise NubisError(f"the Nubis cloud '{obj.name}': {err}") from None
            _problems[obj.name] = str(err)
            status.set_error(f"the Nubis cloud '{obj.name}' is not drawn: {err}")
            continue
        if cloud.level:
            _levels[obj.name] = cloud.level
            if strict and (obj.name, cloud.level) not in _level_noted:  # once, though a command reads it again
                console.current().line(f"nubis: note: the Nubis cloud '{obj.name}' is {cloud.level_note}")
                _level_noted.add((obj.name, cloud.level))
        out.append(placed)
    return tuple(out)


def level_note(obj) -> str:
    """The sidebar's short line for a cloud drawn coarser than its file ("" at its own voxels); the
    command line's note says it in full."""
    level = _levels.get(obj.name, 0)
    if not level:
        return ""
    return f"Level {level}: {2**level}x coarser, over the GPU budget (Preferences)"


def add_files(scene, paths) -> list:
    """The command line's --vdb: each file as a Volume object marked as a Nubis cloud, at the file's own
    transform."""
    objects = []
    for path in paths:
        path = os.path.abspath(os.path.expanduser(str(path)))
        vdbread.check_fits(path)
        name = os.path.splitext(os.path.basename(path))[0] or "VDB Cloud"
        volume = bpy.data.volumes.new(name)
        volume.filepath = path
        obj = bpy.data.objects.new(name, volume)
        scene.collection.objects.link(obj)
        volume.nubis_cloud.enabled = True
        objects.append(obj)
    return objects


def problem(obj) -> str:
    return _problems.get(obj.name, "")


def first_problem() -> str:
    """The sidebar's error line after a draw: the first VDB cloud left out and why ("" when none is)."""
    for name, why in _problems.items():
        return why if why.startswith("the Nubis cloud") else f"the Nubis cloud '{name}' is not drawn: {why}"
    return ""


def gpu_bytes(scene) -> int:
    """What the scene's VDB clouds take on the GPU (0 when one cannot be read: the sidebar says why)."""
    try:
        return gpu_side.gpu_bytes(placements(scene, strict=False))
    except NubisError:
        return 0


def draw_cloud_settings(layout, volume) -> None:
    settings = volume.nubis_cloud
    layout.use_property_split = True
    layout.prop(settings, "enabled")
    col = layout.column()
    col.active = settings.enabled
    col.prop_search(settings, "grid", volume, "grids", text="Grid")
    col.prop(settings, "density")


class NUBIS_PT_volume_cloud(bpy.types.Panel):
    """In the Volume's data properties: draw it as a Nubis cloud."""

    bl_space_type = "PROPERTIES"
    bl_region_type = "WINDOW"
    bl_context = "data"
    bl_label = "Nubis Cloud"

    @classmethod
    def poll(cls, context):
        return getattr(context, "volume", None) is not None

    def draw(self, context):
        draw_cloud_settings(self.layout, context.volume)
        obj = context.object
        if obj is not None and problem(obj):
            self.layout.label(text=problem(obj), icon="ERROR")
        elif obj is not None and level_note(obj):
            self.layout.label(text=level_note(obj), icon="INFO")


class NUBIS_PT_vdb_clouds(SidebarPanel, bpy.types.Panel):
    """The sidebar's list of the scene's VDB clouds, with the active Volume's settings."""

    bl_label = "VDB Clouds"
    bl_options = {"DEFAULT_CLOSED"}

    def draw(self, context):
        layout = self.layout
        obj = context.object
        if obj is not None and obj.type == "VOLUME":
            draw_cloud_settings(layout, obj.data)
        else:
            layout.label(text="Select a Volume (File > Import > OpenVDB)", icon="INFO")
        clouds = all_marked(context.scene)
        for cloud in clouds:
            row = layout.row()
            row.label(text=cloud.name, icon="ERROR" if problem(cloud) else "OUTLINER_OB_VOLUME")
            if problem(cloud):
                layout.label(text=problem(cloud))
            elif level_note(cloud):
                layout.label(text=level_note(cloud), icon="INFO")
        if clouds:
            layout.label(text=f"GPU memory: {human_bytes(gpu_bytes(context.scene))}")


_CLASSES = (NubisVolumeCloud, NUBIS_PT_volume_cloud, NUBIS_PT_vdb_clouds)


register, _unregister = property_group_registration(_CLASSES, bpy.types.Volume, "nubis_cloud", NubisVolumeCloud)


def unregister() -> None:
    _unregister()
    _cache.clear()
