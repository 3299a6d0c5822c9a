"""Tune the viewport's lighting defaults against Cycles (compare --mode full) over every preset.

Run from the repository root:
    .venv-5.3/bin/python tests/pictures/tune_lighting.py OUT_DIR [W H SAMPLES [ROUNDS]]

Cycles' reference of each preset (its own volume bounces, the camera's bake) does not depend on the
viewport's lighting terms, so it is rendered once; then a coordinate search re-renders only the
viewport. The objective is the mean luminance error over the presets (compare's metric). Presets
that set a tuned parameter themselves keep their value. Prints the search and the before/after
table; nothing is written to the presets: copy the result into core/schema.py by hand.
"""

from __future__ import annotations

import json
import sys
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

# name: (lower bound, upper bound, first step)
TUNED = {
    "lighting_ms_attenuation": (0.02, 1.0, 0.1),
    "lighting_ms_contribution": (0.1, 1.0, 0.15),
    "lighting_ms_eccentricity": (0.0, 1.0, 0.2),
    "lighting_ambient": (0.2, 2.0, 0.3),
    "lighting_ambient_bottom": (0.0, 1.0, 0.2),
    "lighting_powder": (0.0, 1.0, 0.25),
}


def preset_overrides(name: str) -> set[str]:
    from nubis_addon.core.presets import preset_dir

    data = tomllib.loads((preset_dir() / f"{name}.toml").read_text(encoding="utf-8"))
    return {f"lighting_{k}" for k in data.get("lighting", {})}


def prepare(out: Path, width: int, height: int, samples: int) -> dict:
    """Each preset's converged Cycles reference (compare --mode full with a noise estimate) and its
    viewport shot. A reference already in OUT_DIR/<preset>/ at this size and sample count is reused: it
    does not depend on the viewport's lighting, and the thick presets take minutes each."""
    import bpy
    from compare_presets import compare_preset  # the sibling script (this folder is on sys.path)

    from nubis_addon.blender import ensure_registered, pipeline, scene_io
    from nubis_addon.core import imageio
    from nubis_addon.core.presets import list_presets, load_preset

    shots = {}
    for name in list_presets():
        done = out / name / "metrics.json"
        m = json.loads(done.read_text(encoding="utf-8")) if done.exists() else {}
        if (m.get("width"), m.get("height"), m.get("samples")) == (width, height, samples):
            bpy.ops.wm.read_factory_settings(use_empty=True)
            ensure_registered()
            scene = bpy.context.scene
            scene_io.apply_preset(scene, load_preset(name))
        else:
            scene, m = compare_preset(name, out, width, height, samples)
            done.write_text(json.dumps(m, indent=2) + "\n", encoding="utf-8")  # with its total time
        ss = m["viewport_supersampling"]
        shot = pipeline.viewport_shot(scene, width * ss, height * ss, 0, "full", tuple(m["clip_box"]))
        cycles = imageio.read_image(out / name / "cycles.exr")
        shots[name] = (shot, ss, cycles, preset_overrides(name), m)
        noise = m["cycles_noise"]["luminance_rel_error"]
        print(f"{name}: reference in {m.get('total_s', 0):.0f} s, Cycles noise {noise * 100:.1f} %", flush=True)
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
    return sum(m["luminance_rel_error"] for m in per_preset.values()) / len(per_preset)


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
