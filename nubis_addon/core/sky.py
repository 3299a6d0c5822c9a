"""The sky as the clouds see it: the atmosphere's transmittance towards the sun, and equirectangular
environments (what a World radiates, captured as an image) with their irradiance from above and below.

Equirectangular images follow Blender's Environment Texture mapping: the column u = 0.5 - azimuth / 2 pi
with azimuth = atan2(y, x) (so the image centre looks along +X and u = 0.25 along +Y), the row
v = 0.5 + elevation / pi counted from the bottom. Arrays are (H, W, C), bottom row first like
Blender images.
"""

from __future__ import annotations

import math

import numpy as np

from . import metrics

# Earth and atmosphere (Bruneton and Neyret 2008, Bruneton 2017; the same constants Blender's own sky
# model uses): radii in metres, scale heights, and sea-level coefficients per metre at 680, 550 and
# 440 nm, the wavelengths standing for red, green and blue.
EARTH_RADIUS = 6360e3
ATMOSPHERE_TOP = 6420e3
RAYLEIGH_HEIGHT = 8000.0
MIE_HEIGHT = 1200.0
RAYLEIGH = np.array([5.802e-6, 13.558e-6, 33.1e-6])
MIE_EXTINCTION = 2.0e-5 / 0.9  # scattering over the single-scattering albedo of 0.9
OZONE = np.array([0.650e-6, 1.881e-6, 0.085e-6])  # absorption at the layer's peak
OZONE_PEAK, OZONE_WIDTH = 25e3, 15e3  # a tent from 10 to 40 km (Bruneton 2017)


def _optical_depth(r0, mu, air: float, aerosol: float, ozone: float, n: int = 256) -> np.ndarray:
    """Optical depths (..., 3) along rays from radius `r0` at the cosine `mu` of their zenith angle to
    the top of the atmosphere (arrays of one shape; rays that meet the ground are not told apart here)."""
    r0 = np.asarray(r0, np.float64)[..., None]
    mu = np.asarray(mu, np.float64)[..., None]
    top = np.maximum(ATMOSPHERE_TOP, r0)
    length = -r0 * mu + np.sqrt(np.maximum(r0 * r0 * (mu * mu - 1.0) + top * top, 0.0))
    # Samples crowd near the start, where the air is densest: t = length u^2.
    u = (np.arange(n) + 0.5) / n
    t = length * u * u
    dt = 2.0 * length * u / n
    h = np.sqrt(r0 * r0 + t * t + 2.0 * r0 * t * mu) - EARTH_RADIUS
    rayleigh = air * np.sum(np.exp(-h / RAYLEIGH_HEIGHT) * dt, axis=-1)
    mie = aerosol * np.sum(np.exp(-h / MIE_HEIGHT) * dt, axis=-1)
    oz = ozone * np.sum(np.clip(1.0 - np.abs(h - OZONE_PEAK) / OZONE_WIDTH, 0.0, None) * dt, axis=-1)
    return RAYLEIGH * rayleigh[..., None] + MIE_EXTINCTION * mie[..., None] + OZONE * oz[..., None]


def _meets_ground(r0, mu):
    """Whether rays from radius `r0` at zenith cosine `mu` meet the ground: Earth's shadow, for a ray to the sun."""
    return (mu < 0.0) & (r0 * r0 * (mu * mu - 1.0) + EARTH_RADIUS**2 >= 0.0)


def transmittance(
    elevation: float, altitude: float = 0.0, air: float = 1.0, aerosol: float = 1.0, ozone: float = 1.0
) -> tuple[float, float, float]:
    """RGB transmittance of the atmosphere along a ray leaving `altitude` (metres) at `elevation`
    (radians above the horizon) towards space: what is left of the sun's light when it arrives. The
    densities are multiples of the standard atmosphere, as the Sky Texture's air, dust (aerosol) and
    ozone settings are. A ray that meets the ground gives zero (Earth's shadow)."""
    r0 = EARTH_RADIUS + max(altitude, 0.0)
    mu = math.sin(elevation)
    if _meets_ground(r0, mu):
        return (0.0, 0.0, 0.0)
    tau = _optical_depth(r0, mu, air, aerosol, ozone)
    return tuple(float(x) for x in np.exp(-tau))


# ---- the sun each cloud sees (docs/sky.md#the-sun-each-cloud-sees) ---------------------------------------
#
# The transmittance towards the sun from every altitude at every sun angle, as one small table the shaders
# read per sample (the idea of Bruneton and Neyret's transmittance table, 2008/2017): a column is the
# distance to the top of the atmosphere along the ray, from the shortest (straight up) to the longest (the
# ray grazing the ground), a row the radius, as the distance to the horizon over the greatest. Rays that meet
# the ground are zero and are not in the table: the shader tells them by geometry. The mapping puts texels
# where the transmittance changes (near the horizon, low down): 256 KB of texture.
AIR_TABLE_SIZE = (256, 64)  # texels along the distance (the sun's angle) and along the altitude
AIR_SPAN = math.sqrt(ATMOSPHERE_TOP**2 - EARTH_RADIUS**2)  # the horizon's distance from the top


def air_table_coords(altitude, mu) -> tuple[np.ndarray, np.ndarray]:
    """The table's unit coordinates (x along the distance, y along the altitude) of rays from `altitude`
    (metres, clamped into the atmosphere) at zenith cosine `mu` (arrays)."""
    r = EARTH_RADIUS + np.clip(np.asarray(altitude, np.float64), 0.0, ATMOSPHERE_TOP - EARTH_RADIUS)
    mu = np.asarray(mu, np.float64)
    rho = np.sqrt(np.maximum(r * r - EARTH_RADIUS**2, 0.0))
    d = np.maximum(-r * mu + np.sqrt(np.maximum(r * r * (mu * mu - 1.0) + ATMOSPHERE_TOP**2, 0.0)), 0.0)
    d_min, d_max = ATMOSPHERE_TOP - r, rho + AIR_SPAN
    along = np.clip((d - d_min) / np.maximum(d_max - d_min, 1e-9), 0.0, 1.0)
    return 1.0 - np.sqrt(1.0 - along), rho / AIR_SPAN  # more texels towards the horizon


def _air_table_rays(x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The rays (radius, zenith cosine) at unit table coordinates: air_table_coords inverted."""
    rho = y * AIR_SPAN
    r = np.sqrt(rho * rho + EARTH_RADIUS**2)
    d_min, d_max = ATMOSPHERE_TOP - r, rho + AIR_SPAN
    d = d_min + (1.0 - (1.0 - x) ** 2) * (d_max - d_min)
    mu = np.where(d > 0.0, (AIR_SPAN**2 - rho * rho - d * d) / np.maximum(2.0 * r * d, 1e-9), 1.0)
    return r, np.clip(mu, -1.0, 1.0)


_air_tables: dict[tuple, np.ndarray] = {}


def air_table(air: float = 1.0, aerosol: float = 1.0, ozone: float = 1.0) -> np.ndarray:
    """The transmittance table for these densities, (rows, columns, 4) float32, RGB and 1, each texel
    the ray at its centre (a texture's linear filter then interpolates between them). Remembered per
    densities: a redraw costs nothing, a new sky under half a second."""
    key = (round(float(air), 9), round(float(aerosol), 9), round(float(ozone), 9))
    table = _air_tables.get(key)
    if table is None:
        cols, rows = AIR_TABLE_SIZE
        x = (np.arange(cols) + 0.5) / cols
        y = (np.arange(rows) + 0.5) / rows
        xx, yy = np.meshgrid(x, y)
        r, mu = _air_table_rays(xx, yy)
        tau = _optical_depth(r, mu, *key, n=96)
        table = np.ones((rows, cols, 4), np.float32)
        table[..., :3] = np.exp(-tau)
        if len(_air_tables) > 16:
            _air_tables.clear()
        _air_tables[key] = table
    return table


def air_table_lookup(table: np.ndarray, altitude, mu) -> np.ndarray:
    """What the shaders read (nubis_air_transmittance): the table bilinearly at the rays' coordinates,
    zero for rays that meet the ground. Arrays of altitudes and zenith cosines; (..., 3)."""
    x, y = air_table_coords(altitude, mu)
    rows, cols = table.shape[:2]
    fx = np.clip(x * cols - 0.5, 0.0, cols - 1.0)
    fy = np.clip(y * rows - 0.5, 0.0, rows - 1.0)
    x0 = np.minimum(np.floor(fx).astype(int), cols - 2)
    y0 = np.minimum(np.floor(fy).astype(int), rows - 2)
    ax, ay = (fx - x0)[..., None], (fy - y0)[..., None]
    rgb = table[..., :3].astype(np.float64)
    lo = rgb[y0, x0] * (1 - ax) + rgb[y0, x0 + 1] * ax
    hi = rgb[y0 + 1, x0] * (1 - ax) + rgb[y0 + 1, x0 + 1] * ax
    value = lo * (1 - ay) + hi * ay
    r = EARTH_RADIUS + np.clip(np.asarray(altitude, np.float64), 0.0, None)
    return np.where(_meets_ground(r, np.asarray(mu, np.float64))[..., None], 0.0, value)


def elevation_azimuth(direction) -> tuple[float, float]:
    """Elevation above the horizon and azimuth (radians, atan2(y, x)) of a direction."""
    x, y, z = (float(c) for c in direction)
    n = math.sqrt(x * x + y * y + z * z) or 1.0
    return math.asin(max(-1.0, min(1.0, z / n))), math.atan2(y, x)


def directions(width: int, height: int) -> np.ndarray:
    """Unit direction of every pixel centre of an equirectangular image, (H, W, 3), bottom row first."""
    u = (np.arange(width) + 0.5) / width
    v = (np.arange(height) + 0.5) / height
    azimuth = (0.5 - u) * 2.0 * math.pi
    elevation = (v - 0.5) * math.pi
    az, el = np.meshgrid(azimuth, elevation)
    return np.stack([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)], axis=-1)


def sample(env: np.ndarray, dirs: np.ndarray) -> np.ndarray:
    """Bilinear look-up of an equirectangular image in directions (..., 3); wraps around in azimuth."""
    h, w = env.shape[:2]
    d = dirs / np.maximum(np.linalg.norm(dirs, axis=-1, keepdims=True), 1e-12)
    u = 0.5 - np.arctan2(d[..., 1], d[..., 0]) / (2.0 * math.pi)
    v = 0.5 + np.arcsin(np.clip(d[..., 2], -1.0, 1.0)) / math.pi
    x = u * w - 0.5
    y = np.clip(v * h - 0.5, 0.0, h - 1.0)
    x0 = np.floor(x).astype(np.int64)
    y0 = np.minimum(np.floor(y).astype(np.int64), h - 2) if h > 1 else np.zeros_like(x0)
    fx = (x - x0)[..., None]
    fy = (y - y0)[..., None] if h > 1 else np.zeros_like(fx)
    x0 %= w
    x1 = (x0 + 1) % w
    y1 = np.minimum(y0 + 1, h - 1)
    top = env[y1, x0] * (1 - fx) + env[y1, x1] * fx
    bottom = env[y0, x0] * (1 - fx) + env[y0, x1] * fx
    return bottom * (1 - fy) + top * fy


def camera_directions(inv_view_proj, eye, width: int, height: int) -> np.ndarray:
    """The view ray of every pixel centre (H, W, 3), top row first, as the shaders build them
    (nubis_view_ray): through the far plane from the eye, or from the near plane for w = 0."""
    inv = np.array(inv_view_proj, dtype=np.float64).reshape(4, 4)
    x = (np.arange(width) + 0.5) / width * 2.0 - 1.0
    y = 1.0 - (np.arange(height) + 0.5) / height * 2.0
    nx, ny = np.meshgrid(x, y)

    def unproject(depth: float) -> np.ndarray:
        h = np.stack([nx, ny, np.full_like(nx, depth), np.ones_like(nx)], axis=-1) @ inv.T
        return h[..., :3] / h[..., 3:4]

    far = unproject(1.0)
    origin = np.asarray(eye[:3], np.float64) if eye[3] > 0.5 else unproject(-1.0)
    d = far - origin
    return d / np.linalg.norm(d, axis=-1, keepdims=True)


def solid_angles(width: int, height: int) -> np.ndarray:
    """Solid angle of each pixel of an equirectangular image, (H, 1); they sum to 4 pi per row sweep."""
    v0 = np.arange(height) / height
    v1 = (np.arange(height) + 1) / height
    band = (np.sin((v1 - 0.5) * math.pi) - np.sin((v0 - 0.5) * math.pi)) * 2.0 * math.pi / width
    return band[:, None]


def hemisphere_radiance(env: np.ndarray) -> tuple[tuple[float, float, float], tuple[float, float, float]]:
    """The cosine-weighted mean radiance over the upper and the lower hemisphere, E / pi from above and
    from below: what a horizontal surface facing up (down) receives from the environment, expressed as
    the uniform radiance that would give it. A uniform environment returns its own radiance twice."""
    h, w = env.shape[:2]
    dirs = directions(w, h)
    weight = solid_angles(w, h) * dirs[..., 2]
    rgb = env[..., :3].astype(np.float64)
    up = np.clip(weight, 0.0, None)[..., None]
    down = np.clip(-weight, 0.0, None)[..., None]
    above = (rgb * up).sum(axis=(0, 1)) / max(float(up.sum()), 1e-12)
    below = (rgb * down).sum(axis=(0, 1)) / max(float(down.sum()), 1e-12)
    return tuple(float(c) for c in above), tuple(float(c) for c in below)


def flank_radiance(env: np.ndarray) -> tuple[float, float, float]:
    """What an upright surface receives from the environment (E / pi), averaged over the directions it
    can face: the light entering a cloud through its flank. Each direction weighs with the sine of its
    angle from the zenith (the mean over azimuth of a vertical surface's cosine), the sky above the
    horizon and the ground below it alike; so the horizon, which a surface facing up barely sees, counts
    most. A uniform environment returns its own radiance (docs/viewport.md#light-model)."""
    h, w = env.shape[:2]
    dirs = directions(w, h)
    weight = solid_angles(w, h) * np.sqrt(np.clip(1.0 - dirs[..., 2] ** 2, 0.0, None))
    rgb = env[..., :3].astype(np.float64)
    total = (rgb * weight[..., None]).sum(axis=(0, 1)) / max(float(weight.sum()), 1e-12)
    return tuple(float(c) for c in total)


def flank_balance(above, flank) -> float:
    """The factor that gives the flank's light the luminance of the light from above: the sky light's
    strength (the Ambient setting) was fitted with every cloud lit by the light from above, so a sky
    whose flank light is weighed at its fitting sun keeps the fit's balance there and takes the flank's
    own colour and its change with the sun (docs/viewport.md#light-model)."""
    top, side = (float(metrics.luminance(np.asarray(c, np.float64))) for c in (above, flank))
    return top / side if side > 1e-12 and top > 0.0 else 1.0


def ground_light(albedo, sky_light, sun_light) -> tuple[float, float, float]:
    """A Lambertian ground's radiance: its albedo times the sky's light from above (E / pi) and the sun's
    on it (`sun_light`: colour, strength and the sine of its elevation; None for no sun)."""
    light = np.array(sky_light, np.float64)
    if sun_light is not None:
        colour, energy, sine = sun_light
        light = light + np.array(colour, np.float64) * energy * sine / math.pi
    return tuple(float(c) for c in np.array(albedo, np.float64) * light)


_hemispheres: dict[int, tuple] = {}


def hemisphere_radiance_cached(env: np.ndarray) -> tuple:
    """hemisphere_radiance and flank_radiance of an environment array (above, below, flank), remembered
    per array (callers replace arrays, they never edit one in place), so a redraw costs nothing."""
    hit = _hemispheres.get(id(env))
    if hit is not None and hit[0] is env:
        return hit[1]
    if len(_hemispheres) > 32:
        _hemispheres.clear()
    result = (*hemisphere_radiance(env), flank_radiance(env))
    _hemispheres[id(env)] = (env, result)
    return result


def uniform(colour, width: int = 8, height: int = 4) -> np.ndarray:
    """An environment of one radiance everywhere (a World that is a flat colour)."""
    return np.broadcast_to(np.asarray(colour, np.float32)[:3], (height, width, 3)).copy()


def with_ground(env: np.ndarray, ground, band: float) -> np.ndarray:
    """The environment below its horizon as the Nubis sky's World shows it (blender/scene/sky.py): the sky
    mirrored at the horizon, fading into the ground's radiance `ground` with a smoothstep over the
    sines of elevation 0 to -`band`. Each row takes the smoothstep's mean over its own solid angle (a
    render's texel is the mean over its area, and a row is about as tall as the band); rows are
    mirrored exactly (their elevations are symmetric), so the sky above stays as it was rendered."""
    if ground is None:
        return env
    h = env.shape[0]
    edges = np.sin((np.arange(h + 1) / h - 0.5) * math.pi)  # row boundaries, as sines of elevation

    def integral(t):  # of the smoothstep t^2 (3 - 2 t) from 0 to t, then 1 beyond t = 1
        t = np.clip(t, 0.0, None)
        inside = np.minimum(t, 1.0)
        return inside**3 - inside**4 / 2.0 + np.maximum(t - 1.0, 0.0)

    t0, t1 = -edges[1:] / band, -edges[:-1] / band  # t grows downwards: the row's upper and lower edge
    span = np.maximum(t1 - t0, 1e-12)
    weight = np.where(t1 > 0.0, (integral(t1) - integral(t0)) / span, 0.0)[:, None, None]
    mirrored = env[::-1]
    colour = np.asarray(ground, np.float32)[:3]
    below = (edges[1:] <= 0.0)[:, None, None]
    out = np.where(below, mirrored * (1.0 - weight) + colour * weight, env)
    return out.astype(np.float32)
