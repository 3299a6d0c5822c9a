"""Tune the viewport's lighting defaults against Cycles (compare --mode full) over every preset.

Run from the repository root:
    .venv-5.3/bin/python tests/pictures/tune_lighting.py OUT_DIR [W H SAMPLES [EVALUATIONS]] [--presets A,B]
        [--params NAME,NAME] [--lights DIR [--lights-for A,B]] [--supersampling N]
(defaults 160 90 256 120, the README's parity size; SAMPLES is where Cycles starts: it adds samples
until its own noise is at most 5 %, at 256 volume bounces, more than any preset needs to converge,
docs/convergence.md)

Cycles' reference of each preset (compare --mode full into OUT_DIR/<preset>/, the camera's bake) does
not depend on the viewport's lighting terms, so it is rendered once; then a Nelder-Mead search re-renders
only the viewport. The objective is the mean over the presets of the luminance error plus |bias|, the
error measured on 4x4-pixel blocks: Cycles' per-pixel noise (5 %) would otherwise weigh as much as the
light's own error and flatten the search. Presets that set a tuned parameter themselves keep their
value. --params frees only those of TUNED (the others keep their defaults). Prints each improvement
and the before/after table (per pixel, as compare measures); nothing is written to the presets: copy
the result into core/schema.py by hand.

--lights DIR adds each preset lit by one light at a time (docs/viewport.md#one-light-at-a-time):
DIR/presets/<preset>_sun.toml and <preset>_sky.toml, copies of the preset with the World's or the
sun's strength at 0 (written when missing), and their converged references in DIR/<preset>_sun/ and
DIR/<preset>_sky/ (made as above when missing: 1.5-6 minutes of Cycles each on the 2-core machine).
Each counts in the objective as a preset of its own, so the sun's terms and the sky's are fitted to
what each light does and not to how their errors cancel in the scene. --lights-for limits the one-light
references to those presets (the others count with their scene alone).
"""

from __future__ import annotations

import json
import sys
import tomllib
from pathlib import Path

import numpy as np

from nubis_addon.core.jobs import CompareOptions

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

# name: (lower bound, upper bound, the first simplex's step)
TUNED = {
    "lighting_ms_attenuation": (0.0, 1.0, 0.08),
    "lighting_ms_contribution": (0.0, 1.0, 0.08),
    "lighting_sky_occlusion": (0.02, 4.0, 0.5),
    "lighting_diffusion_edge": (0.02, 4.0, 0.2),
    "lighting_ms_buildup": (0.0, 8.0, 0.8),
    "lighting_ambient": (0.3, 3.0, 0.2),
    "lighting_ambient_bottom": (0.0, 1.0, -0.2),
    "lighting_side_light": (0.0, 8.0, 0.5),
}
BLOCK = 4  # pixels a side of the blocks the search's luminance error is measured on


def one_light_preset(path: Path, light: str) -> str:
    """The preset's TOML lit by `light` alone ("sun" or "sky"): the other light's strength set to 0."""
    section = "[world]" if light == "sun" else "[sun]"
    lines = path.read_text(encoding="utf-8").splitlines()
    start = next((i for i, line in enumerate(lines) if line.strip() == section), None)
    if start is None:
        lines += ["", section, "strength = 0.0"]
    else:
        end = next((i for i in range(start + 1, len(lines)) if lines[i].startswith("[")), len(lines))
        key = next((i for i in range(start + 1, end) if lines[i].split("=")[0].strip() == "strength"), None)
        if key is None:
            lines.insert(start + 1, "strength = 0.0")
        else:
            lines[key] = "strength = 0.0"
    text = "\n".join(lines) + "\n"
    other = "world" if light == "sun" else "sun"
    assert tomllib.loads(text)[other]["strength"] == 0.0
    return text


def preset_overrides(path: Path) -> set[str]:
    data = tomllib.loads(path.read_text(encoding="utf-8"))
    return {f"lighting_{k}" for k in data.get("lighting", {})}


NOISE_TARGET = 0.05  # the parity targets ask Cycles' own noise to be at most 5 %


def reference(name: str, out: Path, width: int, height: int, samples: int) -> dict:
    """The preset's converged Cycles reference: OUT/<preset>/ as `compare --mode full --noise-target 5`
    leaves it (256 volume bounces, samples until Cycles' own noise is at most 5 %). A comparison already
    there at this size and noise is used as it is (the README's parity table and this tuning share one
    set of references); otherwise one is made, without the reference-march diagnostic."""
    import bpy

    from nubis_addon.blender.jobs import comparison

    try:
        m = json.loads((out / name / "metrics.json").read_text(encoding="utf-8"))
    except (OSError, ValueError):
        m = {}
    noise = (m.get("cycles_noise") or {}).get("luminance_rel_error", 1.0)
    if m.get("mode") == "full" and (m.get("width"), m.get("height")) == (width, height) and noise <= NOISE_TARGET:
        return m
    return comparison.compare(
        bpy.context.scene,
        out / name,
        CompareOptions(
            width=width,
            height=height,
            samples=samples,
            mode="full",
            noise_target=NOISE_TARGET * 100,
            reuse_reference=True,
            reference=False,
        ),
        step=lambda text: print(f"{name}: {text}", flush=True),
    )


PRESETS: list[str] = []  # --presets: fit these only (default: every shipped preset)
PARAMS: list[str] = []  # --params: free these only (default: all of TUNED)
LIGHTS: Path | None = None  # --lights: the folder of the one-light presets and references
LIGHTS_FOR: list[str] = []  # --lights-for: only these presets' one-light references (default: every one)
# the viewport shots of the search (compare takes 4; 2 keeps a round of the nine presets under a minute;
# --supersampling 1 keeps one with the one-light references, 27 shots, about as short)
SUPERSAMPLING = 2


def prepare(out: Path, width: int, height: int, samples: int) -> dict:
    """Each preset's converged Cycles reference (reference()) and its viewport shot."""
    import bpy

    from nubis_addon.blender import ensure_registered
    from nubis_addon.blender.jobs import pipeline
    from nubis_addon.blender.scene import scenepresets
    from nubis_addon.core import imageio
    from nubis_addon.core.presets import find_preset, list_presets, load_preset

    cases = []  # (label, preset file, folder of its reference)
    for name in PRESETS or list_presets():
        cases.append((name, find_preset(name), out))
        for light in ("sun", "sky") if LIGHTS and (not LIGHTS_FOR or name in LIGHTS_FOR) else ():
            path = LIGHTS / "presets" / f"{name}_{light}.toml"
            if not path.exists():
                path.parent.mkdir(parents=True, exist_ok=True)
                path.write_text(one_light_preset(find_preset(name), light), encoding="utf-8")
            cases.append((f"{name}_{light}", path, LIGHTS))
    shots = {}
    for name, path, where in cases:
        bpy.ops.wm.read_factory_settings(use_empty=True)
        ensure_registered()
        scene = bpy.context.scene
        scenepresets.apply_preset(scene, load_preset(path))
        m = reference(name, where, width, height, samples)
        ss = SUPERSAMPLING
        shot = pipeline.viewport_shot(scene, width * ss, height * ss, 0, "full", tuple(m["clip_box"]))
        cycles = imageio.read_image(where / name / "cycles.exr")
        shots[name] = (shot, ss, cycles, preset_overrides(path), m)
        noise = m["cycles_noise"]["luminance_rel_error"]
        ref = m["cycles_reference"]
        print(
            f"{name}: reference of {ref['samples']} samples at {m['volume_bounces']} bounces "
            f"({ref['cycles_s']:.0f} s of Cycles), Cycles noise {noise * 100:.1f} %",
            flush=True,
        )
    return shots


def _blocks(image: np.ndarray) -> np.ndarray:
    h, w = image.shape[0] // BLOCK * BLOCK, image.shape[1] // BLOCK * BLOCK
    return image[:h, :w].reshape(h // BLOCK, BLOCK, w // BLOCK, BLOCK, -1).mean(axis=(1, 3))


def evaluate(shots: dict, values: dict) -> dict:
    """Each preset's metrics (per pixel) with the block error added as `block_error`."""
    from nubis_addon.blender.jobs import pipeline
    from nubis_addon.core import metrics

    result = {}
    for name, (shot, ss, cycles, overrides, _m) in shots.items():
        base = dict(shot.state.params)
        shot.state.params.update({k: v for k, v in values.items() if k not in overrides})
        image = pipeline.downsample(pipeline.render_shot(shot), ss)
        shot.state.params.clear()
        shot.state.params.update(base)
        result[name] = metrics.compare(image, cycles)
        result[name]["block_error"] = metrics.compare(_blocks(image), _blocks(cycles))["luminance_rel_error"]
    return result


def objective(per_preset: dict) -> float:
    """The mean over the presets of the block luminance error plus the size of the bias: the parity limits
    hold both per preset."""
    return sum(m["block_error"] + abs(m["luminance_bias"]) for m in per_preset.values()) / len(per_preset)


def nelder_mead(score, start: np.ndarray, steps: np.ndarray, lo: np.ndarray, hi: np.ndarray, evaluations: int):
    """Minimise `score` from `start` (the points clipped to [lo, hi]); the best point and its score."""
    n = len(start)
    simplex = [np.clip(start, lo, hi)] + [np.clip(start + np.eye(n)[i] * steps[i], lo, hi) for i in range(n)]
    scores = [score(x) for x in simplex]
    count = len(simplex)
    while count < evaluations:
        order = np.argsort(scores)
        simplex, scores = [simplex[i] for i in order], [scores[i] for i in order]
        centre = np.mean(simplex[:-1], axis=0)
        reflected = np.clip(2 * centre - simplex[-1], lo, hi)
        fr = score(reflected)
        count += 1
        if fr < scores[0]:
            expanded = np.clip(3 * centre - 2 * simplex[-1], lo, hi)
            fe = score(expanded)
            count += 1
            simplex[-1], scores[-1] = (expanded, fe) if fe < fr else (reflected, fr)
        elif fr < scores[-2]:
            simplex[-1], scores[-1] = reflected, fr
        else:
            contracted = np.clip((centre + simplex[-1]) / 2, lo, hi)
            fc = score(contracted)
            count += 1
            if fc < scores[-1]:
                simplex[-1], scores[-1] = contracted, fc
            else:
                simplex = [simplex[0]] + [(simplex[0] + x) / 2 for x in simplex[1:]]
                scores = [scores[0]] + [score(x) for x in simplex[1:]]
                count += n
    best = int(np.argmin(scores))
    return simplex[best], scores[best]


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


def main(out_dir: str, width: int = 160, height: int = 90, samples: int = 256, evaluations: int = 120) -> None:
    import nubis_addon
    from nubis_addon.core.schema import defaults
    from nubis_addon.render.gpu_context import ensure_gpu_context

    nubis_addon.register()
    ensure_gpu_context()
    shots = prepare(Path(out_dir), width, height, samples)
    unknown = sorted(set(PARAMS) - set(TUNED))
    if unknown:
        raise SystemExit(f"--params: not tuned here: {', '.join(unknown)} (choose from {', '.join(TUNED)})")
    keys = PARAMS or list(TUNED)
    start = np.array([float(defaults()[k]) for k in keys])
    lo, hi, steps = (np.array([TUNED[k][i] for k in keys]) for i in range(3))
    before = evaluate(shots, dict(zip(keys, start, strict=True)))
    best = [objective(before)]
    print(f"start {best[0]:.4f}", flush=True)

    def score(x: np.ndarray) -> float:
        values = {k: float(v) for k, v in zip(keys, x, strict=True)}
        result = objective(evaluate(shots, values))
        if result < best[0]:
            best[0] = result
            print(f"{result:.4f} {json.dumps({k: round(v, 3) for k, v in values.items()})}", flush=True)
        return result

    x, _ = nelder_mead(score, start, steps, lo, hi, evaluations)
    values = {k: float(v) for k, v in zip(keys, x, strict=True)}
    after = evaluate(shots, values)
    print("before:\n" + table(before, shots))
    print("after:\n" + table(after, shots))
    print("tuned:", json.dumps({k: round(v, 3) for k, v in values.items()}))


def take_option(args: list[str], flag: str) -> str | None:
    """The value after `flag` in `args`, both removed from it; None when the flag is not there."""
    if flag not in args:
        return None
    i = args.index(flag)
    value = args[i + 1]
    del args[i : i + 2]
    return value


if __name__ == "__main__":
    args = sys.argv[1:]
    if (value := take_option(args, "--presets")) is not None:
        PRESETS.extend(value.split(","))
    if (value := take_option(args, "--params")) is not None:
        PARAMS.extend(value.split(","))
    if (value := take_option(args, "--supersampling")) is not None:
        SUPERSAMPLING = int(value)
    if (value := take_option(args, "--lights")) is not None:
        LIGHTS = Path(value)
    if (value := take_option(args, "--lights-for")) is not None:
        LIGHTS_FOR.extend(value.split(","))
    main(args[0] if args else "tune_lighting", *(int(a) for a in args[1:5]))
