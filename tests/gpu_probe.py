"""Read the cloud density back from the GPU at arbitrary world points: a test instrument, not shipped.

The probe stage (tests/shaders/nubis_probe_frag.glsl) runs the shared `nubis_density` once per texel of a
float texture of points, so tests can compare the exact shader the viewport and the bake use against an
independent implementation.
"""

from __future__ import annotations

from pathlib import Path

import gpu
import numpy as np

from nubis_addon.render.engine import STAGES, CloudGPU, Stage, draw_stage
from nubis_addon.render.offscreens import draw_offscreen

# Registered by the tests: the extension ships no probe, and a stage only compiles when asked for.
_FRAGMENT = str(Path(__file__).resolve().parent / "shaders" / "nubis_probe_frag.glsl")
STAGES.setdefault("probe", Stage((("VEC4", "probe_mode"),), (("FLOAT_2D", "probe_points"),), fragment=_FRAGMENT))

MAX_WIDTH = 1024  # texels per row of the point texture; rows grow as needed
_MODE_DENSITY = 0.0
_MODE_REMAP = 1.0
_MODE_NOISE = 2.0
_MODE_VORTEX = 3.0
_MODE_GLOW = 4.0
_MODE_SLAB = 5.0
_MODE_DIFFUSION = 6.0
_MODE_SKY_WEIGHTS = 7.0
_MODE_REACH = 8.0
_MODE_SUN = 9.0
NOISE_TEXTURES = {"lf": 0.0, "hf": 1.0, "curl": 2.0}


def probe_density(gpu_inputs: CloudGPU, points: np.ndarray, cheap: bool = False) -> np.ndarray:
    """(fine, coarse, height fraction) of the shader's density at `points` (N, 3) world metres: (N, 3) float32.
    `cheap` takes the cheap sample (no detail fetch) the light march takes in opaque cloud.

    The points reach the GPU as float32; pass the same float32 values to anything compared with the result.
    """
    pts = np.asarray(points, dtype=np.float32)
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise ValueError(f"points must have shape (N, 3), not {pts.shape}")
    texels = np.zeros((len(pts), 4), np.float32)
    texels[:, :3] = pts
    return _run(gpu_inputs, texels, (_MODE_DENSITY, float(cheap), 0.0, 0.0))[:, :3]


def probe_remap(gpu_inputs: CloudGPU, args: np.ndarray) -> np.ndarray:
    """The shader's own `remap(value, old_min, old_max, new_min, new_max)` for each row of `args` (N, 5).

    The first four arguments travel per texel; new_max is a push constant, so it must be the same for
    every row.
    """
    a = np.asarray(args, dtype=np.float32)
    if a.ndim != 2 or a.shape[1] != 5:
        raise ValueError(f"args must have shape (N, 5), not {a.shape}")
    if len(a) and np.any(a[:, 4] != a[0, 4]):
        raise ValueError("probe_remap takes one new_max for all rows")
    new_max = float(a[0, 4]) if len(a) else 0.0
    return _run(gpu_inputs, np.ascontiguousarray(a[:, :4]), (_MODE_REMAP, new_max, 0.0, 0.0))[:, 0]


def probe_noise(gpu_inputs: CloudGPU, which: str, coords: np.ndarray) -> np.ndarray:
    """The GPU's filtered read (RGBA) of the padded noise texture `which` ("lf", "hf" or "curl") at
    normalised texture coordinates `coords` (N, 3), or (N, 2) for the 2D curl texture: (N, 4) float32.

    No tiling is applied: this observes the sampler itself (filtering precision, texel centres, edges).
    """
    if which not in NOISE_TEXTURES:
        raise ValueError(f"which must be one of {sorted(NOISE_TEXTURES)}, not {which!r}")
    c = np.asarray(coords, dtype=np.float32)
    if c.ndim != 2 or c.shape[1] not in (2, 3):
        raise ValueError(f"coords must have shape (N, 2) or (N, 3), not {c.shape}")
    texels = np.zeros((len(c), 4), np.float32)
    texels[:, : c.shape[1]] = c
    return _run(gpu_inputs, texels, (_MODE_NOISE, NOISE_TEXTURES[which], 0.0, 0.0))


def probe_vortex(gpu_inputs: CloudGPU, xy: np.ndarray) -> np.ndarray:
    """Where the superstorm vortex moves the detail-noise sample at world `xy` (N, 2): (N, 4) holding the
    moved xy and the neighbouring ring's xy (equal outside ring overlaps)."""
    p = np.asarray(xy, dtype=np.float32)
    texels = np.zeros((len(p), 4), np.float32)
    texels[:, :2] = p
    return _run(gpu_inputs, texels, (_MODE_VORTEX, 0.0, 0.0, 0.0))


def probe_glow(gpu_inputs: CloudGPU, points: np.ndarray, fine_density: float = 0.0) -> np.ndarray:
    """The storms' glow radiance (rgb) at world `points` (N, 3) for a given fine density: (N, 3)."""
    p = np.asarray(points, dtype=np.float32)
    texels = np.zeros((len(p), 4), np.float32)
    texels[:, :3] = p
    texels[:, 3] = fine_density
    return _run(gpu_inputs, texels, (_MODE_GLOW, 0.0, 0.0, 0.0))[:, :3]


def probe_slab(gpu_inputs: CloudGPU, args: np.ndarray) -> np.ndarray:
    """A cirrus slab's light per unit of the sun's irradiance for each row (view cosine, sun cosine,
    vertical optical depth) of `args` (N, 3): (N, 2) holding its multiple and its single scattering."""
    return probe_slab_shape(gpu_inputs, args)[:, :2]


def probe_slab_shape(gpu_inputs: CloudGPU, args: np.ndarray) -> np.ndarray:
    """probe_slab plus a third column, the angular shape of the slab's diffuse light towards the viewer
    (nubis_slab_exit_shape); a fourth column in `args` of 1 lights the face away from the viewer."""
    a = np.asarray(args, dtype=np.float32)
    texels = np.zeros((len(a), 4), np.float32)
    texels[:, : a.shape[1]] = a
    return _run(gpu_inputs, texels, (_MODE_SLAB, 0.0, 0.0, 0.0))[:, :3]


def probe_diffusion(gpu_inputs: CloudGPU, args: np.ndarray, kappa: float) -> np.ndarray:
    """The sky light's slab diffusion for each row (near, far, rate, edge) of `args` (N, 4) at decay
    rate `kappa`, and the decay rate for (albedo, g) read from the first two columns: (N, 2)."""
    return _run(gpu_inputs, np.asarray(args, dtype=np.float32), (_MODE_DIFFUSION, float(kappa), 0.0, 0.0))[:, :2]


def probe_sky_weights(gpu_inputs: CloudGPU, args: np.ndarray) -> np.ndarray:
    """A slab's weights of the diffuse light from its far and its near face, as the viewer sees them, for
    each row (view cosine, vertical optical depth, rate, edge) of `args` (N, 4), and the chance that light
    scattered in it leaves unscattered: (N, 3)."""
    return _run(gpu_inputs, np.asarray(args, dtype=np.float32), (_MODE_SKY_WEIGHTS, 0.0, 0.0, 0.0))[:, :3]


def probe_reach(gpu_inputs: CloudGPU) -> np.ndarray:
    """The altitude at which the view march ends each of the four cloud layers (nubis_layer_reach): (4,)."""
    return _run(gpu_inputs, np.zeros((1, 4), np.float32), (_MODE_REACH, 0.0, 0.0, 0.0))[0]


def probe_sun(gpu_inputs: CloudGPU, points: np.ndarray) -> np.ndarray:
    """The sun's light arriving at `points` (N, 3) world metres (nubis_sun_at): (N, 3)."""
    texels = np.zeros((len(points), 4), np.float32)
    texels[:, :3] = np.asarray(points, np.float32)
    return _run(gpu_inputs, texels, (_MODE_SUN, 0.0, 0.0, 0.0))[:, :3]


def _run(gpu_inputs: CloudGPU, texels: np.ndarray, mode: tuple[float, float, float, float]) -> np.ndarray:
    n = len(texels)
    if n == 0:
        return np.zeros((0, 4), np.float32)
    width = min(n, MAX_WIDTH)
    height = -(-n // width)
    data = np.zeros((height * width, 4), np.float32)
    data[:n] = texels
    # Row 0 of the texture is the first `width` points and also the bottom framebuffer row, which
    # read_pixels returns first: texel and pixel indices coincide.
    buf = gpu.types.Buffer("FLOAT", data.size, data.ravel())
    tex = gpu.types.GPUTexture((width, height), format="RGBA32F", data=buf)
    out = draw_offscreen(
        width,
        height,
        lambda: draw_stage("probe", gpu_inputs, {"probe_mode": mode}, samplers={"probe_points": tex}),
    )
    return out.reshape(-1, 4)[:n]
