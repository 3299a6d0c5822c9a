"""The scene's own surfaces as the clouds' renders see them: the solid objects camera rays meet (what F12's
and preview's depth pre-pass draws), and the mark on the objects Nubis adds for a render, which no pass
draws."""

from __future__ import annotations

import bpy
import numpy as np

# Objects the depth pre-pass draws (as meshes); hair curves and point clouds are left out (docs/limits.md).
SOLID_TYPES = {"MESH", "CURVE", "SURFACE", "META", "FONT"}
OWN_KEY = "nubis_own"  # an ID property on the objects Nubis adds for a render (the veil, the shadow casters)


def camera_meshes(scene):
    """The evaluated scene's solid surfaces that camera rays see, one mesh at a time: world-space
    vertices (N, 3) and triangles (M, 3). Instances (particles, geometry nodes, collections) included."""
    depsgraph = bpy.context.evaluated_depsgraph_get()
    shared: dict[str, tuple[np.ndarray, np.ndarray] | None] = {}  # an instanced object's mesh, read once
    for inst in depsgraph.object_instances:
        obj = inst.object
        if obj.type not in SOLID_TYPES or obj.original.get(OWN_KEY) or not obj.visible_camera:
            continue
        if obj.original.hide_render:
            continue
        if inst.is_instance:
            if obj.name not in shared:
                shared[obj.name] = _triangles(obj)
            found = shared[obj.name]
        else:
            found = _triangles(obj)
        if found is None:
            continue
        co, tris = found
        m = np.array(inst.matrix_world, np.float64)
        yield co @ m[:3, :3].T + m[:3, 3], tris


def _triangles(obj) -> tuple[np.ndarray, np.ndarray] | None:
    """An evaluated object's surface as vertices (object space, float64) and triangles, or None."""
    try:
        mesh = obj.to_mesh()
    except RuntimeError:  # an object with no surface to give
        return None
    try:
        if mesh is None or not mesh.polygons:
            return None
        mesh.calc_loop_triangles()
        co = np.empty(len(mesh.vertices) * 3, np.float32)
        mesh.vertices.foreach_get("co", co)
        tris = np.empty(len(mesh.loop_triangles) * 3, np.int32)
        mesh.loop_triangles.foreach_get("vertices", tris)
    finally:
        obj.to_mesh_clear()
    return co.reshape(-1, 3).astype(np.float64), tris.reshape(-1, 3)
