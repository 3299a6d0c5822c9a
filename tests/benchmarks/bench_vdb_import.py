"""Benchmark: a large VDB cloud from marking it to its first drawn frame (docs/measurements.md#vdb-import).

Run from the repository root:  .venv-5.3/bin/python tests/benchmarks/bench_vdb_import.py [MILLIONS]

Makes a cloud of at least MILLIONS (100 by default) million active voxels with OpenVDB's own Python module
(Blender's bundle), block by block: a billowy mass of value noise, 10 m voxels, written once to the system's
temporary folder and reused. Then, each in a process of its own (so its peak memory is its own):

- marking the Volume and drawing the first frame at the file's own voxels (the default budget);
- the same under a budget that makes it a coarser level (NUBIS_VDB_GPU_BUDGET).

Prints one table: the file, the seconds from marking to the first frame (reading and packing, upload and
march), the level drawn, its bricks on the GPU, the process's peak resident memory over what it held
before marking, and the dense bounding box at half floats for scale (the reader never makes it).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

BLOCK = 128  # voxels per side of one block written (an OpenVDB lower internal node)
VOXEL = 10.0


def _value_noise(rng, shape, cells: int) -> np.ndarray:
    """Smooth noise in [0, 1] over a block: a coarse random lattice, trilinearly interpolated."""
    lattice = rng.random((cells + 2,) * 3, dtype=np.float32)
    axes = [np.linspace(0, cells, n, endpoint=False, dtype=np.float32) for n in shape]
    idx = [np.floor(a).astype(np.int64) for a in axes]
    t = [a - i for a, i in zip(axes, idx, strict=True)]
    out = np.zeros(shape, np.float32)
    for dz in (0, 1):
        wz = (t[0] if dz else 1 - t[0])[:, None, None]
        for dy in (0, 1):
            wy = (t[1] if dy else 1 - t[1])[None, :, None]
            for dx in (0, 1):
                wx = (t[2] if dx else 1 - t[2])[None, None, :]
                out += wz * wy * wx * lattice[np.ix_(idx[0] + dz, idx[1] + dy, idx[2] + dx)]
    return out


def make_cloud(path: Path, millions: int) -> dict:
    """Blocks of BLOCK^3 voxels in a box of about three times `millions` million voxels; a voxel is cloud
    where an ellipsoid eroded by noise is positive (about 44 % of the box)."""
    from nubis_addon.core import bundled

    vdb = bundled.openvdb()
    n = max(2, round(6 * (millions / 100) ** (1 / 3)))
    blocks = (n, n, max(1, n * 2 // 3))  # x, y, z: a mass wider than tall (6 x 6 x 4 blocks: 133 M voxels)
    size = np.array(blocks) * BLOCK
    grid = vdb.FloatGrid()
    grid.name = "density"
    grid.gridClass = vdb.GridClass.FOG_VOLUME
    rng = np.random.default_rng(11)
    for bz in range(blocks[2]):
        for by in range(blocks[1]):
            for bx in range(blocks[0]):
                o = np.array([bx, by, bz]) * BLOCK
                z, y, x = np.mgrid[0:BLOCK, 0:BLOCK, 0:BLOCK].astype(np.float32)
                u = ((x + o[0]) / size[0] - 0.5) * 2
                v = ((y + o[1]) / size[1] - 0.5) * 2
                w = ((z + o[2]) / size[2] - 0.5) * 2
                shape = 1.0 - np.sqrt(u * u + v * v + 1.4 * w * w)
                noise = _value_noise(rng, (BLOCK,) * 3, 4) * 0.6 + _value_noise(rng, (BLOCK,) * 3, 12) * 0.4
                density = np.clip((shape + (noise - 0.5) * 0.5) * 0.08, 0.0, None).astype(np.float32)
                block = np.ascontiguousarray(density.transpose(2, 1, 0))
                grid.copyFromArray(block, ijk=tuple(int(c) for c in o), tolerance=1e-5)
    grid.transform = vdb.createLinearTransform(voxelSize=VOXEL)
    vdb.write(str(path), grids=[grid])
    return {"active": int(grid.activeVoxelCount()), "box": [int(c) for c in size]}


def _status_bytes(field: str) -> int:
    """A memory field of /proc/self/status (VmRSS: resident now; VmHWM: its peak), in bytes."""
    with open("/proc/self/status", encoding="utf-8") as f:
        for line in f:
            if line.startswith(field + ":"):
                return int(line.split()[1]) * 1024
    return 0


def child(path: str) -> None:
    """One measurement: a fresh scene with the default sky, the Volume added, then marked and drawn."""
    import bpy

    from nubis_addon.blender import ensure_registered
    from nubis_addon.blender.jobs import pipeline
    from nubis_addon.blender.scene import scenepresets
    from nubis_addon.core.presets import load_preset

    bpy.ops.wm.read_factory_settings(use_empty=True)
    ensure_registered()
    scene = bpy.context.scene
    scenepresets.apply_preset(scene, load_preset("default"))
    scene.nubis.density_cover = 0.0
    pipeline.render_viewport(scene, 480, 270)  # the sky's own first frame (noise, shaders): not the cloud's
    vol = bpy.data.volumes.new("big")
    vol.filepath = path
    obj = bpy.data.objects.new("big", vol)
    scene.collection.objects.link(obj)
    # Where the default camera looks: the mass's base centred about 5 km ahead, 1.4 km up.
    size = np.array(json.loads(Path(path).with_suffix(".json").read_text())["box"]) * VOXEL
    obj.location = (-1500.0 - size[0] / 2, -2000.0 - size[1] / 2, 1400.0)
    before = _status_bytes("VmRSS")
    with open("/proc/self/clear_refs", "w", encoding="utf-8") as f:
        f.write("5")  # resets VmHWM to the current resident size (Linux)
    t = time.perf_counter()
    vol.nubis_cloud.enabled = True
    image = pipeline.render_viewport(scene, 480, 270)
    seconds = time.perf_counter() - t
    [placed] = pipeline.viewport_shot(scene, 32, 18).state.vdb_clouds
    cloud = placed.cloud
    box = np.subtract(cloud.bounds[1], cloud.bounds[0]) + 1
    print(
        json.dumps(
            {
                "seconds": seconds,
                "level": cloud.level,
                "gpu_bytes": cloud.gpu_bytes,
                "peak_over_before": _status_bytes("VmHWM") - before,
                "dense_box_half": int(np.prod(box.astype(np.int64))) * 2 * 8**cloud.level,
                "cloud_pixels": float((image[..., 3] > 0.5).mean()),
            }
        )
    )
    sys.stdout.flush()
    os._exit(0)


def main() -> None:
    if len(sys.argv) > 2 and sys.argv[1] == "--child":
        child(sys.argv[2])
        return
    millions = int(sys.argv[1]) if len(sys.argv) > 1 else 100
    path = Path(tempfile.gettempdir()) / f"nubis_bench_cloud_{millions}M.vdb"
    meta = path.with_suffix(".json")
    if not (path.is_file() and meta.is_file()):
        t = time.perf_counter()
        info = make_cloud(path, millions)
        info["make_s"] = time.perf_counter() - t
        meta.write_text(json.dumps(info))
    info = json.loads(meta.read_text())
    rows = []
    for label, budget in (("default budget", None), ("budget 128 MB", "128")):
        env = dict(os.environ)
        env.pop("NUBIS_VDB_GPU_BUDGET", None)
        if budget:
            env["NUBIS_VDB_GPU_BUDGET"] = budget
        r = subprocess.run(
            [sys.executable, __file__, "--child", str(path)], env=env, capture_output=True, text=True, cwd=ROOT
        )
        lines = [ln for ln in r.stdout.splitlines() if ln.startswith("{")]
        if r.returncode != 0 or not lines:
            print(r.stderr[-3000:])
            raise SystemExit(f"the {label} run failed")
        rows.append((label, json.loads(lines[-1])))
    box = "x".join(map(str, info["box"]))
    print(
        f"file: {path.name}, {path.stat().st_size / 2**20:.0f} MB, {info['active'] / 1e6:.1f} M active voxels, "
        f"box {box} of {VOXEL:g} m voxels (made in {info.get('make_s', 0):.0f} s)"
    )
    print(f"{'run':<16} {'mark to frame':>14} {'level':>6} {'GPU bricks':>11} {'peak memory':>12} {'dense box':>10}")
    for label, m in rows:
        print(
            f"{label:<16} {m['seconds']:>12.1f} s {m['level']:>6} {m['gpu_bytes'] / 2**20:>8.0f} MB "
            f"{m['peak_over_before'] / 2**20:>9.0f} MB {m['dense_box_half'] / 2**20:>7.0f} MB"
        )


if __name__ == "__main__":
    main()
