"""Damaged VDB files through `render`, `compare` and `benchmark --vdb`, under an 8 GB address-space cap as
the issue's machine has: each exits 1 with one sentence, no traceback, no internal error, no line over
1,000 characters, nothing written (docs/vdb.md#damaged-files)."""

from __future__ import annotations

import random
import resource
import subprocess

import pytest
from conftest import run_cli
from vdb_helpers import ball, write_cumulus, write_grid, write_two_voxels

CAP = 8 * 1024**3


def _capped() -> None:
    resource.setrlimit(resource.RLIMIT_AS, (CAP, CAP))


def run_capped(tmp_path, cache_dir, *args: str) -> subprocess.CompletedProcess:
    tmp = tmp_path / "tmp"
    tmp.mkdir(exist_ok=True)
    env = {"TMPDIR": str(tmp), "NUBIS_CACHE_DIR": str(cache_dir)}
    return run_cli(*args, env=env, timeout=300, preexec_fn=_capped)


@pytest.fixture(scope="module")
def whole(tmp_path_factory):
    path = tmp_path_factory.mktemp("whole") / "cloud.vdb"
    write_cumulus(path, n_xy=14, n_z=14)
    return path.read_bytes()


def _one_error_line(r: subprocess.CompletedProcess, words: str) -> str:
    assert r.returncode == 1, r.stderr[-2000:]
    lines = [line for line in r.stderr.splitlines() if line.startswith("nubis:")]
    assert len(lines) == 1 and lines[0].startswith("nubis: error:") and words in lines[0], r.stderr[-2000:]
    assert "Traceback" not in r.stderr and "internal error" not in r.stderr
    assert max(len(line) for line in r.stderr.splitlines()) < 1000
    return lines[0]


# A cut in the header's metadata, in the descriptor, in the grid's metadata and past it, and the first 64
# bytes followed by garbage: through each command once.
CASES = [("render", 70), ("render", 200), ("compare", 137), ("benchmark", 345), ("render", "garbage")]


@pytest.mark.parametrize("command, cut", CASES)
def test_a_damaged_vdb_is_one_sentence_in_every_command(tmp_path, cache_dir, whole, command, cut):
    path = tmp_path / "damaged.vdb"
    if cut == "garbage":
        rng = random.Random(5)
        path.write_bytes(whole[:64] + bytes(rng.randrange(256) for _ in range(6000)))
    else:
        path.write_bytes(whole[:cut])
    out = tmp_path / ("out" if command != "render" else "clouds.png")
    size = ["--width", "32", "--height", "18"]
    r = run_capped(tmp_path, cache_dir, command, "--vdb", str(path), "--out", str(out), *size)
    line = _one_error_line(r, "is damaged (")
    assert "export or copy the file again" in line
    assert not out.exists()


def test_a_nameless_grid_is_refused_before_any_work(tmp_path, cache_dir):
    path = write_grid(tmp_path / "nameless.vdb", ball(), name="")
    out = tmp_path / "clouds.png"
    r = run_capped(tmp_path, cache_dir, "render", "--vdb", str(path), "--out", str(out), "--width", "32")
    _one_error_line(r, "holds one float grid with no name, which Blender's renderers cannot draw")
    assert not out.exists()


def test_a_grid_too_wide_for_the_index_is_refused_before_any_work(tmp_path, cache_dir):
    """Wider than the index texture holds even at the coarsest level (16 voxels to one per side); a grid
    narrower than that is drawn at a coarser level (tests/core/test_vdb_damaged.py)."""
    path = write_two_voxels(tmp_path / "wide.vdb", (16_400 * 16, 0, 0))
    out = tmp_path / "out"
    r = run_capped(tmp_path, cache_dir, "benchmark", "--vdb", str(path), "--out", str(out), "--width", "32")
    _one_error_line(r, "spans 262401 voxels along x")
    assert not out.exists()
