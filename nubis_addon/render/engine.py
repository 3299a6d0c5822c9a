"""The GPU side of Nubis: one set of shaders and inputs, three consumers (viewport, offscreen render, bake)."""

from __future__ import annotations

import functools
import time
from collections.abc import Callable
from dataclasses import dataclass, replace

import gpu
import numpy as np
from gpu.types import GPUShaderCreateInfo, GPUStageInterfaceInfo
from gpu_extras.batch import batch_for_shader

from ..core import lightvolume, noise, sky
from ..core.schema import defaults
from ..core.state import CloudState
from . import fieldpatch, offscreens, uniforms, vdbatlas
from .gpu_context import release_at_exit
from .sources import CLOUD_LIBS, assemble, read_shader
from .textures import NoiseTextures, field_stack_texture, field_texture, sky_texture, texture_from_array

CLOUD_SAMPLERS = (
    ("FLOAT_2D_ARRAY", "field_a"),
    ("FLOAT_2D_ARRAY", "field_b"),
    ("FLOAT_2D", "field_c"),
    ("FLOAT_3D", "noise_lf"),
    ("FLOAT_3D", "noise_lf_mip1"),
    ("FLOAT_3D", "noise_lf_mip2"),
    ("FLOAT_3D", "noise_hf"),
    ("FLOAT_3D", "noise_hf_mip1"),
    ("FLOAT_2D", "noise_curl"),
    ("FLOAT_2D", "noise_cirrus"),
    ("FLOAT_2D", "sky_env"),
    ("FLOAT_2D", "sun_air"),
    ("FLOAT_3D", "sun_volume"),
    ("FLOAT_3D", "sky_volume"),
)
VOLUMES = ("sun_volume", "sky_volume")
# The libraries the optical-depth volumes are filled with (the density and the absorption).
VOLUME_LIBS = CLOUD_LIBS[:4]
# The permutation switches every stage is compiled with (0 or 1); see shaders/nubis_common_lib.glsl.
SWITCHES = (
    "NUBIS_STORMS",
    "NUBIS_REFERENCE",
    "NUBIS_NAIVE",
    "NUBIS_CIRRUS",
    "NUBIS_FETCH_STATS",
    "NUBIS_LIGHT_VOLUME",
    "NUBIS_VDB",
)
# The VDB clouds' textures, bound only in the NUBIS_VDB permutation (render/vdbatlas.py).
VDB_SAMPLERS = (("FLOAT_3D", "vdb_index"), ("FLOAT_3D", "vdb_atlas"))


@dataclass(frozen=True)
class Stage:
    """A full-screen shader stage: fragment source shaders/nubis_<name>_frag.glsl after its libraries."""

    push_constants: tuple[tuple[str, str], ...] = ()
    samplers: tuple[tuple[str, str], ...] = ()  # beyond the cloud inputs
    libs: tuple[str, ...] = CLOUD_LIBS
    cloud_inputs: bool = True  # binds the cloud samplers (the libraries in CLOUD_LIBS read them)
    outputs: tuple[str, ...] = ("color",)
    blocks: tuple[tuple[str, str], ...] = ()  # extra uniform blocks (struct type, name) after P
    vertex: str = "nubis_fullscreen_vert.glsl"
    far_plane: bool = False  # the triangle on the far plane: a LESS_EQUAL depth test keeps it behind objects
    fragment: str = ""  # default: shaders/nubis_<name>_frag.glsl


_VIEW = (("MAT4", "inv_view_proj"), ("VEC4", "eye"))
# The temporal resolve reads the working buffer and the previous history, and writes the new history.
_TEMPORAL_TARGETS = ("color", "attr", "flash")
_RESOLVE = {
    "samplers": (
        *(("FLOAT_2D", f"{src}_{t}") for src in ("work", "hist") for t in _TEMPORAL_TARGETS),
        ("FLOAT_2D", "scene_depth"),
    ),
    "libs": ("nubis_common_lib.glsl", "nubis_motion_lib.glsl"),
    "cloud_inputs": False,
    "outputs": _TEMPORAL_TARGETS,
    "blocks": (("NubisTemporal", "T"),),
}
# The bake reads the lighting library too, for the glow grid.
STAGES: dict[str, Stage] = {
    "raymarch": Stage(_VIEW),
    # F12's camera view split at the scene's first surface (the depth pre-pass's world positions): the
    # clouds in front of it and those behind (docs/sky.md#objects-in-the-clouds).
    "split": Stage(_VIEW, (("FLOAT_2D", "scene_hit"),), outputs=("near", "far")),
    # The clouds in every direction from one point (equirectangular), and their transmittance towards
    # the sun over a plane facing it (the scene's cloud shadows).
    "panorama": Stage((("VEC4", "eye"),)),
    "shadow": Stage((("VEC4", "shadow_origin"), ("VEC4", "shadow_u"), ("VEC4", "shadow_v"))),
    "bake": Stage((("VEC4", "bake_origin"), ("VEC4", "bake_voxel"), ("VEC4", "bake_tile"))),
    "motion": Stage(_VIEW, blocks=(("NubisMotionCameras", "C"),)),
    # The temporal viewport (render/temporal.py): one pixel of every 4x4 block into the working buffer,
    # the resolve into the full-resolution history, and the upscale onto the view.
    # Where the scene's depth is bound, the march ends at its surfaces (T: the view's depth mapping).
    "temporal_march": Stage(
        (*_VIEW, ("VEC4", "block")),
        (("FLOAT_2D", "scene_depth"),),
        outputs=_TEMPORAL_TARGETS,
        blocks=(("NubisTemporal", "T"),),
    ),
    "resolve": Stage(**_RESOLVE),
    # The World's sky behind the clouds in Solid shading, on the far plane: a LESS_EQUAL depth test keeps
    # it behind the scene's objects.
    "sky": Stage(_VIEW, far_plane=True),
    # On the far plane: with the scene's depth it is drawn without a depth test, each pixel holding the
    # clouds in front of what it shows (docs/viewport.md#clouds-in-front-of-the-scene); without, a
    # LESS_EQUAL test keeps the clouds behind the objects.
    "upscale": Stage(
        (("VEC4", "filter_size"), ("VEC4", "scene"), ("VEC4", "depth_map")),
        tuple(("FLOAT_2D", name) for name in ("hist_color", "hist_flash", "hist_attr", "scene_depth")),
        libs=("nubis_common_lib.glsl",),
        cloud_inputs=False,
        far_plane=True,
    ),
}
_shaders: dict[tuple, gpu.types.GPUShader] = {}
_batches: dict[tuple, gpu.types.GPUBatch] = {}
release_at_exit(_batches.clear)  # (run in reverse: the batches before the shaders they draw with)
release_at_exit(_shaders.clear)


def _create_info(name: str, defines: dict[str, object]) -> GPUShaderCreateInfo:
    stage = STAGES[name]
    iface = GPUStageInterfaceInfo(f"nubis_{name}_iface")
    iface.smooth("VEC2", "uv")
    info = GPUShaderCreateInfo()
    # Permutations rather than branches on uniforms: the superstorm terms cost a software rasterizer
    # ~40 % even with no storm in the scene, so skies without storms compile them out; the same holds
    # for the reference light march, the cirrus layer, the naive march and the fetch counter.
    for key, value in defines.items():
        info.define(key, str(value))
    info.define("NUBIS_FULLSCREEN_DEPTH", "1.0" if stage.far_plane else "0.0")
    info.typedef_source(uniforms.struct_source() + read_shader("nubis_params.glsl"))
    info.uniform_buf(0, "NubisParams", "P")
    for slot, (struct, block) in enumerate(stage.blocks, start=1):
        info.uniform_buf(slot, struct, block)
    samplers = (_cloud_samplers(defines) if stage.cloud_inputs else ()) + stage.samplers
    for slot, (kind, sampler) in enumerate(samplers):
        info.sampler(slot, kind, sampler)
    for kind, constant in stage.push_constants:
        info.push_constant(kind, constant)
    info.vertex_in(0, "VEC2", "pos")
    info.vertex_out(iface)
    for slot, out in enumerate(stage.outputs):
        info.fragment_out(slot, "VEC4", out)
    info.vertex_source(read_shader(stage.vertex))
    info.fragment_source(assemble(*stage.libs, stage.fragment or f"nubis_{name}_frag.glsl"))
    return info


def _cloud_samplers(defines: dict[str, object]) -> tuple[tuple[str, str], ...]:
    return CLOUD_SAMPLERS + (VDB_SAMPLERS if int(defines.get("NUBIS_VDB", 0)) else ())


def _volume_create_info(defines: dict[str, object]) -> GPUShaderCreateInfo:
    """The compute stage that fills an optical-depth volume (shaders/nubis_light_volume_comp.glsl)."""
    info = GPUShaderCreateInfo()
    for key, value in defines.items():
        info.define(key, str(value))
    info.define("NUBIS_VOLUME_STEPS", str(lightvolume.STEPS_PER_SLICE))
    info.typedef_source(uniforms.struct_source() + read_shader("nubis_params.glsl"))
    info.uniform_buf(0, "NubisParams", "P")
    for slot, (kind, sampler) in enumerate(_cloud_samplers(defines)):
        info.sampler(slot, kind, sampler)
    info.image(0, lightvolume.FORMAT, "FLOAT_3D", "volume_out", qualifiers={"WRITE"})
    for name in ("volume_origin", "volume_u", "volume_v", "volume_w"):
        info.push_constant("VEC4", name)
    info.local_group_size(VOLUME_GROUP, VOLUME_GROUP, 1)
    info.compute_source(assemble(*VOLUME_LIBS, "nubis_light_volume_comp.glsl"))
    return info


VOLUME_GROUP = 8


def _side_create_info() -> GPUShaderCreateInfo:
    """The compute stage that adds the sideways depths to the sky volume (shaders/nubis_sky_side_comp.glsl)."""
    info = GPUShaderCreateInfo()
    info.sampler(0, "FLOAT_3D", "sky_depth")
    info.image(0, lightvolume.SKY_FORMAT, "FLOAT_3D", "volume_out", qualifiers={"WRITE"})
    info.push_constant("VEC4", "side_scale")
    info.local_group_size(VOLUME_GROUP, VOLUME_GROUP, 1)
    info.compute_source(read_shader("nubis_sky_side_comp.glsl"))
    return info


def _key(name: str, defines: dict[str, object]) -> tuple:
    return (name, *sorted(defines.items()))


def shader(name: str, defines: dict[str, object]) -> gpu.types.GPUShader:
    key = _key(name, defines)
    if key not in _shaders:
        if name == "light_volume":
            info = _volume_create_info(defines)
        elif name == "sky_side":
            info = _side_create_info()
        else:
            info = _create_info(name, defines)
        _shaders[key] = gpu.shader.create_from_info(info)
    return _shaders[key]


def fullscreen_batch(name: str, defines: dict[str, object]) -> gpu.types.GPUBatch:
    key = _key(name, defines)
    if key not in _batches:
        _batches[key] = batch_for_shader(shader(name, defines), "TRIS", {"pos": ((-1, -1), (3, -1), (-1, 3))})
    return _batches[key]


class CloudGPU:
    """GPU inputs of the cloud shaders, updated from a CloudState."""

    def __init__(self, noise_set: noise.NoiseSet | NoiseTextures):
        # The noise textures never change once made: a fork shares them (fork()).
        self.noise = noise_set if isinstance(noise_set, NoiseTextures) else NoiseTextures(noise_set)
        self._field_arrays: tuple = ()
        self.field_a = self.field_b = self.field_c = None
        self._sky_key = None
        self._sky_array = None
        self.sky_env = None
        self.sun_air = None  # the transmittance towards the sun (core/sky.py air_table)
        self._air_key = None
        self.switches = dict.fromkeys(SWITCHES, 0)
        # The optical-depth volumes light the real-time march; 0 measures GPU Pro 7's long tap instead.
        self.switches["NUBIS_LIGHT_VOLUME"] = 1
        self.ubo = None
        self.ubo_bytes = b""
        self.volumes = {name: None for name in VOLUMES}
        self._volume_key = None
        self._no_volume = None
        self.volume_fills = 0  # how often the volumes were filled (tests, the benchmark)
        self.field_revision = 0  # bumped by each in-place patch of the field textures (patch_field)
        self._field_uploads = 0  # bumped by each upload of other pixels: with the patches, what the volumes hold
        self.light_held_until = 0.0  # time.monotonic() before which filled volumes are not refilled
        self.vdb = vdbatlas.VdbTextures()

    def fork(self) -> CloudGPU:
        """GPU inputs of their own over the same noise textures: a bake or a render that runs while the
        3D viewport keeps drawing uploads its snapshot here once, and the viewport's uploads to the shared
        inputs cannot reach it (blender/jobs/snapshot.py). Costs the field, sky and light-volume textures only."""
        return CloudGPU(self.noise)

    @property
    def storms(self) -> bool:
        return bool(self.switches["NUBIS_STORMS"])

    def update(self, state: CloudState, light: bool = True) -> None:
        """Upload what the shaders read for `state`; `light` False skips the light volumes (the bake reads
        densities only), which keep their last contents and are refilled by the next lit update."""
        self._upload_fields(state)
        env = state.sky_env
        sky_key = id(env) if env is not None else tuple(state.ambient)
        if self.sky_env is None or sky_key != self._sky_key or (env is not None and env is not self._sky_array):
            self.sky_env = sky_texture(env if env is not None else sky.uniform(state.ambient))
            self._sky_key, self._sky_array = sky_key, env
        air = state.sun_air or (1.0, 1.0, 1.0)  # without the air the shaders do not read it
        if self.sun_air is None or air != self._air_key:
            self.sun_air = texture_from_array(sky.air_table(*air), "RGBA16F")
            self._air_key = air
        try:
            self.vdb.update(state.vdb_clouds, state.vdb_gpu_budget)
        except Exception:
            self.switches["NUBIS_VDB"] = 0  # no half-made VDB textures are ever bound
            raise
        self.ubo_bytes = uniforms.pack(state).tobytes()
        self.ubo = gpu.types.GPUUniformBuf(self.ubo_bytes)
        self.switches.update(
            NUBIS_STORMS=int(bool(state.storms)),
            NUBIS_REFERENCE=int(state.light_mode),
            NUBIS_CIRRUS=int(state.has_cirrus()),
            NUBIS_VDB=int(bool(state.vdb_clouds)),
        )
        if self._no_volume is None:  # bound in place of the volumes while they are filled or skipped
            self._no_volume = gpu.types.GPUTexture((1, 1, 1), format="R32F")
        held = time.monotonic() < self.light_held_until and all(v is not None for v in self.volumes.values())
        if light and not held:
            self._update_volumes(state)

    def _upload_fields(self, state: CloudState) -> None:
        """The field textures: the drawn cloud layers' A and B images as two array textures (a slice a
        layer, docs/layers.md) and the cirrus image."""
        # Fields are replaced, never edited in place, by everything that changes them but a brush (which
        # patches the textures too, patch_field): holding the arrays and comparing identity is exact, and
        # costs nothing per redraw. Other arrays of the same pixels (each state read from the scene has its
        # own) keep the textures and the light volumes filled from them: a frame's several states then
        # fill the volumes once, not once each (docs/measurements.md#light-volume-fills).
        layers = state.drawn_layers()
        arrays = (*(f.field_a for f in layers), *(f.field_b for f in layers), state.field_c)
        held = self._field_arrays
        if len(arrays) == len(held) and all(a is b for a, b in zip(arrays, held, strict=True)):
            return
        if not self._same_pixels(arrays):
            n = len(layers)
            self.field_a = field_stack_texture(list(arrays[:n]))
            self.field_b = field_stack_texture(list(arrays[n : 2 * n]))
            self.field_c = field_texture(arrays[-1])
            self._field_uploads += 1
        self._field_arrays = arrays

    def _same_pixels(self, arrays: tuple) -> bool:
        """Whether `arrays` hold exactly the pixels of the arrays the field textures were made from (a
        comparison of 12 MB at the default resolution: milliseconds, where a refill of the volumes takes
        a second on a software rasterizer)."""
        held = self._field_arrays
        return (
            len(held) == len(arrays)
            and self.field_a is not None
            and all(a.shape == b.shape and np.array_equal(a, b) for a, b in zip(arrays, held, strict=True))
        )

    def hold_light(self, seconds: float) -> None:
        """Keep the light volumes as they are for `seconds` (a brush drag: the clouds under the brush change
        at once, their shadows when the drag pauses or ends, docs/painting.md#live)."""
        self.light_held_until = time.monotonic() + seconds

    def patch_field(self, arrays: tuple, which: int, rect: tuple[int, int, int, int]) -> bool:
        """A brush changed `rect` of field image `which` (0 A, 1 B, 2 cirrus) of one cloud layer's arrays
        (A, B, cirrus), in place: write that rectangle into the texture's slice those arrays were uploaded
        to (render/fieldpatch.py). Returns False, doing nothing, when they are not among the arrays uploaded
        (the next update uploads them whole)."""
        held = self._field_arrays
        at = next((k for k, a in enumerate(held) if a is arrays[which]), None)
        if at is None:
            return False
        layers = (len(held) - 1) // 2
        if at == len(held) - 1:
            fieldpatch.patch(self.field_c, held[at], rect)
        else:
            texture = self.field_a if at < layers else self.field_b
            fieldpatch.patch(texture, held[at], rect, layer=at % layers)
        self.field_revision += 1
        return True

    def _update_volumes(self, state: CloudState) -> None:
        """Refill the optical-depth volumes when what they hold changed: the field, the density
        settings, the sun's direction, the storms, the box, or the time by a step of the wind's drift
        (core/lightvolume.py). The jitter of an accumulation pass, small camera moves and lighting-only
        settings do not refill them."""
        plain = defaults()
        still = replace(
            state,
            params={k: (plain.get(k, v) if lightvolume.lighting_only(k) else v) for k, v in state.params.items()},
            time=lightvolume.refill_time(state),
            sun_radiance=(1.0, 1.0, 1.0),
            ambient=(1.0, 1.0, 1.0),
            ambient_below=None,
            ambient_flank=None,
            jitter=True,
            jitter_pass=0,
            pixel_angle=0.0,
            pixel_size=0.0,
            light_mode=0,
            sky_env=None,
            draw_center=lightvolume.key_centre(state),
        )
        density_switches = {k: self.switches[k] for k in ("NUBIS_STORMS", "NUBIS_CIRRUS", "NUBIS_VDB")}
        key = (
            self._field_uploads,
            self.field_revision,
            self.vdb.key,
            uniforms.pack(still).tobytes(),
            tuple(sorted(self.noise.defines.items())),
            tuple(sorted(density_switches.items())),
        )
        if key == self._volume_key and all(v is not None for v in self.volumes.values()):
            return
        if self.volumes["sun_volume"] is None:
            self.volumes["sun_volume"] = gpu.types.GPUTexture(lightvolume.SIZE, format=lightvolume.FORMAT)
            self.volumes["sky_volume"] = gpu.types.GPUTexture(lightvolume.SIZE, format=lightvolume.SKY_FORMAT)
        # The sky's depths from the top, which the sideways pass reads into the sky volume: held during
        # the fill only (4 MB).
        sky_depth = gpu.types.GPUTexture(lightvolume.SIZE, format=lightvolume.FORMAT)
        defines = self.defines(NUBIS_REFERENCE=0, NUBIS_NAIVE=0, NUBIS_FETCH_STATS=0)
        sky_box = lightvolume.sky_volume(state)
        sh = shader("light_volume", defines)
        for name, box in (("sun_volume", lightvolume.sun_volume(state)), ("sky_volume", sky_box)):
            self.bind(sh, volumes=False)
            sh.image("volume_out", self.volumes[name] if name == "sun_volume" else sky_depth)
            sh.uniform_float("volume_origin", (*box.origin, 0.0))
            for axis, edge in zip(("volume_u", "volume_v", "volume_w"), box.axes, strict=True):
                sh.uniform_float(axis, (*edge, 0.0))
            groups = [-(-n // VOLUME_GROUP) for n in lightvolume.SIZE[:2]]
            gpu.compute.dispatch(sh, groups[0], groups[1], 1)
        side = shader("sky_side", {})
        side.bind()
        side.uniform_sampler("sky_depth", sky_depth)
        side.image("volume_out", self.volumes["sky_volume"])
        side.uniform_float("side_scale", lightvolume.side_scale(sky_box))
        gpu.compute.dispatch(side, groups[0], groups[1], 1)
        self._volume_key = key
        self.volume_fills += 1

    def defines(self, **switches: int) -> dict[str, object]:
        """The permutation for this state, with `switches` (e.g. NUBIS_NAIVE=1) on top."""
        return {"NUBIS_COARSE_STRIDE": 2, **self.noise.defines, **self.switches, **switches}

    def bind(self, sh: gpu.types.GPUShader, cloud_inputs: bool = True, volumes: bool = True) -> None:
        """Bind the uniform block and the cloud samplers (the VDB clouds' in their permutation); `volumes`
        False binds an empty texture for the optical-depth volumes (while they are being filled)."""
        sh.bind()
        sh.uniform_block("P", self.ubo)
        if not cloud_inputs:
            return
        textures = {"field_a": self.field_a, "field_b": self.field_b, "field_c": self.field_c, "sky_env": self.sky_env}
        textures["sun_air"] = self.sun_air
        for name in VOLUMES:
            textures[name] = self.volumes[name] if volumes and self.volumes[name] is not None else self._no_volume
        for _kind, name in CLOUD_SAMPLERS:
            tex = textures.get(name) or self.noise.textures[name.removeprefix("noise_")]
            sh.uniform_sampler(name, tex)
        if self.switches["NUBIS_VDB"] and self.vdb.atlas is not None:
            sh.uniform_sampler("vdb_index", self.vdb.index)
            sh.uniform_sampler("vdb_atlas", self.vdb.atlas)


def draw_clouds(gpu_inputs: CloudGPU, inv_view_proj, eye, **switches: int) -> None:
    """Draw the clouds into the bound framebuffer (premultiplied radiance, alpha). `eye` is the
    perspective camera's position with w = 1, or w = 0 for an orthographic view. `switches` pick a
    permutation: NUBIS_NAIVE=1 for the benchmark's naive march, NUBIS_FETCH_STATS=1 to count fetches."""
    draw_stage("raymarch", gpu_inputs, {"inv_view_proj": inv_view_proj, "eye": tuple(eye)}, switches=switches)


def draw_stage(
    stage: str,
    gpu_inputs: CloudGPU,
    uniforms: dict | None = None,
    blocks: dict | None = None,
    samplers: dict | None = None,
    switches: dict | None = None,
) -> None:
    """One full-screen draw of a cloud stage with the cloud inputs bound plus the stage's own."""
    defines = gpu_inputs.defines(**(switches or {}))
    sh = shader(stage, defines)
    gpu_inputs.bind(sh, STAGES[stage].cloud_inputs)
    for name, value in (uniforms or {}).items():
        sh.uniform_float(name, value)
    for name, value in (blocks or {}).items():
        sh.uniform_block(name, value)
    for name, value in (samplers or {}).items():
        sh.uniform_sampler(name, value)
    fullscreen_batch(stage, defines).draw(sh)


def render_motion(gpu_inputs: CloudGPU, inv_view_proj, eye, prev_view_proj, width: int, height: int) -> np.ndarray:
    """Per-pixel motion vectors (dx, dy in pixels per timestep), cloud distance and alpha, top row first.
    `prev_view_proj` is the camera one timestep earlier (the same matrix for a still camera)."""
    # mathutils matrices are row-major; GLSL reads columns.
    cams = np.array([np.array(inv_view_proj.inverted()).T, np.array(prev_view_proj).T], np.float32)
    cameras = gpu.types.GPUUniformBuf(cams.tobytes())
    px = offscreens.draw_offscreen(
        width,
        height,
        lambda: draw_stage("motion", gpu_inputs, {"inv_view_proj": inv_view_proj, "eye": tuple(eye)}, {"C": cameras}),
    )
    # Rows run top-down in the result, so a motion up the screen becomes negative y, as in image space.
    out = px[::-1].copy()
    out[..., 1] *= -1.0
    return out


# Pixels per side of the tiles offscreen renders are drawn in: a tile of the default sky takes about half a
# second on llvmpipe (2 cores), which bounds how long an interrupt waits.
TILE = 128


def render_offscreen(
    gpu_inputs: CloudGPU, inv_view_proj, eye, width: int, height: int, tile: int = TILE, **switches: int
) -> np.ndarray:
    """Scene-linear premultiplied RGBA, shape (height, width, 4), top row first.

    The frame is drawn in tiles so that one huge draw call never stalls a software rasterizer.
    """
    return offscreens.run_steps(render_offscreen_steps(gpu_inputs, inv_view_proj, eye, width, height, tile, **switches))


def render_offscreen_steps(
    gpu_inputs: CloudGPU, inv_view_proj, eye, width: int, height: int, tile: int = TILE, **switches: int
):
    """render_offscreen as a generator yielding the fraction done after each tile (for modal operators);
    returns the image."""
    draws = _tile_draws(width, height, tile, lambda: draw_clouds(gpu_inputs, inv_view_proj, eye, **switches))
    px = yield from offscreens.draw_offscreen_steps(width, height, draws)
    return px[::-1].copy()


def _tile_draws(width: int, height: int, tile: int, draw: Callable[[], None]) -> list[Callable[[], None]]:
    """`draw` once per tile, each clipped to its tile and waited for."""

    def draw_tile(x: int, y: int) -> None:
        gpu.state.scissor_test_set(True)
        gpu.state.scissor_set(x, y, min(tile, width - x), min(tile, height - y))
        draw()
        _finish_tile(x, y)
        gpu.state.scissor_test_set(False)

    return [functools.partial(draw_tile, x, y) for y in range(0, height, tile) for x in range(0, width, tile)]


def _finish_tile(x: int, y: int) -> None:
    """Wait for a tile's draw (one pixel read back). Blender's read-back holds Python's lock while it waits
    for the GPU, so a whole large frame waited for at once kept an interrupt's handler (core/interrupt.py)
    out for minutes on a software rasterizer; tile by tile, it runs within a tile's time."""
    gpu.state.active_framebuffer_get().read_color(x, y, 1, 1, 4, 0, "FLOAT")


def _tiled(stage: str, gpu_inputs: CloudGPU, values: dict, width: int, height: int, tile: int = TILE) -> np.ndarray:
    """A full-screen stage drawn in tiles into a float offscreen; its pixels, bottom row first."""
    draws = _tile_draws(width, height, tile, lambda: draw_stage(stage, gpu_inputs, values))
    return offscreens.run_steps(offscreens.draw_offscreen_steps(width, height, draws))


def render_panorama(gpu_inputs: CloudGPU, eye, width: int, height: int) -> np.ndarray:
    """The clouds around the point `eye` as an equirectangular image (premultiplied RGBA, bottom row first,
    in the layout of Blender's Environment Texture: core/sky.py)."""
    return _tiled("panorama", gpu_inputs, {"eye": (*eye[:3], 1.0)}, width, height)


def render_shadow(gpu_inputs: CloudGPU, origin, u, v, size: int) -> np.ndarray:
    """The clouds' transmittance towards the sun over the square `origin` +- u/2 +- v/2 (metres), size x size
    texels, bottom row first (v up): RGB the transmittance, A 1."""
    values = {"shadow_origin": (*origin[:3], 0.0), "shadow_u": (*u[:3], 0.0), "shadow_v": (*v[:3], 0.0)}
    return _tiled("shadow", gpu_inputs, values, size, size)


def render_split(gpu_inputs: CloudGPU, inv_view_proj, eye, hit_texture, width: int, height: int, tile: int = TILE):
    """F12's camera view split at the scene's first surface (shaders/nubis_split_frag.glsl): the clouds in
    front of it and those behind it, premultiplied RGBA (height, width, 4) each, bottom row first.
    `hit_texture` is the depth pre-pass's (render/depthpass.py) at this size."""
    targets = [
        offscreens._gpu_image(lambda: gpu.types.GPUTexture((width, height), format="RGBA32F"), width, height)
        for _ in range(2)
    ]
    fb = gpu.types.GPUFrameBuffer(color_slots=targets)
    values = {"inv_view_proj": inv_view_proj, "eye": tuple(eye)}
    draw = functools.partial(draw_stage, "split", gpu_inputs, values, samplers={"scene_hit": hit_texture})
    with fb.bind():
        fb.clear(color=(0.0, 0.0, 0.0, 0.0))
        gpu.state.blend_set("NONE")
        for tile_draw in _tile_draws(width, height, tile, draw):
            tile_draw()
        return tuple(offscreens.read_pixels(fb, width, height, slot) for slot in range(2))
