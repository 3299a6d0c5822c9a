"""Benchmark of the sparse tiled VDB bake (docs/bake.md): wall time from start-up to the file, peak
memory (maximum resident set), voxels per second of the active bounding box, and whether OpenVDB 10's
`vdb_print` (Debian's libopenvdb-tools) reads the file.

Run from the repository root:  .venv-5.3/bin/python tests/benchmarks/bench_bake.py [--quick]
Each bake is a fresh `python -m nubis_addon bake` process, timed and measured with os.wait4 (its own
peak RSS, start-up included). Ratios are measured in the same run. --quick skips the 20 m bakes.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

GIB = 1024**3


def run_bake(args: list[str]) -> tuple[float, int, str]:
    """Wall seconds, peak RSS in bytes and the summary line of one bake process."""
    start = time.perf_counter()
    proc = subprocess.Popen(
        [sys.executable, "-m", "nubis_addon", "bake", *args], cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE
    )
    out = proc.stdout.read().decode()
    err = proc.stderr.read().decode()
    _pid, status, usage = os.wait4(proc.pid, 0)
    seconds = time.perf_counter() - start
    if os.waitstatus_to_exitcode(status) != 0:
        raise SystemExit(f"bake {' '.join(args)} failed: {err.strip()}")
    return seconds, usage.ru_maxrss * 1024, out.strip()


def vdb_print_reads(path: Path) -> str:
    tool = shutil.which("vdb_print")
    if tool is None:
        return "not installed"
    r = subprocess.run([tool, str(path)], capture_output=True, text=True)
    return "yes" if r.returncode == 0 and "density" in r.stdout else f"NO ({r.stderr.strip()[:60]})"


def main() -> None:
    from nubis_addon.core import vdbwrite

    quick = "--quick" in sys.argv
    cases = [
        ("whole sky, 100 m", ["--voxel-size", "100"]),
        ("camera only, 40 m", ["--voxel-size", "40", "--camera-only"]),
    ]
    if not quick:
        cases += [
            ("camera only, 20 m", ["--voxel-size", "20", "--camera-only"]),
            ("camera only, 20 m, --half", ["--voxel-size", "20", "--camera-only", "--half"]),
        ]
    rows = []
    with tempfile.TemporaryDirectory(prefix="nubis-bench-bake-") as tmp:
        for label, args in cases:
            path = Path(tmp) / "clouds.vdb"
            seconds, rss, summary = run_bake([*args, "--out", str(path)])
            info = vdbwrite.read_grid_info(path)["density"]
            (x0, y0, z0), (x1, y1, z1) = info.index_bbox
            bbox = (x1 - x0 + 1) * (y1 - y0 + 1) * (z1 - z0 + 1)
            box = summary.split(": ", 1)[1].split(" voxels")[0]
            rows.append(
                {
                    "label": label,
                    "box": box,
                    "seconds": seconds,
                    "rss": rss,
                    "bbox": bbox,
                    "active": info.active_voxels,
                    "rate": bbox / seconds,
                    "file": path.stat().st_size,
                    "vdb_print": vdb_print_reads(path),
                }
            )
            path.unlink()
    base = rows[0]["rate"]
    print(f"sparse tiled bake, default preset, {os.cpu_count()} cores, Python {sys.version.split()[0]}")
    head = "| bake | box (voxels) | wall (s) | peak RSS | active bbox | active voxels | M voxels/s of bbox | "
    print(head + "vs 100 m | file | vdb_print (OpenVDB 10) |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        print(
            f"| {r['label']} | {r['box']} | {r['seconds']:.1f} | {r['rss'] / GIB:.2f} GB | {r['bbox'] / 1e6:.0f} M | "
            f"{r['active'] / 1e6:.1f} M | {r['rate'] / 1e6:.1f} | {r['rate'] / base:.2f}x | "
            f"{r['file'] / 1024**2:.0f} MiB | {r['vdb_print']} |"
        )


if __name__ == "__main__":
    main()
