"""The real-time viewport's draw path: temporal upscaling and progressive convergence (docs/viewport.md).

One redraw marches one pixel of every 4x4 block (S15: "update 1 out of 16 pixels for each 4x4 pixel
block"; GDC22: a 2 ms render where the plain march took 16 ms) into a working buffer, then resolves a
full-resolution history from it and from the previous history, reprojected with the previous camera and
the clouds' own motion. While nothing changes the history converges: 16 redraws give every pixel its
sample, then jittered passes average in until the sample count the artist set, after which redraws only
upscale the history. Any change (camera, setting, field, frame) restarts the count.

The same code runs in the 3D viewport's draw handler (blender/live/viewport.py) and headless (the `preview`
and `benchmark` commands), so what the tests and benchmarks measure is what the artist gets.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import gpu
import mathutils
import numpy as np

from ..core import camera, march
from ..core.errors import NubisError
from ..core.state import CloudState
from . import engine, offscreens, uniforms

BLOCK = 4  # the working buffer holds one pixel of every BLOCK x BLOCK block
REDRAWS_PER_SAMPLE = BLOCK * BLOCK


@dataclass(frozen=True)
class View:
    """A view to draw: the ray matrix (camera.ray_inverse_view_projection), the eye (w = 1 for a
    perspective view, 0 for orthographic), the size in pixels, and how its depth buffer reads as distances
    (camera.depth_mapping; needed with a scene depth)."""

    inv_view_proj: tuple  # 4x4 rows
    eye: tuple[float, float, float, float]
    width: int
    height: int
    depth_map: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 0.0)
    axis: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 0.0)

    @classmethod
    def of(cls, inv_view_proj, eye, width: int, height: int, mapping=None) -> View:
        rows = tuple(tuple(float(x) for x in row) for row in np.asarray(inv_view_proj, dtype=np.float64))
        depth_map, axis = mapping if mapping is not None else ((0.0,) * 4, (0.0,) * 4)
        return cls(
            rows,
            tuple(float(e) for e in eye),
            int(width),
            int(height),
            tuple(float(v) for v in depth_map),
            tuple(float(v) for v in axis),
        )


def _matrix_block(m) -> np.ndarray:
    """A row-major 4x4 as std140 column-major floats."""
    return np.asarray(m, dtype=np.float32).reshape(4, 4).T.ravel()


def _mathutils(rows):
    return mathutils.Matrix(rows)


class TemporalViewport:
    """The history and working buffers of one view, and where it stands in converging."""

    def __init__(self) -> None:
        self._history: list[dict] = []  # two sets of colour / attr / flash textures, ping-pong
        self._work: dict = {}
        self._sizes = None
        self.redraw_index = 0  # counts every march, for the Bayer order
        self.since_change = 0  # marches since the last change
        self.samples = 8
        # Where this view starts in the jitter sequence: two views at different offsets are independent
        # estimates of the same converged image, and half their difference is its grain.
        self.first_pass = 0
        self._valid = False
        self._key = None
        self._time = None
        self._view_proj = None
        self._axis = (0.0, 0.0, 0.0, 0.0)  # the previous redraw's view axis (View.axis)
        self._dummy_depth = None
        self._scene = None  # the scene depth of the last redraw and its view, for the upscale
        self.last_restart_reason = ""

    # ---- buffers ------------------------------------------------------------------------------------------
    @staticmethod
    def sizes(view: View, resolution: float) -> tuple[tuple[int, int], tuple[int, int]]:
        """(history, working buffer) sizes for a view at a relative resolution."""
        hw = max(BLOCK, math.ceil(view.width * resolution))
        hh = max(BLOCK, math.ceil(view.height * resolution))
        return (hw, hh), (math.ceil(hw / BLOCK), math.ceil(hh / BLOCK))

    @staticmethod
    def memory_bytes(history: tuple[int, int], work: tuple[int, int]) -> int:
        """GPU memory of the buffers: colour and flash mask RGBA16F, distance RG32F, history twice."""
        per_pixel = 8 + 8 + 8
        return per_pixel * (2 * history[0] * history[1] + work[0] * work[1])

    def _allocate(self, history: tuple[int, int], work: tuple[int, int]) -> None:
        def target(size):
            tex = {
                "color": gpu.types.GPUTexture(size, format="RGBA16F"),
                "attr": gpu.types.GPUTexture(size, format="RG32F"),
                "flash": gpu.types.GPUTexture(size, format="RGBA16F"),
            }
            tex["fb"] = gpu.types.GPUFrameBuffer(color_slots=(tex["color"], tex["attr"], tex["flash"]))
            return tex

        self._history = [target(history), target(history)]
        self._work = target(work)
        self._sizes = (history, work)
        self._valid = False
        self.since_change = 0
        for t in self._history:
            with t["fb"].bind():
                t["fb"].clear(color=(0.0, 0.0, 0.0, 0.0))

    def _allocate_for(self, view: View, history: tuple[int, int], work: tuple[int, int]) -> None:
        """_allocate, or a NubisError with a size to try when the GPU refuses the buffers (Blender raises a
        plain RuntimeError, which would read as an internal fault)."""
        try:
            self._allocate(history, work)
        except Exception as err:
            self.free()
            mb = self.memory_bytes(history, work) / 2**20
            raise NubisError(
                f"the GPU could not hold the viewport's buffers for a {view.width}x{view.height} view "
                f"({mb:.0f} MB): draw it smaller, for example {max(4, view.width // 2)}x{max(4, view.height // 2)}, "
                f"or on a GPU with more memory ({err})"
            ) from None

    def free(self) -> None:
        self._history = []
        self._work = {}
        self._dummy_depth = None
        self._scene = None
        self._sizes = None
        self._valid = False
        self._key = None

    # ---- state --------------------------------------------------------------------------------------------
    def restart(self, reason: str = "requested") -> None:
        """Forget the convergence (the history stays, reprojected as after any change)."""
        self.since_change = 0
        self.last_restart_reason = reason

    @property
    def converged(self) -> bool:
        return self._valid and self.since_change >= REDRAWS_PER_SAMPLE * self.samples

    def _state_key(self, state: CloudState, clouds: engine.CloudGPU) -> tuple:
        """What the image depends on, but the camera and time (which reproject) and the flash
        intensities (which the flash mask applies at full rate without restarting)."""
        quiet = dataclasses.replace(
            state,
            jitter_pass=0,
            time=0.0,
            storms=tuple(dataclasses.replace(s, flash=0.0) for s in state.storms),
        )
        return (
            uniforms.pack(quiet).tobytes(),
            tuple(id(a) for a in (state.field_a, state.field_b, state.field_c)),
            clouds.field_revision,
            tuple(id(p.cloud.bricks) for p in state.vdb_clouds),
        )

    # ---- one redraw ---------------------------------------------------------------------------------------
    def redraw(
        self,
        clouds: engine.CloudGPU,
        state: CloudState,
        view: View,
        resolution: float = 1.0,
        samples: int = 8,
        depth=None,
        depth_key=None,
    ) -> bool:
        """March and resolve once, if the view is not converged yet. Returns whether it marched.
        `depth` is the scene's depth at the view's size (a float texture, 1 = nothing there), or None."""
        self.samples = max(1, int(samples))
        history_size, work_size = self.sizes(view, resolution)
        if self._sizes != (history_size, work_size):
            self._allocate_for(view, history_size, work_size)
        inv = np.array(view.inv_view_proj, dtype=np.float64)
        angle, size = camera.pixel_footprint(inv, history_size[0], history_size[1])
        state = dataclasses.replace(state, pixel_angle=angle, pixel_size=size)
        dt, prev_view_proj = self._follow(view, inv, state, clouds, depth_key)
        prev_axis, self._axis = self._axis if self._valid else view.axis, view.axis
        depth_tex = depth if depth is not None else self._no_depth()
        self._scene = (depth_tex, view) if depth is not None else None
        if self.converged:
            clouds.update(state)  # the upscale reads this frame's flash intensities from the block
            return False
        sample_pass = self.since_change // REDRAWS_PER_SAMPLE if self._valid else 0
        state = dataclasses.replace(state, jitter_pass=sample_pass + self.first_pass)
        clouds.update(state)
        bayer = self.redraw_index % REDRAWS_PER_SAMPLE
        offset = march.bayer_offset(bayer)
        defines = clouds.defines()
        scale = (view.width / history_size[0], view.height / history_size[1])
        block = np.concatenate(
            [
                _matrix_block(view.inv_view_proj),
                _matrix_block(prev_view_proj),
                np.asarray(view.eye, np.float32),
                np.array([*history_size, *work_size], np.float32),
                np.array([bayer, min(self.since_change, 1 << 20), 1.0 / (sample_pass + 1), dt], np.float32),
                np.array([1.0 if self._valid else 0.0, 0.0, *offset], np.float32),
                np.array([1.0 if depth is not None else 0.0, *scale, 0.0], np.float32),
                np.asarray(view.depth_map, np.float32),
                np.asarray(view.axis, np.float32),
                np.asarray(prev_axis, np.float32),
            ]
        ).astype(np.float32)
        temporal_ubo = gpu.types.GPUUniformBuf(block.tobytes())
        self._march(clouds, view, defines, offset, depth_tex, temporal_ubo)
        self._resolve(clouds, defines, temporal_ubo, depth_tex)
        self.redraw_index += 1
        self.since_change += 1
        self._valid = True
        return True

    def _follow(self, view: View, inv: np.ndarray, state: CloudState, clouds, depth_key) -> tuple[float, object]:
        """Restart the accumulation when the view, the settings, the depth or the time changed; returns the
        wind time since the last redraw and the previous view-projection (for reprojecting the history)."""
        key = (view.inv_view_proj, view.eye, self._state_key(state, clouds), depth_key)
        dt = 0.0
        prev_view_proj = self._view_proj
        if key != self._key:
            reasons = []
            if self._key is None or key[:2] != self._key[:2]:
                reasons.append("view")
            if self._key is not None and key[2] != self._key[2]:
                reasons.append("settings")
            if self._time is not None and state.time != self._time:
                dt = state.time - self._time
                reasons.append("time")
            self.restart("+".join(reasons) or "depth")
            self._key = key
        elif self._time is not None and state.time != self._time:
            dt = state.time - self._time
            self.restart("time")
        self._time = state.time
        view_proj = camera.forward_view_projection(inv)
        self._view_proj = view_proj
        return dt, (view_proj if prev_view_proj is None else prev_view_proj)

    def _no_depth(self):
        """A 1x1 depth of nothing drawn, bound where no scene depth is."""
        if self._dummy_depth is None:
            nothing = gpu.types.Buffer("FLOAT", 1, [1.0])
            self._dummy_depth = gpu.types.GPUTexture((1, 1), format="R32F", data=nothing)
        return self._dummy_depth

    def _march(self, clouds, view: View, defines, offset: tuple[float, float], depth_tex, temporal_ubo) -> None:
        """Step 1: march one pixel of every block into the working buffer, each up to the scene's surface
        where its depth is bound (T.scene says whether, and how its pixels scale to the history's)."""
        history_size, work_size = self._sizes
        with self._work["fb"].bind():
            gpu.state.blend_set("NONE")
            gpu.state.depth_test_set("NONE")
            gpu.state.viewport_set(0, 0, *work_size)
            sh = engine.shader("temporal_march", defines)
            clouds.bind(sh)
            sh.uniform_float("inv_view_proj", _mathutils(view.inv_view_proj))
            sh.uniform_float("eye", view.eye)
            block = (float(offset[0]), float(offset[1]), float(history_size[0]), float(history_size[1]))
            sh.uniform_float("block", block)
            sh.uniform_sampler("scene_depth", depth_tex)
            sh.uniform_block("T", temporal_ubo)
            engine.fullscreen_batch("temporal_march", defines).draw(sh)

    def _resolve(self, clouds, defines, temporal_ubo, depth_tex) -> None:
        """Step 2: resolve the new history from the working buffer and the previous history (`temporal_ubo`:
        the redraw's uniform block, shaders' T; `depth_tex` the scene's depth, or the 1x1 of nothing)."""
        history_size, _work_size = self._sizes
        src, dst = self._history
        with dst["fb"].bind():
            gpu.state.blend_set("NONE")
            gpu.state.viewport_set(0, 0, *history_size)
            sh = engine.shader("resolve", defines)
            clouds.bind(sh, cloud_inputs=False)
            sh.uniform_block("T", temporal_ubo)
            for name in ("color", "attr", "flash"):
                sh.uniform_sampler(f"work_{name}", self._work[name])
                sh.uniform_sampler(f"hist_{name}", src[name])
            sh.uniform_sampler("scene_depth", depth_tex)
            engine.fullscreen_batch("resolve", defines).draw(sh)
        self._history = [dst, src]

    # ---- showing it ---------------------------------------------------------------------------------------
    def upscale(self, clouds: engine.CloudGPU, blur: float = 1.0) -> None:
        """Draw the history over the bound framebuffer's viewport (premultiplied), flashes added: with the
        last redraw's scene depth, each pixel the clouds in front of what it shows."""
        if not self._history:
            return
        hist = self._history[0]
        hw, hh = self._sizes[0]
        defines = clouds.defines()
        sh = engine.shader("upscale", defines)
        clouds.bind(sh, cloud_inputs=False)
        sh.uniform_float("filter_size", (float(blur), 0.0, 1.0 / hw, 1.0 / hh))
        depth_tex, view = self._scene if self._scene is not None else (self._no_depth(), None)
        sh.uniform_float("scene", (1.0 if view is not None else 0.0, 0.0, 0.0, 0.0))
        sh.uniform_float("depth_map", view.depth_map if view is not None else (0.0, 0.0, 0.0, 0.0))
        sh.uniform_sampler("hist_color", hist["color"])
        sh.uniform_sampler("hist_flash", hist["flash"])
        sh.uniform_sampler("hist_attr", hist["attr"])
        sh.uniform_sampler("scene_depth", depth_tex)
        engine.fullscreen_batch("upscale", defines).draw(sh)

    def read_history(self) -> np.ndarray:
        """The history's colour, (h, w, 4) float, top row first (tests)."""
        hw, hh = self._sizes[0]
        with self._history[0]["fb"].bind():
            return offscreens.read_pixels(self._history[0]["fb"], hw, hh)[::-1].copy()

    def sync(self) -> None:
        """Wait for the GPU to finish this redraw (one pixel read back), for timing."""
        if self._history:
            with self._history[0]["fb"].bind():
                self._history[0]["fb"].read_color(0, 0, 1, 1, 4, 0, "FLOAT")


def render_view(tv: TemporalViewport, clouds: engine.CloudGPU, view: View, blur: float = 1.0) -> np.ndarray:
    """The upscaled view as premultiplied scene-linear RGBA (height, width, 4), top row first."""
    return offscreens.draw_offscreen(view.width, view.height, lambda: tv.upscale(clouds, blur))[::-1].copy()
