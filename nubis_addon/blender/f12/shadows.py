"""The clouds' shadows in final renders: horizontal squares that only shadow rays see, each carrying a map
of the clouds' transmittance towards the sun as its transparency, so the Sun lamp's shadows in EEVEE and
Cycles hold the clouds' shadows and move with the wind.

Where no object reaches the clouds' floor, one caster just above the objects (or just under the floor)
carries the transmittance through the whole layer. Where objects rise into the layer, a stack of casters
climbs through it, each carrying the layer between its altitude and the next one's, so a point's shadow
rays gather the clouds above that point and not the ones below it (docs/sky.md#objects-in-the-clouds)."""

from __future__ import annotations

import bpy
import numpy as np
from mathutils import Matrix, Vector

from ...core import composition as plan
from ...render import engine
from ..scene import sceneparams
from ..scene.surfaces import OWN_KEY, SOLID_TYPES
from .composition import (
    RECIPE_KEY,
    UNIT_SQUARE,
    built,
    collapsed,
    finished,
    image_material,
    put_away,
    render_quad,
    set_corners,
    show,
    stow,
    stowed,
    write_image,
)

SHADOW_IMAGE = "Nubis Cloud Shadow"
CASTER_NAME = "Nubis Cloud Shadow"
CASTER_MATERIAL = "Nubis Cloud Shadow"
MAX_SHADOW_SIZE = 20000.0  # metres of ground the shadow map covers at most
MIN_SHADOW_SIZE = 50.0
# The caster's distance below the clouds' floor when the objects' top would put it higher.
CASTER_BELOW_CLOUDS = 10.0
# Objects whose extent the shadow casters cover: the depth pre-pass's, and those it cannot draw as meshes.
_SOLID_TYPES = SOLID_TYPES | {"CURVES", "POINTCLOUD", "GREASEPENCIL"}


def caster_name(index: int) -> str:
    """The caster (and its map and material) at this place in the stack, the lowest first."""
    return CASTER_NAME if index == 0 else f"{CASTER_NAME} {index}"


def objects_box(scene) -> tuple[Vector, Vector]:
    """The world box of the scene's solid objects (Nubis's own left out); a 1 km square at the ground
    when there are none."""
    corners = []
    for obj in scene.objects:
        if obj.type not in _SOLID_TYPES or obj.hide_render or obj.get(OWN_KEY):
            continue
        m = sceneparams.evaluated_matrix(obj)
        corners.extend(m @ Vector(c) for c in obj.bound_box)
    if not corners:
        corners = [Vector((x, y, 0.0)) for x in (-500.0, 500.0) for y in (-500.0, 500.0)]
    lo = Vector([min(c[i] for c in corners) for i in range(3)])
    hi = Vector([max(c[i] for c in corners) for i in range(3)])
    return lo, hi


def shadow_frame(scene, sun_dir, cloud_floor: float | None = None) -> tuple[Vector, Vector, Vector, float]:
    """Where the single shadow caster goes: a horizontal square above the scene's tallest object and below
    the clouds' floor (`cloud_floor`, the lowest altitude a cloud reaches), wide enough that the sunlight
    reaching every object crosses it. Returns its centre, its two unit edge directions and its width
    (metres). The shadow map marches from the caster through the whole layer towards the sun, so a
    caster above the floor would miss the clouds beneath it: a 200 km ground plane had put it 4.4 km
    up, above the cumulus, and the renders showed no cloud shadow at all."""
    lo, hi = objects_box(scene)
    height = hi.z + max(0.02 * max(hi.x - lo.x, hi.y - lo.y), 5.0)
    if cloud_floor is not None:
        # Just under the floor, but never below the objects' top (stack_frames serves objects in the layer).
        height = max(min(height, cloud_floor - CASTER_BELOW_CLOUDS), hi.z + 1.0)
    centres, u, v, size = stack_frames(scene, sun_dir, [height], (lo, hi))
    return centres[0], u, v, size


def stack_frames(scene, sun_dir, altitudes: list[float], box=None) -> tuple[list[Vector], Vector, Vector, float]:
    """The casters' squares at these altitudes: each the lowest moved along the sun, so texel (i, j) of every
    map lies on one sun ray; wide enough that the sunlight reaching every point of every object crosses each.
    Returns their centres, the edge directions and the width (metres)."""
    sun = Vector(sun_dir).normalized()
    lo, hi = box or objects_box(scene)
    slope = Vector((sun.x, sun.y, 0.0)) / max(sun.z, 0.05)
    base = altitudes[0]
    # Where the sun rays through the objects' lowest and highest points cross the lowest square.
    # (A caster above the objects keeps the span from their own footprint, as one caster always had.)
    rise_lo, rise_hi = slope * (base - lo.z), slope * min(base - hi.z, 0.0)
    centre = (lo + hi) / 2 + (rise_lo + rise_hi) / 2
    spread = rise_lo - rise_hi
    extent = max(hi.x - lo.x + abs(spread.x), hi.y - lo.y + abs(spread.y))
    size = scene.nubis.sky_shadow_size or min(max(1.05 * extent, MIN_SHADOW_SIZE), MAX_SHADOW_SIZE)
    centres = []
    for h in altitudes:
        c = centre + slope * (h - base)
        c.z = h
        centres.append(c)
    return centres, Vector((1.0, 0.0, 0.0)), Vector((0.0, 1.0, 0.0)), size


def update_shadow(scene, state, clouds) -> bpy.types.Object:
    """This frame's shadow maps and the casters that carry them; returns the lowest caster."""
    floor, top = state.shell()
    lo, hi = objects_box(scene)
    res = scene.nubis.sky_shadow_resolution
    clouds.update(state)
    if hi.z <= floor:
        altitudes = [shadow_frame(scene, state.sun_direction, floor)[0].z]
    else:
        altitudes = plan.caster_altitudes(floor, top, hi.z, plan.MIN_CASTER_SPACING)
    centres, u, v, size = stack_frames(scene, state.sun_direction, altitudes, (lo, hi))
    maps = [engine.render_shadow(clouds, tuple(c), tuple(u * size), tuple(v * size), res)[..., 0] for c in centres]
    for index, (centre, slab) in enumerate(zip(centres, plan.slab_transmittances(maps), strict=True)):
        rgba = np.ones(slab.shape + (4,), np.float32)
        rgba[..., :3] = slab[..., None]
        image = write_image(caster_name(index), rgba)
        caster = ensure_caster(scene, image, index)
        n = u.cross(v)
        caster.matrix_world = Matrix(
            (
                (u.x * size, v.x * size, n.x, centre.x),
                (u.y * size, v.y * size, n.y, centre.y),
                (u.z * size, v.z * size, n.z, centre.z),
                (0.0, 0.0, 0.0, 1.0),
            )
        )
        if stowed(caster):
            set_corners(caster, UNIT_SQUARE)
        show(caster)
    stow_casters(scene, first=len(centres))
    return scene.objects[CASTER_NAME]


def _casters(scene, first: int = 0):
    index = first
    while (obj := bpy.data.objects.get(caster_name(index))) is not None:
        yield obj
        index += 1


def in_use(scene) -> list:
    """The casters the last frame's shadows used (the lowest first), during the render or after it."""
    return [obj for obj in _casters(scene) if not collapsed(obj)]


def stacked(scene) -> int:
    """How many casters of a stack this frame uses beyond the lowest (0 for one caster or none)."""
    return max(len([o for o in _casters(scene) if not stowed(o)]) - 1, 0)


def ready_casters(scene) -> None:
    """When a render with the clouds starts: the casters there are shown and stowed (the frames place
    those they use; docs/sky.md#render-animation)."""
    for obj in _casters(scene):
        stow(obj)
        show(obj)


def stow_casters(scene, first: int = 0) -> None:
    """The casters from `first` up out of this frame (all of them by default)."""
    for obj in _casters(scene, first):
        stow(obj)


def put_away_casters(scene) -> None:
    """Every caster out of renders, once the render has ended."""
    for obj in _casters(scene):
        put_away(obj)


def ensure_caster(scene, image, index: int = 0) -> bpy.types.Object:
    """A unit square that only shadow rays see, with the shadow map as its transparency."""
    name = caster_name(index)
    obj = render_quad(scene, name, _caster_material(name, image))
    for ray in ("camera", "diffuse", "glossy", "transmission", "volume_scatter"):
        setattr(obj, f"visible_{ray}", False)
    obj.visible_shadow = True
    return obj


def _caster_material(name: str, image) -> bpy.types.Material:
    """Opaque where the clouds block the sun, transparent where they let it through (a mix by the
    transmittance), so Cycles' and EEVEE's shadow rays carry the clouds' shadow."""
    if (kept := built(name, "caster", image)) is not None:
        return kept
    mat, nt, tex = image_material(name, image, "Linear")
    mat[RECIPE_KEY] = "caster"
    opaque = nt.nodes.new("ShaderNodeEmission")
    opaque.inputs["Strength"].default_value = 0.0
    clear = nt.nodes.new("ShaderNodeBsdfTransparent")
    mix = nt.nodes.new("ShaderNodeMixShader")
    out = nt.nodes.new("ShaderNodeOutputMaterial")
    nt.links.new(tex.outputs["Color"], mix.inputs["Fac"])
    nt.links.new(opaque.outputs[0], mix.inputs[1])
    nt.links.new(clear.outputs[0], mix.inputs[2])
    nt.links.new(mix.outputs[0], out.inputs["Surface"])
    # EEVEE: a dithered surface whose shadows follow its transparency.
    mat.use_transparent_shadow = True
    return finished(mat, "DITHERED")
