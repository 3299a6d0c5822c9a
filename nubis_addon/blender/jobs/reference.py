"""Cycles as a reference for `compare`: samples until its own noise is under a target, and the reuse of
an earlier comparison's Cycles image when nothing Cycles sees has changed (docs/convergence.md#samples).

The noise of a Cycles image is measured as `compare --noise-estimate` measures it: the samples are split
over two halves rendered with different seeds, and half the relative difference of the halves' means is
the noise of their mean. Rounds of seed pairs are added until that is under the target; each round is
sized from the last measurement (noise falls as one over the square root of the samples). Every
sample is kept, so the result is the same unbiased estimate a single render of that many samples is.
"""

from __future__ import annotations

import hashlib
import json
import math
import re
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import bpy
import numpy as np

from ...core import imageio, metrics
from ...core.errors import NubisError
from ..scene import cycles_setup, sky, skycapture

# The most samples a noise target may ask of Cycles: 16384 at 160x90 is several hours on a 2-core machine.
MAX_SAMPLES = 16384
# Each round aims this much below the target, so one more round is rarely needed.
_AIM = 0.9


def noise_of(a: np.ndarray, b: np.ndarray) -> dict[str, float]:
    """Noise of the mean of two equally sampled renders (Cycles' seeds, or the viewport's jitter passes):
    half their difference."""
    own = metrics.compare(a, b)
    return {k: own[k] / 2 for k in ("alpha_rmse", "luminance_rel_error")}


@dataclass(frozen=True)
class NoiseGoal:
    """When sampling stops: once the noise of the luminance (a fraction) and, when given, of the alpha are
    at most these, or once `most` samples are spent. `who` and `unit` name the renderer and its samples
    in what is said."""

    luminance: float
    alpha: float | None = None
    most: int = MAX_SAMPLES
    who: str = "Cycles'"
    unit: str = "samples"

    def over(self, noise: dict[str, float]) -> float:
        """How far the noise is over the goal: at most 1 once it is met."""
        level = noise["luminance_rel_error"] / self.luminance
        if self.alpha is not None:
            level = max(level, noise["alpha_rmse"] / self.alpha)
        return level

    def describe(self, noise: dict[str, float] | None = None) -> str:
        """The goal's figures, or (with `noise`) the noise's."""
        lum = self.luminance if noise is None else noise["luminance_rel_error"]
        text = f"{lum * 100:.3g} %" if noise is None else f"{lum * 100:.1f} %"
        if self.alpha is not None:
            text += f" (alpha {self.alpha if noise is None else noise['alpha_rmse']:.2g})"
        return text


def sample_to_target(
    render: Callable[[int, int], np.ndarray],
    samples: int,
    goal: NoiseGoal | None,
    say: Callable[[str], None],
) -> tuple[np.ndarray, dict[str, float], int]:
    """The image, its noise and the samples taken. `render(samples, seed_offset)` renders once.

    Without a goal: two halves of `samples` (the noise estimate). With one: rounds of two halves,
    each sized from the noise just measured, until the noise meets the goal or its most samples are
    spent, which `say` reports."""
    per = max(1, samples // 2)
    sums = [None, None]
    taken = 0
    seed = 0
    while True:
        for half in (0, 1):
            image = render(per, seed) * per
            sums[half] = image if sums[half] is None else sums[half] + image
            seed += 1
        taken += 2 * per
        a, b = sums[0] / (taken / 2), sums[1] / (taken / 2)
        noise = noise_of(a, b)
        if goal is None or goal.over(noise) <= 1.0:
            return (a + b) / 2, noise, taken
        heard = f"{goal.who} noise is {goal.describe(noise)} after {taken} {goal.unit}"
        if taken >= goal.most:
            say(f"{heard} (the most a target may ask)")
            return (a + b) / 2, noise, taken
        need = min(goal.most, math.ceil(taken * (goal.over(noise) / _AIM) ** 2))
        per = max(1, math.ceil((need - taken) / 2))
        say(f"{heard}: {2 * per} more for {goal.describe()}")


# ---- reusing an earlier reference ---------------------------------------------------------------------

REFERENCE_FILE = "cycles.exr"


# OpenVDB writes a fresh UUID into each file's header, so two bakes of the same clouds differ there alone.
_UUID = re.compile(rb"[0-9A-Fa-f]{8}-[0-9A-Fa-f]{4}-[0-9A-Fa-f]{4}-[0-9A-Fa-f]{4}-[0-9A-Fa-f]{12}")


def _digest_vdb(path: Path) -> str:
    """The bake's bytes without the header's UUID."""
    h = hashlib.sha256()
    with open(path, "rb") as f:
        h.update(_UUID.sub(b"", f.read(128), count=1))
        for chunk in iter(lambda: f.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def _object_items(obj) -> list:
    items = [obj.name, obj.type, [list(row) for row in obj.matrix_world]]
    data = obj.data
    if data is None:
        return items
    items.append(data.name)
    if obj.type == "LIGHT":
        items += [data.type, list(data.color), data.energy, getattr(data, "angle", 0.0)]
    elif obj.type == "CAMERA":
        items += [data.type, data.lens, data.sensor_width, data.sensor_fit, data.shift_x, data.shift_y]
        items += [data.clip_start, data.clip_end]
    elif obj.type == "VOLUME":
        items += _volume_items(data)
    elif obj.type == "MESH":
        co = np.empty(len(data.vertices) * 3, np.float32)
        data.vertices.foreach_get("co", co)
        items += [hashlib.sha256(co.tobytes()).hexdigest(), [m.name if m else "" for m in data.materials]]
    return items


def _volume_items(volume) -> list:
    """A Volume as Cycles renders it: its file (and when it last changed), how its frames are read, its
    render settings and the Nubis cloud settings its comparison material is made from."""
    path = bpy.path.abspath(volume.filepath, library=volume.library)
    try:
        st = Path(path).stat()
        stamp = [st.st_size, st.st_mtime_ns]
    except OSError:
        stamp = []
    frames = [volume.is_sequence, volume.frame_start, volume.frame_duration, volume.frame_offset]
    render = [volume.render.space, volume.render.step_size, volume.render.clipping]
    cloud = volume.nubis_cloud
    return [path, stamp, frames, volume.sequence_mode, render, [cloud.enabled, cloud.grid, cloud.density]]


def key(scene, vdb_path: Path, width: int, height: int, bounces: int) -> str:
    """What Cycles' reference of a comparison depends on: the bake's bytes, the settings of the material
    the bake is rendered with, the World's nodes, the camera and the lights, every other visible
    object's transform and (for meshes) vertices, the render size, seed and bounces, and Blender's
    version. Not the viewport's lighting terms, which Cycles never sees."""
    s = scene.nubis
    material = [s.density_sigma, s.lighting_phase_g0, s.lighting_phase_g1, s.lighting_phase_mix]
    material += [s.lighting_cycles_mie, s.lighting_droplet_size, [list(st.glow_color) for st in s.storms]]
    view_layer = bpy.context.view_layer
    objects = [
        _object_items(obj)
        for obj in sorted(scene.objects, key=lambda o: o.name)
        if obj.visible_get(view_layer=view_layer) and obj.name != cycles_setup.VOLUME_NAME
    ]
    items = {
        "vdb": _digest_vdb(vdb_path),
        "material": material,
        "world": repr(skycapture.fingerprint(scene.world)),
        # How the sun reaches the clouds: through the air (blender/jobs/sun_air.py), which a reference made
        # before it did not do, or the lamp's colour.
        "sun": ["through the air, per shadow ray", sky.sun_air(scene)],
        "objects": objects,
        "camera": scene.camera.name if scene.camera else "",
        "render": [width, height, bounces, scene.cycles.seed, scene.cycles.max_bounces, scene.frame_current],
        "blender": list(bpy.app.version),
    }
    return hashlib.sha256(json.dumps(items, sort_keys=True, default=str).encode()).hexdigest()


def reusable(out: Path, wanted: str, samples: int, target: float | None) -> tuple[np.ndarray, dict] | None:
    """An earlier comparison's Cycles image in `out` made with the same key, and at least as good as asked:
    under the noise target, or with the same samples when there is none. None otherwise."""
    try:
        previous = json.loads((out / "metrics.json").read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    ref = previous.get("cycles_reference") or {}
    if ref.get("key") != wanted or not (out / REFERENCE_FILE).is_file():
        return None
    noise = previous.get("cycles_noise")
    if target is not None:
        if not noise or noise["luminance_rel_error"] > target:
            return None
    elif ref.get("samples") != samples:
        return None
    try:
        image = imageio.read_image(out / REFERENCE_FILE)
    except (OSError, NubisError):  # a damaged file is rendered again, not reported
        return None
    return image, {"samples": ref["samples"], "cycles_noise": noise, "cycles_s": ref.get("cycles_s", 0.0)}
