"""core/sky.py: the light a cloud's flank receives (docs/viewport.md#light-model), without Blender."""

import math

import numpy as np

from nubis_addon.core import sky


def _env(width: int = 512, radiance=None) -> np.ndarray:
    height = width // 2
    dirs = sky.directions(width, height)
    return np.stack([radiance(dirs)] * 3, axis=-1).astype(np.float32)


def test_a_uniform_environment_gives_its_own_radiance_through_the_flank():
    assert np.allclose(sky.flank_radiance(sky.uniform((0.2, 0.4, 0.8), 256, 128)), (0.2, 0.4, 0.8), rtol=1e-6)


def test_the_horizon_weighs_with_the_sine_of_its_zenith_angle():
    # A sky bright only within 10 degrees of the zenith, or only within 10 degrees of the horizon (above
    # it): the flank sees the band by the horizon, a surface facing up the one at the zenith.
    band = math.sin(math.radians(10.0))
    cap = _env(radiance=lambda d: (d[..., 2] > math.cos(math.radians(10.0))).astype(float))
    ring = _env(radiance=lambda d: ((d[..., 2] >= 0.0) & (d[..., 2] < band)).astype(float))
    # Exact: the flank's weight sin(theta) over the sphere integrates to pi^2; the cap's to
    # (theta - sin theta cos theta) / 2 x 2 pi, the ring's likewise about the horizon.
    t = math.radians(10.0)
    cap_exact = (t - math.sin(t) * math.cos(t)) * math.pi / math.pi**2
    ring_exact = (t + math.sin(t) * math.cos(t)) * math.pi / math.pi**2
    assert abs(sky.flank_radiance(cap)[0] - cap_exact) < 0.15 * cap_exact
    assert abs(sky.flank_radiance(ring)[0] - ring_exact) < 0.05 * ring_exact
    # ... and a surface facing up sees the cap far more than the ring.
    assert sky.hemisphere_radiance(cap)[0][0] > 3.0 * sky.flank_radiance(cap)[0]
    assert sky.hemisphere_radiance(ring)[0][0] < 0.5 * sky.flank_radiance(ring)[0]


def test_the_balance_gives_the_flank_the_luminance_from_above():
    above, flank = (0.1, 0.2, 0.4), (0.3, 0.25, 0.1)
    balance = sky.flank_balance(above, flank)
    lum = lambda c: 0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2]  # noqa: E731
    # metrics.luminance's weights are float32
    assert math.isclose(lum([c * balance for c in flank]), lum(above), rel_tol=1e-6)
    assert sky.flank_balance(above, (0.0, 0.0, 0.0)) == 1.0  # a black flank: nothing to balance
