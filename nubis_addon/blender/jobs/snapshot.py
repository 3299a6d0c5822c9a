"""What a bake evaluates, taken once when it starts.

Bake VDB, Bake Sequence and Render Clouds run in steps while the artist keeps working: orbiting,
scrubbing the timeline, dragging a slider, painting a layer, pressing Ctrl-Z, saving. Everything that
decides a bake's result is read here at its start into data of its own: the CloudState (its field arrays
are read from the images into new arrays), the frame and its time, the plan, the frame rate, the settings
its metadata names, and the noise textures of its seed. Its GPU inputs are then uploaded from that data
into textures of its own (CloudGPU.fork), so the viewport's uploads to the shared inputs, made on every
redraw, cannot reach it. After the snapshot a bake touches no Blender data: not the scene, which an undo
or a file load frees, nor the timeline.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field

import numpy as np

from ...core import lightvolume
from ...core.bakeplan import BakePlan, plan_bake, view_footprint
from ...core.errors import NubisError
from ...core.jobs import BakeOptions
from ...core.sequence import human_bytes
from ...core.state import CloudState
from ...render.engine import CloudGPU
from ...render.textures import NoiseTextures
from ..host import runtime
from ..scene import cloudstate, sceneparams

# The field arrays a sequence's snapshot may hold when the field changes from frame to frame (keyed
# layers, storms): frames whose field is unchanged share one copy.
SEQUENCE_SNAPSHOT_LIMIT = 2 * 1024**3


@dataclass
class BakeSnapshot:
    """One frame's bake as it was when the work started; its steps read nothing else."""

    state: CloudState
    plan: BakePlan
    noise: NoiseTextures
    fps: float
    frame: int
    preset: str
    density_sigma: float
    noise_seed: int
    settings: dict = field(default_factory=dict)  # those that decide the density (not the light's)

    def gpu_inputs(self) -> CloudGPU:
        """The snapshot on the GPU, in textures of the bake's own (densities only: no light volumes)."""
        clouds = CloudGPU(self.noise)
        clouds.update(self.state, light=False)
        return clouds

    def metadata(self, grids: tuple[str, ...]) -> dict:
        """What pipelines read from the file: units, the snapshot's frame and the settings that decide the
        density (the same bake writes the same bytes: no time stamp), the preset, the density scale
        (extinction per metre at density 1), the grids and their meaning (docs/bake.md)."""
        meta = {
            "nubis_sigma": self.density_sigma,
            "nubis_density_scale": self.density_sigma,
            "nubis_voxel_size": float(self.plan.voxel_size),
            "nubis_time": float(self.state.time),
            "nubis_preset": self.preset,
            "nubis_units": "metres",
            "nubis_frame": int(self.frame),
            "nubis_fps": float(self.fps),
            "nubis_noise_seed": int(self.noise_seed),
            "nubis_sun_direction": ",".join(f"{c:.6f}" for c in self.state.sun_direction),
            "nubis_settings": json.dumps(self.settings, sort_keys=True),
            "nubis_grids": ",".join(grids),
            "nubis_grid_classes": ",".join(f"{g}:{'vector' if g == 'velocity' else 'fog volume'}" for g in grids),
        }
        if "velocity" in grids:
            meta["nubis_velocity_units"] = "metres per second"
        return meta


def scene_options(scene, voxel_size: float | None = None) -> BakeOptions:
    """The bake the scene's Bake settings ask for (the Bake panel's), at `voxel_size` if given."""
    s = scene.nubis
    return BakeOptions(
        voxel_size=voxel_size or None, camera_only=s.bake_camera_only, half=s.bake_half, velocity=s.bake_velocity
    )


def bake_plan(scene, options: BakeOptions, wait: bool = True) -> tuple[CloudState, BakePlan]:
    """The scene's cloud state at its current frame and the bake's plan (tiles, memory estimate:
    refused politely before any GPU work when it does not fit). `wait` False plans without capturing
    the World's light (the plan does not depend on it); `options.vdb` False leaves the VDB clouds out (a
    comparison's Cycles renders their own files: vdbclouds.native)."""
    state = cloudstate.state_from_scene(scene, wait=wait)
    if not options.vdb:
        state.vdb_clouds = ()
    region = None
    if options.camera_only:
        # The camera's aspect only: a camera-only bake renders no image, so the image size limit does not apply.
        w, h = options.size or (scene.render.resolution_x, scene.render.resolution_y)
        inv = np.array(cloudstate.camera_inv_view_proj(scene, w, h))
        region = view_footprint(state, inv)
    plan = plan_bake(
        state,
        options.voxel_size or scene.nubis.bake_voxel_size,
        region=region,
        velocity=options.velocity,
        thin_cirrus=options.thin_cirrus,
        active_share=options.active_share,
    )
    state.cirrus_slab = plan.cirrus_slab
    return state, plan


def take(scene, options: BakeOptions) -> BakeSnapshot:
    """The bake of the scene's current frame, as it is now (planned and refused here when it does not fit)."""
    s = scene.nubis
    noise = runtime.cloud_gpu(s.noise_seed).noise  # made or loaded now: a seed change later makes a new set
    state, plan = bake_plan(scene, options)
    fps = sceneparams.scene_fps(scene)
    state.motion_dt = s.wind_time_scale / fps  # one frame of wind time, for the velocity grid
    return BakeSnapshot(
        state=state,
        plan=plan,
        noise=noise,
        fps=fps,
        frame=int(scene.frame_current),
        preset=s.preset,
        density_sigma=float(s.density_sigma),
        noise_seed=int(s.noise_seed),
        settings=_plain({k: v for k, v in state.params.items() if not lightvolume.lighting_only(k)}),
    )


def take_sequence(scene, frames: list[int], options: BakeOptions) -> list[BakeSnapshot]:
    """Every frame's snapshot, taken now: the scene is set to each frame in turn and back to the frame it
    was on. Frames whose field did not change share its arrays; when it changes from frame to frame and
    the copies would pass SEQUENCE_SNAPSHOT_LIMIT, refused before the first frame is read."""
    settings = scene.nubis
    res = settings.field_resolution
    per_frame = 3 * res * res * 4 * 4  # three RGBA float images
    if len(frames) > 1 and sceneparams.field_animated(settings):
        need = per_frame * len(frames)
        if need > SEQUENCE_SNAPSHOT_LIMIT:
            fit = max(1, SEQUENCE_SNAPSHOT_LIMIT // per_frame)
            raise NubisError(
                f"the field changes every frame, and a snapshot of {len(frames)} frames of it would hold "
                f"{human_bytes(need)}: bake at most {fit} frames at a time (the scene's frame range) or lower "
                "the field's Resolution"
            )
    current, subframe = scene.frame_current, scene.frame_subframe
    snaps: list[BakeSnapshot] = []
    try:
        for frame in frames:
            scene.frame_set(frame)
            snap = take(scene, options)
            if snaps:
                _share_fields(snap.state, snaps[-1].state)
            snaps.append(snap)
    finally:
        scene.frame_set(current, subframe=subframe)
    return snaps


def _share_fields(state: CloudState, previous: CloudState) -> None:
    """Reuse the previous frame's field arrays where this frame's are equal (one copy for a still field)."""
    for name in ("field_a", "field_b", "field_c"):
        a, b = getattr(state, name), getattr(previous, name)
        if a.shape == b.shape and np.array_equal(a, b):
            setattr(state, name, b)


def _plain(params: dict) -> dict:
    """The settings as JSON values (tuples and numpy numbers to lists and floats)."""
    out = {}
    for key, value in params.items():
        if isinstance(value, (list, tuple)):
            out[key] = [float(v) if isinstance(v, (float, np.floating)) else v for v in value]
        elif isinstance(value, np.generic):
            out[key] = value.item()
        else:
            out[key] = value
    return out
