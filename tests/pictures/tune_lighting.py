"""Tune the viewport's lighting defaults against Cycles (compare --mode full) over every preset.

Run from the repository root:
    .venv-5.3/bin/python tests/pictures/tune_lighting.py OUT_DIR [W H SAMPLES [ROUNDS]]
(defaults 160 90 256 3, the README's parity size; Cycles renders each preset at its converged bounce
count from docs/convergence.json)

Cycles' reference of each preset (its own volume bounces, the camera's bake) does not depend on the
viewport's lighting terms, so it is rendered once; then a coordinate search re-renders only the
viewport. The objective is the mean over the presets of the luminance error plus |bias|. Presets
that set a tuned parameter themselves keep their value. Prints the search and the before/after
table; nothing is written to the presets: copy the result into core/schema.py by hand.
"""

from __future__ import annotations

import json
import sys
import time
import tomllib
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

# name: (lower bound, upper bound, first step)
TUNED = {
    "lighting_ms_attenuation": (0.0, 1.0, 0.02),
    "lighting_ms_contribution": (0.1, 1.0, 0.15),
    "lighting_ms_eccentricity": (0.0, 1.0, 0.2),
    "lighting_ambient": (0.2, 3.0, 0.3),
    "lighting_ambient_bottom": (0.0, 1.0, 0.2),
    "lighting_powder": (0.0, 1.0, 0.25),
    "lighting_sky_occlusion": (0.0, 3.0, 0.3),
}


def preset_overrides(name: str) -> set[str]:
    from nubis_addon.core.presets import preset_dir

    data = tomllib.loads((preset_dir() / f"{name}.toml").read_text(encoding="utf-8"))
    return {f"lighting_{k}" for k in data.get("lighting", {})}


def converged_bounces() -> dict[str, int]:
    """Each preset's converged volume-bounce count (docs/convergence.json: the count before the doubling
    that changed the mean by less than Cycles' noise)."""
    data = json.loads((ROOT / "docs" / "convergence.json").read_text(encoding="utf-8"))
    counts = {}
    for name, run in data.items():
        rows = run["rows"]
        counts[name] = rows[-1]["bounces"]
        for before, after in zip(rows, rows[1:], strict=False):
            if abs(after["change"]) < max(after["noise"], 0.005):
                counts[name] = before["bounces"]
                break
    return counts


def reference(name: str, out: Path, width: int, height: int, samples: int, bounces: int) -> dict:
    """The preset's converged Cycles reference: the camera's bake rendered twice with different seeds
    (their mean, and half their difference as the noise), as compare --mode full renders it, without
    compare's viewport renders. Written to OUT/<preset>/cycles.exr and reference.json."""
    import bpy

    from nubis_addon.blender import pipeline, scene_io
    from nubis_addon.core import imageio, metrics
    from nubis_addon.core.bakeplan import camera_voxel_size

    scene = bpy.context.scene
    folder = out / name
    folder.mkdir(parents=True, exist_ok=True)
    start = time.perf_counter()
    state = scene_io.state_from_scene(scene)
    inv = np.array(scene_io.camera_inv_view_proj(scene, width, height))
    voxel = camera_voxel_size(state, inv, width, height, scene.nubis.bake_voxel_size)
    baked = pipeline.bake(
        scene, folder / "clouds.vdb", voxel, camera_only=True, size=(width, height), thin_cirrus=pipeline.THIN_CIRRUS
    )
    renders = []
    for seed in (0, 1):
        scene.cycles.seed += seed
        try:
            renders.append(
                pipeline.render_cycles(
                    scene, width, height, samples // 2, str(baked.path), bounces=bounces, exact_samples=True
                )
            )
        finally:
            scene.cycles.seed -= seed
    cycles = (renders[0] + renders[1]) / 2
    imageio.write_image(folder / "cycles.exr", cycles)
    own = metrics.compare(renders[0], renders[1])
    m = {
        "width": width,
        "height": height,
        "samples": samples,
        "bounces": bounces,
        "voxel_size": baked.plan.voxel_size,
        "clip_box": list(pipeline.bake_clip_box(baked.plan)),
        "cycles_noise": {k: own[k] / 2 for k in ("alpha_rmse", "luminance_rel_error")},
        "total_s": time.perf_counter() - start,
    }
    (folder / "reference.json").write_text(json.dumps(m, indent=2) + "\n", encoding="utf-8")
    return m


SUPERSAMPLING = 2  # the viewport shots of the search (compare takes 4; 2 keeps a round under a minute)


def prepare(out: Path, width: int, height: int, samples: int) -> dict:
    """Each preset's converged Cycles reference and its viewport shot. A reference already in
    OUT_DIR/<preset>/ at this size and sample count is reused: it does not depend on the viewport's
    lighting, and the thick presets take minutes each."""
    import bpy

    from nubis_addon.blender import ensure_registered, pipeline, scene_io
    from nubis_addon.core import imageio
    from nubis_addon.core.presets import list_presets, load_preset

    bounces = converged_bounces()
    shots = {}
    for name in list_presets():
        bpy.ops.wm.read_factory_settings(use_empty=True)
        ensure_registered()
        scene = bpy.context.scene
        scene_io.apply_preset(scene, load_preset(name))
        done = out / name / "reference.json"
        m = json.loads(done.read_text(encoding="utf-8")) if done.exists() else {}
        if (m.get("width"), m.get("height"), m.get("samples")) != (width, height, samples):
            m = reference(name, out, width, height, samples, bounces.get(name, 256))
        ss = SUPERSAMPLING
        shot = pipeline.viewport_shot(scene, width * ss, height * ss, 0, "full", tuple(m["clip_box"]))
        cycles = imageio.read_image(out / name / "cycles.exr")
        shots[name] = (shot, ss, cycles, preset_overrides(name), m)
        noise = m["cycles_noise"]["luminance_rel_error"]
        print(
            f"{name}: reference at {m['bounces']} bounces in {m['total_s']:.0f} s, Cycles noise {noise * 100:.1f} %",
            flush=True,
        )
    return shots


def evaluate(shots: dict, values: dict) -> dict:
    from nubis_addon.blender import pipeline
    from nubis_addon.core import metrics

    result = {}
    for name, (shot, ss, cycles, overrides, _m) in shots.items():
        base = dict(shot.state.params)
        shot.state.params.update({k: v for k, v in values.items() if k not in overrides})
        image = pipeline.downsample(pipeline.render_shot(shot), ss)
        shot.state.params.clear()
        shot.state.params.update(base)
        result[name] = metrics.compare(image, cycles)
    return result


def objective(per_preset: dict) -> float:
    """The mean over the presets of the luminance error plus the size of its bias: the parity limits hold
    both per preset."""
    return sum(m["luminance_rel_error"] + abs(m["luminance_bias"]) for m in per_preset.values()) / len(per_preset)


def table(per_preset: dict, shots: dict) -> str:
    lines = [
        "| preset | alpha RMSE | luminance error | bias | IoU | Cycles noise (lum.) |",
        "|---|---|---|---|---|---|",
    ]
    for name, m in per_preset.items():
        noise = shots[name][4]["cycles_noise"]["luminance_rel_error"]
        lines.append(
            f"| {name} | {m['alpha_rmse']:.3f} | {m['luminance_rel_error'] * 100:.1f} % | "
            f"{m['luminance_bias'] * 100:+.1f} % | {m['silhouette_iou']:.2f} | {noise * 100:.1f} % |"
        )
    return "\n".join(lines)


def main(out_dir: str, width: int = 160, height: int = 90, samples: int = 256, rounds: int = 3) -> None:
    import nubis_addon
    from nubis_addon.core.schema import defaults
    from nubis_addon.render.gpu_context import ensure_gpu_context

    nubis_addon.register()
    ensure_gpu_context()
    shots = prepare(Path(out_dir), width, height, samples)
    values = {k: float(defaults()[k]) for k in TUNED}
    before = evaluate(shots, values)
    best = objective(before)
    print(f"start {best:.4f} {json.dumps(values)}", flush=True)
    steps = {k: spec[2] for k, spec in TUNED.items()}
    for r in range(rounds):
        for key, (lo, hi, _step) in TUNED.items():
            improved = True
            while improved:
                improved = False
                for sign in (1.0, -1.0):
                    trial = dict(values)
                    trial[key] = min(hi, max(lo, values[key] + sign * steps[key]))
                    if trial[key] == values[key]:
                        continue
                    score = objective(evaluate(shots, trial))
                    if score < best - 1e-4:
                        best, values, improved = score, trial, True
                        print(f"round {r} {key}={trial[key]:.3f}: {best:.4f}", flush=True)
                        break
            steps[key] /= 2
    after = evaluate(shots, values)
    print("before:\n" + table(before, shots))
    print("after:\n" + table(after, shots))
    print("tuned:", json.dumps({k: round(v, 3) for k, v in values.items()}))


if __name__ == "__main__":
    args = sys.argv[1:]
    main(args[0] if args else "tune_lighting", *(int(a) for a in args[1:5]))
