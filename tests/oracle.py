"""A numpy oracle of the cloud density (tests only, never a product path).

An independent port of `nubis_density` (shaders/nubis_density_lib.glsl; GPU Pro 7, GDC22) that the GPU
read-backs are compared against. The constants are not copied: they come from the same CloudState, the
same NoiseSet and the same uniform vectors (render/uniforms.member_values) the shader is fed, rounded to
float32 as the uniform block stores them.

Texture sampling follows the GL rules rather than an idealised continuous noise, because that is what
the shader actually reads:
* the noise volumes are 8-bit (value / 255), uploaded with one wrapped texel per axis (textures.py), and
  filtered trilinearly / bilinearly with texel centres at (i + 0.5) / size and clamp-to-edge;
* the data fields are float textures, bilinear with clamp-to-edge.
GL leaves the precision of that filtering to the implementation, and Mesa llvmpipe filters 8-bit textures
in 8-bit fixed point (off by up to 1.4 / 255 from the float filter): `unorm8_filter=True` reproduces it
bit for bit (see sample_linear); the tests pick the model that matches the GPU's own raw reads.
The positions the noise is read at are formed in float32 like the shader's, since an 8-bit filter
turns a one-ulp coordinate difference into a whole 8-bit step now and then; all other arithmetic is
float64, so what remains against the GPU is the GPU's float32 rounding.
"""

from __future__ import annotations

import itertools

import numpy as np

from nubis_addon.core.noise import FBM_WEIGHTS, NoiseSet, downsample2
from nubis_addon.core.state import CloudState
from nubis_addon.render.uniforms import layer_fields, member_values

_FBM = np.asarray(FBM_WEIGHTS, np.float64)


# ---- helpers of nubis_common_lib.glsl ------------------------------------------------------------


def clamp01(x):
    return np.clip(x, 0.0, 1.0)


def mix(a, b, t):
    return a + (b - a) * t


def fract(x):
    # GLSL fract: x - floor(x), in [0, 1) also for negative x (unlike np.fmod).
    return x - np.floor(x)


def remap(value, old_min, old_max, new_min, new_max):
    """GPU Pro 7, GDC22 and the Habr implementation agree: unclamped; a zero-width input range gives new_min,
    as the shader."""
    value, old_min, old_max, new_min, new_max = np.broadcast_arrays(
        *(np.asarray(a, np.float64) for a in (value, old_min, old_max, new_min, new_max))
    )
    span = old_max - old_min
    degenerate = np.abs(span) < 1e-8
    out = new_min + (value - old_min) / np.where(degenerate, 1.0, span) * (new_max - new_min)
    return np.where(degenerate, new_min, out)[()]


def altitude(p: np.ndarray, planet_radius: float) -> np.ndarray:
    """Height above the sphere of radius R centred at (0, 0, -R) (docs/sources.md#spherical-height-fraction)."""
    centre_dist = np.sqrt(p[:, 0] ** 2 + p[:, 1] ** 2 + (p[:, 2] + planet_radius) ** 2)
    # |p + c| - R without cancelling two 6e6 numbers: (|p + c|^2 - R^2) / (|p + c| + R).
    return (np.einsum("ij,ij->i", p, p) + 2.0 * planet_radius * p[:, 2]) / (centre_dist + planet_radius)


def tile_coords(coords: np.ndarray, padded_size: np.ndarray) -> np.ndarray:
    """A repeating coordinate on the padded texture layout (textures._pad_wrap): texel 0 is repeated at
    index N, so a clamped linear filter across the seam equals a REPEAT filter of the N-texel tile."""
    size = np.asarray(padded_size, coords.dtype)  # keep the caller's precision (float32 for the GPU's)
    n = size - 1.0
    return (fract(coords) * n + 0.5) / size


def sample_linear(tex: np.ndarray, coords: np.ndarray, unorm8: bool = False) -> np.ndarray:
    """GL linear filtering (no mipmaps) of `tex` at normalised `coords`, clamp-to-edge.

    `tex` is indexed like the arrays textures.py uploads: ([z,] y, x, channel), so texture axis s is
    the last spatial array axis. `coords` is (N, d) in texture order (s, t[, r]). Returns (N, channels).

    unorm8=False is the GL specification's filter (GL 4.6 section 8.14.2) in float, on `tex` / 255 when
    `tex` holds 8-bit integers. unorm8=True emulates a fixed-point sampler that filters 8-bit textures
    in 8 bits, as Mesa llvmpipe does: 8 bits of sub-texel weight (the coordinate x * 256 rounded, from
    float32 arithmetic), and every lerp stage rounded back to an 8-bit value, v0 + ((v1 - v0) * w + 128)
    >> 8. `tex` must then hold the 8-bit integers.
    """
    d = coords.shape[1]
    sizes = tex.shape[:d][::-1]  # texture order: width, height[, depth]
    lo, hi, weights = [], [], []
    for axis in range(d):
        if unorm8:
            c = coords[:, axis].astype(np.float32)
            x = c * np.float32(sizes[axis]) - np.float32(0.5)
            fixed = np.rint(x * np.float32(256.0)).astype(np.int64)
            i, w = fixed >> 8, fixed & 255
        else:
            # The filter footprint starts at u * size - 0.5: texel centres sit at (i + 0.5) / size.
            x = coords[:, axis].astype(np.float64) * sizes[axis] - 0.5
            i = np.floor(x)
            w = x - i
            i = i.astype(np.int64)
        lo.append(np.clip(i, 0, sizes[axis] - 1))
        hi.append(np.clip(i + 1, 0, sizes[axis] - 1))
        weights.append(w)

    def texel(corner: tuple[int, ...]) -> np.ndarray:
        index = tuple((hi[axis] if corner[axis] else lo[axis]) for axis in reversed(range(d)))
        return tex[index].astype(np.int64) if unorm8 else tex[index].astype(np.float64)

    def lerp(a: np.ndarray, b: np.ndarray, w: np.ndarray) -> np.ndarray:
        if unorm8:
            return a + (((b - a) * w[:, None] + 128) >> 8)
        return a + (b - a) * w[:, None]

    # Separable: lerp along s for every (t, r) corner, then along t, then along r.
    values = {corner: texel(corner) for corner in itertools.product((0, 1), repeat=d)}
    for axis in range(d):
        values = {
            rest: lerp(values[(0, *rest)], values[(1, *rest)], weights[axis])
            for rest in itertools.product((0, 1), repeat=d - axis - 1)
        }
    out = values[()]
    if unorm8 or np.issubdtype(tex.dtype, np.integer):
        return out.astype(np.float64) / 255.0
    return out


def _size(tex: np.ndarray, d: int) -> np.ndarray:
    """Texture size in texture order (width, height[, depth]), float32 like textureSize() in the shader."""
    return np.asarray(tex.shape[:d][::-1], np.float32)


def padded_texture(arr: np.ndarray, spatial_axes: int) -> np.ndarray:
    """The 8-bit texture as uploaded: one wrapped texel appended per spatial axis (textures._pad_wrap)."""
    pad = [(0, 1)] * spatial_axes + [(0, 0)]
    return np.pad(arr, pad, mode="wrap")


# ---- nubis_density_lib.glsl ----------------------------------------------------------------------------


def top_ramp_end(top_type):
    """The height fraction above which the profile of this top type is zero."""
    t = clamp01(np.asarray(top_type, np.float64))
    return np.where(t < 0.5, mix(0.20, 0.60, t * 2.0), mix(0.60, 1.00, t * 2.0 - 1.0))


def vertical_profile(h, top_type, bottom_type):
    """Trapezoids (docs/sources.md#vertical-profile), split into bottom x top ramps (GDC22)."""
    t = clamp01(np.asarray(top_type, np.float64))
    low_half = t < 0.5
    ramp_start = np.where(low_half, mix(0.10, 0.40, t * 2.0), mix(0.40, 0.70, t * 2.0 - 1.0))
    ramp_end = top_ramp_end(t)
    bottom_end = mix(0.05, 0.35, clamp01(bottom_type))
    bottom = clamp01(h / bottom_end)
    top = clamp01(remap(h, ramp_start, ramp_end, 1.0, 0.0))
    return bottom * top


def _vectors(state: CloudState) -> dict[str, tuple]:
    """The uniform block's named members, grouped into the vectors this oracle computes with."""
    m = member_values(state)

    def group(*names):
        return tuple(m[n] for n in names)

    # The first cloud layer's fields (render/uniforms.py, _LAYER_ROWS): the oracle draws one layer.
    L = layer_fields(state)[0]
    return {
        "layer": (m["layer_planet_radius"], L["bottom"], L["top"], m["layer_draw_radius"]),
        "shell": group("shell_bottom", "shell_top"),
        "field": group("field_origin_x", "field_origin_y", "field_size", "field_inv_size"),
        "draw": group("draw_center_x", "draw_center_y", "draw_fade"),
        "noise": tuple(L["noise"]),
        "wind": (*L["wind_dir"], L["wind_distance"], L["detail_speed"]),
        "wind2": (L["top_offset"], L["upward_bias"], m["time"]),
        "density": (m["density_sigma"], L["coverage"], L["erosion"], L["multiply_coverage"]),
        "clip_box": m["clip_box"],
    }


class DensityOracle:
    """`nubis_density(p, cheap=false, lod)` for a CloudState and NoiseSet, vectorised over points."""

    def __init__(self, state: CloudState, noise_set: NoiseSet, unorm8_filter: bool = False):
        if state.field_a is None or state.field_b is None:
            raise ValueError("the oracle needs the state's field A and B arrays")
        # The uniform block is float32: use exactly the values the shader sees.
        self.v32 = {k: np.asarray(vec, np.float32) for k, vec in _vectors(state).items()}
        self.v = {k: vec.astype(np.float64) for k, vec in self.v32.items()}
        # As textures.field_texture uploads them: float32, non-finite texels zeroed.
        self.field_a, self.field_b = (
            np.nan_to_num(f.astype(np.float32), nan=0.0, posinf=0.0, neginf=0.0).astype(np.float64)
            for f in (state.field_a, state.field_b)
        )
        self.unorm8 = unorm8_filter  # see sample_linear: how the GPU filters the 8-bit noise
        self.lf = padded_texture(noise_set.lf, 3)
        # textures.py: the half-resolution copy is the 2-texel box filter, rounded back to 8 bits.
        lf_mip1 = np.round(downsample2(noise_set.lf.astype(np.float32))).astype(np.uint8)
        self.lf_mip1 = padded_texture(lf_mip1, 3)
        self.hf = padded_texture(noise_set.hf, 3)
        self.curl = padded_texture(noise_set.curl, 2)

    def sample_fields(self, xy: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(field A, field B, inside) at world xy (N, 2), as nubis_sample_field."""
        field, draw, layer = self.v["field"], self.v["draw"], self.v["layer"]
        uv = (xy - field[:2]) * field[3] + 0.5
        a = sample_linear(self.field_a, clamp01(uv))
        b = sample_linear(self.field_b, clamp01(uv))
        # Nothing outside the painted field, and the draw-radius fade (S15; docs/sources.md#draw-radius-fade).
        edge = np.minimum(uv, 1.0 - uv) * field[2]
        fade = max(draw[2], 1.0)
        in_field = clamp01(np.minimum(edge[:, 0], edge[:, 1]) / fade)
        dist = np.hypot(xy[:, 0] - draw[0], xy[:, 1] - draw[1])
        in_radius = clamp01((layer[3] - dist) / fade)
        inside = in_field * in_radius
        # The optional clip box (x0, y0, x1, y1; off when x1 < x0): nothing outside it.
        clip = self.v.get("clip_box")
        if clip is not None and clip[2] >= clip[0]:
            outside = np.any(xy < clip[:2], axis=1) | np.any(xy > clip[2:], axis=1)
            inside = np.where(outside, 0.0, inside)
        return a, b, inside

    def coverage(self, xy: np.ndarray) -> np.ndarray:
        """The effective coverage the density uses at world xy: field x multiplier x inside fade."""
        a, _b, inside = self.sample_fields(np.asarray(xy, np.float64))
        return clamp01(a[:, 0] * self.v["density"][1]) * inside

    def density(self, points: np.ndarray, lod: int = 0) -> np.ndarray:
        """(fine, coarse, height fraction) at world points (N, 3): (N, 3) float64."""
        p = np.asarray(points, np.float64)
        v = self.v
        layer, dens = v["layer"], v["density"]
        n = p.shape[0]

        alt = altitude(p, layer[0])
        in_shell = (alt >= v["shell"][0]) & (alt <= v["shell"][1])
        a, b, inside = self.sample_fields(p[:, :2])
        # The height fraction on the spherical shell, with the min/max height field (GDC22).
        thickness = layer[2] - layer[1]
        lo = layer[1] + b[:, 1] * thickness
        hi = layer[1] + b[:, 2] * thickness
        h = (alt - lo) / np.maximum(hi - lo, 1.0)
        coverage = clamp01(a[:, 0] * dens[1]) * inside
        profile = vertical_profile(h, a[:, 2], a[:, 3])
        live = in_shell & (h > 0.0) & (h < 1.0) & (coverage > 0.0) & (profile > 0.0)

        # The noise is read at positions the GPU forms in float32, and an 8-bit filter (sample_linear) turns a
        # one-ulp difference in a coordinate into a whole 1/255 step now and then: the positions are built
        # here in float32 with the shader's operations, everything else is float64.
        f = self.v32
        p32, h32 = p.astype(np.float32), h.astype(np.float32)
        # GPU Pro 7 skew and drift, GDC22 sign (docs/sources.md#wind-direction-and-sign): offsets are subtracted
        # so features move downwind; the field sample above uses the unmoved p (GDC22).
        wind_dir = np.array([f["wind"][0], f["wind"][1], 0.0], np.float32)
        drift = (wind_dir + np.array([0.0, 0.0, f["wind2"][1]], np.float32)) * f["wind"][2]
        skewed = p32 - h32[:, None] * wind_dir * f["wind2"][0]
        p_lf = skewed - drift

        lf_tex = self.lf if lod < 1 else self.lf_mip1
        lf = sample_linear(lf_tex, tile_coords(p_lf / f["noise"][0], _size(lf_tex, 3)), self.unorm8)
        lf_fbm = lf[:, 1:4] @ _FBM
        # GPU Pro 7: Worley fBm dilates the Perlin-Worley base shape, then the profile.
        base = remap(lf[:, 0], -(1.0 - lf_fbm), 1.0, 0.0, 1.0) * profile
        # GDC22's 1 - coverage, GPU Pro 7's optional multiply by coverage (docs/sources.md#coverage-erosion).
        with_coverage = clamp01(remap(base, 1.0 - coverage, 1.0, 0.0, 1.0))
        with_coverage = with_coverage * mix(1.0, coverage, dens[3])
        multiplier = np.maximum(b[:, 3], 0.0)
        coarse = with_coverage * multiplier

        # GPU Pro 7: curl noise displaces the detail at the base, (1 - h) weighted.
        p_hf = skewed - drift * f["wind"][3]
        curl = sample_linear(self.curl, tile_coords(p_hf[:, :2] / f["noise"][2], _size(self.curl, 2)), self.unorm8)
        curl32 = curl[:, :2].astype(np.float32) * 2.0 - 1.0
        p_hf[:, :2] += curl32 * (1.0 - h32)[:, None] * f["noise"][3]
        hf = sample_linear(self.hf, tile_coords(p_hf / f["noise"][1], _size(self.hf, 3)), self.unorm8)
        hf_fbm = hf[:, :3] @ _FBM
        # GPU Pro 7: wispy at the base, billowy above the lowest 10 % (a rising bottom type raises that).
        billow = clamp01(h * mix(10.0, 2.0, clamp01(a[:, 3])))
        hf_modifier = mix(hf_fbm, 1.0 - hf_fbm, billow)
        eroded = clamp01(remap(with_coverage, hf_modifier * dens[2], 1.0, 0.0, 1.0))
        fine = np.where(with_coverage <= 0.0, coarse, eroded * multiplier)

        out = np.zeros((n, 3), np.float64)
        out[:, 0] = np.where(live, fine, 0.0)
        out[:, 1] = np.where(live, coarse, 0.0)
        out[:, 2] = np.where(in_shell, clamp01(h), 0.0)
        return out
