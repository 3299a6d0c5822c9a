"""The real-time viewport headless: `preview` replays the 3D viewport's draw path from the scene camera,
`benchmark` measures it against the naive march and EEVEE (docs/viewport.md)."""

from __future__ import annotations

import contextlib
import json
import math
import statistics
import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path

import bpy
import gpu
import mathutils
import numpy as np

from ...core import camera, imageio, interrupt, limits, quality, sequence, staging
from ...core.bakeplan import comparison_voxel_size, view_footprint
from ...core.errors import NubisError
from ...core.fsutil import check_output_dir
from ...core.jobs import BakeOptions, BenchmarkOptions, PreviewOptions
from ...render import depthpass, engine, offscreens, temporal
from ...render.gpu_context import renderer_name
from ..host import runtime
from ..scene import cloudstate, cycles_setup, sceneparams, surfaces
from . import pipeline

Progress = Callable[[float], None]


def parse_frames(text: str | None, current: int) -> list[int]:
    """'A-B' or 'N' to the frames it names; None is the current frame."""
    if text is None:
        return [current]
    return sequence.parse_frames(text, limits.PREVIEW_FRAMES_MAX, "preview")


def apply_quality(scene, name: str | None) -> str:
    """Write a quality row into the scene's settings; returns the name in effect ('custom' if none fits)."""
    s = scene.nubis
    if name:
        with sceneparams.batch_edit():
            for key, value in quality.quality(name).settings.items():
                setattr(s, key, value)
            s.viewport_quality = name
        return name
    params = {k: getattr(s, k) for k in quality.ROW_KEYS.values()}
    for row in quality.qualities().values():
        if row.matches(params):
            return row.name
    return "custom"


def camera_view(scene, width: int, height: int) -> temporal.View:
    inv = cloudstate.camera_inv_view_proj(scene, width, height)
    return temporal.View.of(np.array(inv), cloudstate.camera_eye(scene), width, height)


@contextlib.contextmanager
def scene_depth(scene, view: temporal.View):
    """The scene's depth from the camera of `view` as the 3D viewport has it (a float texture of window
    depths, 1 where nothing is drawn), drawn by F12's depth pre-pass; yields the view with its depth
    mapping and the texture, for `TemporalViewport.redraw(..., depth=...)`."""
    window, view_matrix = cloudstate.camera_matrices(scene, view.width, view.height)
    mapping = camera.depth_mapping(window, view_matrix)
    forward = np.array(window, np.float64) @ np.array(view_matrix, np.float64)
    with depthpass.scene_hits(surfaces.camera_meshes(scene), forward, view.width, view.height) as (_tex, hits):
        drawn = hits[..., 3] > 0.5
        depth = np.where(drawn, camera.window_depth(hits[..., :3], window, view_matrix), 1.0).astype(np.float32)
    texture = gpu.types.GPUTexture(
        (view.width, view.height), format="R32F", data=gpu.types.Buffer("FLOAT", depth.size, depth.ravel())
    )
    yield temporal.View.of(np.array(view.inv_view_proj), view.eye, view.width, view.height, mapping), texture


def orbit_camera(scene, degrees: float) -> None:
    """Turn the camera about the vertical axis through its own position."""
    cam = scene.camera
    turn = mathutils.Matrix.Rotation(math.radians(degrees), 4, "Z")
    loc = cam.matrix_world.translation.copy()
    m = turn @ cam.matrix_world
    m.translation = loc
    cam.matrix_world = m
    bpy.context.view_layer.update()


def _naive(clouds: engine.CloudGPU, view: temporal.View) -> np.ndarray:
    return engine.render_offscreen(
        clouds, mathutils.Matrix(view.inv_view_proj), view.eye, view.width, view.height, NUBIS_NAIVE=1
    )


def _with_footprint(state, view: temporal.View):
    angle, size = camera.pixel_footprint(np.array(view.inv_view_proj), view.width, view.height)
    state.pixel_angle, state.pixel_size = angle, size
    return state


@dataclass
class PreviewResult:
    frames: list[int]
    redraw_ms: list[list[float]] = field(default_factory=list)
    naive_ms: list[float] = field(default_factory=list)
    quality: str = ""
    size: tuple[int, int] = (0, 0)


def preview(scene, out_dir, options: PreviewOptions, progress: Progress | None = None) -> PreviewResult:
    """Replay the viewport's draw path from the scene camera: for each frame, `redraws` redraws of the
    temporal viewport (the draw handler's own code), the camera turned by `orbit` degrees per frame.
    Writes NNNN.exr and NNNN.png per frame (and NNNN_naive.* with `naive`) and preview.json."""
    width, height, frames, redraws, orbit, naive = (
        options.width, options.height, list(options.frames), options.redraws, options.orbit, options.naive
    )  # fmt: skip
    limits.check_int("--redraws", redraws, *limits.REDRAWS_RANGE)
    limits.check_orbit("--orbit", orbit)
    out = check_output_dir(out_dir)
    offscreens.check_offscreen(
        width, height
    )  # the full-size image read at the end, refused before the minutes of drawing
    q = apply_quality(scene, options.quality)
    s = scene.nubis
    result = PreviewResult(frames, quality=q, size=(width, height))
    tv = temporal.TemporalViewport()
    clouds = runtime.cloud_gpu(s.noise_seed)
    # Every file of the run appears together at the end, or none (core/staging.py).
    with staging.output_set() as outputs:
        try:
            for n, f in enumerate(frames):
                scene.frame_set(f)
                if n and orbit:
                    orbit_camera(scene, orbit)
                view = camera_view(scene, width, height)
                state = cloudstate.state_from_scene(scene)
                times = []
                for _ in range(redraws):
                    t = time.perf_counter()
                    tv.redraw(clouds, state, view, s.viewport_resolution, s.viewport_samples)
                    tv.sync()
                    times.append((time.perf_counter() - t) * 1000.0)
                result.redraw_ms.append(times)
                rgba = temporal.render_view(tv, clouds, view, s.viewport_blur)
                name = f"{f:04d}"
                pipeline.save_render(scene, outputs.stage(out / f"{name}.exr"), rgba)
                pipeline.save_render(scene, outputs.stage(out / f"{name}.png"), rgba)
                if naive:
                    clouds.update(_with_footprint(state, view))
                    t = time.perf_counter()
                    ref = _naive(clouds, view)
                    result.naive_ms.append((time.perf_counter() - t) * 1000.0)
                    pipeline.save_render(scene, outputs.stage(out / f"{name}_naive.exr"), ref)
                    pipeline.save_render(scene, outputs.stage(out / f"{name}_naive.png"), ref)
                if progress:
                    progress((n + 1) / len(frames))
        finally:
            tv.free()
        report = {
            "preset": s.preset,
            "width": width,
            "height": height,
            "quality": q,
            "redraws_per_frame": redraws,
            "orbit_degrees_per_frame": orbit,
            "renderer": renderer_name(),
            "frames": [
                {"frame": f, "redraw_ms": [round(x, 3) for x in ms]}
                | ({"naive_ms": round(result.naive_ms[i], 3)} if naive else {})
                for i, (f, ms) in enumerate(zip(frames, result.redraw_ms, strict=True))
            ],
        }
        outputs.stage(out / "preview.json").write_text(json.dumps(report, indent=2) + "\n", encoding="utf-8")
    return result


# The render settings the EEVEE measurement changes, restored afterwards: the Benchmark button runs in
# the artist's own scene.
_RENDER_SETTINGS = (
    "render.engine",
    "render.resolution_x",
    "render.resolution_y",
    "render.resolution_percentage",
    "render.film_transparent",
    "render.filepath",
    "render.image_settings.file_format",
    "render.image_settings.color_depth",
    "render.image_settings.color_mode",
    "eevee.taa_render_samples",
    "eevee.volumetric_start",
    "eevee.volumetric_end",
    "cycles.samples",
    "cycles.device",
    "cycles.use_denoising",
    "cycles.pixel_filter_type",
    "cycles.filter_width",
    "cycles.max_bounces",
    "cycles.volume_bounces",
    "cycles.use_adaptive_sampling",
    "camera.data.clip_end",
)


def _resolve(owner, path: str):
    *parents, name = path.split(".")
    for part in parents:
        owner = getattr(owner, part, None)
        if owner is None:
            return None, name
    return owner, name


@contextlib.contextmanager
def preserved(scene, paths=_RENDER_SETTINGS):
    """Put the scene's `paths` back as they were, whatever happens inside."""
    saved = []
    for path in paths:
        owner, name = _resolve(scene, path)
        if owner is not None and hasattr(owner, name):
            saved.append((owner, name, getattr(owner, name)))
    try:
        yield
    finally:
        for owner, name, value in saved:
            setattr(owner, name, value)


def render_eevee(scene, width: int, height: int, vdb_path: str, samples: int = 16) -> tuple[np.ndarray, float]:
    """EEVEE rendering a bake of the clouds from the scene camera: premultiplied RGBA and the seconds
    the render took (the bake not included). The scene's render settings are left as they were."""
    engines = {e.identifier for e in bpy.types.RenderSettings.bl_rna.properties["engine"].enum_items}
    eevee = "BLENDER_EEVEE_NEXT" if "BLENDER_EEVEE_NEXT" in engines else "BLENDER_EEVEE"
    with (
        interrupt.temporary_dir("nubis-eevee-") as tmp,
        preserved(scene),
    ):
        cycles_setup.import_volume(scene, vdb_path)
        try:
            cycles_setup.configure_render(scene, width, height, None)
            scene.render.engine = eevee
            scene.eevee.taa_render_samples = samples
            # Clouds sit kilometres away: EEVEE's volume range must reach them.
            scene.eevee.volumetric_start = 1.0
            scene.eevee.volumetric_end = scene.nubis.layer_draw_radius * 2.0
            exr = Path(tmp) / "eevee.exr"
            scene.render.filepath = str(exr)
            t = time.perf_counter()
            with runtime.own_render():
                bpy.ops.render.render(write_still=True, scene=scene.name)
            seconds = time.perf_counter() - t
            if not exr.is_file():
                raise NubisError("EEVEE wrote no image: check the console for errors")
            rgba = imageio.read_image(exr)
        finally:
            cycles_setup.remove_volume(scene)
    return rgba, seconds


def benchmark(scene, out_dir, options: BenchmarkOptions, baseline: dict | None = None) -> dict:
    """Naive march, temporal redraws and EEVEE on the same view in one run; writes benchmark.json,
    naive.png and converged.png (after 16 redraws). `baseline`: an earlier benchmark of the same view in
    this run (the procedural cloudscape before VDB clouds were added), whose redraw the result names."""
    out = check_output_dir(out_dir)
    q = apply_quality(scene, options.quality)
    clouds = runtime.cloud_gpu(scene.nubis.noise_seed)
    view = camera_view(scene, options.width, options.height)
    state = _with_footprint(cloudstate.state_from_scene(scene), view)
    clouds.update(state)
    stats = _fetch_stats(clouds, view, options)
    timed = _timed_rounds(scene, clouds, state, view, options.rounds)
    result = _benchmark_result(scene, q, options, timed, stats)
    if state.vdb_clouds:
        # GPU memory of the VDB clouds' bricks against their dense boxes at the same half floats.
        result["vdb_gpu_bytes"] = clouds.vdb.bytes
        result["vdb_active_voxels"] = sum(p.cloud.active_voxels for p in state.vdb_clouds)
        result["vdb_dense_box_bytes"] = sum(
            2 * int(np.prod(np.subtract(p.cloud.bounds[1], p.cloud.bounds[0]) + 1)) for p in state.vdb_clouds
        )
    if baseline is not None:
        result["baseline_redraw_ms"] = baseline["redraw_ms"]
        result["baseline_preset"] = baseline["preset"]
        result["baseline_label"] = baseline.get("label", "the cloudscape")
    images = {
        "naive.png": pipeline.display_image(scene, timed.naive),
        "converged.png": pipeline.display_image(scene, timed.converged),
    }
    result["converged_psnr_db"] = psnr(images["converged.png"], images["naive.png"])
    if options.eevee:
        images["eevee.png"] = _benchmark_eevee(scene, view, options, result)
    with staging.output_set() as outputs:
        for name, image in images.items():
            imageio.write_image(outputs.stage(out / name), image)
        outputs.stage(out / "benchmark.json").write_text(json.dumps(result, indent=2) + "\n", encoding="utf-8")
    return result


# The light march's far part as the light volumes give it, and as its long tap (docs/viewport.md#light-volumes).
_VARIANTS = (("volumes", 1), ("long_tap", 0))


def _fetch_stats(clouds, view, options: BenchmarkOptions) -> dict:
    """Texture fetches and samples per pixel of the coarse-to-fine and the naive march, per variant."""
    stats = {}
    for variant, volume in _VARIANTS:
        clouds.switches["NUBIS_LIGHT_VOLUME"] = volume
        for label, switches in (("coarse_to_fine", {}), ("naive", {"NUBIS_NAIVE": 1})):
            px = engine.render_offscreen(
                clouds,
                mathutils.Matrix(view.inv_view_proj),
                view.eye,
                options.width,
                options.height,
                NUBIS_FETCH_STATS=1,
                **switches,
            )
            key = label if variant == "volumes" else f"{label}_{variant}"
            stats[key] = {
                "fetches_3d_per_pixel": float(px[..., 0].mean()),
                "view_samples_per_pixel": float(px[..., 1].mean()),
                "density_samples_per_pixel": float(px[..., 2].mean()),
            }
    return stats


@dataclass
class _Timed:
    times: dict  # milliseconds of each run, by what was run
    fills: list  # milliseconds to fill the light volumes once
    naive: np.ndarray  # the naive march's image (light volumes on)
    converged: np.ndarray  # the temporal viewport's after a convergence


def _timed_rounds(scene, clouds, state, view, rounds: int) -> _Timed:
    """Rounds of one naive march and one convergence (16 redraws from a restart) per variant, alternating,
    so a load that comes and goes on the machine weighs on all alike; then the light volumes' fills."""
    s = scene.nubis
    tv = temporal.TemporalViewport()
    times: dict[str, list[float]] = {}
    try:
        for _variant, volume in _VARIANTS:
            clouds.switches["NUBIS_LIGHT_VOLUME"] = volume
            _naive(clouds, view)  # compiles the permutation
            tv.redraw(clouds, state, view, s.viewport_resolution, 64)  # allocates and compiles
        for _ in range(rounds):
            for variant, volume in _VARIANTS:
                clouds.switches["NUBIS_LIGHT_VOLUME"] = volume
                clouds.update(state)  # the redraws leave their own block behind (the history's footprint)
                t = time.perf_counter()
                naive_img = _naive(clouds, view)
                times.setdefault(f"naive_{variant}", []).append((time.perf_counter() - t) * 1000.0)
                tv.restart()
                for _ in range(temporal.REDRAWS_PER_SAMPLE):
                    t = time.perf_counter()
                    tv.redraw(clouds, state, view, s.viewport_resolution, 64)
                    tv.sync()
                    times.setdefault(f"redraw_{variant}", []).append((time.perf_counter() - t) * 1000.0)
                if volume:
                    converged = temporal.render_view(tv, clouds, view, s.viewport_blur)
                    volume_naive = naive_img
        fills = _volume_fills(clouds, state, rounds)
    finally:
        clouds.switches["NUBIS_LIGHT_VOLUME"] = 1
        clouds.update(state)
        tv.free()
    return _Timed(times, fills, volume_naive, converged)


def _volume_fills(clouds, state, rounds: int) -> list[float]:
    """Filling the two light volumes once (a change of the field, the sun or the wind's drift): the sun moves."""
    fills = []
    for i in range(rounds):
        t = time.perf_counter()
        sun = np.asarray(state.sun_direction, np.float64) + (0.0, 0.0, 1e-3 * (i + 1))
        clouds.update(replace(state, sun_direction=tuple(sun / np.linalg.norm(sun))))
        clouds.volumes["sky_volume"].read()  # waits for both fills (the sky's is dispatched last)
        fills.append((time.perf_counter() - t) * 1000.0)
    return fills


def _benchmark_result(scene, quality_name: str, options: BenchmarkOptions, timed: _Timed, stats: dict) -> dict:
    times = timed.times
    naive_runs, redraws = times["naive_volumes"], times["redraw_volumes"]
    result = {
        "preset": scene.nubis.preset,
        "quality": quality_name,
        "width": options.width,
        "height": options.height,
        "renderer": renderer_name(),
        "naive_ms": statistics.median(naive_runs),
        "redraw_ms": statistics.median(redraws),
        "naive_ms_long_tap": statistics.median(times["naive_long_tap"]),
        "redraw_ms_long_tap": statistics.median(times["redraw_long_tap"]),
        "volume_fill_ms": statistics.median(timed.fills),
        "naive_ms_all": [round(x, 3) for x in naive_runs],
        "redraw_ms_all": [round(x, 3) for x in redraws],
        "fetches": stats,
    }
    result["naive_over_redraw"] = result["naive_ms"] / result["redraw_ms"]
    c2f, nv = stats["coarse_to_fine"]["fetches_3d_per_pixel"], stats["naive"]["fetches_3d_per_pixel"]
    result["fetch_saving"] = 1.0 - c2f / nv if nv else 0.0
    return result


def _benchmark_eevee(scene, view, options: BenchmarkOptions, result: dict) -> np.ndarray:
    """EEVEE rendering the bake of the same view; its time into `result`, its display image returned."""
    with interrupt.temporary_dir("nubis-bench-") as tmp:
        st = cloudstate.state_from_scene(scene)
        region = view_footprint(st, np.array(view.inv_view_proj))
        voxel = comparison_voxel_size(st, scene.nubis.bake_voxel_size, region)
        bake_options = BakeOptions(voxel, camera_only=True, size=(options.width, options.height))
        baked = pipeline.bake(scene, Path(tmp) / "clouds.vdb", bake_options)
        # A first render of one sample compiles EEVEE's shaders (on llvmpipe each sample costs about as much
        # as the compile, so the warm-up takes one); the second, of the options' samples, is EEVEE's own cost.
        render_eevee(scene, options.width, options.height, str(baked.path), 1)
        eevee_img, seconds = render_eevee(scene, options.width, options.height, str(baked.path), options.eevee_samples)
    result["eevee_ms"] = seconds * 1000.0
    result["eevee_voxel_size"] = baked.plan.voxel_size
    result["eevee_samples"] = options.eevee_samples
    result["eevee_over_redraw"] = result["eevee_ms"] / result["redraw_ms"]
    return pipeline.display_image(scene, eevee_img)


def psnr(a: np.ndarray, b: np.ndarray) -> float:
    """PSNR in dB of two display images with values in [0, 1] (colour channels)."""
    mse = float(np.mean((np.asarray(a[..., :3], np.float64) - np.asarray(b[..., :3], np.float64)) ** 2))
    return float("inf") if mse == 0 else 10.0 * math.log10(1.0 / mse)


def sidebar_rows(result: dict) -> list[tuple[str, str]]:
    """The benchmark in short (name, value) rows that fit the sidebar's default width (table() has the rest)."""
    rows = [
        ("Redraw", f"{result['redraw_ms']:.1f} ms"),
        ("Naive march", f"{result['naive_ms']:.0f} ms"),
        ("Naive / redraw", f"{result['naive_over_redraw']:.1f}x"),
    ]
    if "eevee_ms" in result:
        rows.append(("EEVEE / redraw", f"{result['eevee_over_redraw']:.0f}x"))
    rows.append(("3D fetches/px", f"{result['fetches']['coarse_to_fine']['fetches_3d_per_pixel']:.0f}"))
    rows.append(("PSNR vs naive", f"{result['converged_psnr_db']:.1f} dB"))
    return rows


def _count(n: int, noun: str) -> str:
    return f"{n} {noun}" if n == 1 else f"{n} {noun}s"


def table(result: dict) -> str:
    rows = [
        ("naive march (every pixel, full samples)", f"{result['naive_ms']:.1f} ms"),
        ("temporal redraw while converging (median)", f"{result['redraw_ms']:.1f} ms"),
        ("  naive / redraw", f"{result['naive_over_redraw']:.1f}x"),
    ]
    if "eevee_ms" in result:
        samples = _count(result.get("eevee_samples", 16), "sample")
        rows += [
            (f"EEVEE, {samples}, bake of {result['eevee_voxel_size']:g} m voxels", f"{result['eevee_ms']:.0f} ms"),
            ("  EEVEE / redraw", f"{result['eevee_over_redraw']:.0f}x"),
        ]
    f = result["fetches"]
    if "redraw_ms_long_tap" in result:
        rows += [
            ("naive march, GPU Pro 7's long tap instead of the volumes", f"{result['naive_ms_long_tap']:.1f} ms"),
            ("temporal redraw, long tap (median)", f"{result['redraw_ms_long_tap']:.1f} ms"),
            (
                "  volumes / long tap: naive, redraw",
                f"{result['naive_ms'] / result['naive_ms_long_tap']:.2f}x, "
                f"{result['redraw_ms'] / result['redraw_ms_long_tap']:.2f}x",
            ),
            ("filling the two light volumes (a change)", f"{result['volume_fill_ms']:.0f} ms"),
            (
                "3D fetches per pixel, coarse to fine, long tap",
                f"{f['coarse_to_fine_long_tap']['fetches_3d_per_pixel']:.1f}",
            ),
        ]
    rows += [
        ("3D fetches per pixel, naive", f"{f['naive']['fetches_3d_per_pixel']:.1f}"),
        ("3D fetches per pixel, coarse to fine", f"{f['coarse_to_fine']['fetches_3d_per_pixel']:.1f}"),
        ("  saving", f"{result['fetch_saving'] * 100:.0f}%"),
        ("converged (16 redraws) vs naive, PSNR", f"{result['converged_psnr_db']:.1f} dB"),
    ]
    if "vdb_gpu_bytes" in result:
        rows += [
            ("VDB clouds on the GPU (brick atlas and index)", sequence.human_bytes(result["vdb_gpu_bytes"])),
            ("  their dense boxes at half floats", sequence.human_bytes(result["vdb_dense_box_bytes"])),
            ("  bricks / dense box", f"{result['vdb_gpu_bytes'] / result['vdb_dense_box_bytes']:.2f}"),
        ]
    if "baseline_redraw_ms" in result:
        rows += [
            (f"{result['baseline_label']}: redraw, same view and run", f"{result['baseline_redraw_ms']:.1f} ms"),
            ("  redraw / that redraw", f"{result['redraw_ms'] / result['baseline_redraw_ms']:.2f}x"),
        ]
    width = max(len(r[0]) for r in rows)
    head = f"{result['preset']} at {result['width']}x{result['height']}, quality {result['quality']}"
    head += f", {result['renderer']}"
    return "\n".join([head, *(f"{name:<{width}}  {value}" for name, value in rows)])
