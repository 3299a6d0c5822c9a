"""Ray generation matrices that keep their precision through a kilometres-deep frustum."""

from __future__ import annotations

import numpy as np

# Depths of the substitute clipping planes: any pair well inside float precision gives the same rays.
_RAY_NEAR, _RAY_FAR = 1.0, 2.0


def ray_inverse_view_projection(window_matrix, view_matrix) -> np.ndarray:
    """Inverse view-projection for building view rays, in float64.

    A sky camera clips from 0.1 m to 200 km. Inverting that projection in float32 (as mathutils does)
    cancels catastrophically in the depth row and turns every ray by ~0.3 degrees, a fifth of a
    pixel at 48x27, which moves every cloud edge. Rays only need the x/y mapping, so a perspective
    projection's depth row is replaced by a well-conditioned one; orthographic projections keep theirs
    because their rays start on the real near plane.
    """
    proj = np.array(window_matrix, dtype=np.float64).reshape(4, 4)
    view = np.array(view_matrix, dtype=np.float64).reshape(4, 4)
    perspective = abs(proj[3, 3]) < 1e-9
    if perspective:
        n, f = _RAY_NEAR, _RAY_FAR
        proj = proj.copy()
        proj[2] = (0.0, 0.0, -(f + n) / (f - n), -2.0 * f * n / (f - n))
    return np.linalg.inv(proj @ view)


def depth_mapping(window_matrix, view_matrix) -> tuple[tuple[float, ...], tuple[float, ...]]:
    """How a view's depth buffer reads as distances (shaders/nubis_common_lib.glsl nubis_axial_depth and
    nubis_axial_to_ray): ((A, B, 1 = perspective, 0), (the view's forward axis, offset)), A and B the window
    matrix's depth row, so that a point p stands dot(p, axis) - offset in front of the camera."""
    proj = np.array(window_matrix, dtype=np.float64).reshape(4, 4)
    view = np.array(view_matrix, dtype=np.float64).reshape(4, 4)
    perspective = abs(proj[3, 3]) < 1e-9
    depth = (float(proj[2, 2]), float(proj[2, 3]), 1.0 if perspective else 0.0, 0.0)
    return depth, (*(float(-v) for v in view[2, :3]), float(view[2, 3]))


def window_depth(points: np.ndarray, window_matrix, view_matrix) -> np.ndarray:
    """The window depth (0-1, as a depth buffer holds it) of world points (..., 3); NaN points read 1."""
    m = np.array(window_matrix, dtype=np.float64).reshape(4, 4) @ np.array(view_matrix, dtype=np.float64).reshape(4, 4)
    pts = np.asarray(points, dtype=np.float64)
    z, w = pts @ m[2, :3] + m[2, 3], pts @ m[3, :3] + m[3, 3]
    with np.errstate(invalid="ignore", divide="ignore"):
        d = (z / w) * 0.5 + 0.5
    return np.where(np.isfinite(d), np.clip(d, 0.0, 1.0), 1.0)


def _unproject(inv: np.ndarray, ndc_x: float, ndc_y: float, depth: float) -> np.ndarray:
    h = inv @ np.array([ndc_x, ndc_y, depth, 1.0])
    return h[:3] / h[3]


def pixel_footprint(inv_view_proj, width: int, height: int) -> tuple[float, float]:
    """How wide one pixel is at the centre of the view: (radians, i.e. metres per metre of distance,
    metres) for a perspective view (angle, 0) or an orthographic one (0, metres). It picks the noise mip
    levels the march reads at a distance."""
    inv = np.array(inv_view_proj, dtype=np.float64).reshape(4, 4)
    dx = 2.0 / max(width, 1)
    near = [_unproject(inv, x, 0.0, -1.0) for x in (0.0, dx)]
    far = [_unproject(inv, x, 0.0, 1.0) for x in (0.0, dx)]
    dirs = [f - n for f, n in zip(far, near, strict=True)]
    spread = float(np.linalg.norm(near[1] - near[0]))
    a, b = (d / np.linalg.norm(d) for d in dirs)
    angle = float(np.arccos(np.clip(np.dot(a, b), -1.0, 1.0)))
    if angle < 1e-9:  # parallel rays: orthographic
        return 0.0, spread
    return angle, 0.0


def forward_view_projection(inv_view_proj) -> np.ndarray:
    """The view-projection whose inverse builds the rays, for projecting world points back to the
    screen (reprojection needs only x, y and w, which the substitute depth row leaves exact)."""
    return np.linalg.inv(np.array(inv_view_proj, dtype=np.float64).reshape(4, 4))


# One over the plastic number and its square: the steps of M. Roberts' R2 sequence
# (docs/sources.md#numerical-methods), whose points cover a square evenly however many are taken.
_R2 = (0.7548776662466927, 0.5698402909980532)


def subpixel_offset(index: int) -> tuple[float, float]:
    """Where pass `index`'s rays cross their pixels, in pixels from the centres, each in [-0.5, 0.5):
    passes of consecutive indices sample the pixels' areas evenly, and two disjoint runs of indices are
    two independent estimates of the same box-filtered image."""
    return tuple(float((0.5 + step * index) % 1.0 - 0.5) for step in _R2)


def shifted_inverse(inv_view_proj, dx: float, dy: float, width: int, height: int) -> np.ndarray:
    """The inverse view-projection whose rays leave each pixel (dx, dy) pixels from its centre, for a
    `width` x `height` image (x right, y up)."""
    inv = np.array(inv_view_proj, dtype=np.float64).reshape(4, 4)
    shift = np.identity(4)
    shift[0, 3] = 2.0 * dx / width
    shift[1, 3] = 2.0 * dy / height
    # A ray through NDC point p of the shifted camera is the unshifted camera's ray through p + shift.
    return inv @ shift
