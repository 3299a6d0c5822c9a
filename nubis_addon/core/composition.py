"""F12's depth composition, the maths (no bpy): how far the frame is widened for the pixel filter and
the shutter, where the veil of the clouds in front of the objects stands, and the stack of shadow
casters through the cloud layer (docs/sky.md#objects-in-the-clouds)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import camera

# Pixels the veil reaches past the frame on every side without motion blur: the engines' pixel filters
# (1.5 px wide by default) take samples up to this far outside a pixel.
FILTER_MARGIN = 4
# The veil stands this share of the nearest surface's distance in front of it.
VEIL_CLEARANCE = 0.98
# Shadow casters through the layer: at most this many, at least this far apart (metres).
MAX_CASTERS = 12
MIN_CASTER_SPACING = 100.0
# A transmittance this low is opaque: the slab beneath it is not resolved from the ratio of the two.
OPAQUE = 1e-4


@dataclass(frozen=True)
class Frame:
    """The widened frame the veil covers: the render's size plus `margin` pixels on every side, and the
    inverse view-projection of the widened frame (rays in float64, core/camera.py)."""

    width: int
    height: int
    margin: int
    inv_view_proj: np.ndarray

    @property
    def size(self) -> tuple[int, int]:
        return self.width + 2 * self.margin, self.height + 2 * self.margin


def widened(inv_view_proj, width: int, height: int, margin: int) -> Frame:
    """The camera's frame widened by `margin` pixels on every side: the same rays for the pixels it shares
    with the frame, and more of them around it."""
    scale = np.diag([(width + 2.0 * margin) / width, (height + 2.0 * margin) / height, 1.0, 1.0])
    inv = np.asarray(inv_view_proj, dtype=np.float64).reshape(4, 4) @ scale
    return Frame(width, height, margin, inv)


def blur_margin(centre_inv, shutter_invs, width: int, height: int, limit: int) -> int:
    """Pixels the shutter's cameras see beyond the frame's edge, as the frame's centre camera images them:
    the veil is made that much wider so that every ray of a motion-blurred frame meets it. At most
    `limit` (a wider pan keeps a band of its motion unveiled at the frame's edges: docs/limits.md)."""
    forward = camera.forward_view_projection(centre_inv)
    worst = 0.0
    ndc = [(x, y) for x in (-1.0, 0.0, 1.0) for y in (-1.0, 0.0, 1.0) if (x, y) != (0.0, 0.0)]
    for inv in shutter_invs:
        inv = np.asarray(inv, dtype=np.float64).reshape(4, 4)
        for x, y in ndc:
            near, far = (inv @ np.array([x, y, z, 1.0]) for z in (-1.0, 1.0))
            near, far = near[:3] / near[3], far[:3] / far[3]
            # A point far along the ray (the depth row of the ray matrices is a substitute: any point on
            # the ray projects to the same pixel).
            point = far + (far - near) * 1e3
            clip = forward @ np.append(point, 1.0)
            if clip[3] <= 0.0:
                return limit  # behind the centre camera: a turn of more than 90 degrees
            px = (clip[0] / clip[3] * 0.5 + 0.5) * width
            py = (clip[1] / clip[3] * 0.5 + 0.5) * height
            worst = max(worst, -px, px - width, -py, py - height)
    return int(min(limit, np.ceil(worst)))


def veil_distance(hits: np.ndarray, eye, forward, clip_start: float, clip_end: float) -> float:
    """How far in front of the camera (along its view axis `forward`, from `eye`) the veil stands: in front
    of the nearest surface the widened frame shows (`hits`, the depth pre-pass's world positions with
    w = 1 where a surface was drawn), never outside the camera's clipping range. With no surface in
    view it stands as far as the clipping allows, with the clouds."""
    lo, hi = clip_start * 1.01, clip_end * 0.99
    mask = hits[..., 3] > 0.5
    if not mask.any():
        return hi
    depth = (hits[mask][:, :3] - np.asarray(eye, np.float64)[:3]) @ np.asarray(forward, np.float64)
    return float(np.clip(VEIL_CLEARANCE * depth.min(), lo, hi))


def veil_corners(frame: Frame, eye, forward, distance: float) -> np.ndarray:
    """The widened frame's four corners (bottom-left, bottom-right, top-right, top-left) on the plane
    `distance` in front of the camera, perpendicular to its view axis: where the veil's quad goes."""
    forward = np.asarray(forward, np.float64)
    eye = np.asarray(eye, np.float64)[:3]
    corners = []
    for x, y in ((-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)):
        near, far = (frame.inv_view_proj @ np.array([x, y, z, 1.0]) for z in (-1.0, 1.0))
        near, far = near[:3] / near[3], far[:3] / far[3]
        s = (distance - (near - eye) @ forward) / ((far - near) @ forward)
        corners.append(near + s * (far - near))
    return np.array(corners)


def caster_altitudes(floor: float, top: float, objects_top: float, spacing: float) -> list[float]:
    """The altitudes of the shadow casters when objects rise into the cloud layer (`floor` to `top`): one
    under the floor, then one every `spacing` metres (at least MIN_CASTER_SPACING, at most MAX_CASTERS in
    all) up to the objects' top; each carries the clouds' transmittance towards the sun from its altitude
    to the next one's, so a point's shadow rays gather the layer above it. Under the floor only the one."""
    bottom = floor - 10.0
    reach = min(objects_top, top)
    if reach <= floor:
        return [bottom]
    step = max(spacing, MIN_CASTER_SPACING, (reach - floor) / (MAX_CASTERS - 1))
    count = int(np.ceil((reach - floor) / step))
    return [bottom] + [floor + i * step for i in range(1, count + 1)]


def slab_transmittances(maps: list[np.ndarray]) -> list[np.ndarray]:
    """Each caster's share of the transmittance, from the maps of the whole way up from each (the lowest
    caster's first): the layer between its altitude and the next caster's, the top one all above it. The
    maps' texels lie on the same sun rays, so the product of the slabs a shadow ray crosses is the whole
    way up from the lowest of them. Above a practically opaque slab a slab passes everything."""
    slabs = []
    for below, above in zip(maps, maps[1:], strict=False):
        ratio = np.where(above > OPAQUE, below / np.maximum(above, OPAQUE), 1.0)
        slabs.append(np.clip(ratio, 0.0, 1.0).astype(np.float32))
    slabs.append(np.asarray(maps[-1], np.float32))
    return slabs
