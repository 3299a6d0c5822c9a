"""Benchmark: the VDB clouds' light on a family of clouds against converged Cycles (docs/vdb.md#light).

Run from the repository root:  .venv-5.3/bin/python tests/benchmarks/bench_vdb_light.py [OUTDIR] [--only A,B]
                                                                                          [--checkout DIR]

Makes each cloud once with OpenVDB's own Python module (Blender's bundle), into OUTDIR (the system's temporary
folder by default), then runs `compare --mode full --noise-target 5` at 160x90 on each with the default
preset's sky, sun and camera, reusing the Cycles reference of an earlier run when nothing Cycles sees has
changed (`--reuse-reference`): a second run with other light factors in the shaders costs only the viewport.
`--checkout DIR` runs another checkout's `compare` on the same clouds and references (a candidate's shaders);
with `--viewport-only` it runs that checkout's `render` at the comparison's size and supersampling instead
and measures it against the reference an earlier run left (the fit's quick loop: no bake, no march).

The family, fixed before the light factors were fitted (docs/vdb.md#light):
- fit: `cumulus` (the tests' cauliflower, 50 m voxels), `billowy` (a finer, more eroded one, 25 m), `deck`
  (a broken stratocumulus deck 6.4 km across seen from below, 50 m), `wisps` (thin streaks, 25 m);
- check, never seen by the fit: `cumulus_s3` (another seed, turned), `tower_object` and `tower_world` (a
  detailed tower of 5 m voxels on an object scaled x4, Render > Space Object and World, through a .blend);
- moved: `tower_rotated`, `tower_parented` (to an Empty moved afterwards) and `tower_delta` (delta location,
  rotation and scale), the World-space tower moved as an artist moves a Volume.

Prints one table: cloud, set, world voxel size, active voxels, luminance error, bias, alpha RMSE, silhouette
IoU, Cycles' samples and noise, and the run's seconds; adds them to OUTDIR/light.json
(light_viewport_only.json with --viewport-only).
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests"))

import vdb_helpers  # noqa: E402

BASE = vdb_helpers.DEFAULT_VIEW_BASE
FINE = ((4, 0.5), (9, 0.25), (18, 0.15), (36, 0.1))  # one more octave than the cumulus: a billowy edge


def deck(seed: int = 5, n: int = 128, nz: int = 16, peak: float = 0.02) -> np.ndarray:
    """A broken deck: cells of cover from two octaves, a lumpy top, a flat base, holes where cover is low."""
    rng = np.random.default_rng(seed)
    cover = (
        0.6 * vdb_helpers._value_noise((1, n, n), (1, 6, 6), rng)[0]
        + 0.4 * vdb_helpers._value_noise((1, n, n), (1, 16, 16), rng)[0]
    )
    z = np.arange(nz, dtype=np.float64)[:, None, None]
    top = nz * (0.3 + 0.7 * cover)[None]
    lumps = 0.5 + 2.0 * vdb_helpers._value_noise((nz, n, n), (3, 24, 24), rng)
    density = np.clip((top - z) / lumps, 0, 1) * np.clip((z - 1.0) / 1.5, 0, 1)
    density *= np.clip((cover - 0.38) / 0.12, 0, 1)[None]
    return (density * peak).astype(np.float32)


def wisps(seed: int = 9, n: int = 128, nz: int = 24, peak: float = 0.006) -> np.ndarray:
    """Thin streaks along x: noise with long cells along x, kept in a narrow band, under a soft envelope."""
    rng = np.random.default_rng(seed)
    streak = (
        vdb_helpers._value_noise((nz, n, n), (4, 20, 3), rng) * 0.7
        + vdb_helpers._value_noise((nz, n, n), (8, 40, 6), rng) * 0.3
    )
    band = np.clip(1.0 - np.abs(streak - 0.5) / 0.08, 0, 1)
    zz, yy, xx = np.meshgrid(*(np.linspace(-1, 1, s) for s in (nz, n, n)), indexing="ij")
    envelope = np.clip(1.0 - (xx**2 + yy**2 + (zz * 1.2) ** 2), 0, 1)
    return (band * envelope * peak).astype(np.float32)


# name: (set, dense maker, voxel size in the file, turn, object scale, render space)
CLOUDS = {
    "cumulus": ("fit", lambda: vdb_helpers.cumulus(), 50.0, 0.5, 1.0, None),
    "billowy": (
        "fit",
        lambda: vdb_helpers.cumulus(128, 88, seed=11, puffs=50, erosion=9.0, octaves=FINE),
        25.0,
        0.9,
        1.0,
        None,
    ),
    "deck": ("fit", deck, 50.0, 0.2, 1.0, None),
    "wisps": ("fit", wisps, 25.0, 0.7, 1.0, None),
    "cumulus_s3": ("check", lambda: vdb_helpers.cumulus(seed=3), 50.0, 1.2, 1.0, None),
    "tower_object": (
        "check",
        lambda: vdb_helpers.cumulus(128, 176, seed=21, puffs=60, erosion=9.0, octaves=FINE),
        5.0,
        0.3,
        4.0,
        "OBJECT",
    ),
    "tower_world": (
        "check",
        lambda: vdb_helpers.cumulus(128, 176, seed=21, puffs=60, erosion=9.0, octaves=FINE),
        5.0,
        0.3,
        4.0,
        "WORLD",
    ),
}
TOWER = CLOUDS["tower_world"][1:]
# The tower moved as the done-when's transforms move it (the same physical cloud in World space): set
# "moved", compared as the check clouds are.
CLOUDS.update({f"tower_{move}": ("moved", *TOWER) for move in ("rotated", "parented", "delta")})

BLEND_SCRIPT = """
import sys
sys.path.insert(0, sys.argv[-5])
import bpy
from nubis_addon.blender import ensure_registered
from nubis_addon.blender.scene import datafield, cloudstate, scenepresets, vdbclouds
from nubis_addon.core.presets import load_preset
vdb, blend, space, move = sys.argv[-4:]
bpy.ops.wm.read_factory_settings(use_empty=True)
ensure_registered()
scene = bpy.context.scene
scenepresets.apply_preset(scene, load_preset("default"))
obj = vdbclouds.add_files(scene, [vdb])[0]
obj.location, obj.scale = {base}, ({scale},) * 3
obj.data.render.space = space
if move == "rotated":
    obj.rotation_euler = (0.15, -0.1, 0.8)
elif move == "parented":  # an Empty moved after the parenting carries the cloud to where the others stand
    empty = bpy.data.objects.new("Carrier", None)
    scene.collection.objects.link(empty)
    obj.parent = empty
    obj.location = (obj.location[0] - 400.0, obj.location[1] + 300.0, obj.location[2] - 200.0)
    empty.location, empty.rotation_euler = (400.0, -300.0, 200.0), (0.0, 0.0, 0.0)
elif move == "delta":
    obj.location = (obj.location[0] - 250.0, obj.location[1], obj.location[2])
    obj.delta_location, obj.delta_rotation_euler = (250.0, 0.0, 0.0), (0.0, 0.0, 0.6)
    obj.scale, obj.delta_scale = ({scale} / 1.25,) * 3, (1.25, 1.25, 1.25)
s = scene.nubis
s.density_cover, s.cirrus_coverage = 0.0, 0.0
s.storms.clear()
datafield.generate_fields(scene)
bpy.ops.wm.save_as_mainfile(filepath=blend)
"""


def make(out: Path, name: str) -> list[str]:
    """The cloud's file (made once) and the `compare` arguments that show it."""
    _set, dense_of, voxel, turn, scale, space = CLOUDS[name]
    stem = name.rsplit("_", 1)[0] if space else name
    vdb = out / f"{stem}.vdb"
    if not vdb.exists():
        vdb_helpers.write_cloud(vdb, dense_of(), (0.0, 0.0, 0.0) if space else BASE, voxel, turn)
    if not space:
        return ["--vdb", str(vdb)]
    blend = out / f"{name}.blend"
    if not blend.exists():
        script = out / "make_blend.py"
        script.write_text(BLEND_SCRIPT.format(base=tuple(BASE), scale=scale))
        move = name.rsplit("_", 1)[1] if CLOUDS[name][0] == "moved" else ""
        subprocess.run([sys.executable, str(script), str(ROOT), str(vdb), str(blend), space, move], check=True)
    return ["--blend", str(blend)]


def compare(checkout: Path, out: Path, name: str, source: list[str]) -> dict:
    run = out / name
    cmd = [sys.executable, "-m", "nubis_addon", "compare", *source, "--out", str(run), "--mode", "full"]
    cmd += ["--noise-target", "5", "--width", "160", "--height", "90", "--reuse-reference"]
    t = time.perf_counter()
    r = subprocess.run(cmd, cwd=checkout, capture_output=True, text=True)
    if r.returncode:
        raise SystemExit(f"{name}: compare failed:\n{r.stderr}")
    m = json.loads((run / "metrics.json").read_text())
    m["run_s"] = time.perf_counter() - t
    return m


VIEWPORT_SCRIPT = """
import os
import sys
sys.path.insert(0, os.getcwd())
from types import SimpleNamespace
import numpy as np
from nubis_addon.blender.headless import commands
from nubis_addon.blender.jobs import comparison, pipeline, snapshot
from nubis_addon.core import imageio
from nubis_addon.core.jobs import BakeOptions
from nubis_addon.render.gpu_context import ensure_gpu_context
kind, source, out, voxel = sys.argv[-4:]
args = SimpleNamespace(blend=source if kind == "--blend" else None, preset=None)
scene = commands.load_scene(args, False)
if kind == "--vdb":
    commands._add_vdb_clouds(scene, [source], False)
ensure_gpu_context()
# The comparison's clip box (its bake's), which also sets the light volumes' extent.
options = BakeOptions(float(voxel), camera_only=True, size=(160, 90), thin_cirrus=comparison.THIN_CIRRUS, vdb=False)
clip = comparison.bake_clip_box(snapshot.bake_plan(scene, options, wait=False)[1])
shot = pipeline.viewport_shot(scene, 640, 360, 0, "full", clip)
big = pipeline.render_shot(shot, comparison.COMPARE_PASSES).astype(np.float64)
imageio.write_image(out, big.reshape(90, 4, 160, 4, 4).mean(axis=(1, 3)).astype(np.float32))
"""


def viewport_only(checkout: Path, out: Path, name: str, source: list[str]) -> dict:
    """The checkout's viewport as compare draws it (full mode, 4x the size, its passes, box-filtered down),
    against the Cycles image an earlier comparison left in OUTDIR/NAME."""
    from nubis_addon.core import imageio, metrics

    exr = out / name / "candidate.exr"
    script = out / "viewport_only.py"
    script.write_text(VIEWPORT_SCRIPT)
    earlier = json.loads((out / name / "metrics.json").read_text())
    cmd = [sys.executable, str(script), *source, str(exr), str(earlier["voxel_size"])]
    t = time.perf_counter()
    r = subprocess.run(cmd, cwd=checkout, capture_output=True, text=True)
    if r.returncode:
        raise SystemExit(f"{name}: the viewport failed:\n{r.stderr[-3000:]}")
    m = metrics.compare(imageio.read_image(exr), imageio.read_image(out / name / "cycles.exr"))
    m.update(samples=earlier["samples"], cycles_noise=earlier["cycles_noise"], run_s=time.perf_counter() - t)
    m["cycles_reference"] = {"reused": True}
    return m


def main() -> None:
    p = argparse.ArgumentParser()
    p.add_argument("out", nargs="?", default=str(Path(tempfile.gettempdir()) / "nubis-vdb-light"))
    p.add_argument("--only", default="", help="comma-separated cloud names")
    p.add_argument("--checkout", default=str(ROOT), help="the checkout whose compare runs")
    p.add_argument("--viewport-only", action="store_true", help="the checkout's render against the reference")
    args = p.parse_args()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    names = [n for n in args.only.split(",") if n] or list(CLOUDS)
    rows = {}
    for name in names:
        source = make(out, name)
        m = (viewport_only if args.viewport_only else compare)(Path(args.checkout), out, name, source)
        rows[name] = {
            "set": CLOUDS[name][0],
            "voxel_m": CLOUDS[name][2] * CLOUDS[name][4],
            "luminance_rel_error": m["luminance_rel_error"],
            "luminance_bias": m["luminance_bias"],
            "alpha_rmse": m["alpha_rmse"],
            "silhouette_iou": m["silhouette_iou"],
            "cycles_samples": m["samples"],
            "cycles_noise": m["cycles_noise"]["luminance_rel_error"],
            "reference_reused": m["cycles_reference"]["reused"],
            "seconds": m["run_s"],
        }
        r = rows[name]
        print(
            f"{name:13s} {r['set']:5s} {r['voxel_m']:5.0f} m  lum {r['luminance_rel_error'] * 100:5.1f} %  "
            f"bias {r['luminance_bias'] * 100:+5.1f} %  alpha RMSE {r['alpha_rmse']:.4f}  IoU {r['silhouette_iou']:.3f}"
            f"  Cycles {r['cycles_samples']} samples, {r['cycles_noise'] * 100:.1f} % noise  {r['seconds']:.0f} s",
            flush=True,
        )
    report = out / ("light_viewport_only.json" if args.viewport_only else "light.json")
    earlier = json.loads(report.read_text()) if report.exists() else {}
    report.write_text(json.dumps({**earlier, **rows}, indent=1))  # a run of some clouds keeps the others


if __name__ == "__main__":
    main()
