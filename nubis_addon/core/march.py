"""Per-frame constants of the ray march, computed once on the CPU instead of at every sample.

The light march of GPU Pro 7 and S15 takes a few samples in a cone widening towards the sun plus one
long-distance sample; the offsets of those taps depend only on the sun and the settings, so they
travel in the uniform block (``light_taps``) rather than being rebuilt per sample in the shader.
"""

from __future__ import annotations

import numpy as np

MAX_LIGHT_TAPS = 16
# The cone's reach in light steps (GPU Pro 7: five steps) and the long sample at three times it.
CONE_STEPS = 5.0
LONG_REACH = 3.0

# Six random offsets in [-1, 1]^3 that widen the light march into a cone: GPU Pro 7 uses six but does not
# print them, so these are the project's own (docs/sources.md#light-march).
_CONE_KERNEL = np.array(
    [
        (0.38051305, 0.92453449, -0.02111345),
        (-0.50625799, -0.03590792, -0.86163418),
        (-0.32509218, -0.94557439, 0.01428793),
        (0.09026238, -0.27376545, 0.95755165),
        (0.28128598, 0.42443639, -0.86065785),
        (-0.16852403, 0.14748697, 0.97460106),
    ]
)


def cone_kernel(count: int) -> np.ndarray:
    """`count` unit offsets: GPU Pro 7's six first, then directions of our own (a fixed seed), so a
    quality with more light samples keeps the first taps where the standard quality has them."""
    if count <= len(_CONE_KERNEL):
        return _CONE_KERNEL[:count]
    extra = np.random.default_rng(7).normal(size=(count - len(_CONE_KERNEL), 3))
    extra /= np.linalg.norm(extra, axis=1, keepdims=True)
    return np.concatenate([_CONE_KERNEL, extra])


def light_taps(sun_direction, light_step: float, samples: int) -> np.ndarray:
    """(samples, 4) float64: each tap's offset from the lit point (xyz metres) and the length of the
    path it stands for (w). The last tap is the long-distance sample; the cone's reach stays five
    light steps whatever the sample count, so more samples refine the same shadow rather than
    reaching further (GDC22's 6 and 10 light samples then differ in precision, not in look)."""
    if not 2 <= samples <= MAX_LIGHT_TAPS:
        raise ValueError(f"light samples must be between 2 and {MAX_LIGHT_TAPS}, not {samples}")
    sun = np.asarray(sun_direction, np.float64)
    sun = sun / max(float(np.linalg.norm(sun)), 1e-12)
    cone = samples - 1
    reach = CONE_STEPS * light_step
    step = reach / cone
    i = np.arange(cone, dtype=np.float64)
    offsets = sun[None, :] * (step * (i + 0.5))[:, None] + cone_kernel(cone) * (step * i * 0.5)[:, None]
    taps = np.zeros((samples, 4))
    taps[:cone, :3] = offsets
    taps[:cone, 3] = step
    taps[cone, :3] = sun * (LONG_REACH * reach)
    taps[cone, 3] = (LONG_REACH - 1.0) * reach
    return taps


# The order in which the temporal upscaler marches the 16 pixels of each 4x4 block (the 4x4 Bayer
# matrix, as nubis_bayer4 in shaders/nubis_common_lib.glsl): BAYER4[y][x] is the redraw index of (x, y).
BAYER4 = ((0, 8, 2, 10), (12, 4, 14, 6), (3, 11, 1, 9), (15, 7, 13, 5))


def bayer_offset(index: int) -> tuple[int, int]:
    """The (x, y) pixel of a 4x4 block marched on redraw `index` (mod 16)."""
    index %= 16
    for y, row in enumerate(BAYER4):
        if index in row:
            return row.index(index), y
    raise AssertionError("BAYER4 is a permutation of 0-15")


# Mesa's llvmpipe stops a shader's loops after 65535 iterations in total (its loop limiter), which cut
# long marches short without a word. What one view step costs in loop iterations, with n storms
# (each density call turns through n vortices, each extinction call darkens by n storms, and the
# storm glow, flash and ambient loop over them once per lit step):
#   any step          1 + n                       (the view loop and its density call)
#   a lit step adds   8 + 4n + the light march    (octaves; extinction, glow, flash, ambient)
#   real-time light   taps x (1 + 2n)
#   reference light   48 x (1 + 2n), and the sky: 12 x (1 + 16 x (1 + 2n)) (single scattering's, mode 1)
#                     or the column up and down: 2 x 24 x (1 + 2n), and sideways: 8 x (1 + 4 x (1 + 2n))
#                     (the full model's, mode 2)
LOOP_LIMIT = 65535
_MARGIN = 512  # per-ray set-up, the octaves' phases, the cirrus


def iterations_per_step(light_taps: int, storms: int, reference: int, vdb: int = 0) -> int:
    """`reference` is the light mode: 0 real time, 1 or 2 a reference march (core/state.py); `vdb` the VDB
    clouds drawn, each density sample turning through them once (shaders/nubis_vdb_lib.glsl)."""
    n = int(storms)
    per_sample = 1 + 2 * n + int(vdb)
    if reference == 2:
        light = (48 + 2 * 24) * per_sample + 8 * (1 + 4 * per_sample)
    elif reference:
        light = 48 * per_sample + 12 * (1 + 16 * per_sample)
    else:
        light = int(light_taps) * per_sample
    return (1 + n + int(vdb)) + (8 + 4 * n + light)


def max_steps(light_taps: int, storms: int, reference: int, vdb: int = 0) -> int:
    """The most view steps a march can take within the loop limit, every step lit. Beyond it the march
    takes longer steps (the ray still ends where it should) rather than being cut short."""
    return max(8, (LOOP_LIMIT - _MARGIN) // iterations_per_step(light_taps, storms, reference, vdb))
