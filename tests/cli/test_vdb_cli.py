"""`render`, `compare` and `benchmark --vdb FILE`: an artist's cloud with the preset's sky, and
one line for each bad file, no traceback, nothing written."""

from __future__ import annotations

import json

import pytest
from conftest import run_cli
from vdb_helpers import BAD_KINDS, bad_vdb, write_cumulus


@pytest.fixture(scope="module")
def cumulus(tmp_path_factory):
    return write_cumulus(tmp_path_factory.mktemp("vdb") / "cumulus.vdb")


def _env(tmp_path, cache_dir) -> dict:
    tmp = tmp_path / "tmp"
    tmp.mkdir(exist_ok=True)
    return {"TMPDIR": str(tmp), "NUBIS_CACHE_DIR": str(cache_dir)}


@pytest.mark.parametrize("kind", BAD_KINDS)
def test_a_bad_vdb_gets_one_line_and_writes_nothing(tmp_path, cache_dir, kind):
    path, words = bad_vdb(tmp_path, kind)
    out = tmp_path / "clouds.png"
    r = run_cli(
        "render",
        "--vdb",
        str(path),
        "--out",
        str(out),
        "--width",
        "32",
        "--height",
        "18",
        env=_env(tmp_path, cache_dir),
    )
    assert r.returncode == 1, r.stderr
    lines = [line for line in r.stderr.splitlines() if line.startswith("nubis:")]
    assert len(lines) == 1 and lines[0].startswith("nubis: error:") and words in lines[0], r.stderr[-1500:]
    assert "Traceback" not in r.stderr and "internal error" not in r.stderr
    assert not out.exists()


def test_too_many_clouds_and_a_lone_with_cloudscape_are_refused(tmp_path, cache_dir, cumulus):
    env = _env(tmp_path, cache_dir)
    out = tmp_path / "x.png"
    r = run_cli("render", *(["--vdb", str(cumulus)] * 5), "--out", str(out), env=env)
    assert r.returncode == 1 and "at most 4 VDB clouds are drawn at once" in r.stderr
    r = run_cli("render", "--with-cloudscape", "--out", str(out), env=env)
    assert r.returncode == 1 and "--with-cloudscape goes with --vdb" in r.stderr
    assert not out.exists()


def test_render_vdb_draws_the_cloud_alone_or_with_the_cloudscape(tmp_path, cache_dir, cumulus):
    from nubis_addon.core import imageio

    env = _env(tmp_path, cache_dir)
    alone, both = tmp_path / "alone.exr", tmp_path / "both.exr"
    r = run_cli("render", "--vdb", str(cumulus), "--out", str(alone), "--width", "96", "--height", "54", env=env)
    assert r.returncode == 0, r.stderr
    r = run_cli(
        "render",
        "--vdb",
        str(cumulus),
        "--with-cloudscape",
        "--out",
        str(both),
        "--width",
        "96",
        "--height",
        "54",
        env=env,
    )
    assert r.returncode == 0, r.stderr
    a, b = imageio.read_image(alone), imageio.read_image(both)
    cover_alone, cover_both = (a[..., 3] > 0.5).mean(), (b[..., 3] > 0.5).mean()
    assert 0.03 < cover_alone < 0.4 and cover_both > cover_alone + 0.05


def test_compare_vdb_renders_the_same_file_in_cycles(tmp_path, cache_dir, cumulus):
    """Cycles renders the cloud's own file with the clouds' material: the silhouettes agree."""
    out = tmp_path / "cmp"
    r = run_cli(
        "compare", "--vdb", str(cumulus), "--out", str(out), "--width", "64", "--height", "36", "--samples", "16",
        "--draft", env=_env(tmp_path, cache_dir),
    )  # fmt: skip
    assert r.returncode == 0, r.stderr
    m = json.loads((out / "metrics.json").read_text())
    assert m["alpha_rmse"] < 0.03 and m["silhouette_iou"] > 0.9
    assert m["luminance_rel_error"] < 0.35  # 16 samples of Cycles: grainy; the README has the converged numbers
