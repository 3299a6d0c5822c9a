"""Everything one frame of clouds depends on, as plain data: what Blender state turns into before
the GPU sees it. Building it from a preset needs no Blender at all, which keeps core/ testable."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from . import cloudlayers, fieldstats, schema
from .bricks import DEFAULT_GPU_LIMIT
from .schema import defaults

_STORM = {s.name: s.default for s in schema.STORM}


@dataclass(frozen=True)
class StormLight:
    """What the renderer needs of a superstorm beyond the field: its centre and radius for the vortex
    and the storm lighting (GDC22), and the lifecycle blend."""

    x: float
    y: float
    radius: float
    # Defaults are the settings schema's (core/schema.py).
    blend: float = _STORM["blend"]
    spin: float = _STORM["spin"]  # radians per second at the centre
    darkening: float = _STORM["darkening"]  # optical-depth scale of the light march at the centre
    glow: float = _STORM["glow"]  # internal glow intensity
    ambient_boost: float = _STORM["ambient_boost"]  # ambient under the storm relative to the clouds'
    glow_color: tuple[float, float, float] = _STORM["glow_color"]
    flash: float = 0.0  # lightning: intensity of this frame's flash
    flash_x: float = 0.0  # the flash's offset from the storm centre (m)
    flash_y: float = 0.0
    flash_ground: float = 0.0  # 1 for a ground discharge (adds the external flash)
    # Seconds of vortex motion so far: the lifecycle fade integrated over time (core/storms.py,
    # vortex_time); None when the blend is not animated, which makes it time x fade(blend).
    vortex_time: float | None = None


MAX_STORMS = 4


@dataclass
class CloudState:
    params: dict[str, Any] = field(default_factory=defaults)
    field_a: np.ndarray | None = None  # (H, W, 4) float32, bottom row first like Blender images
    field_b: np.ndarray | None = None
    field_c: np.ndarray | None = None  # cirrus coverage and type
    sun_direction: tuple[float, float, float] = (0.0, 0.0, 1.0)  # unit vector towards the sun
    sun_radiance: tuple[float, float, float] = (4.0, 4.0, 4.0)  # colour x strength
    # The atmosphere the sun shines through (the Nubis sky's air, aerosol and ozone densities): with it,
    # `sun_radiance` is the sun's above the atmosphere and each sample takes its own transmittance towards
    # the sun (core/sky.py air_table, docs/sky.md#the-sun-each-cloud-sees); None: `sun_radiance` everywhere.
    sun_air: tuple[float, float, float] | None = None
    ambient: tuple[float, float, float] = (0.35, 0.5, 0.8)  # the sky's radiance from above (E / pi)
    ambient_below: tuple[float, float, float] | None = None  # ... from below (None: the same as above)
    ambient_flank: tuple[float, float, float] | None = None  # ... through an upright flank (None: above's)
    # The World's radiance in every direction, equirectangular (H, W, 3) bottom row first (core/sky.py),
    # for the reference sky light and the aerial perspective; None: `ambient` everywhere.
    sky_env: np.ndarray | None = None
    draw_center: tuple[float, float] = (0.0, 0.0)
    time: float = 0.0  # seconds of simulated wind
    # 0 the real-time light; 1 single scattering's reference march (the sky direction by direction); 2 the
    # real-time light model with every optical depth it reads marched (docs/viewport.md#light-model)
    light_mode: int = 0
    jitter: bool = True
    jitter_pass: int = 0  # which accumulation pass: shifts the per-pixel jitter
    cirrus_slab: float | None = None  # the bake's cirrus slab thickness, when wider than the setting
    clip_box: tuple[float, float, float, float] | None = None  # x0, y0, x1, y1: clouds only inside
    storms: tuple[StormLight, ...] = ()
    motion_dt: float = 1.0 / 24.0  # seconds per frame, for motion vectors
    # A pixel's footprint for the noise mip levels: metres per metre of distance (perspective) plus
    # metres (orthographic). 0 reads the full-resolution noise everywhere, as the bake does.
    pixel_angle: float = 0.0
    pixel_size: float = 0.0
    # Artists' OpenVDB clouds drawn with the sky (core/vdbplacement.py Placement), at most MAX_CLOUDS of them.
    vdb_clouds: tuple = ()
    vdb_gpu_budget: int = DEFAULT_GPU_LIMIT  # bytes the VDB clouds may take on the GPU (the preference)
    # A layered sky (core/cloudlayers.py): the further layers drawn with the first, in the artist's order,
    # and whether the first (these params and field_a, field_b) is drawn (switched off or another soloed).
    cloud_layers: tuple[cloudlayers.LayerField, ...] = ()
    first_layer_drawn: bool = True

    def has_cirrus(self) -> bool:
        if self.field_c is None or self.params["cirrus_coverage"] <= 0:
            return False
        return fieldstats.channel_max(self.field_c, 0) > 0

    def drawn_layers(self) -> list[cloudlayers.LayerField]:
        """The cloud layers drawn, the first (this state's own settings and field) first when it is."""
        first = []
        if self.first_layer_drawn and self.field_a is not None and self.field_b is not None:
            first = [cloudlayers.LayerField("", self.params, self.field_a, self.field_b)]
        return first + list(self.cloud_layers)

    def shell(self) -> tuple[float, float]:
        """Lowest and highest altitude a cloud can occupy: every drawn layer's base to top, widened by the
        min/max height channels (GDC22), and the VDB clouds' boxes."""
        extents = cloudlayers.disjoint_extents(self.drawn_layers())
        if extents:
            bottom, top = min(lo for lo, _hi in extents), max(hi for _lo, hi in extents)
        else:
            bottom, top = self.params["layer_bottom"], self.params["layer_top"]
        for placed in self.vdb_clouds:
            # The VDB clouds' boxes too (heights as altitudes: a cloud within tens of kilometres of the
            # origin stands within metres of the planet's curve).
            lo_box, hi_box = placed.world_box
            bottom, top = min(bottom, float(lo_box[2])), max(top, float(hi_box[2]))
        return bottom, top


def sun_vector(elevation_deg: float, azimuth_deg: float) -> tuple[float, float, float]:
    """Azimuth is measured from +Y (north) towards +X (east), like a compass."""
    el, az = math.radians(elevation_deg), math.radians(azimuth_deg)
    return (math.cos(el) * math.sin(az), math.cos(el) * math.cos(az), math.sin(el))


def wind_vector(heading: float) -> tuple[float, float]:
    return (math.cos(heading), math.sin(heading))
