"""The comparison's passes sample the pixels' areas (core/camera.py): where each pass's rays cross their
pixels, and the camera that sends them there."""

import numpy as np

from nubis_addon.core import camera


def test_passes_cover_the_pixel_evenly_and_disjoint_runs_sample_different_places():
    points = np.array([camera.subpixel_offset(i) for i in range(64)])
    assert points.min() >= -0.5 and points.max() < 0.5
    # Every cell of a 4x4 grid over the pixel holds 4 of 64 points, give or take 2: an even cover,
    # which a fixed point (the centre) or a grid of 16 repeated would not give.
    cells = np.floor((points + 0.5) * 4).astype(int)
    counts = np.bincount(cells[:, 0] * 4 + cells[:, 1], minlength=16)
    assert counts.min() >= 2 and counts.max() <= 6, counts
    # The two halves of a comparison (passes 0-15 and 16-31) share no place.
    first, second = {tuple(np.round(p, 9)) for p in points[:16]}, {tuple(np.round(p, 9)) for p in points[16:32]}
    assert len(first) == 16 and not first & second
    assert abs(points[:, 0].mean()) < 0.02 and abs(points[:, 1].mean()) < 0.02


def _ray(inv, ndc):
    near = inv @ np.array([*ndc, -1.0, 1.0])
    far = inv @ np.array([*ndc, 1.0, 1.0])
    d = far[:3] / far[3] - near[:3] / near[3]
    return d / np.linalg.norm(d)


def test_a_shifted_camera_sends_each_pixels_rays_through_the_shifted_place():
    """At 40x20 pixels, a shift of (0.25, -0.5) pixels: the ray of NDC point p is the unshifted camera's
    ray through p + (0.5 / 40, -1 / 20), for a perspective and an orthographic camera."""
    view = np.identity(4)
    view[:3, 3] = (10.0, -5.0, -3.0)
    f, aspect = 1.0 / np.tan(np.radians(30)), 2.0
    perspective = np.array([[f / aspect, 0, 0, 0], [0, f, 0, 0], [0, 0, -1.0001, -0.20001], [0, 0, -1, 0]])
    orthographic = np.diag([0.1, 0.2, -0.001, 1.0])
    for proj in (perspective, orthographic):
        inv = camera.ray_inverse_view_projection(proj, view)
        shifted = camera.shifted_inverse(inv, 0.25, -0.5, 40, 20)
        for ndc in ((0.0, 0.0), (0.7, -0.3), (-0.95, 0.9)):
            moved = (ndc[0] + 2 * 0.25 / 40, ndc[1] - 2 * 0.5 / 20)
            assert np.allclose(_ray(shifted, ndc), _ray(inv, moved), atol=1e-9)
            near = shifted @ np.array([*ndc, -1.0, 1.0])
            expect = inv @ np.array([*moved, -1.0, 1.0])
            assert np.allclose(near[:3] / near[3], expect[:3] / expect[3], atol=1e-6)
        # The shift is real: the centre's ray turns (perspective) or starts elsewhere (orthographic).
        centre = [m @ np.array([0.0, 0.0, -1.0, 1.0]) for m in (shifted, inv)]
        moved_start = not np.allclose(centre[0][:3] / centre[0][3], centre[1][:3] / centre[1][3], atol=1e-6)
        assert moved_start or not np.allclose(_ray(shifted, (0.0, 0.0)), _ray(inv, (0.0, 0.0)), atol=1e-6)
