"""The light model's closed-form terms as the GPU compiles them, read back through the probe stage
(tests/gpu_probe.py): the cirrus slab's multiple scattering, the sky's and the ground's light diffusing
through it, and the sky light's diffusion through absorbing cloud (docs/sources.md#cirrus-lighting,
docs/sources.md#diffusion-through-a-slab). Each is checked against a float64 evaluation written here
from the physics, and for the limits it must keep."""

import numpy as np
import pytest


@pytest.fixture
def clouds(make_scene):
    from nubis_addon.blender.host import runtime
    from nubis_addon.blender.scene import cloudstate

    scene = make_scene("default")
    state = cloudstate.state_from_scene(scene)
    gpu_inputs = runtime.cloud_gpu(scene.nubis.noise_seed)
    gpu_inputs.update(state)
    p = state.params
    g = (1.0 - p["lighting_phase_mix"]) * p["lighting_phase_g0"] + p["lighting_phase_mix"] * p["lighting_phase_g1"]
    return gpu_inputs, g


def _eddington_multiple(mu_v, mu_l, tau, g):
    """The slab's light beyond single scattering, per unit of the sun's irradiance (float64)."""
    direct = np.exp(-tau / mu_l)
    k = 0.75 * (1.0 - g) * tau
    reflected = (k + (0.5 - 0.75 * mu_l) * (1.0 - direct)) / (1.0 + k)
    diffuse = np.where(mu_v > 0.0, 1.0 - reflected - direct, reflected)
    leaves_unscattered = -np.expm1(-2.0 * tau) / (2.0 * tau)
    return mu_l * diffuse * (1.0 - leaves_unscattered) / np.pi


def test_a_cirrus_slab_scatters_more_than_once_only_where_it_is_thick(clouds):
    """A thin cirrus is single scattering; under a thick anvil the light that scattered many times is
    most of what reaches the viewer (converged Cycles lights its underside white)."""
    from gpu_probe import probe_slab

    gpu_inputs, g = clouds
    taus = np.array([0.02, 0.1, 0.3, 1.0, 2.0, 4.0])
    rows = np.array([(mu_v, 0.5, tau) for mu_v in (0.3, -0.3) for tau in taus])
    got = probe_slab(gpu_inputs, rows).astype(np.float64)
    multiple = got[:, 0]
    single = got[:, 1] / (4.0 * np.pi)  # single scattering's light with an isotropic phase
    expected = _eddington_multiple(rows[:, 0], rows[:, 1], rows[:, 2], g)
    np.testing.assert_allclose(multiple, expected, rtol=2e-3, atol=1e-7)
    below, above = multiple[: len(taus)], multiple[len(taus) :]
    # Reflected light grows with the depth; transmitted light too, until the layer holds more back than
    # it scatters on (past a depth of about 2 here).
    assert np.all(np.diff(above) > 0.0) and np.all(np.diff(below[:5]) > 0.0) and below[5] < below[4]
    # Second order and more in a thin layer: under 2 % of its single scattering at depth 0.02.
    assert below[0] < 0.02 * single[0] and above[0] < 0.02 * single[len(taus)]
    # Through a thick layer almost nothing arrives scattered once: the multiple scattering dominates.
    assert below[-1] > 3.0 * single[len(taus) - 1]
    # It never spends more than the diffuse light the slab passes on: pi L / mu0 <= 1.
    assert np.all(np.pi * multiple / 0.5 <= 1.0)
    # No sun above the layer, no light from it.
    dark = probe_slab(gpu_inputs, np.array([(0.3, -0.2, 2.0), (-0.3, -0.2, 2.0)]))
    assert np.all(dark[:, 0] == 0.0)


def test_a_cirrus_slab_passes_the_sky_on_as_the_clouds_diffuse_it(clouds):
    """The sky's and the ground's light through a cirrus layer: the clouds' linear diffusion weights
    integrated along the view ray. Checked against a float64 quadrature; thin, each face gives half the
    opacity (single scattering of a uniform sky); thick, the far face's light fades as 1 / tau and the
    near face's is all sent back, which is why converged Cycles shows a thick anvil's underside
    lit by the ground more than by the sky above it."""
    from gpu_probe import probe_sky_weights

    gpu_inputs, _g = clouds
    rate, edge = 1.2, 1.0
    rows = np.array([(mu_v, tau, rate, edge) for mu_v in (0.9, 0.3, -0.3, 0.05) for tau in (1e-4, 0.05, 0.5, 2.0, 8.0)])
    got = probe_sky_weights(gpu_inputs, rows).astype(np.float64)
    for (mu_v, tau, _r, _e), (far, near, once) in zip(rows, got, strict=True):
        m = 1.0 / abs(mu_v)
        y = (np.arange(20000) + 0.5) / 20000 * tau  # depth between the point and the viewer
        seen = m * np.exp(-m * y) * (tau / 20000)
        span = rate * tau + 2.0 * edge
        assert far == pytest.approx(np.sum(seen * (rate * y + edge)) / span, rel=2e-3, abs=1e-7)
        assert near == pytest.approx(np.sum(seen * (rate * (tau - y) + edge)) / span, rel=2e-3, abs=1e-7)
        assert once == pytest.approx(-np.expm1(-2.0 * tau) / (2.0 * tau), rel=1e-3)
    # Together the faces' weights are the layer's opacity at any depth: it sends on what it holds back.
    opacity = -np.expm1(-rows[:, 1] / np.abs(rows[:, 0]))
    np.testing.assert_allclose(got[:, 0] + got[:, 1], opacity, rtol=1e-4, atol=1e-7)
    thin = got[rows[:, 1] == 0.05]
    opacity = opacity[rows[:, 1] == 0.05]
    np.testing.assert_allclose(thin[:, :2], 0.5 * np.stack([opacity, opacity], axis=1), rtol=0.01)
    thick = got[(rows[:, 1] == 8.0) & (rows[:, 0] == 0.3)][0]
    assert thick[0] < 0.15 and thick[1] > 0.8 and thick[0] + thick[1] == pytest.approx(1.0, abs=1e-3)


def test_a_cirrus_slab_sends_its_diffuse_sunlight_out_with_the_diffusion_profiles_shape(clouds, blender):
    """The sun's light scattered more than once leaves the layer with the angular shape of the light
    model's linear profile, its flux kept (docs/sources.md#cirrus-lighting): a thin layer seen at a grazing
    angle shows more of it (its longer path), a thick one lit from the far face less (what reaches the
    viewer's face is what is left of it). Leaving evenly, the first model lit a thick anvil's middle too
    brightly and its thin edges too dimly against converged Cycles."""
    from gpu_probe import probe_slab_shape

    gpu_inputs, _g = clouds
    p = blender.context.scene.nubis
    rate, edge = p.lighting_sky_occlusion, p.lighting_diffusion_edge
    mus = (np.arange(64) + 0.5) / 64
    for far in (1.0, 0.0):
        for tau in (0.02, 0.5, 4.0):
            rows = np.array([(mu, 0.5, tau, far) for mu in mus])
            shape = probe_slab_shape(gpu_inputs, rows)[:, 2].astype(np.float64)
            # float64: the face's weight seen at each cosine (slant capped at 1 / 0.05), over twice its flux
            m = 1.0 / np.maximum(mus, 0.05)
            a = -np.expm1(-m * tau)
            b = (a - m * tau * np.exp(-m * tau)) / m
            w = (rate * b + edge * a) if far else (rate * (tau * a - b) + edge * a)
            expected = w / (2.0 * np.sum(w * mus) / 64)
            np.testing.assert_allclose(shape, expected, rtol=0.03)
            # the flux of the light that leaves is kept: 2 x the integral of shape x mu is 1
            assert 2.0 * np.sum(shape * mus) / 64 == pytest.approx(1.0, abs=0.03)
            if tau == 0.02:
                assert shape[6] > 2.0 * shape[-1] and shape[6] > 1.0  # grazing (mu 0.1) brighter than overhead
            if tau == 4.0 and far:
                assert shape[6] < 1.0 < shape[-1]  # a thick layer lit from above, seen from below at a grazing angle


def _robin_slab(near, far, rate, edge, kappa):
    """phi'' = k^2 phi across the slab in transport depth, phi - edge phi' = 1 on the lit face and
    phi + edge phi' = 0 on the far one, at the point `near` from the lit face (float64)."""
    k = kappa / rate
    u, span = rate * far, rate * (near + far)
    num = np.sinh(k * u) + k * edge * np.cosh(k * u)
    den = (1.0 + (k * edge) ** 2) * np.sinh(k * span) + 2.0 * k * edge * np.cosh(k * span)
    return num / den


def test_the_sky_light_dies_out_in_absorbing_cloud_and_falls_linearly_in_clear_cloud(clouds):
    from gpu_probe import probe_diffusion

    gpu_inputs, _g = clouds
    rate, edge = 1.2, 1.0
    rows = np.array([(near, far, rate, edge) for near in (0.0, 0.5, 2.0, 6.0) for far in (0.0, 1.0, 5.0)])
    near, far = rows[:, 0], rows[:, 1]
    linear = (rate * far + edge) / (rate * (near + far) + 2.0 * edge)
    clear = probe_diffusion(gpu_inputs, rows, 0.0)[:, 0]
    np.testing.assert_allclose(clear, linear, rtol=1e-5)
    # A vanishing absorption joins the linear weights without a step.
    np.testing.assert_allclose(probe_diffusion(gpu_inputs, rows, 1e-4)[:, 0], linear, rtol=1e-3)
    for kappa in (0.3, 1.0):
        dim = probe_diffusion(gpu_inputs, rows, kappa)[:, 0].astype(np.float64)
        np.testing.assert_allclose(dim, _robin_slab(near, far, rate, edge, kappa), rtol=2e-4, atol=1e-7)
        assert np.all(dim <= linear + 1e-6)
    # Deep in a thick absorbing tower: finite, and the lit face of a thick slab keeps 1 / (1 + kappa edge / rate).
    deep = probe_diffusion(gpu_inputs, np.array([(0.0, 400.0, rate, edge), (400.0, 400.0, rate, edge)]), 1.0)[:, 0]
    assert deep[0] == pytest.approx(1.0 / (1.0 + edge / rate), rel=1e-4)
    assert 0.0 <= deep[1] < 1e-6


def _transport_decay(albedo: float) -> float:
    """The exact decay rate of diffuse light in isotropically scattering cloud: the root kappa in (0, 1)
    of albedo / (2 kappa) ln((1 + kappa) / (1 - kappa)) = 1 (bisection)."""
    if albedo <= 0.0:
        return 1.0  # no scattering: the unscattered light's own rate
    lo, hi = 0.0, 1.0
    for _ in range(60):
        k = 0.5 * (lo + hi)
        if albedo / (2.0 * k) * np.log((1.0 + k) / (1.0 - k)) > 1.0:
            hi = k
        else:
            lo = k
    return 0.5 * (lo + hi)


def test_the_decay_rate_follows_transport_theory_where_diffusion_fails(clouds):
    """Diffusion's rate sqrt(3 (1 - albedo)) is 42 % too fast at albedo 1/3; the bent rate stays within
    6 % of transport theory's at every albedo, and never exceeds the unscattered light's 1."""
    from gpu_probe import probe_diffusion

    gpu_inputs, _g = clouds
    albedos = np.array([0.999, 0.99, 0.9, 0.8, 0.6, 0.5, 1.0 / 3.0, 0.1, 0.0])
    rows = np.zeros((len(albedos), 4), np.float32)
    rows[:, 0] = albedos
    rows[:, 2] = 1.0  # the diffusion's own arguments are unused here
    decay = probe_diffusion(gpu_inputs, rows, 0.0)[:, 1].astype(np.float64)
    exact = np.array([_transport_decay(a) for a in albedos])
    assert np.all(np.abs(decay / exact - 1.0) < 0.06), list(zip(albedos, decay, exact, strict=True))
    assert np.all(decay <= 1.0)
    assert np.sqrt(3.0 * (1.0 - 1.0 / 3.0)) / exact[6] > 1.4  # what plain diffusion would have taken
    one = np.array([[1.0, 0.5, 1.0, 0.0]], np.float32)  # no absorption: no decay, whatever g
    assert probe_diffusion(gpu_inputs, one, 0.0)[0, 1] == 0.0
