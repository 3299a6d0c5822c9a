"""The scene as the renderer sees it: its settings, field, storms, sky and cameras as one CloudState
(state_from_scene) for core/ and render/."""

from __future__ import annotations

import bpy
import numpy as np
from mathutils import Matrix, Vector

from ...core import camera
from ...core import sky as skymath
from ...core.errors import NubisError
from ...core.state import CloudState
from . import datafield, sceneparams, sky, skycapture, skyground, superstorms, vdbclouds


def world_ambient(scene) -> tuple[float, float, float]:
    world = scene.world
    if world is None:
        return (0.0, 0.0, 0.0)
    if world.node_tree is not None:
        bg = next((n for n in world.node_tree.nodes if n.type == "BACKGROUND"), None)
        if bg is not None:
            c = bg.inputs["Color"].default_value
            s = bg.inputs["Strength"].default_value
            return (c[0] * s, c[1] * s, c[2] * s)
    return tuple(world.color)


def state_from_scene(scene, camera_location=None, fields: tuple | None = None, wait: bool = True) -> CloudState:
    """The frame's CloudState; `fields` passes already-read (field_a, field_b) arrays to skip reading pixels.
    The sky light comes from the World's radiance (blender/scene/sky.py); `wait` False (the viewport's draw)
    takes the last capture of the World rather than rendering a new one there and then."""
    settings = scene.nubis
    if fields is None:
        fields = datafield.read_fields(settings)  # first: a composite owed also sets the coverage multiplier
    params = sceneparams.params_from_scene(settings)
    params["density_coverage"] = datafield.coverage_multiplier(scene)
    further, first_drawn = datafield.drawn_cloud_layers(scene)
    sun = skyground.find_sun(scene)
    if sun is not None:
        direction = tuple(sceneparams.evaluated_matrix(sun).to_3x3() @ Vector((0.0, 0.0, 1.0)))
        radiance = tuple(c * sun.data.energy for c in sun.data.color)
    else:
        direction, radiance = (0.0, 0.0, 1.0), (0.0, 0.0, 0.0)
    air = sky.sun_air(scene)
    if air is not None and sun is not None:  # the sun above the atmosphere; each sample takes its own air
        radiance = (sun.data.energy,) * 3
    if camera_location is None:
        camera_location = sceneparams.evaluated_matrix(scene.camera).translation if scene.camera else (0.0, 0.0, 0.0)
    fps = sceneparams.scene_fps(scene)
    time = (scene.frame_current + scene.frame_subframe) / fps * params["wind_time_scale"] + params["wind_time_offset"]
    env = skycapture.environment(scene, wait)
    above, below, flank = skymath.hemisphere_radiance_cached(env)
    return CloudState(
        params=params,
        field_a=fields[0],
        field_b=fields[1],
        field_c=fields[2],
        sun_direction=direction,
        sun_radiance=radiance,
        sun_air=air,
        ambient=above,
        ambient_below=below,
        ambient_flank=sky.flank_light(scene, above, flank),
        sky_env=env,
        draw_center=(float(camera_location[0]), float(camera_location[1])),
        time=time,
        storms=superstorms.storm_lights(settings, scene, time),
        vdb_clouds=vdbclouds.placements(scene, strict=wait),
        vdb_gpu_budget=vdbclouds.gpu_budget(),
        cloud_layers=further,
        first_layer_drawn=first_drawn,
    )


def camera_matrices(scene, width: int, height: int) -> tuple[np.ndarray, np.ndarray]:
    """The scene camera's projection (its clipping planes included) at this resolution and its view matrix,
    float64."""
    cam = scene.camera
    if cam is None:
        raise NubisError("the scene has no camera: add one or use New Cloudscape")
    depsgraph = bpy.context.evaluated_depsgraph_get()
    proj = cam.evaluated_get(depsgraph).calc_matrix_camera(depsgraph, x=width, y=height, scale_x=1.0, scale_y=1.0)
    view = np.linalg.inv(np.array(sceneparams.evaluated_matrix(cam).normalized(), dtype=np.float64))
    return np.array(proj, dtype=np.float64), view


def camera_inv_view_proj(scene, width: int, height: int):
    """Inverse view-projection of the scene camera at this resolution, as a mathutils Matrix."""
    proj, view = camera_matrices(scene, width, height)
    return Matrix(camera.ray_inverse_view_projection(proj, view).tolist())


def camera_eye(scene) -> tuple[float, float, float, float]:
    """The scene camera's position (w = 1), or w = 0 for an orthographic camera (rays start on the
    near plane then)."""
    cam = scene.camera
    if cam is None or getattr(cam.data, "type", "PERSP") == "ORTHO":
        return (0.0, 0.0, 0.0, 0.0)
    t = sceneparams.evaluated_matrix(cam).translation
    return (float(t.x), float(t.y), float(t.z), 1.0)
