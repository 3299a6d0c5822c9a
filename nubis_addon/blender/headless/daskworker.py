"""The worker side of a farm bake (blender/jobs/farm.py): the functions a Dask worker process runs. Each loads
the same scene as the submitting process (a preset by name or a saved .blend, the extension registered),
bakes a frame or some tiles with the same GPU code, and hands the bytes back: the submitting process
writes every file itself, atomically."""

from __future__ import annotations

import atexit
import shutil
import tempfile
from pathlib import Path

import bpy

from ...core import interrupt
from ...core.distributed import SceneSource
from ...core.errors import NubisError
from ...core.jobs import BakeOptions
from ...core.presets import load_preset
from ...render.gpu_context import ensure_gpu_context
from ..jobs import pipeline, snapshot
from ..registration import ensure_registered
from ..scene import scenepresets

_loaded: dict[str, object] = {}


def _worker_scene(source: SceneSource | dict, frame: int):
    """This worker's copy of the scene at `frame` (loaded once per process and source)."""
    if isinstance(source, dict):  # tasks carry plain data (core/distributed.py)
        source = SceneSource(**source)
    if "cleanup" not in _loaded:
        # A worker ends without Blender's teardown, which alone removes Blender's session folder.
        _loaded["cleanup"] = atexit.register(_remove_blender_tempdir)
    key = repr(source)
    if _loaded.get("key") != key:
        if source.blend:
            bpy.ops.wm.open_mainfile(filepath=source.blend, load_ui=False)
            ensure_registered()
        else:
            bpy.ops.wm.read_factory_settings(use_empty=True)
            ensure_registered()
            scenepresets.apply_preset(bpy.context.scene, load_preset(source.preset or "default"))
        ensure_gpu_context()
        _loaded["key"] = key
    scene = bpy.context.scene
    pipeline.check_scene(scene)
    scene.frame_set(frame)
    return scene


def _remove_blender_tempdir() -> None:
    tmp = interrupt.blender_tempdir()
    if tmp is not None:
        shutil.rmtree(tmp, ignore_errors=True)


def worker_bake_frame(source: SceneSource | dict, frame: int, options: BakeOptions | dict) -> dict:
    """One whole frame, baked on this worker: the file's bytes and its summary."""
    options = BakeOptions.of(options)
    scene = _worker_scene(source, frame)
    with tempfile.TemporaryDirectory(prefix="nubis-worker-") as tmp:
        r = pipeline.bake(scene, Path(tmp) / "frame.vdb", options)
        data = r.path.read_bytes()
    return {"data": data, "plan": r.plan, "active": r.active_voxels, "seconds": r.seconds, "grids": list(r.grids)}


def worker_bake_tiles(
    source: SceneSource | dict, frame: int, options: BakeOptions | dict, ids: list[int], dims
) -> bytes:
    """Some tiles of one frame, baked on this worker: a partial VDB (no metadata) of their voxels."""
    options = BakeOptions.of(options)
    scene = _worker_scene(source, frame)
    snap = snapshot.take(scene, options)
    plan = snap.plan
    if tuple(plan.dims) != tuple(dims):
        raise NubisError(f"this worker planned a {plan.dims} bake, not {tuple(dims)}: it reads a different scene")
    grids = pipeline.bake_grids(snap, [plan.tiles[n] for n in ids])
    with tempfile.TemporaryDirectory(prefix="nubis-worker-") as tmp:
        path = grids.write(Path(tmp) / "part.vdb", keep=())
        return path.read_bytes()
