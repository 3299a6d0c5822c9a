"""The light at the edges of the day against a path-traced truth (docs/sky.md#the-sun-each-cloud-sees).

Each cell is `compare --mode full --noise-target T` (the reference-march diagnostic left out, the bake's
voxels no finer than `--voxel-floor`, 30 m as compare --draft's) with Cycles'
shell replaced by the truth of tests/atmosphere_truth.py: every shadow ray towards the sun carries the
standard atmosphere's transmittance along its own path, integrated in the shell's own nodes, not read from
the table the viewport and the production shell share. So the viewport's luminance error, bias and alpha
RMSE printed are against a reference that computes the sun's attenuation per point itself. `--production`
also renders compare's own Cycles (the production shell) for each cell and prints its bias against the truth.

Run from the repository root:
    .venv-5.3/bin/python tests/benchmarks/sunset_truth.py OUT [--size 160x90] [--noise-target 5]
        [--production] [--light sun|sky] [CELL ...]
a CELL is PRESET[@ELEVATION[@AZIMUTH]] (degrees), e.g. default@4 or altocumulus_over_stratocumulus@2;
without cells, the issue's: the default at 4, 1 and -1 degrees and the layered preset at 2. `--light sun`
lights each cell by the sun alone (the World's strength 0), `--light sky` by the World alone (the sun's 0),
on both sides, to tell which light's model an error comes from (docs/viewport.md#one-light-at-a-time).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests"))

CELLS = ("default@4", "default@1", "default@-1", "altocumulus_over_stratocumulus@2")


def _scene(cell: str, light: str = ""):
    import bpy

    from nubis_addon.blender import ensure_registered
    from nubis_addon.blender.scene import scenepresets
    from nubis_addon.core.presets import load_preset

    name, *sun = cell.split("@")
    preset = load_preset(name)
    if sun:
        preset.extra["sun"]["elevation"] = float(sun[0])
    if len(sun) > 1:
        preset.extra["sun"]["azimuth"] = float(sun[1])
    if light:
        preset.extra.setdefault("world" if light == "sun" else "sun", {})["strength"] = 0.0
    bpy.ops.wm.read_factory_settings(use_empty=True)
    ensure_registered()
    scene = bpy.context.scene
    scenepresets.apply_preset(scene, preset)
    return scene


def main() -> None:
    import atmosphere_truth

    from nubis_addon.blender.jobs import comparison
    from nubis_addon.core import imageio, metrics
    from nubis_addon.core.jobs import CompareOptions
    from nubis_addon.render.gpu_context import ensure_gpu_context

    parser = argparse.ArgumentParser()
    parser.add_argument("out")
    parser.add_argument("cells", nargs="*", default=list(CELLS))
    parser.add_argument("--size", default="160x90")
    parser.add_argument("--noise-target", type=float, default=5.0)
    parser.add_argument("--production", action="store_true")
    parser.add_argument("--light", choices=("sun", "sky"), default="", help="one light alone (both by default)")
    parser.add_argument(
        "--voxel-floor", type=float, default=30.0, help="the bake's coarsest voxels (compare --draft's)"
    )
    args = parser.parse_intermixed_args()
    width, height = (int(v) for v in args.size.split("x"))
    ensure_gpu_context()
    import nubis_addon

    nubis_addon.register()
    print(f"truth's quadrature against a 20000-step integral: {atmosphere_truth.self_check() * 100:.2f} % at most")
    options = CompareOptions(
        width=width,
        height=height,
        mode="full",
        noise_target=args.noise_target,
        reference=False,
        voxel_floor=args.voxel_floor,
    )
    rows = []
    for cell in args.cells:
        out = Path(args.out) / (cell.replace("@", "_") + (f"_{args.light}" if args.light else ""))
        t = time.perf_counter()
        with atmosphere_truth.installed():
            m = comparison.compare(
                _scene(cell, args.light), out, options, step=lambda text, c=cell: print(f"  {c}: {text}", flush=True)
            )
        row = [
            cell,
            m["luminance_rel_error"],
            m["luminance_bias"],
            m["alpha_rmse"],
            m["samples"],
            time.perf_counter() - t,
        ]
        if args.production:
            own = Path(args.out) / (cell.replace("@", "_") + "_production")
            comparison.compare(_scene(cell, args.light), own, options)
            truth = imageio.read_image(out / "cycles.exr")
            mine = imageio.read_image(own / "cycles.exr")
            row.append(metrics.compare(mine, truth)["luminance_bias"])
        rows.append(row)
        print(f"  {cell}: done in {row[5]:.0f} s", flush=True)
    print(f"\nviewport against the truth, {width}x{height}, full mode, Cycles' noise at most {args.noise_target:g} %")
    print(
        f"{'cell':<36}{'lum. error':>11}{'bias':>9}{'alpha RMSE':>12}{'samples':>9}"
        + ("  production vs truth" if args.production else "")
    )
    for row in rows:
        extra = f"{row[6] * 100:>+19.1f} %" if args.production else ""
        print(f"{row[0]:<36}{row[1] * 100:>10.1f}%{row[2] * 100:>+8.1f}%{row[3]:>12.4f}{row[4]:>9d}" + extra)


if __name__ == "__main__":
    main()
