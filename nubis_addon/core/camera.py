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
