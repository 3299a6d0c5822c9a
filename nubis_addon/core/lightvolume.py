"""The optical-depth volumes of the real-time lighting (docs/viewport.md#light-volumes).

Each volume is a box of texels laid out along a direction: texel (i, j, k) holds the optical depth from
its point towards the direction until the cloud domain ends. The sun's volume gives every lit sample
the whole depth of the layer towards the sun beyond the cone of the light march (the Beer shadow maps
of real-time cloud renderers, here with depth slices instead of a fitted curve); the sky's volume,
laid out upwards, gives the depth of cloud above and below each point for the sky light.

The box is fitted around the cloud domain: the draw radius' square around its centre (or a
comparison's baked box) between the cloud shell's floor, lowered by the planet's curvature at the
radius, and its top, seen along the direction. This module computes the maps between world space and
the volume's unit cube; the GPU fills and reads it (shaders/nubis_light_volume_comp.glsl,
shaders/nubis_lighting_lib.glsl).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

# Texels across the box (u, v) and depth slices along the direction, as half floats: 4 MB a channel, the
# sun's volume one, the sky's two (12 MB; with the noise texture set's 10.3 MiB a little over the 20 MB GPU
# Pro 7 spent on all of its cloud textures: docs/viewport.md#sideways says why). 128 texels across left a
# superstorm's towers narrower than a texel (570 m in its comparison's box): the interpolation lent their
# flanks the core's optical depth, and the real-time light read 11 % darker than the reference march; 256
# across, 3.6 % (docs/viewport.md#light-volumes). Half floats hold optical depths to a few parts in ten
# thousand, far finer than the light can show.
SIZE = (256, 256, 32)
FORMAT = "R16F"
# The sky's volume holds a second channel, the optical depth sideways to the open sky.
SKY_FORMAT = "RG16F"
BYTES_PER_TEXEL = 2
# Density samples per depth slice when the volume is filled (each slice's depth is the midpoint sum).
STEPS_PER_SLICE = 4
# The box's centre moves in steps of this share of the draw radius.
SNAP = 0.125
# A direction this close to vertical builds its frame on the x axis.
NEAR_VERTICAL = 0.999


@dataclass(frozen=True)
class Volume:
    """A box along a direction: point = origin + x * axes[0] + y * axes[1] + z * axes[2] for x, y, z in
    [0, 1]; z runs from the side the direction points to (the sun) away from it."""

    origin: np.ndarray  # (3,)
    axes: np.ndarray  # (3, 3): the box's edges, rows

    def to_unit(self) -> np.ndarray:
        """(3, 4): rows (a, b) with unit coordinate i = a . p + b, for the shaders."""
        inv = np.linalg.inv(self.axes.T)
        return np.concatenate([inv, (-inv @ self.origin)[:, None]], axis=1)

    def point(self, unit) -> np.ndarray:
        return self.origin + np.asarray(unit, np.float64) @ self.axes


def _domain_corners(centre, half: tuple[float, float], bottom: float, top: float) -> np.ndarray:
    cx, cy = centre
    hx, hy = half
    return np.array([(cx + sx * hx, cy + sy * hy, z) for sx in (-1, 1) for sy in (-1, 1) for z in (bottom, top)])


def domain(state) -> tuple[tuple[float, float], tuple[float, float], float, float]:
    """The clouds' box: centre (x, y), half extents (x, y), lowest and highest z."""
    p = state.params
    radius = float(p["layer_draw_radius"])
    bottom, top = state.shell()
    planet = float(p["layer_planet_radius"])
    if state.clip_box is not None and state.clip_box[2] >= state.clip_box[0]:
        x0, y0, x1, y1 = state.clip_box
        centre = ((x0 + x1) / 2.0, (y0 + y1) / 2.0)
        half = ((x1 - x0) / 2.0, (y1 - y0) / 2.0)
    else:
        # The draw radius follows the camera; the volume's box follows it in steps of SNAP radii (with
        # that much margin), so a moving camera does not refill the volumes at every redraw.
        grid = SNAP * radius
        centre = tuple(float(round(c / grid) * grid) for c in state.draw_center[:2])
        half = (radius * (1.0 + SNAP), radius * (1.0 + SNAP))
    # z = altitude - r^2 / (2 R) near the surface, r from the world's origin (nubis_altitude): the shell's
    # floor is lower at the box's far corner. The box then depends on the snapped centre alone, so the
    # map the shaders read stays the one the volumes were filled with while the camera moves.
    reach = float(np.hypot(abs(centre[0]) + half[0], abs(centre[1]) + half[1]))
    sag = reach * reach / (2.0 * planet) if planet > 0.0 else 0.0
    return centre, half, float(bottom) - sag, float(top)


# Above this sine of its elevation the light's volume is sliced by altitude (`_layered`); a lower light
# (within 5 degrees of the horizon, or below it) takes a box around the domain along its direction.
LAYERED_MIN_SIN = 0.087


def volume(direction, state) -> Volume:
    """The volume around the cloud domain laid out along `direction` (towards the light)."""
    s = np.asarray(direction, np.float64)
    s = s / np.linalg.norm(s)
    if s[2] > LAYERED_MIN_SIN:
        return _layered(s, state)
    helper = np.array([1.0, 0.0, 0.0]) if abs(s[2]) > NEAR_VERTICAL else np.array([0.0, 0.0, 1.0])
    u = np.cross(helper, s)
    u /= np.linalg.norm(u)
    v = np.cross(s, u)
    centre, half, bottom, top = domain(state)
    corners = _domain_corners(centre, half, bottom, top)
    cu, cv, cs = corners @ u, corners @ v, corners @ s
    # z = 0 on the side towards the light (the largest s), 1 on the far side; at least a metre deep.
    extent = [max(float(c.max() - c.min()), 1.0) for c in (cu, cv, cs)]
    origin = u * cu.min() + v * cv.min() + s * cs.max()
    axes = np.array([u * extent[0], v * extent[1], -s * extent[2]])
    return Volume(origin, axes)


def _layered(s: np.ndarray, state) -> Volume:
    """A parallelepiped whose depth slices are altitudes: its top face is the domain's top, its columns
    run from there against the light down to the domain's floor. A box along the light's direction
    would spread its 32 slices over the whole domain's length seen along the sun (70 km for a stratus
    deck under a 30 degree sun, 2 km a slice), and interpolating the optical depth across the deck's
    sunlit face overestimated it there (the real-time light read 10-15 % darker than the reference
    march); sliced by altitude the same deck gets 85 m a slice."""
    centre, half, bottom, top = domain(state)
    w = -s * ((top - bottom) / s[2])  # from the top face down to the floor, away from the light
    # A point on the floor at (x, y) is reached by the column starting at (x, y) - w_xy on the top face.
    lo = [min(centre[i] - half[i], centre[i] - half[i] - w[i]) for i in (0, 1)]
    hi = [max(centre[i] + half[i], centre[i] + half[i] - w[i]) for i in (0, 1)]
    origin = np.array([lo[0], lo[1], top])
    axes = np.array([[hi[0] - lo[0], 0.0, 0.0], [0.0, hi[1] - lo[1], 0.0], w])
    return Volume(origin, axes)


def sun_volume(state) -> Volume:
    return volume(state.sun_direction, state)


def sky_volume(state) -> Volume:
    return volume((0.0, 0.0, 1.0), state)


# The volumes are refilled once the wind has carried the noise this share of a texel (a quarter of the
# 128-texel volumes' texel they replaced, so playback refills no more often): the coverage field,
# which places the clouds, does not move with the wind (only the noises drift through it), so between
# refills the volumes hold the same clouds, their detail up to this drift out of date.
REFILL_DRIFT = 0.5


def refill_time(state) -> float:
    """The time the volumes hold for `state`: its time rounded down to the step in which the wind carries
    the noise REFILL_DRIFT of a texel (the faster of the two noises). A still wind refills only on edits."""
    p = state.params
    speed = abs(float(p["wind_speed"])) * max(1.0, abs(float(p.get("wind_detail_speed", 1.0))))
    _centre, half, _bottom, _top = domain(state)
    texel = 2.0 * max(half) / SIZE[0]
    if speed <= 0.0:
        return 0.0
    step = REFILL_DRIFT * texel / speed
    return float(np.floor(state.time / step) * step)


# Settings the volumes' contents do not depend on: the lighting terms applied when they are read (rain's
# absorption is not among them: the volumes hold it).
def lighting_only(key: str) -> bool:
    return key.startswith("lighting_") and key != "lighting_rain_absorption"


def key_centre(state) -> tuple[float, float]:
    """The draw centre as the volumes see it (snapped), for deciding when to refill them."""
    return domain(state)[0]


def memory_bytes() -> int:
    """GPU memory of the two volumes: the sun's one channel, the sky's two (a fill holds one more channel's
    worth for a moment, the sky's depths before the sideways pass)."""
    return 3 * BYTES_PER_TEXEL * SIZE[0] * SIZE[1] * SIZE[2]


def side_scale(box: Volume) -> tuple[float, float, float, float]:
    """The sky volume's texel widths across (u, v) and its depth slices' thickness, in metres, for the
    pass that adds the sideways depths (shaders/nubis_sky_side_comp.glsl)."""
    widths = [float(np.linalg.norm(box.axes[i])) / max(SIZE[i] - 1, 1) for i in range(3)]
    return (widths[0], widths[1], max(widths[2], 1e-3), 0.0)


# How far the sideways depths reach, in texels of the sky volume (the last of the pass's steps).
SIDE_REACH_TEXELS = 24


def side_reach(state) -> float:
    """How far the sky volume's sideways depths reach, in metres (the reference march marches as far)."""
    scale = side_scale(sky_volume(state))
    return SIDE_REACH_TEXELS * 0.5 * (scale[0] + scale[1])
