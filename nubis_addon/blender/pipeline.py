"""The headless pipeline shared by the operators and the command line: render, bake, Cycles, compare."""

from __future__ import annotations

import json
import os
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import bpy
import numpy as np

from ..core import imageio, metrics, vdbio
from ..core.bakeplan import BakePlan, plan_bake
from ..core.errors import NubisError
from ..core.fsutil import atomic_path, check_output_dir, check_output_path
from ..render import bake as gpu_bake
from ..render import engine
from . import cycles_setup, runtime, scene_io

Progress = Callable[[float], None]


def ocio_config() -> str:
    return os.path.join(bpy.utils.resource_path("LOCAL"), "datafiles", "colormanagement", "config.ocio")


def display_image(scene, rgba: np.ndarray) -> np.ndarray:
    """What the artist sees: the clouds over the world's sky colour, through the scene's view transform."""
    sky = scene_io.world_ambient(scene)
    return imageio.to_display(imageio.composite_over(rgba, sky), scene.view_settings.view_transform, ocio_config())


def save_render(scene, path: str | os.PathLike, rgba: np.ndarray) -> Path:
    """EXR keeps scene-linear premultiplied RGBA; PNG is display-referred over the sky."""
    path = Path(path)
    if path.suffix.lower() == ".exr":
        return imageio.write_image(path, rgba)
    return imageio.write_image(path, display_image(scene, rgba))


def resolution(scene, width: int | None, height: int | None) -> tuple[int, int]:
    w = width or scene.render.resolution_x * scene.render.resolution_percentage // 100
    h = height or scene.render.resolution_y * scene.render.resolution_percentage // 100
    if not (4 <= w <= 16384 and 4 <= h <= 16384):
        raise NubisError(f"a {w}x{h} image is out of range: use a width and height between 4 and 16384")
    return w, h


def render_viewport(scene, width: int, height: int, light_mode: int = 0) -> np.ndarray:
    """The viewport's clouds from the scene camera: premultiplied scene-linear RGBA, top row first."""
    state = scene_io.state_from_scene(scene)
    state.light_mode = light_mode
    clouds = runtime.cloud_gpu(scene.nubis.noise_seed)
    clouds.update(state)
    return engine.render_offscreen(clouds, scene_io.camera_inv_view_proj(scene, width, height), width, height)


@dataclass
class BakeResult:
    path: Path
    plan: BakePlan
    active_voxels: int
    seconds: float


def bake(scene, path: str | os.PathLike, voxel_size: float | None = None, progress: Progress | None = None):
    """Bake the viewport's density to an OpenVDB `density` grid in world space (atomic write)."""
    path = check_output_path(path, (".vdb",))
    start = time.perf_counter()
    state = scene_io.state_from_scene(scene)
    plan = plan_bake(state, voxel_size or scene.nubis.bake_voxel_size)
    clouds = runtime.cloud_gpu(scene.nubis.noise_seed)
    clouds.update(state)
    density = gpu_bake.bake_density(clouds, plan, progress)
    active = int(np.count_nonzero(density > vdbio.DEFAULT_TOLERANCE))
    meta = {
        "nubis_sigma": float(scene.nubis.density_sigma),
        "nubis_voxel_size": float(plan.voxel_size),
        "nubis_time": float(state.time),
        "nubis_preset": scene.nubis.preset,
    }
    vdbio.write_vdb(path, {"density": density}, plan.voxel_size, plan.origin, meta)
    return BakeResult(path, plan, active, time.perf_counter() - start)


def render_cycles(
    scene,
    width: int,
    height: int,
    samples: int | None = None,
    vdb_path: str | None = None,
    voxel_size: float | None = None,
    bounces: int | None = None,
) -> np.ndarray:
    """Bake (unless given a VDB), import it with the matched material, render with Cycles; premultiplied RGBA."""
    with tempfile.TemporaryDirectory(prefix="nubis-cycles-") as tmp:
        if vdb_path is None:
            vdb_path = str(Path(tmp) / "clouds.vdb")
            bake(scene, vdb_path, voxel_size)
        cycles_setup.import_volume(scene, vdb_path)
        exr = Path(tmp) / "cycles.exr"
        cycles_setup.configure_render(scene, width, height, samples, bounces)
        scene.render.filepath = str(exr)
        bpy.ops.render.render(write_still=True, scene=scene.name)
        if not exr.is_file():
            raise NubisError("Cycles wrote no image: check the console for Cycles errors")
        rgba = imageio.read_image(exr)
        cycles_setup.remove_volume(scene)
    return rgba


def compare(
    scene,
    out_dir: str | os.PathLike,
    width: int,
    height: int,
    samples: int | None = None,
    light_mode: int = 0,
    bounces: int | None = None,
    voxel_size: float | None = None,
) -> dict:
    """Viewport and Cycles renders of the same shot, their side-by-side, and metrics.json; the bake the
    Cycles render used is kept as clouds.vdb."""
    out = check_output_dir(out_dir)
    viewport = render_viewport(scene, width, height, light_mode)
    baked = bake(scene, out / "clouds.vdb", voxel_size)
    cycles = render_cycles(scene, width, height, samples, vdb_path=str(baked.path), bounces=bounces)
    result = metrics.compare(viewport, cycles)
    result.update(
        width=width,
        height=height,
        samples=samples or scene.cycles.samples,
        preset=scene.nubis.preset,
        voxel_size=baked.plan.voxel_size,
        volume_bounces=scene.cycles.volume_bounces,
    )
    save_render(scene, out / "viewport.exr", viewport)
    save_render(scene, out / "cycles.exr", cycles)
    view_png, cyc_png = display_image(scene, viewport), display_image(scene, cycles)
    imageio.write_image(out / "viewport.png", view_png)
    imageio.write_image(out / "cycles.png", cyc_png)
    diff = metrics.difference_image(viewport, cycles)
    imageio.write_image(out / "difference.png", diff)
    imageio.write_image(out / "side_by_side.png", metrics.side_by_side(view_png, cyc_png, diff))
    with atomic_path(out / "metrics.json") as tmp:
        tmp.write_text(json.dumps(result, indent=2) + "\n", encoding="utf-8")
    return result
