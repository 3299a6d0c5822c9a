"""Make the real-time viewport pictures of docs/guide.md from the `preview` command's outputs: the first
redraw next to the one after 16 and 64 redraws (480x270), and an orbit strip (320x180, 1.5 degrees and
one redraw per frame, the wind blowing).

Run from the repository root:  .venv-5.3/bin/python tests/pictures/viewport.py OUT_DIR
It runs `python -m nubis_addon preview` three times and writes viewport_convergence.png and
viewport_orbit.png into OUT_DIR.
"""

from __future__ import annotations

import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))


def _preview(out: Path, *args: str) -> None:
    cmd = [sys.executable, "-m", "nubis_addon", "preview", "--out", str(out), *args]
    r = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True)
    if r.returncode:
        raise SystemExit(r.stderr)
    print(r.stdout.strip())


def _label_strip(images: list[np.ndarray], gap: int = 4) -> np.ndarray:
    h = images[0].shape[0]
    white = np.ones((h, gap, 4), np.float32)
    parts = []
    for i, img in enumerate(images):
        parts += ([white] if i else []) + [img]
    return np.concatenate(parts, axis=1)


def main(out_dir: str) -> None:
    from nubis_addon.core import imageio

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as tmp:
        t = Path(tmp)
        size = ("--width", "480", "--height", "270")
        _preview(t / "r1", *size, "--redraws", "1")
        _preview(t / "r16", *size, "--redraws", "16", "--naive")
        _preview(t / "r64", *size, "--redraws", "64")
        row = [imageio.read_image(t / d / "0001.png") for d in ("r1", "r16", "r64")]
        imageio.write_image(out / "viewport_convergence.png", _label_strip(row))
        _preview(t / "orbit", "--width", "320", "--height", "180", "--frames", "1-24", "--orbit", "1.5")
        strip = [imageio.read_image(t / "orbit" / f"{f:04d}.png") for f in (1, 8, 16, 24)]
        imageio.write_image(out / "viewport_orbit.png", _label_strip(strip))
    print(f"wrote {out / 'viewport_convergence.png'} (1, 16, 64 redraws) and {out / 'viewport_orbit.png'}")


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else ".")
